"""The grousered wheel's section of docs/results/wheel.md: its predictions beside the smooth wheel's, from
docs/results/wheel.json (the variants of scripts/wheel_study.py) and the two conditions files, as markdown.

    python scripts/wheel_grouser_table.py
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from finrft.data import wheel_dir

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results" / "wheel.json"
WHEELS = {"grouser": "grouser-", "smooth": ""}
# finrft's variants and the experimenters' own predictions (their columns, held at each trial's sinkage)
MODELS = {"plain RFT, held": "li2013-cmu-held", "deforming surface, held": "li2013-cmu-deforming-held",
          "plain RFT, free under the load": "li2013-cmu-free",
          "deforming surface, free under the load": "li2013-cmu-deforming-free"}
THEIRS = {"theirs: plain RFT, held": "rft", "theirs: RFT + pile-up, held": "rftsand"}
BRAKED = -0.45  # s = -1, -0.7, -0.5


def conditions(wheel: str) -> list[dict[str, str]]:
    with open(wheel_dir() / f"{wheel}_wheel_by_condition.csv", newline="") as f:
        return list(csv.DictReader(f))


def rmse(predicted: list[float], measured: list[float]) -> float:
    return float(np.sqrt(np.mean((np.array(predicted) - np.array(measured)) ** 2)))


def summary(results: dict) -> str:
    """RMSE against each wheel's measurements over beta <= 60 deg: all 45 conditions, and the braked ones."""
    lines = ["| wheel | model | Fx (N) | Fy (N) | Fz (N) | sinkage (mm) | braked: Fx / Fy (N) |", "|" + "---|" * 7]
    for wheel, prefix in WHEELS.items():
        data = conditions(wheel)
        keep = [i for i, c in enumerate(data) if float(c["beta_deg"]) <= 60]
        braked = [i for i in keep if float(data[i]["slip_meas_mean"]) < BRAKED]
        measured = {k: [float(c[f"{k}_meas_N"]) for c in data] for k in ("Fx", "Fy", "Fz")}
        measured["sinkage"] = [float(c["sinkage_mm"]) for c in data]
        models = {label: {k: [r[f"{k}_N"] for r in results[prefix + name]["rows"]] for k in ("Fx", "Fy", "Fz")}
                  | {"sinkage": [r["sinkage_mm"] for r in results[prefix + name]["rows"]]}
                  for label, name in MODELS.items() if prefix + name in results}
        models |= {label: {k: [float(c[f"{k}_{column}_N"]) for c in data] for k in ("Fx", "Fy", "Fz")}
                   for label, column in THEIRS.items()}
        for label, p in models.items():
            held = "held" in label

            def cell(key: str, rows: list[int]) -> str:
                if key not in p or (key == "sinkage" and held) or (key == "Fz" and not held):
                    return "–"
                return f"{rmse([p[key][i] for i in rows], [measured[key][i] for i in rows]):.2f}"
            lines.append(f"| {wheel} | {label} | {cell('Fx', keep)} | {cell('Fy', keep)} | {cell('Fz', keep)} | "
                         f"{cell('sinkage', keep)} | {cell('Fx', braked)} / {cell('Fy', braked)} |")
    return "\n".join(lines)


def side_by_side(results: dict, beta: float) -> str:
    """At one slip angle, per slip: measured and predicted drawbar pull (and side force at beta > 0) held at the
    measured sinkage, plain and on the deforming surface, and the sinkage free under the measured load, for the
    grousered wheel beside the smooth one."""
    keys = ["Fx"] + (["Fy"] if beta > 0 else [])
    head = ["s"]
    for wheel in WHEELS:
        for k in keys:
            head.append(f"{wheel} {k}: measured / plain / deforming (N)")
        head.append(f"{wheel} sinkage: measured / plain / deforming, free (mm)")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    tables = {}
    for wheel, prefix in WHEELS.items():
        data = conditions(wheel)
        rows = [i for i, c in enumerate(data) if float(c["beta_deg"]) == beta]
        runs = [results.get(prefix + name, {}).get("rows") for name in MODELS.values()]
        tables[wheel] = [(data[i], *(r[i] if r else None for r in runs)) for i in rows]
    for n in range(len(tables["smooth"])):
        cells = [f"{float(tables['grouser'][n][0]['slip_meas_mean']):+.2f}"]
        for wheel in WHEELS:
            c, h, d, f, fd = tables[wheel][n]
            for k in keys:
                cells.append(" / ".join([f"{float(c[f'{k}_meas_N']):.1f}"] +
                                        [f"{x[f'{k}_N']:.1f}" if x else "–" for x in (h, d)]))
            cells.append(" / ".join([f"{float(c['sinkage_mm']):.1f}"] +
                                    [f"{x['sinkage_mm']:.1f}" if x else "–" for x in (f, fd)]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    results = json.loads(RESULTS.read_text())
    print(summary(results))
    for beta in (0.0, 45.0):
        print(f"\nbeta = {beta:g} deg\n")
        print(side_by_side(results, beta))


if __name__ == "__main__":
    main()
