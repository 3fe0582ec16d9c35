"""MuJoCo models built from the MJCF files in ``mjcf/`` and a scene: the chain builder every model stands on, and
the robot's model (the plate's is its experiment's, finrft.experiments.plate).

``plate.xml`` and ``robot.xml`` hold the plate's rod and the robot's body and arms; ``segment.xml`` holds one
segment on its hinge, attached N times in series (MjSpec attach) to make the plate's chain and each fin. The specs
are edited through MjSpec (never by string edits) to apply a scene: segment count and sizes, masses and inertias,
hinge spring/damper/stop, and the drive. Indices come from the objects attach returns, not from names.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from . import laws, native
from .geometry import Resolved, resolve
from .laws import SegmentLaw
from .scene import Chain, RobotScene, SceneError, Sim

INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
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
    law: SegmentLaw            # one segment's law, forces in N
    sites: np.ndarray          # (N,) midpoint site of each segment
    bodies: np.ndarray         # (N,) body that carries each segment
    stop_stiffness: float
    hinge_qpos: np.ndarray     # hinges on the group's bodies
    hinge_dof: np.ndarray


def mjcf_path(name: str = "plate.xml"):
    """The path of a packaged MJCF file."""
    return resources.files("finrft.mjcf") / name


@functools.cache
def _parsed(name: str) -> mujoco.MjSpec:
    return mujoco.MjSpec.from_file(str(mjcf_path(name)))


def _spec(name: str) -> mujoco.MjSpec:
    """A fresh MjSpec of a packaged MJCF file: parsed once per process (a batch builds many models), copied."""
    return _parsed(name).copy()


def plugin_config(law: SegmentLaw, stop_stiffness: float) -> dict[str, str]:
    """The native plugin's config for one force group: the same law and penalty stop as the Python coupling."""
    return {**laws.plugin_config(law), "stop_stiffness": repr(stop_stiffness)}


def penalty_stiffness(chain: Chain) -> float:
    return chain.stop_stiffness if chain.kind == "origami" and chain.stop == "penalty" else 0.0


@dataclass(frozen=True)
class AttachedChain:
    """A chain's segments as attached to a spec: their bodies and their hinges about z (none for a rigid chain).
    After compiling, their ``id`` is the index in the model."""

    bodies: list[mujoco.MjsBody]
    hinges: list[mujoco.MjsJoint]


def _segment_spec(chain: Chain, dt: float, spatial: bool, hinged: bool) -> mujoco.MjSpec:
    """mjcf/segment.xml with a chain's segment: length, mass and inertia, hinge spring/damper/stop; without its
    hinge unless ``hinged``; ``spatial``: also free to turn about its own x and y axes (joints ``bendx``,
    ``bendy``)."""
    spec = _spec("segment.xml")
    half = chain.segment_length / 2
    body = spec.body("segment")
    body.mass, body.ipos, body.inertia = chain.segment_mass, [half, 0, 0], [chain.segment_inertia] * 3
    geom = spec.geom("segment")
    geom.size, geom.pos = [half, geom.size[1], geom.size[2]], [half, 0, 0]
    spec.site("midpoint").pos = [half, 0, 0]
    spec.frame("tip").pos = [chain.segment_length, 0, 0]
    hinge = spec.joint("hinge")
    if not hinged:
        spec.delete(hinge)
    elif chain.kind == "origami" and chain.stop == "limit":
        hinge.range = [-np.pi, chain.springref]
        hinge.solref_limit = [max(LIMIT_TIMECONST, 2 * dt), 1.0]
        hinge.solimp_limit = list(LIMIT_IMPEDANCE)
    else:
        hinge.limited = mujoco.mjtLimited.mjLIMITED_FALSE
    hinge.stiffness = [chain.stiffness, 0, 0]
    hinge.springref = chain.springref
    hinge.damping = [chain.damping, 0, 0]
    for axis in ("x", "y") if spatial else ():
        body.add_joint(name=f"bend{axis}", type=mujoco.mjtJoint.mjJNT_HINGE,
                       axis=[float(axis == "x"), float(axis == "y"), 0.0])
    return spec


def attach_chain(spec: mujoco.MjSpec, mount: mujoco.MjsFrame, chain: Chain, dt: float, prefix: str,
                 spatial: bool = False, welded: bool = False) -> AttachedChain:
    """Attach ``chain.segments`` copies of the segment in series, the first at ``mount``, each next one at the
    tip of the one before; copy i is named with ``prefix`` (not empty: MuJoCo warns that the model could not be
    saved) and the suffix i (``{prefix}segment{i}``, ``{prefix}hinge{i}``, ``{prefix}midpoint{i}``). A rigid
    chain has no hinges (its segments are fixed to each other), unless ``welded``: then its hinges are held by weld
    constraints."""
    welded = welded and chain.kind == "rigid"
    hinged = welded or chain.kind != "rigid"
    segment = _segment_spec(chain, dt, spatial, hinged)
    parent = mount.parent  # the body that carries the mount
    attached = AttachedChain([], [])
    for i in range(1, chain.segments + 1):
        body = mount.attach_body(segment.copy().body("segment"), prefix, str(i))
        if hinged:
            attached.hinges.append(body.joints[0])  # the file's hinge; the bends come after it
        if welded:
            weld = spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                                     name1=parent.name, name2=body.name)
            weld.solref = [LIMIT_TIMECONST, 1.0]
            weld.solimp = list(LIMIT_IMPEDANCE)
        attached.bodies.append(body)
        parent, mount = body, body.frames[0]  # the copy's frame "tip"
    return attached


def bind_plugin(spec: mujoco.MjSpec, name: str, law: SegmentLaw, stop_stiffness: float,
                bodies: list[mujoco.MjsBody]) -> None:
    """Bind a native plugin instance carrying one force group's law to its bodies."""
    spec.activate_plugin(native.PLUGIN)
    instance = spec.add_plugin(name=name, plugin_name=native.PLUGIN, active=True)
    instance.config = plugin_config(law, stop_stiffness)
    for body in bodies:
        body.plugin = instance
        body.plugin.name = name
        body.plugin.active = True


def new_spec(file: str, sim: Sim) -> mujoco.MjSpec:
    """A fresh spec of a packaged MJCF file with the scene's time step and integrator."""
    spec = _spec(file)
    spec.option.timestep = sim.dt
    spec.option.integrator = INTEGRATORS[sim.integrator]
    # The prescribed drive's armature (ARMATURE_RATIO) sets the scale of the constraint solver's cost, against
    # which its default relative tolerance (1e-8) can accept the warm start of a welded plate as converged: the
    # drive's load (-armature qacc) then reads 0. With no tolerance it iterates until the cost stops falling (a
    # few Newton iterations here).
    spec.option.tolerance = 0.0
    return spec


def compile_spec(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """The compiled model; SceneError quoting MuJoCo's reason when it refuses the spec."""
    try:
        with native.captured_warnings([]):
            return spec.compile()
    except ValueError as exc:  # e.g. the plugin's init rejecting its config: quote its line, which names the key
        lines = str(exc).strip().splitlines()
        reason = next((line for line in lines if line.startswith(native.PLUGIN)), lines[0])
        raise SceneError(f"MuJoCo rejected the model: {reason}") from None


def force_group(model: mujoco.MjModel, name: str, law: SegmentLaw, stop_stiffness: float,
                bodies: list[mujoco.MjsBody]) -> ForceGroup:
    """A force group of a compiled model: every site on the given (compiled) bodies, and their hinges."""
    ids = [b.id for b in bodies]
    sites = np.array([s for s in range(model.nsite) if model.site_bodyid[s] in ids], dtype=int)
    hinges = [j for j in range(model.njnt) if model.jnt_bodyid[j] in ids  # hinges about z, as the plugin's
              and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and abs(model.jnt_axis[j, 2]) > 0.5]
    return ForceGroup(name, law, sites, model.site_bodyid[sites].copy(), stop_stiffness,
                      np.array([model.jnt_qposadr[j] for j in hinges], dtype=int),
                      np.array([model.jnt_dofadr[j] for j in hinges], dtype=int))


def addresses(model: mujoco.MjModel, joints: list[mujoco.MjsJoint]) -> tuple[np.ndarray, np.ndarray]:
    """The qpos and dof addresses of compiled joints."""
    ids = [j.id for j in joints]
    return model.jnt_qposadr[ids].astype(int), model.jnt_dofadr[ids].astype(int)


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
    resolved: Resolved         # the forces the scene's medium and geometry give (finrft.geometry.resolve)


def body_share(scene: RobotScene) -> float:
    """The share of the body's mass and drag a model carries: all of it, or half for the half robot."""
    return 0.5 if scene.robot.model == "half" else 1.0


def body_law(scene: RobotScene, resolved: Resolved) -> SegmentLaw:
    """The velocity body drag as an isotropic law: F = -tanh(|v|/v_reg) drag v/|v|, the model's share of the whole
    robot's resolved body drag."""
    drag = body_share(scene) * resolved.body_drag
    return SegmentLaw("paper", scene.body.v_reg, {"f_perp": drag, "f_par": drag})


@dataclass(frozen=True)
class _Robot:
    spec: mujoco.MjSpec
    travel: mujoco.MjsJoint
    body: mujoco.MjsBody
    arms: list[mujoco.MjsBody]            # per side
    servos: list[mujoco.MjsJoint]
    actuators: list[mujoco.MjsActuator]   # position servos, per side (empty when prescribed)
    fins: list[AttachedChain]


def _robot(scene: RobotScene, backend: str, resolved: Resolved) -> _Robot:
    spec = new_spec("robot.xml", scene.sim)
    r, a, fin = scene.robot, scene.arm, scene.fin
    sides = ("r",) if r.model == "half" else ("r", "l")
    if r.model == "half":
        spec.delete(spec.body("l_arm"))
    body = spec.body("body")
    body.mass = body_share(scene) * scene.body.mass
    arm_mass = a.mass_base + a.linear_density * a.length
    # What a servo turns, about its pivot: the arm and the fin laid straight out.
    moved = a.inertia + arm_mass * (a.length / 2) ** 2 + sum(
        fin.segment_inertia + fin.segment_mass * (a.length + (i + 0.5) * fin.segment_length) ** 2
        for i in range(fin.segments))
    robot = _Robot(spec, spec.joint("travel"), body, [], [], [], [])
    for side in sides:
        arm = spec.body(f"{side}_arm")
        arm.pos = [a.pivot if side == "r" else -a.pivot, 0, 0]
        arm.mass, arm.ipos, arm.inertia = arm_mass, [a.length / 2, 0, 0], [a.inertia] * 3
        spec.geom(f"{side}_arm").fromto = [0, 0, 0, a.length, 0, 0]
        spec.site(f"{side}_arm").pos = [a.length / 2, 0, 0]
        mount = spec.frame(f"{side}_fin")
        mount.pos = [a.length, 0, 0]
        robot.fins.append(attach_chain(spec, mount, fin, scene.sim.dt, f"{side}_"))
        robot.arms.append(arm)
        servo = spec.joint(f"{side}_servo")
        robot.servos.append(servo)
        if r.servo == "prescribed":
            servo.armature = ARMATURE_RATIO * moved
        else:
            actuator = spec.add_actuator(name=f"{side}_servo", target=servo.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            actuator.set_to_intvelocity(kp=r.servo_kp, dampratio=1.0)
            actuator.actlimited = mujoco.mjtLimited.mjLIMITED_TRUE
            actuator.actrange = [scene.gait.theta2, scene.gait.theta1]
            robot.actuators.append(actuator)
    if backend == "native":
        bind_plugin(spec, "fin_sand", resolved.chain, penalty_stiffness(fin), _fin_bodies(robot))
        bind_plugin(spec, "arm_sand", resolved.arm, 0.0, robot.arms)
        if scene.body.drag_law == "velocity":
            bind_plugin(spec, "body_sand", body_law(scene, resolved), 0.0, [body])
    spec.modelname = f"finrft robot ({r.model}, {fin.kind} fins)"
    return robot


def _fin_bodies(robot: _Robot) -> list[mujoco.MjsBody]:
    return [b for fin in robot.fins for b in fin.bodies]


def robot_spec(scene: RobotScene, backend: str = "python") -> mujoco.MjSpec:
    """The robot's MjSpec for a scene (see mjcf/robot.xml)."""
    return _robot(scene, backend, resolve(scene)).spec


def build_robot(scene: RobotScene) -> RobotModel:
    """Compile the robot model for a scene and collect its indices."""
    backend = native.resolve_backend(scene.sim.backend)
    resolved = resolve(scene)
    robot = _robot(scene, backend, resolved)
    model = compile_spec(robot.spec)
    fin = scene.fin
    sides = ("r",) if scene.robot.model == "half" else ("r", "l")
    groups = [force_group(model, "fin_sand", resolved.chain, penalty_stiffness(fin), _fin_bodies(robot)),
              force_group(model, "arm_sand", resolved.arm, 0.0, robot.arms)]
    if scene.body.drag_law == "velocity":
        groups.append(force_group(model, "body_sand", body_law(scene, resolved), 0.0, [robot.body]))
    (travel_qpos,), (travel_dof,) = addresses(model, [robot.travel])
    servo_qpos, servo_dof = addresses(model, robot.servos)
    hinges = [addresses(model, chain.hinges) for chain in robot.fins]
    prescribed = scene.robot.servo == "prescribed"
    return RobotModel(
        model=model,
        backend=backend,
        sides=sides,
        travel_qpos=int(travel_qpos),
        travel_dof=int(travel_dof),
        body=robot.body.id,
        servo_qpos=servo_qpos,
        servo_dof=servo_dof,
        armature=float(model.dof_armature[servo_dof[0]]) if prescribed else 0.0,
        actuators=np.array([u.id for u in robot.actuators], dtype=int),
        fin_hinge_qpos=np.array([q for q, _ in hinges], dtype=int).reshape(len(sides), -1),
        fin_hinge_dof=np.array([d for _, d in hinges], dtype=int).reshape(len(sides), -1),
        fin_sites=np.array([[b.sites[0].id for b in chain.bodies] for chain in robot.fins]),
        groups=tuple(groups),
        resolved=resolved,
    )
