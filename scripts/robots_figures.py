"""The figures of docs/guide/robots.md: the example robots of mjcf/ run with the Python API (finrft.attach and
MuJoCo's own step at 0.1 ms, where the explicit surface forces have converged to about 1 %).

    python scripts/robots_figures.py [--out docs/guide] [--wheel-data smooth_wheel_by_condition.csv]

writes robots-swimmer.png (the swimmer's track), robots-hexapod.png (the hexapod's speed) and robots-wheel.png (the
wheel's forces against slip; with --wheel-data, the smooth-wheel experiments' condition means at slip angle 0 for
comparison: qishuny/3D-RFT-wheel, output/all_smooth_data_2.mat, as extracted in finrft's wheel data). About a
minute on one core.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from scipy import special  # noqa: E402

import finrft  # noqa: E402
from finrft.models import mjcf_path  # noqa: E402

DT = 1e-4
SAND = dict(law="rft3d", rho_c=1500.0, mu_int=0.4, mu_surf=0.4)
SIZE = (4.2, 3.0)  # inches: small PNGs


def build(name: str, bodies: list[str], element_size: float, **medium) -> tuple[mujoco.MjModel, mujoco.MjData]:
    spec = mujoco.MjSpec.from_file(str(mjcf_path(f"{name}_scene.xml")))
    finrft.attach(spec, bodies, element_size=element_size, **medium)
    model = spec.compile()
    model.opt.timestep = DT
    return model, mujoco.MjData(model)


def swimmer(out: Path) -> str:
    """The head's and the centre of mass's tracks seen from above, and the body's outline once a second."""
    model, data = build("sand_swimmer", [f"link{i}" for i in range(1, 8)], 0.005, **SAND)
    theta0, f, duration = math.radians(60), 1.0, 5.0
    head, com, outlines = [], [], []
    links = [model.body(f"link{i}").id for i in range(1, 8)]
    tail = model.site("tail").id
    for k in range(int(round(duration / DT))):
        data.ctrl[:] = min(data.time / 0.5, 1.0) * theta0 * np.sin(2 * math.pi * f * data.time
                                                                   - np.arange(1, 7) * math.pi / 3)
        mujoco.mj_step(model, data)
        if k % 50 == 0:
            head.append(data.xpos[links[0], :2].copy())
            com.append((data.time, *data.subtree_com[links[0]]))
        if (k + 1) % int(round(1.0 / DT)) == 0:
            outlines.append(np.vstack([data.xpos[links, :2], data.site_xpos[tail, :2]]))
    head, com = np.array(head), np.array(com)
    window = com[:, 0] >= 1.0
    speed = np.polyfit(com[window, 0], com[window, 1], 1)[0]
    eta = speed / (f * 6 * 0.04 * special.j0(theta0))
    fig, ax = plt.subplots(figsize=(5.6, 2.4))
    ax.plot(1e3 * head[:, 0], 1e3 * head[:, 1], lw=0.8, label="head")
    ax.plot(1e3 * com[:, 1], 1e3 * com[:, 2], lw=1.5, label="centre of mass")
    for i, line in enumerate(outlines):
        ax.plot(1e3 * line[:, 0], 1e3 * line[:, 1], "k-", lw=1.2, alpha=0.3 + 0.14 * i)
    ax.set_aspect("equal")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(f"sand-swimmer, rft3d: {1e3 * speed:.0f} mm/s, eta = {eta:.2f}", fontsize=9)
    ax.legend(fontsize=7, loc="lower right", ncols=2)
    fig.tight_layout()
    fig.savefig(out / "robots-swimmer.png", dpi=90)
    plt.close(fig)
    return f"swimmer: {1e3 * speed:.1f} mm/s, eta {eta:.3f}, depth at the end {-1e3 * com[-1, 3]:.1f} mm"


def hexapod(out: Path) -> str:
    """The chassis's forward speed (mean over each gait cycle of 0.5 s) and its height, walking at 2 Hz."""
    model, data = build("hexapod", ["chassis", "front_left", "middle_left", "rear_left", "front_right",
                                    "middle_right", "rear_right"], 0.004, **SAND)
    omega, duration = 4 * math.pi, 5.0
    track = []
    for k in range(int(round(duration / DT))):
        data.ctrl[:] = omega * min(data.time / 0.5, 1.0)
        mujoco.mj_step(model, data)
        if k % 10 == 0:
            track.append((data.time, *data.qpos[:3]))
    t, x, y, z = np.array(track).T
    ends = np.arange(0, len(t), 500)  # a gait cycle (0.5 s) is 500 samples
    tc = t[ends[1:]]
    speed = np.hypot(np.diff(x[ends]), np.diff(y[ends])) / np.diff(t[ends])
    fig, ax = plt.subplots(figsize=SIZE)
    ax.step(tc, speed, where="pre", label="speed, per gait cycle")
    ax.axhline(omega * 0.04, color="k", ls="--", lw=0.8, label="legs rolling without slip, omega 2R")
    ax.set_xlabel("time, s")
    ax.set_ylabel("forward speed, m/s")
    ax.set_ylim(0, 0.6)
    height = ax.twinx()
    height.plot(t, 1e3 * z, lw=0.6, color="C1")
    height.set_ylabel("chassis centre above the surface, mm", color="C1", fontsize=8)
    height.set_ylim(0, 60)
    ax.set_title("hexapod at 2 Hz, rft3d", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(out / "robots-hexapod.png", dpi=90)
    plt.close(fig)
    late = tc >= 1.0
    return f"hexapod: {speed[late].mean():.3f} m/s after 1 s, chassis at {1e3 * z[t >= 1].mean():.1f} mm"


SLIPS = (-0.5, -0.2, 0.0, 0.167, 0.5, 0.75, 0.9)


def wheel_at(slip: float, speed: float = 0.01, duration: float = 3.0) -> tuple[float, float, float]:
    """Mean Fx, Fz (N, of the sand on the wheel) and sinkage (m) of the driven wheel at slip angle 0, over the
    second half of the run; the carriage and the spin are set to their prescribed motion before every step."""
    model, data = build("wheel_rig", ["wheel"], 0.004, law="li2013", zeta=0.6)
    radius = 0.0625
    # s = 1 - v/(omega R) driving, s = omega R / v - 1 braking (the experiments' convention)
    omega = speed / (radius * (1 - slip)) if slip >= 0 else (1 + slip) * speed / radius
    carriage, spin, angle = (model.joint(j) for j in ("carriage", "spin", "slip_angle"))
    lift = model.joint("lift").dofadr[0]
    data.qpos[model.joint("lift").qposadr[0]] = -0.012  # near the static sinkage, so the drop is small
    rows = []
    for _ in range(int(round(duration / DT))):
        data.qvel[carriage.dofadr[0]], data.qvel[spin.dofadr[0]], data.qvel[angle.dofadr[0]] = speed, omega, 0.0
        data.qpos[carriage.qposadr[0]], data.qpos[spin.qposadr[0]] = speed * data.time, omega * data.time
        mujoco.mj_step(model, data)
        if data.time >= duration / 2:
            rows.append((data.qfrc_passive[carriage.dofadr[0]], data.qfrc_passive[lift], -data.qpos[lift]))
    return tuple(np.mean(rows, axis=0))


def measured(path: Path) -> np.ndarray:
    """(slip, Fx, Fz, sinkage m) of the experiments' condition means at slip angle 0."""
    with path.open() as f:
        rows = [r for r in csv.DictReader(f) if float(r["beta_deg"]) == 0]
    return np.array([(float(r["slip_model"]), float(r["Fx_meas_N"]), float(r["Fz_meas_N"]),
                      1e-3 * float(r["sinkage_mm"])) for r in rows])


def wheel(out: Path, data_path: Path | None) -> str:
    results = np.array([wheel_at(s) for s in SLIPS])
    fig, ax = plt.subplots(figsize=SIZE)
    ax.plot(SLIPS, results[:, 0], "o-", label="Fx, finrft (li2013, zeta 0.6)")
    ax.plot(SLIPS, results[:, 1], "s-", label="Fz, finrft (free sinkage)")
    if data_path is not None:
        m = measured(data_path)
        m = m[m[:, 0] >= min(SLIPS)]
        ax.plot(m[:, 0], m[:, 1], "o", mfc="none", color="C0", label="Fx, measured")
        ax.plot(m[:, 0], m[:, 2], "s", mfc="none", color="C1", label="Fz, measured")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("slip s")
    ax.set_ylabel("force of the sand on the wheel, N")
    ax.set_title("wheel rig, 21 N, 10 mm/s, slip angle 0", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "robots-wheel.png", dpi=90)
    plt.close(fig)
    return "wheel: " + "; ".join(f"s {s:+.2f}: Fx {fx:.2f} N, Fz {fz:.2f} N, sinkage {1e3 * z:.1f} mm"
                                 for s, (fx, fz, z) in zip(SLIPS, results))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/guide"), help="folder of the PNGs")
    parser.add_argument("--wheel-data", type=Path, help="smooth_wheel_by_condition.csv, to compare the wheel")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for line in (swimmer(args.out), hexapod(args.out), wheel(args.out, args.wheel_data)):
        print(line)


if __name__ == "__main__":
    main()
