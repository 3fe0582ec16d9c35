"""The instructions of one run of the bench's wheel (finrft.studies.bench: WHEEL_SURFACE_RUN, held at slip -0.5,
or WHEEL_SURFACE_DRIVEN, at slip 0.5) on the flat or the deforming surface, counted by callgrind around the second
of two runs (the first makes the one-off costs of a process: imports, caches), the one measure of cost that holds
still on a shared machine (docs/results/wheel.md, Cost):

    valgrind --tool=callgrind --instr-atstart=no python scripts/wheel_surface_cost.py held deforming
    # the count: the line "Collected" of valgrind's report; held or driven; flat, deforming or first-run
"""

import os
import subprocess
import sys

from finrft.experiments.wheel import DEFORMING_GRID, default_scene, run_wheel
from finrft.studies.bench import WHEEL_SURFACE_DRIVEN, WHEEL_SURFACE_RUN

RUNS = {"held": WHEEL_SURFACE_RUN, "driven": WHEEL_SURFACE_DRIVEN}
SURFACES = {"flat": {}, "deforming": {"medium.surface": "deforming", "medium.pile_factor": 0.7, **DEFORMING_GRID}}
# the deforming surface as first run: stepped every half grid spacing, relaxed to within 0.001 of the angle of repose
SURFACES["first-run"] = {**SURFACES["deforming"], "medium.surface_update": 0.5, "medium.relax_tolerance": 0.001}


def main(run: str, surface: str) -> None:
    scene = default_scene(**RUNS[run], **SURFACES[surface])
    run_wheel(scene)
    for switch in ("on", "off"):
        subprocess.run(["callgrind_control", "-i", switch, str(os.getpid())], capture_output=True, check=False)
        if switch == "on":
            fx = run_wheel(scene).summary()["Fx_N"]
    print(f"{run} {surface}: Fx {fx:+.4f} N")


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in RUNS or sys.argv[2] not in SURFACES:
        print(f"usage: {sys.argv[0]} {{{','.join(RUNS)}}} {{{','.join(SURFACES)}}}", file=sys.stderr)
        sys.exit(2)
    main(*sys.argv[1:])
