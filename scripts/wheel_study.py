"""The wheel in sand against the smooth-wheel experiments (docs/results/wheel.md): every condition of finrft's
wheel data run by `finrft wheel --data` for each law, medium and mode, the statistics in docs/results/wheel.json,
the figures docs/results/wheel-NAME.png, the table printed as markdown. DRFT's term checked on one condition.

    python scripts/wheel_study.py            # about 40 minutes on one core

Each variant is one command line (printed as it runs), the JSON of its last line kept whole.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from finrft.data import wheel_dir

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "results"
DATA = str(wheel_dir() / "smooth_wheel_by_condition.csv")
# Held at the measured sinkage, the forces are steady from the start: 1 s, averaged from 0.5 s. Free, the wheel
# starts at its equilibrium under the measured load: the command's default 3 s, averaged from 1 s.
HELD = ["--sinkage-from-data", "--set", "sim.duration=1", "--set", "sim.settle=0.5"]
FREE = ["--load-from-data"]
RFT3D = ["--medium", "sand_3d_rft_code", "--set", "medium.law=rft3d", "--set", "medium.surface_friction=0.1806"]
VARIANTS = {
    "li2013-cmu-held": ["--medium", "wheel_sand_cmu", *HELD],
    "li2013-plate-held": ["--medium", "wheel_sand_plate", *HELD],
    "li2013-plate-free": ["--medium", "wheel_sand_plate", *FREE],
    "li2013-cmu-free": ["--medium", "wheel_sand_cmu", *FREE],
    "rft3d-held": [*RFT3D, *HELD],
    "rft3d-free": [*RFT3D, *FREE],
}
# DRFT's term at the experiments' 10 mm/s: lambda = 1 on an assumed bulk density of 1600 kg/m^3 (the sand's is not
# known), on the locked wheel at 60 deg (its largest leading normal speeds, 10 mm/s).
DRFT = ["--slip", "-1", "--slip-angle", "60", "--sinkage", "30", "--medium", "wheel_sand_plate", "--set",
        "medium.bulk_density=1600"]


def finrft(args: list[str]) -> dict:
    command = [sys.executable, "-m", "finrft", "wheel", *args, "--json", "--quiet"]
    print("finrft wheel " + " ".join(args), file=sys.stderr, flush=True)
    done = subprocess.run(command, capture_output=True, text=True, cwd="/")
    if done.returncode != 0:
        raise SystemExit(f"failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(results: dict[str, dict]) -> str:
    lines = ["| variant | subset | Fx RMSE / bias / r (N) | Fy RMSE / bias / r (N) | Fz RMSE / bias / r (N) | "
             "sinkage RMSE / bias / r (mm) |", "|---|---|---|---|---|---|"]
    for name, out in results.items():
        for subset, label in (("beta_le_60", "β ≤ 60°"), ("all", "all β")):
            part = out["compared"][subset]
            cells = []
            for key in ("Fx_N", "Fy_N", "Fz_N", "sinkage_mm"):
                v = part[key]
                r = "–" if v["r"] is None else f"{v['r']:.2f}"
                cells.append(f"{v['rmse']:.2f} / {v['bias']:+.2f} / {r}")
            lines.append(f"| {name} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    results = {}
    for name, args in VARIANTS.items():
        out = finrft(["--data", DATA, *args, "--plot", str(OUT / f"wheel-{name}.png"), "--force"])
        results[name] = {"command": "finrft wheel --data smooth_wheel_by_condition.csv " + " ".join(args),
                         **out}
        (OUT / "wheel.json").write_text(json.dumps(results, indent=1) + "\n")
    plain, drft = finrft(DRFT), finrft([*DRFT, "--set", "medium.drft_lambda=1"])
    results["drft_check"] = {"command": "finrft wheel " + " ".join(DRFT) + " [--set medium.drft_lambda=1]",
                             "without": {k: plain[k] for k in ("Fx_N", "Fy_N", "Fz_N")},
                             "with": {k: drft[k] for k in ("Fx_N", "Fy_N", "Fz_N")}}
    (OUT / "wheel.json").write_text(json.dumps(results, indent=1) + "\n")
    print(table({k: v for k, v in results.items() if "compared" in v}))
    print("DRFT (lambda 1):", results["drft_check"])


if __name__ == "__main__":
    main()
