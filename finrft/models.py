"""MuJoCo models built from the MJCF files in ``mjcf/`` and a scene.

The MJCF file describes the paper's plate and is edited through MjSpec (never by string edits) to apply a scene:
segment count and sizes, masses and inertias, hinge spring/damper/stop, and the drive.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from .scene import Scene

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
    drive: str                 # "drag" or "rotate"
    drive_dof: int
    drive_qpos: int
    armature: float            # the drive's armature (kg or kg m^2)
    hinge_qpos: np.ndarray     # (H,) qpos address of each hinge, H = segments - 1 + 1 or 0 when rigid
    hinge_dof: np.ndarray      # (H,)
    seg_body: np.ndarray       # (N,) body that carries each segment
    seg_site: np.ndarray       # (N,) site at each segment's midpoint
    initial_angle: float       # the plate's orientation at t = 0 (rad, about z)


def mjcf_path(name: str = "plate.xml"):
    """The path of a packaged MJCF file."""
    return resources.files("finrft.mjcf") / name


def _quat_z(angle: float) -> list[float]:
    return [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)]


def initial_heading(drive: str, attack_deg: float) -> float:
    """The plate's orientation about z at t = 0: a drag along +y at angle of attack theta starts at 90 deg - theta."""
    return float(np.radians(90.0 - attack_deg)) if drive == "drag" else 0.0


def plate_spec(scene: Scene, drive: str = "drag", attack_deg: float = 90.0) -> mujoco.MjSpec:
    """The plate's MjSpec for a scene: drive ``drag`` (base slides along +y, the plate at angle of attack
    ``attack_deg`` to the motion) or ``rotate`` (the rod turns about z through its base)."""
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
    else:
        parent, pos = rod, [p.rod_length, 0, 0]
        for i in range(1, p.segments + 1):
            body = parent.add_body(name=f"seg{i}", pos=pos)
            body.mass, body.ipos, body.inertia = p.segment_mass, [half, 0, 0], [p.segment_inertia] * 3
            body.add_joint(spec.find_default("hinge"), name=f"hinge{i}")
            body.add_geom(spec.find_default("segment"), name=f"seg{i}", pos=[half, 0, 0])
            body.add_site(name=f"seg{i}", pos=[half, 0, 0])
            parent, pos = body, [p.segment_length, 0, 0]

    # Everything the drive moves, seen from the drive: total mass (slide) or inertia about the base (hinge).
    lumps = [(p.rod_mass, p.rod_inertia, p.rod_length / 2)] + [
        (p.segment_mass, p.segment_inertia, p.rod_length + (i + 0.5) * p.segment_length) for i in range(p.segments)]
    moved = sum(m for m, _, _ in lumps) if drive == "drag" else sum(i + m * r * r for m, i, r in lumps)
    joint.armature = ARMATURE_RATIO * moved
    spec.modelname = f"finrft {p.kind} plate ({drive})"
    return spec


def build_plate(scene: Scene, drive: str = "drag", attack_deg: float = 90.0) -> PlateModel:
    """Compile the plate model for a scene and collect its indices."""
    spec = plate_spec(scene, drive, attack_deg)
    model = spec.compile()
    n = scene.plate.segments
    drive_id = model.joint("drive").id
    hinge_ids = [model.joint(f"hinge{i}").id for i in range(1, n + 1)] if scene.plate.kind != "rigid" else []
    sites = np.array([model.site(f"seg{i}").id for i in range(1, n + 1)])
    return PlateModel(
        model=model,
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
