"""MuJoCo models built from the MJCF files in ``mjcf/`` and a scene.

The MJCF file describes the paper's plate and is edited through MjSpec (never by string edits) to apply a scene:
segment count and sizes, masses and inertias, hinge spring/damper/stop, and the drive.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from . import laws, native
from .scene import RFT, Chain, RobotScene, Scene, SceneError, Sim

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
# A stiff limit: impedance 0.9999 (MuJoCo's maximum) and a time constant of 1 ms (MuJoCo needs >= 2 dt). A fixed
# time constant keeps the stop the same when dt changes, so results converge in dt.
LIMIT_IMPEDANCE = (0.9999, 0.9999, 0.001, 0.5, 2.0)
LIMIT_TIMECONST = 1e-3


@dataclass(frozen=True)
class ForceGroup:
    """Segments that share one RFT law (one plugin instance in the native backend), and the hinges on the same
    bodies that carry the penalty stop (when stop_stiffness > 0)."""

    name: str
    rft: RFT
    sites: np.ndarray          # (N,) midpoint site of each segment
    bodies: np.ndarray         # (N,) body that carries each segment
    stop_stiffness: float
    hinge_qpos: np.ndarray     # hinges on the group's bodies
    hinge_dof: np.ndarray


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
    groups: tuple[ForceGroup, ...]  # the segments' RFT (one group)


def mjcf_path(name: str = "plate.xml"):
    """The path of a packaged MJCF file."""
    return resources.files("finrft.mjcf") / name


def _quat_z(angle: float) -> list[float]:
    return [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)]


def initial_heading(drive: str, attack_deg: float) -> float:
    """The plate's orientation about z at t = 0: a drag along +y at angle of attack theta starts at 90 deg - theta."""
    return float(np.radians(90.0 - attack_deg)) if drive == "drag" else 0.0


def plugin_config(law: RFT, stop_stiffness: float) -> dict[str, str]:
    """The native plugin's config for one force group: the same law and penalty stop as the Python coupling."""
    return {**laws.plugin_config(law), "stop_stiffness": repr(stop_stiffness)}


def penalty_stiffness(chain: Chain) -> float:
    return chain.stop_stiffness if chain.kind == "origami" and chain.stop == "penalty" else 0.0


def _configure_chain(spec: mujoco.MjSpec, chain: Chain, dt: float) -> None:
    """Apply a chain's hinge and segment parameters to the file's ``hinge`` and ``segment`` default classes."""
    seg_geom = spec.find_default("segment").geom
    seg_geom.size = [chain.segment_length / 2, seg_geom.size[1], seg_geom.size[2]]
    hinge = spec.find_default("hinge").joint
    hinge.stiffness = [chain.stiffness, 0, 0]
    hinge.springref = chain.springref
    hinge.damping = [chain.damping, 0, 0]
    if chain.kind == "origami" and chain.stop == "limit":
        hinge.range = [-np.pi, chain.springref]
        hinge.solref_limit = [max(LIMIT_TIMECONST, 2 * dt), 1.0]
        hinge.solimp_limit = list(LIMIT_IMPEDANCE)
    else:
        hinge.limited = mujoco.mjtLimited.mjLIMITED_FALSE


def _add_chain(spec: mujoco.MjSpec, parent: mujoco.MjsBody, chain: Chain, offset: float,
               prefix: str = "", spatial: bool = False, welded: bool = False) -> list[mujoco.MjsBody]:
    """Segments ``{prefix}seg{i}`` in series from ``offset`` along the parent's x axis, on hinges
    ``{prefix}hinge{i}``; a rigid chain is one body ``{prefix}plate`` carrying every segment, unless ``welded``:
    then hinged segments held by weld constraints. ``spatial``: each segment also turns freely about its own x
    and y axes (hinges ``{prefix}bend{i}x``, ``{prefix}bend{i}y``)."""
    half = chain.segment_length / 2
    segment = spec.find_default("segment")
    if chain.kind == "rigid" and not welded:
        body = parent.add_body(name=f"{prefix}plate", pos=[offset, 0, 0])
        centres = [half + i * chain.segment_length for i in range(chain.segments)]
        com = float(np.mean(centres))
        body.mass, body.ipos = chain.segments * chain.segment_mass, [com, 0, 0]
        body.inertia = [sum(chain.segment_inertia + chain.segment_mass * (c - com) ** 2 for c in centres)] * 3
        for i, c in enumerate(centres, start=1):
            body.add_geom(segment, name=f"{prefix}seg{i}", pos=[c, 0, 0])
            body.add_site(name=f"{prefix}seg{i}", pos=[c, 0, 0])
        return [body]
    bodies, pos = [], [offset, 0, 0]
    for i in range(1, chain.segments + 1):
        body = parent.add_body(name=f"{prefix}seg{i}", pos=pos)
        body.mass, body.ipos, body.inertia = chain.segment_mass, [half, 0, 0], [chain.segment_inertia] * 3
        for axis in ("x", "y") if spatial else ():
            body.add_joint(name=f"{prefix}bend{i}{axis}", type=mujoco.mjtJoint.mjJNT_HINGE,
                           axis=[float(axis == "x"), float(axis == "y"), 0.0])
        body.add_joint(spec.find_default("hinge"), name=f"{prefix}hinge{i}")
        if welded:
            weld = spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                                     name1=parent.name, name2=body.name)
            weld.solref = [LIMIT_TIMECONST, 1.0]
            weld.solimp = list(LIMIT_IMPEDANCE)
        body.add_geom(segment, name=f"{prefix}seg{i}", pos=[half, 0, 0])
        body.add_site(name=f"{prefix}seg{i}", pos=[half, 0, 0])
        bodies.append(body)
        parent, pos = body, [chain.segment_length, 0, 0]
    return bodies


def _bind(spec: mujoco.MjSpec, name: str, law: RFT, stop_stiffness: float, bodies: list[mujoco.MjsBody]) -> None:
    """Bind a native plugin instance carrying one force group's law to its bodies."""
    spec.activate_plugin(native.PLUGIN)
    instance = spec.add_plugin(name=name, plugin_name=native.PLUGIN, active=True)
    instance.config = plugin_config(law, stop_stiffness)
    for body in bodies:
        body.plugin = instance
        body.plugin.name = name
        body.plugin.active = True


def _new_spec(file: str, sim: Sim) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(mjcf_path(file)))
    spec.option.timestep = sim.dt
    spec.option.integrator = INTEGRATORS[sim.integrator]
    return spec


def _compile(spec: mujoco.MjSpec) -> mujoco.MjModel:
    try:
        with native.captured_warnings([]):
            return spec.compile()
    except ValueError as exc:  # e.g. the plugin's init rejecting its config: quote its line, which names the key
        lines = str(exc).strip().splitlines()
        reason = next((line for line in lines if line.startswith(native.PLUGIN)), lines[0])
        raise SceneError(f"MuJoCo rejected the model: {reason}") from None


def _group(model: mujoco.MjModel, name: str, law: RFT, stop_stiffness: float, body_names: list[str]) -> ForceGroup:
    """A force group of a compiled model: every site on the named bodies, and their hinges."""
    ids = [model.body(b).id for b in body_names]
    sites = np.array([s for s in range(model.nsite) if model.site_bodyid[s] in ids], dtype=int)
    hinges = [j for j in range(model.njnt) if model.jnt_bodyid[j] in ids  # hinges about z, as the plugin's
              and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and abs(model.jnt_axis[j, 2]) > 0.5]
    return ForceGroup(name, law, sites, model.site_bodyid[sites].copy(), stop_stiffness,
                      np.array([model.jnt_qposadr[j] for j in hinges], dtype=int),
                      np.array([model.jnt_dofadr[j] for j in hinges], dtype=int))


def plate_spec(scene: Scene, drive: str = "drag", attack_deg: float = 90.0,
               backend: str = "python") -> mujoco.MjSpec:
    """The plate's MjSpec for a scene: drive ``drag`` (base slides along +y, the plate at angle of attack
    ``attack_deg`` to the motion) or ``rotate`` (the rod turns about z through its base); with backend
    ``native`` the RFT plugin is bound to the segments."""
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {DRIVES}, got {drive!r}")
    p = scene.plate
    spec = _new_spec("plate.xml", scene.sim)
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
    _configure_chain(spec, p, scene.sim.dt)
    segments = _add_chain(spec, rod, p, p.rod_length, spatial=p.chain == "spatial", welded=p.rigid_as == "welds")
    if backend == "native":
        _bind(spec, "sand", scene.rft, penalty_stiffness(p), segments)

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
    model = _compile(plate_spec(scene, drive, attack_deg, backend))
    p = scene.plate
    one_body = p.kind == "rigid" and p.rigid_as == "body"
    bodies = ["plate"] if one_body else [f"seg{i}" for i in range(1, p.segments + 1)]
    group = _group(model, "sand", scene.rft, penalty_stiffness(p), bodies)
    drive_id = model.joint("drive").id
    hinge_ids = [] if one_body else [model.joint(f"hinge{i}").id for i in range(1, p.segments + 1)]
    return PlateModel(
        model=model,
        backend=backend,
        drive=drive,
        drive_dof=int(model.jnt_dofadr[drive_id]),
        drive_qpos=int(model.jnt_qposadr[drive_id]),
        armature=float(model.dof_armature[model.jnt_dofadr[drive_id]]),
        hinge_qpos=np.array([model.jnt_qposadr[j] for j in hinge_ids], dtype=int),
        hinge_dof=np.array([model.jnt_dofadr[j] for j in hinge_ids], dtype=int),
        groups=(group,),
    )


@dataclass(frozen=True)
class RobotModel:
    """A compiled robot model and the indices the simulation needs."""

    model: mujoco.MjModel
    backend: str
    sides: tuple[str, ...]     # ("r",) for the half robot, ("r", "l") for the full one
    travel_qpos: int           # the body's slide along +y
    travel_dof: int
    body: int
    servo_qpos: np.ndarray     # (S,) per side
    servo_dof: np.ndarray
    armature: float            # prescribed servos: their armature; 0 with position servos
    actuators: np.ndarray      # position servos' actuator ids (empty when prescribed)
    fin_hinge_qpos: np.ndarray  # (S, H) fin hinges per side (H = 0 for a rigid fin)
    fin_hinge_dof: np.ndarray   # (S, H)
    fin_sites: np.ndarray      # (S, N) fin segment midpoints per side
    groups: tuple[ForceGroup, ...]


def arm_law(scene: RobotScene) -> RFT:
    """The arm's RFT law: the paper law with a normal coefficient that grows with the arm's length."""
    a = scene.arm
    return RFT(law="paper", f_perp=a.f_perp_base + a.f_perp_per_length * a.length, f_par=a.f_par,
               v_reg=scene.rft.v_reg)


def body_share(scene: RobotScene) -> float:
    """The share of the body's mass and drag a model carries: all of it, or half for the half robot."""
    return 0.5 if scene.robot.model == "half" else 1.0


def body_law(scene: RobotScene) -> RFT:
    """The velocity body drag as an isotropic RFT law: F = -tanh(|v|/v_reg) drag v/|v|."""
    drag = body_share(scene) * scene.body.drag
    return RFT(law="paper", f_perp=drag, f_par=drag, v_reg=scene.body.v_reg)


def robot_spec(scene: RobotScene, backend: str = "python") -> mujoco.MjSpec:
    """The robot's MjSpec for a scene (see mjcf/robot.xml)."""
    spec = _new_spec("robot.xml", scene.sim)
    r, a, fin = scene.robot, scene.arm, scene.fin
    sides = ("r",) if r.model == "half" else ("r", "l")
    if r.model == "half":
        spec.delete(spec.body("l_arm"))
    body = spec.body("body")
    body.mass = body_share(scene) * scene.body.mass
    _configure_chain(spec, fin, scene.sim.dt)
    arm_mass = a.mass_base + a.linear_density * a.length
    # What a servo turns, about its pivot: the arm and the fin laid straight out.
    moved = a.inertia + arm_mass * (a.length / 2) ** 2 + sum(
        fin.segment_inertia + fin.segment_mass * (a.length + (i + 0.5) * fin.segment_length) ** 2
        for i in range(fin.segments))
    arms, segments = [], []
    for side in sides:
        arm = spec.body(f"{side}_arm")
        spec.delete(spec.body(f"{side}_seg1"))
        arm.pos = [a.pivot if side == "r" else -a.pivot, 0, 0]
        arm.mass, arm.ipos, arm.inertia = arm_mass, [a.length / 2, 0, 0], [a.inertia] * 3
        spec.geom(f"{side}_arm").fromto = [0, 0, 0, a.length, 0, 0]
        spec.site(f"{side}_arm").pos = [a.length / 2, 0, 0]
        segments += _add_chain(spec, arm, fin, a.length, prefix=f"{side}_")
        arms.append(arm)
        servo = spec.joint(f"{side}_servo")
        if r.servo == "prescribed":
            servo.armature = ARMATURE_RATIO * moved
        else:
            servo.armature = 0.0
            actuator = spec.add_actuator(name=f"{side}_servo", target=f"{side}_servo",
                                         trntype=mujoco.mjtTrn.mjTRN_JOINT)
            actuator.set_to_intvelocity(kp=r.servo_kp, dampratio=1.0)
            actuator.actlimited = mujoco.mjtLimited.mjLIMITED_TRUE
            actuator.actrange = [scene.gait.theta2, scene.gait.theta1]
    if backend == "native":
        _bind(spec, "fin_sand", scene.rft, penalty_stiffness(fin), segments)
        _bind(spec, "arm_sand", arm_law(scene), 0.0, arms)
        if scene.body.drag_law == "velocity":
            _bind(spec, "body_sand", body_law(scene), 0.0, [body])
    spec.modelname = f"finrft robot ({r.model}, {fin.kind} fins)"
    return spec


def build_robot(scene: RobotScene) -> RobotModel:
    """Compile the robot model for a scene and collect its indices."""
    backend = native.resolve_backend(scene.sim.backend)
    model = _compile(robot_spec(scene, backend))
    fin = scene.fin
    sides = ("r",) if scene.robot.model == "half" else ("r", "l")
    fin_bodies = {s: [f"{s}_plate"] if fin.kind == "rigid" else [f"{s}_seg{i}" for i in range(1, fin.segments + 1)]
                  for s in sides}
    groups = [_group(model, "fin_sand", scene.rft, penalty_stiffness(fin), sum(fin_bodies.values(), [])),
              _group(model, "arm_sand", arm_law(scene), 0.0, [f"{s}_arm" for s in sides])]
    if scene.body.drag_law == "velocity":
        groups.append(_group(model, "body_sand", body_law(scene), 0.0, ["body"]))
    travel = model.joint("travel")
    servos = [model.joint(f"{s}_servo") for s in sides]
    hinges = [[model.joint(f"{s}_hinge{i}") for i in range(1, fin.segments + 1)] if fin.kind != "rigid" else []
              for s in sides]
    prescribed = scene.robot.servo == "prescribed"
    return RobotModel(
        model=model,
        backend=backend,
        sides=sides,
        travel_qpos=int(travel.qposadr[0]),
        travel_dof=int(travel.dofadr[0]),
        body=model.body("body").id,
        servo_qpos=np.array([j.qposadr[0] for j in servos], dtype=int),
        servo_dof=np.array([j.dofadr[0] for j in servos], dtype=int),
        armature=float(model.dof_armature[servos[0].dofadr[0]]) if prescribed else 0.0,
        actuators=np.array([] if prescribed else [model.actuator(f"{s}_servo").id for s in sides], dtype=int),
        fin_hinge_qpos=np.array([[j.qposadr[0] for j in side] for side in hinges], dtype=int).reshape(len(sides), -1),
        fin_hinge_dof=np.array([[j.dofadr[0] for j in side] for side in hinges], dtype=int).reshape(len(sides), -1),
        fin_sites=np.array([[model.site(f"{s}_seg{i}").id for i in range(1, fin.segments + 1)] for s in sides]),
        groups=tuple(groups),
    )
