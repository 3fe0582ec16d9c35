"""The figures of docs/guide/robots.md: the example robots of mjcf/ run as `finrft run --example NAME` runs them
(`finrft.run_robot` on their TOML scenes, at the scenes' numerics).

    python scripts/robots_figures.py [--out docs/guide]

writes robots-swimmer.png (the swimmer's track from above, 5 s), robots-hexapod.png (the hexapod's speed and its
chassis's height, 5 s) and robots-wheel.png (the wheel's drawbar pull and sinkage against slip at slip angle 0,
SLIPS, 6 s each instead of the scene's 10 s, with the smooth-wheel experiments' condition means from finrft's wheel
data: `finrft.data.wheel_dir()`). About three minutes on one core.
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
from finrft.data import wheel_dir  # noqa: E402
from finrft.experiments.user_model import example  # noqa: E402
from finrft.models import mjcf_path  # noqa: E402
from finrft.scene import UserScene, load_scene  # noqa: E402

SIZE = (4.2, 3.0)  # inches: small PNGs
LINK, THETA0 = 0.04, math.radians(60)  # the swimmer's link length and joint amplitude (mjcf/sand_swimmer.toml)
WAVELENGTH = 6 * LINK * special.j0(THETA0)  # the wave's length along the travel (tests/test_robots.py)


def run(name: str, **overrides: float) -> finrft.Result:
    """The example's run at its scene's numerics; no companion run (the figures need no error estimate)."""
    return finrft.run_robot(load_scene(example(name), overrides=overrides, cls=UserScene), max_error=None)


def swimmer(out: Path) -> str:
    """The head's and the centre of mass's tracks seen from above, and the body's outline once a second."""
    result = run("sand_swimmer")
    s = result.summary()
    t, links = result.time, result.body_position  # (T, 7, 3): link1 (the head) .. link7
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("sand_swimmer_scene.xml")))
    tail_offset = model.site_pos[model.site("tail").id]  # in link7's frame
    tail_quat = result.link_quat[:, model.body("link7").id - 1]
    tail = np.empty((len(t), 3))
    for k, q in enumerate(tail_quat):
        mujoco.mju_rotVecQuat(tail[k], tail_offset, q)
    tail += links[:, -1]
    vx, vy, _ = s["com_velocity_m_s"]
    eta = vx / (1.0 * WAVELENGTH)
    fig, ax = plt.subplots(figsize=(5.6, 2.4))
    ax.plot(1e3 * links[:, 0, 0], 1e3 * links[:, 0, 1], lw=0.8, label="head")
    ax.plot(1e3 * result.com_position[:, 0], 1e3 * result.com_position[:, 1], lw=1.5, label="centre of mass")
    for second in range(1, int(t[-1] + 1e-9) + 1):
        k = int(np.argmin(np.abs(t - second)))
        line = np.vstack([links[k, :, :2], tail[k, :2]])
        ax.plot(1e3 * line[:, 0], 1e3 * line[:, 1], "k-", lw=1.2, alpha=0.3 + 0.14 * (second - 1))
    ax.set_aspect("equal")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(f"sand-swimmer, li2013 in glass beads: {1e3 * vx:.1f} mm/s, eta = {eta:.2f}", fontsize=9)
    ax.legend(fontsize=7, loc="lower right", ncols=2)
    fig.tight_layout()
    fig.savefig(out / "robots-swimmer.png", dpi=90)
    plt.close(fig)
    return (f"swimmer: {1e3 * vx:.2f} mm/s forward, {1e3 * vy:+.2f} mm/s sideways over {s['window_s'][0]:g}.."
            f"{s['window_s'][1]:g} s, eta {eta:.3f}; the head at the end {-1e3 * links[-1, 0, 2]:.1f} mm deep")


def hexapod(out: Path) -> str:
    """The chassis's forward speed (mean over each gait cycle of 0.5 s) and its height, walking at 2 Hz."""
    result = run("hexapod")
    s = result.summary()
    t, chassis = result.time, result.body_position[:, 0]  # "chassis" is the scene's first body
    omega = 4 * math.pi
    ends = np.flatnonzero(np.isclose(np.mod(t + 1e-9, 0.5), 0.0, atol=1e-6))  # the gait cycles' ends
    tc = t[ends[1:]]
    speed = np.hypot(*np.diff(chassis[ends, :2], axis=0).T) / np.diff(t[ends])
    fig, ax = plt.subplots(figsize=SIZE)
    ax.step(tc, speed, where="pre", label="speed, per gait cycle")
    ax.axhline(omega * 0.04, color="k", ls="--", lw=0.8, label="legs rolling without slip, omega 2R")
    ax.set_xlabel("time, s")
    ax.set_ylabel("forward speed, m/s")
    ax.set_ylim(0, 0.6)
    height = ax.twinx()
    height.plot(t, 1e3 * chassis[:, 2], lw=0.6, color="C1")
    height.set_ylabel("chassis centre above the surface, mm", color="C1", fontsize=8)
    height.set_ylim(0, 60)
    ax.set_title("hexapod at 2 Hz, rft3d in the 3D-RFT code's sand", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(out / "robots-hexapod.png", dpi=90)
    plt.close(fig)
    late = t >= 1.0
    v = s["com_velocity_m_s"]
    w, x, y, z = result.link_quat[:, 0].T  # the chassis is the model's first body
    heading = np.degrees(np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))))
    return (f"hexapod: centre of mass {1e3 * v[0]:.1f}, {1e3 * v[1]:+.1f} mm/s (x, y) over 1..5 s, "
            f"{1e3 * math.hypot(*v[:2]):.1f} mm/s; per gait cycle {1e3 * speed[tc > 1].mean():.1f} mm/s; heading "
            f"{heading[late][0]:+.0f} deg at 1 s, {heading[-1]:+.0f} deg at the end; chassis "
            f"{1e3 * chassis[late, 2].min():.1f}..{1e3 * chassis[late, 2].max():.1f} mm up after 1 s")


SLIPS = (-0.5, -0.2, 0.0, 0.167, 0.5, 0.9)
WHEEL_SPEED, RADIUS = 0.01, 0.0625  # m/s, the hub's (mjcf/wheel_rig.toml); m


def wheel_at(slip: float) -> tuple[float, float, float]:
    """Mean Fx, Fz (N, of the sand on the wheel) and sinkage (m, below the free surface) over 3..6 s of the driven
    wheel at slip angle 0."""
    # s = 1 - v/(omega R) driving, s = omega R / v - 1 braking (the experiments' convention)
    omega = WHEEL_SPEED / (RADIUS * (1 - slip)) if slip >= 0 else (1 + slip) * WHEEL_SPEED / RADIUS
    result = run("wheel_rig", **{"drive.1.speed": omega, "sim.duration": 6.0, "sim.settle": 3.0})
    s = result.summary()
    late = result.time >= 3.0
    sinkage = RADIUS - result.body_position[late, 0, 2].mean()  # the wheel's centre is its body's origin
    return s["medium_force_N"][0], s["medium_force_N"][2], sinkage


def measured() -> np.ndarray:
    """(slip, Fx N, Fz N, sinkage m) of the experiments' condition means at slip angle 0."""
    with (wheel_dir() / "smooth_wheel_by_condition.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if float(r["beta_deg"]) == 0]
    return np.array([(float(r["slip_model"]), float(r["Fx_meas_N"]), float(r["Fz_meas_N"]),
                      1e-3 * float(r["sinkage_mm"])) for r in rows])


def wheel(out: Path) -> str:
    results = np.array([wheel_at(s) for s in SLIPS])
    m = measured()
    m = m[m[:, 0] >= min(SLIPS)]
    fig, ax = plt.subplots(figsize=SIZE)
    ax.plot(SLIPS, results[:, 0], "o-", label="Fx, finrft")
    ax.plot(m[:, 0], m[:, 1], "o", mfc="none", color="C0", label="Fx, measured")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("slip s")
    ax.set_ylabel("drawbar pull Fx, N", color="C0")
    sink = ax.twinx()
    sink.plot(SLIPS, 1e3 * results[:, 2], "s-", color="C1", label="sinkage, finrft")
    sink.plot(m[:, 0], 1e3 * m[:, 3], "s", mfc="none", color="C1", label="sinkage, measured")
    sink.set_ylabel("sinkage, mm", color="C1")
    sink.set_ylim(0, 40)
    ax.set_title("wheel rig, li2013 (zeta 0.6), 10 mm/s, slip angle 0", fontsize=9)
    lines = ax.get_legend_handles_labels()
    more = sink.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "robots-wheel.png", dpi=90)
    plt.close(fig)
    return "wheel: " + "; ".join(f"s {s:+.3f}: Fx {fx:+.2f} N, Fz {fz:.2f} N, sinkage {1e3 * z:.1f} mm"
                                 for s, (fx, fz, z) in zip(SLIPS, results))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/guide"), help="folder of the PNGs")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for figure in (swimmer, hexapod, wheel):
        print(figure(args.out), flush=True)


if __name__ == "__main__":
    main()
