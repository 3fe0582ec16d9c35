"""Instructions per step of each fixed-step implicit method and of MuJoCo's explicit step, counted by callgrind.

    python scripts/step_counts.py [ROBOT ...]     (default: the examples; a few minutes a robot)

For each robot (an example or a battery robot, as `finrft bench steps --robot`), ten steps of each method from the
state `finrft bench steps` starts from (`finrft.studies.bench.step_start`, the stepper's history from the run), in
one process under `valgrind --tool=callgrind --toggle-collect=implicit_step --toggle-collect=mj_step`, each ten
bracketed by os.getppid(), where `--dump-before=getppid` closes a part. Prints a Markdown table: thousands of
instructions a step and the implicit/explicit ratio.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

STEPS = 10
TOGGLES = ("implicit_step", "mj_step")


def count(name: str) -> None:
    """Under callgrind: the steps, each method's ten in a part of their own; each part's name, in order, on stdout."""
    from finrft import native
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    from finrft.studies.bench import step_start
    from finrft.studies.frontier import BATTERY, STEP_METHODS, battery_scene
    scene = load_scene(battery_scene(name) if name in BATTERY else example(name), cls=UserScene)
    parts: list[str] = []

    def part(label: str) -> None:
        os.getppid()
        parts.append(label)
    with native.untimed():
        for method in STEP_METHODS:
            implicit, explicit = step_start(scene.replace(**{"sim.method": method}), scene.sim.dt)
            part("start")
            implicit(STEPS)
            part(method)
            if method == STEP_METHODS[0]:
                explicit(STEPS)
                part("explicit")
    print(json.dumps(parts))


def main(names: list[str]) -> int:
    from finrft.experiments.user_model import EXAMPLES
    from finrft.studies.frontier import BATTERY, STEP_METHODS
    unknown = [n for n in names if n not in EXAMPLES and n not in BATTERY]
    if unknown:
        print(f"step_counts: no robot named {', '.join(unknown)} (the examples and the battery: "
              f"{', '.join((*EXAMPLES, *BATTERY))})", file=sys.stderr)
        return 2
    if shutil.which("valgrind") is None:
        print("step_counts: valgrind is not on PATH; install it (apt-get install valgrind)", file=sys.stderr)
        return 2
    print("| robot | explicit step, k instructions | " + " | ".join(f"`{m}`, k (ratio)" for m in STEP_METHODS)
          + " |\n|---|---:|" + "---:|" * len(STEP_METHODS))
    for name in names or EXAMPLES:
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run(["valgrind", "--tool=callgrind", *(f"--toggle-collect={t}" for t in TOGGLES),
                                  "--dump-before=getppid", f"--callgrind-out-file={tmp}/cg.%p", sys.executable,
                                  __file__, "--count", name], capture_output=True, text=True, check=True)
            labels = json.loads(out.stdout.splitlines()[-1])
            parts = sorted(Path(tmp).glob("cg.*.*"), key=lambda p: int(p.suffix[1:]))
            totals = [int(re.search(r"^totals: (\d+)", p.read_text(), re.M).group(1)) for p in parts]
        per_step = {label: total / STEPS for label, total in zip(labels, totals) if label != "start"}
        explicit = per_step["explicit"]
        print(f"| {name} | {explicit / 1e3:.0f} | " + " | ".join(
            f"{per_step[m] / 1e3:.0f} ({per_step[m] / explicit:.2f})" for m in STEP_METHODS) + " |")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--count"]:
        count(sys.argv[2])
    else:
        sys.exit(main(sys.argv[1:]))
