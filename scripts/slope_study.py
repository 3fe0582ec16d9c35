"""The example robots on slopes of their sand (docs/results/slopes.md): the hexapod walking up a plane and a
generated rough heightfield at 0-20 degrees, its speed up the slope against the slope (docs/results/slopes.png),
and the sand-swimmer under a flat and a tilted surface. Writes docs/results/slopes.json, .png and .md.

    python scripts/slope_study.py    # about ten minutes on two loaded cores
"""

from __future__ import annotations

import json
import math
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np

import finrft
from finrft.experiments.user_model import UserModel, example
from finrft.scene import UserScene, load_scene

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "results"
SLOPES = (0, 5, 10, 15, 20)  # deg
# The hexapod sets off along +x (its hips turn about y), each slope rising along +x, and turns left as it walks
# (about 34 deg a second on level sand: its tripods are not mirror images). Its speed is taken along its own
# heading, the chassis's x axis, from the end of the gait's 0.5 s ramp to 2 s, three strides.
HEXAPOD = {"sim.duration": 2.0, "sim.settle": 0.5}
# The rough ground: the incline plus smooth random heights of 3 mm standard deviation over 5 cm (a stride's
# length is about 8 cm), on a 2 m square at 1 cm.
ROUGH = {"medium.surface": "hfield", "medium.hfield_shape": "noise", "medium.hfield_height": 0.003,
         "medium.hfield_length": 0.05, "medium.hfield_extent": 1.0, "medium.hfield_spacing": 0.01,
         "medium.hfield_seed": 1}
SWIMMER = {"sim.duration": 4.0, "sim.settle": 1.0}


def _run(name: str, settings: dict) -> dict:
    """Over [settle, duration]: the velocity (3, m/s) of the robot's centre of mass (fitted), its mean speed along
    its first body's x axis (m/s), its rise (m) and its first body's turn about z (deg); the estimated
    discretisation error of its horizontal speed (m/s, from the run's companion at half the step) and the run's
    wall time (s)."""
    scene = load_scene(example(name), cls=UserScene)
    scene = scene.replace(**settings)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the laws' published caveats, said once in the page
        run = finrft.run(UserModel.of(scene), scene, max_error=None)  # the estimate reported, not bounded
    t, c, v = run.time, run.series["com_position"], run.series["com_velocity"]
    q = run.series["link_quat"][:, 0]
    heading = np.stack([1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2), 2 * (q[:, 1] * q[:, 2] + q[:, 0] * q[:, 3]),
                        2 * (q[:, 1] * q[:, 3] - q[:, 0] * q[:, 2])], axis=1)  # the body's x axis
    yaw = np.unwrap(np.arctan2(heading[:, 1], heading[:, 0]))
    window = t >= scene.sim.settle
    return {"velocity_m_s": np.polyfit(t[window], c[window], 1)[0].tolist(),
            "speed_m_s": float(np.einsum("ti,ti->t", v[window], heading[window]).mean()),
            "rise_m": float(c[-1, 2] - c[window][0, 2]), "turn_deg": float(np.degrees(yaw[-1] - yaw[window][0])),
            "speed_error_m_s": float(run.error_estimate["com_speed_m_s"]), "wall_s": time.perf_counter() - start}


def hexapod() -> list[dict]:
    rows = []
    for surface in ("plane", "rough"):
        for degrees in SLOPES:
            theta = math.radians(degrees)
            if surface == "plane":
                own = {"medium.surface": "plane", "medium.surface_normal": (-math.sin(theta), 0.0, math.cos(theta))}
            else:
                own = {**ROUGH, "medium.hfield_slope": theta}
            rows.append({"surface": surface, "slope_deg": degrees, **_run("hexapod", {**HEXAPOD, **own})})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def swimmer() -> list[dict]:
    rows = []
    tilt = math.radians(10)
    for label, own in (("flat", {}),
                       ("10 deg, rising ahead (+x)", {"medium.surface": "plane",
                                                      "medium.surface_normal": (-math.sin(tilt), 0.0, math.cos(tilt))}),
                       ("10 deg, rising to its left (+y)", {"medium.surface": "plane",
                                                            "medium.surface_normal": (0.0, -math.sin(tilt),
                                                                                      math.cos(tilt))})):
        rows.append({"surface": label, **_run("sand_swimmer", {**SWIMMER, **own})})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def up_slope(row: dict) -> float:
    """The hexapod's velocity up its slope (m/s, along the ground, the slope rising along +x)."""
    theta = math.radians(row["slope_deg"])
    return row["velocity_m_s"][0] * math.cos(theta) + row["velocity_m_s"][2] * math.sin(theta)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.8))
    for surface, label, colour in (("plane", "plane", "C0"), ("rough", "rough heightfield", "C1")):
        chosen = [r for r in rows if r["surface"] == surface]
        slopes = [r["slope_deg"] for r in chosen]
        ax.plot(slopes, [1e3 * up_slope(r) for r in chosen], "o-", color=colour, label=f"{label}: up the slope")
        ax.errorbar(slopes, [1e3 * r["speed_m_s"] for r in chosen], [1e3 * r["speed_error_m_s"] for r in chosen],
                    fmt="s:", color=colour, capsize=3, label=f"{label}: along its heading")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel("slope (deg)")
    ax.set_ylabel("speed (mm/s)")
    ax.set_title("hexapod on sand_3d_rft_code, 2 Hz")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def page(hexapod_rows: list[dict], swimmer_rows: list[dict]) -> str:
    def row(surface: str, degrees: int) -> dict:
        return next(r for r in hexapod_rows if r["surface"] == surface and r["slope_deg"] == degrees)

    def cells(r: dict) -> str:
        return (f"{1e3 * up_slope(r):.0f} | {1e3 * r['speed_m_s']:.0f} ± {1e3 * r['speed_error_m_s']:.0f} | "
                f"{r['turn_deg']:+.0f}")

    lines = ["# Slopes of sand", "",
             "Regenerated by `python scripts/slope_study.py` (docs/results/slopes.json, slopes.png; about ten "
             "minutes on two loaded cores). The example robots ([Robots](../guide/robots.md)) at their scenes' "
             "numerics (newton-midpoint at 1 ms), on the free surfaces of [Free surfaces](../guide/surfaces.md), "
             "gravity along −z throughout.", "",
             "## The hexapod up a slope", "",
             "The hexapod (`mjcf/hexapod.toml`: rft3d, `sand_3d_rft_code`, every hip at 2 Hz) sets off along +x and "
             "each slope rises along +x, as a plane (`medium.surface = \"plane\"`) and as rough ground, a generated "
             "heightfield (`surface = \"hfield\"`, `hfield_shape = \"noise\"`: 3 mm standard deviation over 5 cm, "
             "on the incline). It turns left as it walks, about 34° a second on level sand (its tripods are not "
             "mirror images). From the end of the gait's 0.5 s ramp to 2 s (three strides): its speed up the slope "
             "(its centre of mass's velocity, fitted, along the ground up the slope), its speed along its own "
             "heading (the chassis's x axis, averaged) and how far it turned. Each ± is the run's own estimate of its "
             "discretisation error (of its horizontal speed, from a companion run at half the step: "
             "`finrft.convergence`).", "",
             "![speed against slope](slopes.png)", "",
             "| slope | plane: up the slope (mm/s) | along its heading (mm/s) | turns (°) | rough: up the slope "
             "(mm/s) | along its heading (mm/s) | turns (°) |",
             "|---|---|---|---|---|---|---|"]
    for degrees in SLOPES:
        lines.append(f"| {degrees}° | {cells(row('plane', degrees))} | {cells(row('rough', degrees))} |")
    def lost(surface: str) -> str:
        down = [d for d in SLOPES if up_slope(row(surface, d)) < 0]
        return f"{down[0]}°" if down else "none of these slopes"

    lines += ["", f"On the plane it walks at much the same pace along its heading up to 15° but turns across the "
              f"slope ever faster, so that it climbs ever less, and loses ground from {lost('plane')}; on the rough "
              f"ground it climbs further and loses ground from {lost('rough')}. A gait "
              f"that walks straight on level sand would need steering to climb. Where the estimate is large (its "
              f"path then depends on small differences: a turn one stride earlier or later), the row is the least "
              f"sure.", "",
              "## The sand-swimmer under a tilted surface", "",
              "The sand-swimmer (`mjcf/sand_swimmer.toml`: li2013 in 3D, glass beads, 40 mm deep at the start) swims "
              "along +x; under a surface tilted 10° the depth of its links, and so the medium's stress on them, "
              "changes along it. Its centre of mass's velocity fitted over 1–4 s and how far it rose meanwhile:", "",
              "| surface | velocity x, y, z (mm/s) | speed's error (mm/s) | rises (mm) |", "|---|---|---|---|"]
    for r in swimmer_rows:
        v = ", ".join(f"{1e3 * x:.1f}" for x in r["velocity_m_s"])
        lines.append(f"| {r['surface']} | {v} | {1e3 * r['speed_error_m_s']:.1f} | {1e3 * r['rise_m']:+.1f} |")
    wrapped = [line if line.startswith(("|", "#", "!")) or not line else textwrap.fill(line, 116)
               for line in lines]
    return "\n".join(wrapped) + "\n"


def main() -> int:
    hexapod_rows = hexapod()
    swimmer_rows = swimmer()
    (OUT / "slopes.json").write_text(json.dumps({"hexapod": hexapod_rows, "swimmer": swimmer_rows}, indent=1) + "\n")
    plot(hexapod_rows, OUT / "slopes.png")
    (OUT / "slopes.md").write_text(page(hexapod_rows, swimmer_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
