"""What a depth-dependent alpha_z would change (docs/results/wheel.md): Li 2013 in 3D integrated over the exact
cylinder at each measured sinkage of the slip angles <= 60 deg (the quadrature of tests/test_wheel.py), with a
constant zeta (the plate calibration's 0.46, the experimenters' 0.6) or with zeta replaced at every depth z by the
calibration's power law alpha_z(z) = 1.9153 z^0.3648 N/cm^3 (z in m), which finrft's engine does not offer.

    python scripts/wheel_depth_law.py      # about a minute
"""

import csv
import math
import sys
from pathlib import Path

import numpy as np

from finrft.data import wheel_dir

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_wheel import quadrature_force  # noqa: E402

SCALES = {"zeta 0.46 (plate, least squares)": 0.46, "zeta 0.6 (the experimenters')": 0.6,
          "alpha_z(z) = 1.9153 z^0.3648 (plate, power law)": lambda z: 1.9153 * np.maximum(z, 1e-9) ** 0.3648}


def main() -> None:
    with open(wheel_dir() / "smooth_wheel_by_condition.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if float(r["beta_deg"]) <= 60]
    measured = np.array([[float(r[f"F{k}_meas_N"]) for k in "xyz"] for r in rows])
    for name, zeta in SCALES.items():
        predicted = np.array([quadrature_force(float(r["slip_meas_mean"]), math.radians(float(r["beta_deg"])),
                                               1e-3 * float(r["sinkage_mm"]), n=600, zeta=zeta) for r in rows])
        error = predicted - measured
        r = [np.corrcoef(predicted[:, i], measured[:, i])[0, 1] for i in range(3)]
        print(f"{name}: RMSE Fx, Fy, Fz {np.sqrt((error ** 2).mean(0)).round(2)} N, bias {error.mean(0).round(2)} N, "
              f"r {np.round(r, 3)}")


if __name__ == "__main__":
    main()
