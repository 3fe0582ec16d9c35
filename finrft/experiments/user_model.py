"""A user's MuJoCo model in the medium, as an experiment (finrft.experiment): RFT `attach`ed to the named bodies of
an MJCF file, one joint moved at constant speed (or as a triangle wave) exactly as the plate's base is moved
(`stepping.Prescribed`: a very large armature, impulses at reversals), and the force that motion needs.

`AttachedModel`, `build_attached` and `JointTrial` serve any experiment made of a spec, `attach` and a prescribed
joint: `UserModel` (``finrft run MODEL.xml``) and `intrusion.Intrusion`.

Only MuJoCo's own (explicit) step runs these models: the newton, implicit and adaptive steps treat implicitly the
forces of the segment law's force groups, and the surface elements of `attach` are not among them.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from .. import laws
from ..attach import Attached, SurfaceForces, attach
from ..drive import Drive
from ..experiment import Compared, Plot, Quantity, Result
from ..models import ARMATURE_RATIO, INTEGRATORS, compile_spec
from ..scene import ExplicitSim, Medium, SceneError, UserScene, load_scene, parse_override
from ..stepping import Prescribed
from .command import Command, error_line, register, steps_line
from .flags import add_max_error, add_result_files, add_scene_flags

_J = mujoco.mjtJoint
DRIVEN = {int(_J.mjJNT_SLIDE): "slide", int(_J.mjJNT_HINGE): "hinge"}


@dataclass(frozen=True, eq=False)
class AttachedModel:
    """A compiled model with RFT attached, and the indices a prescribed-joint experiment needs."""

    model: mujoco.MjModel
    attached: Attached
    drive_dof: int
    drive_qpos: int
    armature: float            # the driven joint's armature (kg or kg m^2)
    bodies: np.ndarray         # ids of the attached bodies, in the order named
    groups: tuple = ()         # no segment force groups: the forces are the attached surfaces'

    @property
    def backend(self) -> str:
        return self.attached.backend

    def python_forces(self) -> SurfaceForces:
        return self.attached.callback(self.model)


def read_spec(path: str) -> mujoco.MjSpec:
    """An MJCF file's spec; SceneError in one line when it is missing or MuJoCo cannot parse it."""
    if not path:
        raise SceneError("no model: give the MJCF file (finrft run MODEL.xml, or model.path in the scene)")
    if not Path(path).is_file():
        raise SceneError(f"cannot read model file {path}: no such file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise SceneError(f"model file {path}: {' '.join(str(exc).split())}") from None


def driven_joint(spec: mujoco.MjSpec, name: str) -> mujoco.MjsJoint:
    """The named slide or hinge joint of a spec; SceneError naming the joints there are."""
    joint = spec.joint(name) if name else None
    if joint is None:
        names = ", ".join(j.name for j in spec.joints if j.name) or "none named"
        raise SceneError(f"drive.joint: the model has no joint named {name!r} (its joints: {names})")
    if int(joint.type) not in DRIVEN:
        raise SceneError(f"drive.joint {name!r} is a {_J(joint.type).name.removeprefix('mjJNT_').lower()} joint: "
                         f"drive a slide or hinge joint")
    return joint


def build_attached(spec: mujoco.MjSpec, joint_name: str, bodies: tuple[str, ...], medium: Medium,
                   sim: ExplicitSim) -> AttachedModel:
    """Give ``spec`` the numerics, the driven joint its armature and the bodies RFT, and compile it."""
    if not bodies:
        raise SceneError("model.bodies is empty: name the bodies the medium acts on")
    joint = driven_joint(spec, joint_name)
    spec.option.timestep = sim.dt
    spec.option.integrator = INTEGRATORS[sim.integrator]
    # The armature is relative to what the joint moves (its diagonal of the mass matrix at qpos0), as the plate's.
    plain = compile_spec(spec)
    d = mujoco.MjData(plain)
    mujoco.mj_forward(plain, d)
    mass = np.zeros((plain.nv, plain.nv))
    mujoco.mj_fullM(plain, d, mass)
    dof = int(plain.jnt_dofadr[plain.joint(joint_name).id])
    joint.armature = ARMATURE_RATIO * mass[dof, dof]
    law = laws.module(medium.law, laws.SURFACE)
    attached = attach(spec, list(bodies), law=medium.law, surface_z=medium.surface_z,
                      element_size=medium.element_size, backend=sim.backend, medium=medium.name or None,
                      drft_lambda=medium.drft_lambda,
                      bulk_density=None if law.DENSITY else medium.bulk_density or None, **law.given(medium))
    model = compile_spec(spec)
    jid = model.joint(joint_name).id
    return AttachedModel(model, attached, int(model.jnt_dofadr[jid]), int(model.jnt_qposadr[jid]),
                         float(model.dof_armature[model.jnt_dofadr[jid]]),
                         np.array([model.body(b).id for b in bodies], dtype=int))


class JointTrial:
    """One run of an attached model on one MjData: the driven joint on its prescribed profile from
    ``drive.start``; read at each recorded instant: the joint's position and the load its drive applies, each
    attached body's origin and the resultant of the medium's force on it (recomputed from the law, whatever the
    backend)."""

    def __init__(self, built: AttachedModel, drive: Drive, d: mujoco.MjData, companion: bool) -> None:
        m = built.model
        self.prescribed = Prescribed([built.drive_dof], [built.drive_qpos], built.armature, drive)
        d.qpos[built.drive_qpos] = drive.start
        self.on_stroke = lambda k: self.prescribed.start_stroke(m, d, k)
        self.watch = [i for i in range(m.nv) if i != built.drive_dof]
        forces = built.python_forces()
        surfaces = [(int(b), s) for b, s in zip(built.bodies, built.attached.surfaces)]

        def bodies(d: mujoco.MjData) -> np.ndarray:
            if companion:  # a companion steps without mj_forward; its positions and forces need it here
                mujoco.mj_forward(m, d)
            force = [forces.element_forces(m, d, b, s)[0].sum(axis=0) for b, s in surfaces]
            return np.concatenate([d.xpos[built.bodies], force], axis=1)

        # In this order: "bodies" brings a companion's kinematics up to date for "drive".
        self.reads = {"bodies": bodies,
                      "drive": lambda d: np.array([d.qpos[built.drive_qpos], self.prescribed.load(d)[0]])}

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        self.prescribed.finish(d)
        bodies, drive = readings["bodies"], readings["drive"]
        return ({"drive_position": drive[:, 0], "drive_load": drive[:, 1], "body_position": bodies[..., :3],
                 "rft_force": bodies[..., 3:], "stroke_impulse": self.prescribed.impulse},
                {"peak_drive_load": float(np.max(np.abs(drive[:, 1])))})


SIGN_CONVENTION = (
    "World frame, z up; the medium lies below z = medium.surface_z. The drive load is what the drive applies to the "
    "driven joint along (about) its axis; rft_force is the medium's force on each attached body.")


@dataclass(frozen=True)
class UserModel:
    """A user's MJCF model (`UserScene`) in the medium, its ``drive.joint`` prescribed. Its result's series, SI
    units: ``drive_position`` and ``drive_load`` (T,) (m and N for a slide joint, rad and N m for a hinge),
    ``body_position`` and ``rft_force`` (T, B, 3) per attached body, world frame, and ``stroke_impulse`` per
    stroke. ``UserModel.of(scene)`` reads the joint's kind from the model."""

    rotary: bool = False       # the driven joint is a hinge
    name = "run"
    schema = "finrft.user/1"
    sign_convention = SIGN_CONVENTION

    @classmethod
    def of(cls, scene: UserScene) -> UserModel:
        joint = driven_joint(read_spec(scene.model.path), scene.drive.joint)
        return cls(rotary=DRIVEN[int(joint.type)] == "hinge")

    @property
    def quantity(self) -> str:
        return "torque" if self.rotary else "force"

    @property
    def unit(self) -> str:
        return "Nm" if self.rotary else "N"

    def build(self, scene: UserScene) -> AttachedModel:
        built = build_attached(read_spec(scene.model.path), scene.drive.joint, scene.model.bodies, scene.medium,
                               scene.sim)
        if (built.model.jnt_type[built.model.dof_jntid[built.drive_dof]] == _J.mjJNT_HINGE) != self.rotary:
            raise SceneError(f"drive.joint {scene.drive.joint!r} is not the kind of joint this run was made for")
        return built

    def drive_for(self, scene: UserScene) -> Drive:
        j = scene.drive
        return Drive("rotate" if self.rotary else "drag", j.speed, j.stroke, j.cycles or None, start=j.start)

    def quantities(self, scene: UserScene) -> dict[str, Quantity]:
        joint, bodies = scene.drive.joint, ",".join(scene.model.bodies)
        return {
            "drive_position": Quantity("rad" if self.rotary else "m", f"position of the driven joint {joint} (qpos)",
                                       plot=Plot("drive/position", f"{joint} ({'deg' if self.rotary else 'mm'})",
                                                 joint, "deg" if self.rotary else "mm")),
            "drive_load": Quantity("N m" if self.rotary else "N", f"{self.quantity} the drive applies to {joint} "
                                   f"about (along) its axis", plot=Plot("drive/load", f"Drive {self.quantity} "
                                   f"({'N m' if self.rotary else 'N'})", f"drive {self.quantity}")),
            "body_position": Quantity("m", "origin of each attached body", attrs={"frame": "world", "bodies": bodies}),
            "rft_force": Quantity("N", "resultant of the medium's force on each attached body",
                                  attrs={"frame": "world", "bodies": bodies}),
            "stroke_impulse": Quantity("N m s" if self.rotary else "N s", "integral of the drive load over each "
                                       "stroke", per="stroke"),
        }

    def compared(self, scene: UserScene) -> tuple[Compared, ...]:
        """The attached bodies' positions (mm, bounded by --max-error) and the per-stroke mean drive load."""
        return (Compared("position_mm", ("body_position",), 1e3),
                Compared(f"{self.quantity}_{self.unit}", ("stroke_impulse",), 1 / self.drive_for(scene).stroke_time))

    def start(self, scene: UserScene, built: AttachedModel, d: mujoco.MjData, companion: bool) -> JointTrial:
        return JointTrial(built, self.drive_for(scene), d, companion)

    def check(self, result: Result) -> None:
        pass

    def attrs(self) -> dict[str, Any]:
        return {"drive_joint_type": "hinge" if self.rotary else "slide"}

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        return []

    def summary(self, run: Result) -> dict[str, Any]:
        q, u, scene = self.quantity, self.unit, run.scene
        final = run.body_position[-1]
        return {
            "model": scene.model.path, "joint": scene.drive.joint, "bodies": list(scene.model.bodies),
            f"peak_drive_{q}_{u}": run.peak_drive_load,
            f"mean_drive_{q}_{u}_per_stroke": (run.stroke_impulse / self.drive_for(scene).stroke_time).tolist(),
            "final_body_position_mm": {b: (1e3 * final[i]).tolist() for i, b in enumerate(scene.model.bodies)},
            "final_rft_force_N": {b: run.rft_force[-1, i].tolist() for i, b in enumerate(scene.model.bodies)},
        }

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from ..views import draw_bodies
        return draw_bodies(rec, run, times, prefix, run.body_position, run.rft_force, "Attached bodies")


# ---------------------------------------------------------------------------------------------------------
# The command: finrft run

@register
class RunCommand(Command):
    name = "run"
    help = "RFT on your own MuJoCo model: a joint driven through the medium"
    description = ("Attach the granular RFT of Li, Zhang & Goldman 2013 to bodies of an MJCF model and move one "
                   "slide or hinge joint at constant speed (one stroke, or --set drive.cycles=N back-and-forth "
                   "cycles), exactly: the joint carries a very large armature and the force (torque) it needs is "
                   "recorded, with each attached body's position and the medium's force on it. The scene (SI units) "
                   "has [model] (path, bodies), [medium] (law, name or zeta, surface_z, element_size), [drive] "
                   "(joint, speed, stroke, cycles, start) and [sim] (dt, integrator, backend, record_dt; MuJoCo's "
                   "explicit step only).")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("model", nargs="?", metavar="MODEL.xml", help="the MJCF file (overrides model.path)")
        add_scene_flags(p, "user-model", "drive.speed=0.05", required=True, backend="where the RFT force is "
                        "computed (overrides sim.backend)")
        add_max_error(p)
        add_result_files(p)

    def scene(self, args: argparse.Namespace) -> UserScene:
        overrides = dict(parse_override(item, UserScene) for item in args.set)
        if args.backend:
            overrides["sim.backend"] = args.backend
        if args.model:
            overrides["model.path"] = args.model
        return load_scene(args.scene, overrides=overrides, cls=UserScene)

    def jobs(self, args: argparse.Namespace, scene: UserScene) -> list[tuple[UserModel, UserScene]]:
        return [(UserModel.of(scene), scene)]

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        run, = runs
        scene, summary = run.scene, run.summary()
        q, u = run.quantity, run.unit.replace("Nm", "N m")
        lines = [f"{scene.model.path}: joint {scene.drive.joint} driven, RFT on {', '.join(scene.model.bodies)} "
                 f"({run.backend}; dt {scene.sim.dt:g} s, {scene.sim.integrator}): {steps_line(summary)} in "
                 f"{run.wall_s:.2f} s",
                 f"mean drive {q} per stroke: " + ", ".join(
                     f"{value:+.4g} {u}" for value in summary[f"mean_drive_{q}_{run.unit}_per_stroke"])]
        for body, position in summary["final_body_position_mm"].items():
            lines.append(f"{body}: final position (mm) " + ", ".join(f"{x:.2f}" for x in position))
        lines.append(error_line(run))
        return "\n".join(lines)
