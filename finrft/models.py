"""MuJoCo models built from the MJCF files in ``mjcf/`` and a scene.

The MJCF file describes the paper's plate and is edited through MjSpec (never by string edits) to apply a scene:
segment count and sizes, masses and inertias, hinge spring/damper/stop, and the drive.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from importlib import resources
from typing import Iterator

import mujoco
import numpy as np

from . import native, rft
from .scene import Scene, SceneError

INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
DRIVES = ("drag", "rotate")
# The drive's armature, relative to what it drives: large enough that the RFT load changes the prescribed
# speed by ~1e-10 per step, small enough that the mass matrix keeps full precision in double.
ARMATURE_RATIO = 1e10
# A stiff limit: impedance 0.9999 (MuJoCo's maximum) and the shortest time constant MuJoCo accepts, 2 dt.
LIMIT_IMPEDANCE = (0.9999, 0.9999, 0.001, 0.5, 2.0)


@dataclass(frozen=True)
class PlateModel:
    """A compiled plate model and the indices the simulation needs."""

    model: mujoco.MjModel
    backend: str               # "native" (the RFT plugin is bound to the segments) or "python"
    drive: str                 # "drag" or "rotate"
    drive_dof: int
    drive_qpos: int
    armature: float            # the drive's armature (kg or kg m^2)
    hinge_qpos: np.ndarray     # (H,) qpos address of each hinge: H = segments, or 0 for a rigid plate
    hinge_dof: np.ndarray      # (H,)
    seg_body: np.ndarray       # (N,) body that carries each segment
    seg_site: np.ndarray       # (N,) site at each segment's midpoint
    initial_angle: float       # the plate's orientation at t = 0 (rad, about z)


@contextlib.contextmanager
def captured_warnings(messages: list[str]) -> Iterator[None]:
    """Collect MuJoCo's warnings, which would otherwise go to stderr, so that an error can quote them."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def mjcf_path(name: str = "plate.xml"):
    """The path of a packaged MJCF file."""
    return resources.files("finrft.mjcf") / name


def _quat_z(angle: float) -> list[float]:
    return [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)]


def initial_heading(drive: str, attack_deg: float) -> float:
    """The plate's orientation about z at t = 0: a drag along +y at angle of attack theta starts at 90 deg - theta."""
    return float(np.radians(90.0 - attack_deg)) if drive == "drag" else 0.0


def plugin_config(scene: Scene) -> dict[str, str]:
    """The native plugin's config for a scene: the same law and penalty stop as the Python coupling."""
    r, p = scene.rft, scene.plate
    config = {"law": r.law, "f_perp": repr(r.f_perp), "f_par": repr(r.f_par), "v_reg": repr(r.v_reg),
              "stop_stiffness": repr(p.stop_stiffness if p.kind == "origami" and p.stop == "penalty" else 0.0)}
    if r.law == "table":
        table = rft.read_table(r.table)
        config["table"] = " ".join(repr(float(x)) for row in zip(table.attack_deg, table.f_perp, table.f_par)
                                   for x in row)
    return config


def plate_spec(scene: Scene, drive: str = "drag", attack_deg: float = 90.0,
               backend: str = "python") -> mujoco.MjSpec:
    """The plate's MjSpec for a scene: drive ``drag`` (base slides along +y, the plate at angle of attack
    ``attack_deg`` to the motion) or ``rotate`` (the rod turns about z through its base); with backend
    ``native`` the RFT plugin is bound to the segments."""
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {DRIVES}, got {drive!r}")
    p, sim = scene.plate, scene.sim
    spec = mujoco.MjSpec.from_file(str(mjcf_path()))
    spec.option.timestep = sim.dt
    spec.option.integrator = INTEGRATORS[sim.integrator]

    rod = spec.body("rod")
    spec.delete(spec.body("seg1"))
    rod.mass, rod.ipos = p.rod_mass, [p.rod_length / 2, 0, 0]
    rod.inertia = [p.rod_inertia] * 3
    spec.geom("rod").fromto = [0, 0, 0, p.rod_length, 0, 0]

    joint = spec.joint("drive")
    heading = initial_heading(drive, attack_deg)
    rod.quat = _quat_z(heading)
    if drive == "drag":
        joint.axis = [np.sin(heading), np.cos(heading), 0.0]  # world +y in the rotated rod frame
    else:
        joint.type = mujoco.mjtJoint.mjJNT_HINGE
        joint.axis = [0, 0, 1]

    seg_geom = spec.find_default("segment").geom
    seg_geom.size = [p.segment_length / 2, seg_geom.size[1], seg_geom.size[2]]
    hinge = spec.find_default("hinge").joint
    hinge.stiffness = [p.stiffness, 0, 0]
    hinge.springref = p.springref
    hinge.damping = [p.damping, 0, 0]
    if p.kind == "origami" and p.stop == "limit":
        hinge.range = [-np.pi, p.springref]
        hinge.solref_limit = [2 * sim.dt, 1.0]
        hinge.solimp_limit = list(LIMIT_IMPEDANCE)
    else:
        hinge.limited = mujoco.mjtLimited.mjLIMITED_FALSE

    half = p.segment_length / 2
    segment_bodies = []
    if p.kind == "rigid":
        plate = rod.add_body(name="plate", pos=[p.rod_length, 0, 0])
        centres = [half + i * p.segment_length for i in range(p.segments)]
        mass = p.segments * p.segment_mass
        com = float(np.mean(centres))
        inertia = sum(p.segment_inertia + p.segment_mass * (c - com) ** 2 for c in centres)
        plate.mass, plate.ipos, plate.inertia = mass, [com, 0, 0], [inertia] * 3
        for i, c in enumerate(centres, start=1):
            plate.add_geom(spec.find_default("segment"), name=f"seg{i}", pos=[c, 0, 0])
            plate.add_site(name=f"seg{i}", pos=[c, 0, 0])
        segment_bodies.append(plate)
    else:
        parent, pos = rod, [p.rod_length, 0, 0]
        for i in range(1, p.segments + 1):
            body = parent.add_body(name=f"seg{i}", pos=pos)
            body.mass, body.ipos, body.inertia = p.segment_mass, [half, 0, 0], [p.segment_inertia] * 3
            body.add_joint(spec.find_default("hinge"), name=f"hinge{i}")
            body.add_geom(spec.find_default("segment"), name=f"seg{i}", pos=[half, 0, 0])
            body.add_site(name=f"seg{i}", pos=[half, 0, 0])
            segment_bodies.append(body)
            parent, pos = body, [p.segment_length, 0, 0]

    if backend == "native":
        spec.activate_plugin(native.PLUGIN)
        sand = spec.add_plugin(name="sand", plugin_name=native.PLUGIN, active=True)
        sand.config = plugin_config(scene)
        for body in segment_bodies:
            body.plugin = sand
            body.plugin.name = "sand"
            body.plugin.active = True

    # Everything the drive moves, seen from the drive: total mass (slide) or inertia about the base (hinge).
    lumps = [(p.rod_mass, p.rod_inertia, p.rod_length / 2)] + [
        (p.segment_mass, p.segment_inertia, p.rod_length + (i + 0.5) * p.segment_length) for i in range(p.segments)]
    moved = sum(m for m, _, _ in lumps) if drive == "drag" else sum(i + m * r * r for m, i, r in lumps)
    joint.armature = ARMATURE_RATIO * moved
    spec.modelname = f"finrft {p.kind} plate ({drive})"
    return spec


def build_plate(scene: Scene, drive: str = "drag", attack_deg: float = 90.0) -> PlateModel:
    """Compile the plate model for a scene and collect its indices."""
    backend = native.resolve_backend(scene.sim.backend)
    spec = plate_spec(scene, drive, attack_deg, backend)
    try:
        with captured_warnings([]):
            model = spec.compile()
    except ValueError as exc:  # e.g. the plugin's init rejecting its config: quote its line, which names the key
        lines = str(exc).strip().splitlines()
        reason = next((line for line in lines if line.startswith(native.PLUGIN)), lines[0])
        raise SceneError(f"MuJoCo rejected the model: {reason}") from None
    n = scene.plate.segments
    drive_id = model.joint("drive").id
    hinge_ids = [model.joint(f"hinge{i}").id for i in range(1, n + 1)] if scene.plate.kind != "rigid" else []
    sites = np.array([model.site(f"seg{i}").id for i in range(1, n + 1)])
    return PlateModel(
        model=model,
        backend=backend,
        drive=drive,
        drive_dof=int(model.jnt_dofadr[drive_id]),
        drive_qpos=int(model.jnt_qposadr[drive_id]),
        armature=float(model.dof_armature[model.jnt_dofadr[drive_id]]),
        hinge_qpos=np.array([model.jnt_qposadr[j] for j in hinge_ids], dtype=int),
        hinge_dof=np.array([model.jnt_dofadr[j] for j in hinge_ids], dtype=int),
        seg_body=model.site_bodyid[sites].copy(),
        seg_site=sites,
        initial_angle=initial_heading(drive, attack_deg),
    )
