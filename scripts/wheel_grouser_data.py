"""The grousered wheel's data (finrft/data/wheel/grouser_wheel_by_condition.csv) from the wheel group's repository,
and the grousered wheel's geometry measured on their mesh (docs/results/wheel.md, finrft.experiments.wheel.GROUSERED).

    python scripts/wheel_grouser_data.py REPO [--write]

REPO: qishuny/3D-RFT-wheel at COMMIT, a checkout or a bare git directory (read with `git show COMMIT:PATH`). The
trials (output/all_grouser_data_2.mat) become condition means exactly as finrft's smooth-wheel file was made: the
same aggregation run on output/all_smooth_data_2.mat must give smooth_wheel_by_condition.csv back (checked here,
to the file's 6 significant digits). --write writes the grousered file; without it the script only checks and
prints.
"""

from __future__ import annotations

import collections
import csv
import io
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import scipy.io

from finrft.data import wheel_dir

COMMIT = "cdd8f8ffcba770a213210a26c6d3495d53cb009a"
NOMINAL_SPEED = 10.0  # mm/s, the hub's
RADIUS = 62.5         # mm: the wheel group's code turns the rim speed into omega with it, for both wheels
COLUMNS = ["wheel", "beta_deg", "Vry_label_mm_s", "n_trials", "slip_meas_mean", "slip_model", "rim_speed_meas_mm_s",
           "omega_model_rad_s", "sinkage_mm", "sinkage_sd_between_trials_mm",
           *(f"{c}_{k}" for c in ("Fx", "Fy", "Fz") for k in ("meas_N", "sd_between_trials_N", "sem_N",
                                                              "within_trial_std_N")),
           *(f"F{c}_{k}_N" for k in ("rft", "rftsand") for c in "xyz")]


def read(repo: Path, path: str) -> dict:
    """A .mat file of the repository at COMMIT."""
    if (repo / path).is_file():
        return scipy.io.loadmat(repo / path)
    blob = subprocess.run(["git", "--git-dir", str(repo), "show", f"{COMMIT}:{path}"], capture_output=True,
                          check=True).stdout
    return scipy.io.loadmat(io.BytesIO(blob))


def records(array: np.ndarray) -> list[dict[str, float]]:
    return [{k: float(np.asarray(r[k]).ravel()[0]) for k in r.dtype.names if np.asarray(r[k]).size == 1}
            for r in array.ravel()]


def slip_model(rim: float) -> float:
    return 1 - NOMINAL_SPEED / rim if rim > NOMINAL_SPEED else rim / NOMINAL_SPEED - 1


def by_condition(repo: Path, wheel: str) -> list[dict[str, float | str]]:
    """Condition means of one wheel's trials, with the experimenters' two predictions per trial averaged alike.
    Their frame (dataprocess.m): the data's Fx is minus their avg_Fy, Fy minus avg_Fx, Fz minus avg_Fz, the
    sinkage minus avg_Z (mm)."""
    trials = records(read(repo, f"output/all_{wheel}_data_2.mat")["all_results"])
    plain = records(read(repo, f"output/{wheel}RFT.mat")["RFToutput"])
    sand = records(read(repo, f"output/{wheel}RFTSand.mat")["RFToutput"])
    groups = collections.defaultdict(list)
    for t, p, s in zip(trials, plain, sand, strict=True):
        # the predictions are one per trial, in the trials' order, at the trial's own sinkage
        assert t["Vry"] == p["wr"] == s["wr"] and t["beta"] == p["beta"] == s["beta"]
        assert abs(t["avg_Z"] - p["depth"]) < 1e-4
        groups[(t["beta"], t["Vry"])].append((t, p, s))
    rows = []
    for (beta, rim), group in sorted(groups.items()):
        n = len(group)
        t = [g[0] for g in group]
        sinkage = [-x["avg_Z"] for x in t]
        row: dict[str, float | str] = {
            "wheel": wheel, "beta_deg": beta, "Vry_label_mm_s": rim, "n_trials": n,
            "slip_meas_mean": np.mean([x["slip"] for x in t]), "slip_model": slip_model(rim),
            "rim_speed_meas_mm_s": np.mean([x["avg_Vry"] for x in t]), "omega_model_rad_s": rim / RADIUS,
            "sinkage_mm": np.mean(sinkage), "sinkage_sd_between_trials_mm": np.std(sinkage, ddof=1)}
        for name, raw in (("Fx", "Fy"), ("Fy", "Fx"), ("Fz", "Fz")):
            values = [-x[f"avg_{raw}"] for x in t]
            sd = float(np.std(values, ddof=1))
            row.update({f"{name}_meas_N": np.mean(values), f"{name}_sd_between_trials_N": sd,
                        f"{name}_sem_N": sd / math.sqrt(n),
                        f"{name}_within_trial_std_N": np.mean([x[f"std_{raw}"] for x in t])})
        for k in "XYZ":
            row[f"F{k.lower()}_rft_N"] = np.mean([g[1][f"Force{k}"] for g in group])
            row[f"F{k.lower()}_rftsand_N"] = np.mean([g[2][f"Force{k}"] for g in group])
        rows.append(row)
    return rows


def check_smooth(repo: Path) -> float:
    """The largest relative difference between the smooth wheel's shipped file and this aggregation."""
    with open(wheel_dir() / "smooth_wheel_by_condition.csv", newline="") as f:
        shipped = list(csv.DictReader(f))
    worst = 0.0
    for old, new in zip(shipped, by_condition(repo, "smooth"), strict=True):
        for key, value in new.items():
            if key != "wheel" and key in old:
                worst = max(worst, abs(float(old[key]) - value) / max(abs(value), 1e-3))
    return worst


def geometry(repo: Path) -> dict[str, float]:
    """The grousered wheel's dimensions measured on the element mesh their RFT ran on (data/grousered_wheel_125.mat:
    face centres, unit normals and areas, mm, the axle along x): the rim's and the tips' radius (mean radius of the
    outward faces below and above 60 mm), the grousers (clusters of tip faces around the wheel), their flanks'
    angular width (faces whose normal is along the rim's tangent) and the width (extent along the axle)."""
    mesh = read(repo, "data/grousered_wheel_125.mat")
    p, n, area = mesh["Points"], mesh["Normals"], mesh["Area"].ravel()
    r = np.hypot(p[1], p[2])
    theta = np.degrees(np.arctan2(p[2], p[1]))
    radial = (n[1] * p[1] + n[2] * p[2]) / r
    tangential = (n[2] * p[1] - n[1] * p[2]) / r
    outward = radial > 0.99
    tips = outward & (r > 60)
    rim = outward & (r < 60)
    ordered = np.sort(theta[tips])
    clusters = 1 + int(np.sum(np.diff(ordered) > 1.0)) - int(ordered[-1] - ordered[0] > 359)
    # a grouser's flanks: the pair of tangent-facing planes that bound solid between them (normals facing apart)
    flank = np.abs(tangential) > 0.999
    lead = np.sort(theta[flank & (tangential > 0)])
    trail = np.sort(theta[flank & (tangential < 0)])
    lead_planes = np.array([c.mean() for c in np.split(lead, np.flatnonzero(np.diff(lead) > 0.5) + 1)])
    trail_planes = np.array([c.mean() for c in np.split(trail, np.flatnonzero(np.diff(trail) > 0.5) + 1)])
    widths = [float(np.min((lp - trail_planes) % 360)) for lp in lead_planes]
    return {"faces": len(area), "area_mm2": float(area.sum()), "rim_radius_mm": float(np.average(r[rim], weights=area[rim])),
            "tip_radius_mm": float(np.average(r[tips], weights=area[tips])), "grousers": clusters,
            "grouser_width_deg_mean": float(np.mean(widths)), "grouser_width_deg_min": float(np.min(widths)),
            "grouser_width_deg_max": float(np.max(widths)), "width_mm": float(np.ptp(p[0])),
            "flank_height_mm": float(area[flank].sum() / (2 * clusters) / np.ptp(p[0]))}


def main(argv: list[str]) -> None:
    if not argv or argv[0].startswith("-"):
        raise SystemExit(__doc__)
    repo = Path(argv[0])
    print(f"smooth: shipped file against this aggregation, largest relative difference {check_smooth(repo):.2g}")
    for key, value in geometry(repo).items():
        print(f"grousered mesh: {key} = {value:.6g}")
    rows = by_condition(repo, "grouser")
    print(f"grouser: {len(rows)} conditions from {sum(int(r['n_trials']) for r in rows)} trials")
    if "--write" in argv:
        path = wheel_dir() / "grouser_wheel_by_condition.csv"
        with open(path, "w", newline="") as f:
            out = csv.writer(f, lineterminator="\n")
            out.writerow(COLUMNS)
            for row in rows:
                out.writerow([row[c] if isinstance(row[c], str) else f"{row[c]:.6g}" for c in COLUMNS])
        print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
