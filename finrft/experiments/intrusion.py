"""A thin plate pushed vertically down into the medium at an angle: the force-depth curves of Li, Zhang & Goldman
2013 (Science 339:1408, their Fig. 2), as an experiment built from the protocol (finrft.experiment) and `attach`.

The plate (width w along y, length L in the x-z plane, at angle beta: 0 horizontal, pi/2 vertical) sits on a slide
joint along -z, prescribed at constant speed from ``clearance`` above the free surface until its lowest point is
``depth`` below it. Fully submerged, each face leading the motion takes alpha_z(beta, pi/2) times its
area-weighted mean depth times its area (`finrft.laws.li2013`): a horizontal plate zeta * 1 N/cm^3 * w L d; a
tilted one alpha_z(beta, pi/2) on its lower face and alpha_z(pi/2 - beta, pi/2) on its lower edge (a horizontal
plate's edges move in their own plane and take nothing). Each face's force is ramped by tanh(n . v / v_reg)
(`finrft.laws.regularised`, medium.v_reg): at beta = 90 deg the faces are parallel to the motion and take nothing,
only the lower edge does (tested).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import mujoco
import numpy as np

from .. import laws
from ..convergence import ErrorLimits
from ..drive import Drive
from ..errors import SceneError, UsageError
from ..experiment import Compared, Plot, Quantity, Result, run
from ..scene import ExplicitSim, Medium, Sections, check_medium, check_sim, load_scene, parse_override, register_scene
from ..schema import field as _f
from .command import Command, Output, register
from .flags import add_force, add_json, add_quiet, add_scene_flags
from .attached_model import AttachedModel, JointTrial, build_attached

SIGN_CONVENTION = (
    "z up; the plate moves along -z. depth is the plate's lowest point below the free surface. force_z is the "
    "medium's vertical force on the plate (+z, up: against the intrusion), force_x its horizontal force along +x; "
    "at angle beta > 0 the plate's lower face looks down and towards -x.")


@dataclass(frozen=True)
class IntrusionPlate:
    width: float = _f(0.025, "m", "plate width (along y, horizontal)", minimum=0.0)
    length: float = _f(0.038, "m", "plate length (in the x-z plane, tilted by angle)", minimum=0.0)
    thickness: float = _f(0.0005, "m", "plate thickness", minimum=0.0)
    angle: float = _f(0.0, "rad", "beta: 0 horizontal, pi/2 vertical (cutting in edge first); positive turns the "
                      "lower face towards -x", minimum=-math.pi / 2, exclusive=False, maximum=math.pi / 2,
                      why_maximum="a plate's angle repeats every pi")
    speed: float = _f(0.01, "m/s", "downward speed (the law is rate-independent unless medium.drft_lambda > 0)",
                      minimum=0.0)
    clearance: float = _f(0.002, "m", "height of the plate's lowest point above the surface at t = 0",
                          minimum=0.0, exclusive=False)
    depth: float = _f(0.05, "m", "depth of the plate's lowest point at the end", minimum=0.0)


@dataclass(frozen=True)
class IntrusionScene(Sections):
    """A thin plate pushed vertically down into the medium at an angle (Li, Zhang & Goldman 2013)."""

    plate: IntrusionPlate = field(default_factory=IntrusionPlate)
    medium: Medium = field(default_factory=Medium)
    sim: ExplicitSim = field(default_factory=lambda: ExplicitSim(dt=1e-3, record_dt=0.01))

    def __post_init__(self) -> None:
        super().__post_init__()
        check_sim(self.sim)
        check_medium(self.medium)
        if self.medium.surface != "flat":
            raise SceneError(f"medium.surface = {self.medium.surface!r}: the intrusion pushes its plate down from the "
                             f"flat surface at medium.surface_z only; leave medium.surface out")


register_scene(IntrusionScene, title="Plate intrusion: `finrft intrude`; `finrft.IntrusionScene`")


def plate_xml(scene: IntrusionScene) -> str:
    """The plate on its vertical slide (qpos: distance moved down), its lowest point ``clearance`` above the
    surface at qpos 0. Its mass, 1 kg, sets only the drive's armature (ARMATURE_RATIO times it): the plate moves as
    prescribed, without gravity, and a heavier armature holds it there under the forces of a deep intrusion (at
    0.01 kg a plate pushed 0.5 m deep fell 2 mm behind)."""
    p, beta = scene.plate, scene.plate.angle
    reach = p.length / 2 * abs(math.sin(beta)) + p.thickness / 2 * math.cos(beta)  # centre to lowest point
    z = scene.medium.surface_z + p.clearance + reach
    return f"""<mujoco model="finrft intrusion"><option gravity="0 0 0"/><worldbody>
  <body name="plate" pos="0 0 {z!r}"><joint name="push" type="slide" axis="0 0 -1"/>
    <geom type="box" size="{p.length / 2!r} {p.width / 2!r} {p.thickness / 2!r}" mass="1"
          quat="{math.cos(beta / 2)!r} 0 {math.sin(beta / 2)!r} 0"/>
  </body></worldbody></mujoco>"""


@dataclass(frozen=True)
class Intrusion:
    """The plate of an `IntrusionScene` pushed down into the medium. Its result's series, SI units: ``depth`` (T,)
    of the lowest point, and the medium's force on the plate ``force_z`` (up) and ``force_x`` (T,)."""

    name = "intrude"
    schema = "finrft.intrusion/1"
    sign_convention = SIGN_CONVENTION

    def build(self, scene: IntrusionScene) -> AttachedModel:
        return build_attached(mujoco.MjSpec.from_string(plate_xml(scene)), ["push"], ("plate",), scene.medium,
                              scene.sim)

    def drive_for(self, scene: IntrusionScene) -> Drive:
        p = scene.plate
        return Drive("drag", p.speed, p.clearance + p.depth)

    def quantities(self, scene: IntrusionScene) -> dict[str, Quantity]:
        return {
            "depth": Quantity("m", "depth of the plate's lowest point below the free surface (< 0 above it)",
                              plot=Plot("plate/depth", "Depth (mm)", "depth", "mm")),
            "force_z": Quantity("N", "vertical force of the medium on the plate, +z up",
                                plot=Plot("force/z", "Vertical force (N)", "force z")),
            "force_x": Quantity("N", "horizontal force of the medium on the plate, along +x",
                                plot=Plot("force/x", "Horizontal force (N)", "force x")),
        }

    def compared(self, scene: IntrusionScene) -> tuple[Compared, ...]:
        """The forces at the same depths (N): reported, not bounded."""
        return (Compared("force_N", ("force_z", "force_x")),)

    def start(self, scene: IntrusionScene, built: AttachedModel, d: mujoco.MjData, companion: bool) -> _Trial:
        return _Trial(JointTrial(built, self.drive_for(scene), d, companion), scene.plate.clearance)

    def check(self, result: Result) -> None:
        pass

    def attrs(self) -> dict[str, Any]:
        return {}

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        return []

    def summary(self, run: Result) -> dict[str, Any]:
        return {"angle_deg": math.degrees(run.scene.plate.angle), "final_depth_mm": 1e3 * float(run.depth[-1]),
                "final_force_z_N": float(run.force_z[-1]), "final_force_x_N": float(run.force_x[-1])}

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from ..views import draw_bodies
        position = np.zeros((len(run.time), 1, 3))
        position[:, 0, 2] = run.scene.medium.surface_z - run.depth
        force = np.zeros_like(position)
        force[:, 0, 0], force[:, 0, 2] = run.force_x, run.force_z
        return draw_bodies(rec, run, times, prefix, position, force, "Plate's lowest point")


class _Trial:
    """A `JointTrial` whose readings become depth and force."""

    def __init__(self, trial: JointTrial, clearance: float) -> None:
        self.trial, self.clearance = trial, clearance
        self.reads, self.watch, self.on_stroke = trial.reads, trial.watch, trial.on_stroke

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        series, _ = self.trial.finish(d, readings)
        force = series["rft_force"][:, 0]
        return {"depth": series["drive_position"] - self.clearance, "force_z": force[:, 2], "force_x": force[:, 0]}, {}


def intrude(scene: IntrusionScene, angles_deg: list[float], *, progress: Callable[[float], None] | None = None,
            max_error: ErrorLimits | None = ErrorLimits()) -> list[Result]:
    """The intrusion at each plate angle (degrees), the rest of the scene as given."""
    runs = []
    for i, angle in enumerate(angles_deg):
        part = None if progress is None else (lambda f, i=i: progress((i + f) / len(angles_deg)))
        runs.append(run(Intrusion(), scene.replace(**{"plate.angle": math.radians(angle)}), progress=part,
                        max_error=max_error))
    return runs


def plot_curves(runs: list[Result], path: str | Path) -> None:
    """The force-depth curves, vertical and horizontal, one line per angle, as a figure (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (vertical, horizontal) = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
    for r in runs:
        label = f"beta = {math.degrees(r.scene.plate.angle):g} deg"
        vertical.plot(1e3 * r.depth, r.force_z, label=label)
        horizontal.plot(1e3 * r.depth, r.force_x, label=label)
    p, medium = runs[0].scene.plate, runs[0].scene.medium
    given = laws.module(medium.law, laws.SURFACE).given(medium)
    values = ", ".join(f"{key} {value:g}" for key, value in given.items() if value is not None)
    vertical.set(xlabel="depth of the lowest point (mm)", ylabel="vertical force F_z (N, up)",
                 title=f"{1e3 * p.width:g} x {1e3 * p.length:g} mm plate, {medium.law}: "
                 f"{', '.join(filter(None, (medium.name, values)))}")
    horizontal.set(xlabel="depth of the lowest point (mm)", ylabel="horizontal force F_x (N)",
                   title="Horizontal force")
    for ax in (vertical, horizontal):
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------------
# The command: finrft intrude

def _angles(text: str) -> list[float]:
    try:
        angles = [float(a) for a in text.split(",") if a.strip()]
    except ValueError:
        raise UsageError(f"--angles expects comma-separated degrees, e.g. 0,30,60,90, got '{text}'") from None
    if not angles:
        raise UsageError(f"--angles expects comma-separated degrees, e.g. 0,30,60,90, got '{text}'")
    if not all(-90 <= a <= 90 for a in angles):
        raise UsageError(f"--angles: each angle must be within -90..90 degrees, got '{text}'")
    if len(set(angles)) < len(angles):
        raise UsageError(f"--angles: an angle is given twice in '{text}': give each once")
    return angles


@register
class IntrudeCommand(Command):
    name = "intrude"
    help = ("a plate pushed vertically into the medium at several angles: the force-depth curves of Li, Zhang & "
            "Goldman 2013")
    description = ("Push a thin plate (plate.width x plate.length) at each angle beta (0 horizontal, 90 vertical, "
                   "cutting in edge first) straight down into the medium at constant speed, from plate.clearance "
                   "above the surface to plate.depth below it, and record the medium's vertical and horizontal force "
                   "against the depth of the plate's lowest point.")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("--angles", default="0,30,60,90", metavar="DEGS",
                       help="comma-separated plate angles in degrees, each in -90..90 (default: %(default)s)")
        add_scene_flags(p, "intrusion", "medium.zeta=0.5", scene_help="intrusion scene file in SI units ([plate], "
                        "[medium], [sim]; default: the schema's defaults, a 25 x 38 mm plate to 50 mm in the generic "
                        "medium)")
        p.add_argument("--plot", metavar="FILE.png", help="write the force-depth curves as a figure")
        add_force(p)
        add_json(p, "each angle's summary and curve")
        add_quiet(p)

    def scene(self, args: argparse.Namespace) -> IntrusionScene:
        overrides = dict(parse_override(item, IntrusionScene) for item in args.set)
        if args.backend:
            overrides["sim.backend"] = args.backend
        return load_scene(args.scene, overrides=overrides, cls=IntrusionScene)

    def jobs(self, args: argparse.Namespace, scene: IntrusionScene) -> list[tuple[Intrusion, IntrusionScene]]:
        return [(Intrusion(), scene.replace(**{"plate.angle": math.radians(a)})) for a in _angles(args.angles)]

    def outputs(self, args: argparse.Namespace) -> list[Output]:
        return [Output("--plot", args.plot, ".png", "figure", lambda runs, path: plot_curves(runs, path))]

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        return "\n".join(f"beta {s['angle_deg']:g} deg: at {s['final_depth_mm']:.1f} mm, vertical force "
                         f"{s['final_force_z_N']:.4g} N, horizontal {s['final_force_x_N']:+.4g} N"
                         for s in (r.summary() for r in runs))

    def to_json(self, runs: list[Result]) -> list[dict[str, Any]]:
        return [{**r.summary(), "depth_mm": 1e3 * r.depth, "force_z_N": r.force_z, "force_x_N": r.force_x}
                for r in runs]
