"""MuJoCo models built from the MJCF files in ``mjcf/`` and a scene: the chain builder every model stands on (the
plate's model is its experiment's, finrft.experiments.plate; the robot's, finrft.experiments.swim).

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

from . import callbacks, laws, native
from .laws import SegmentLaw
from .scene import Chain, SceneError, Sim

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
        with callbacks.compiling(), native.captured_warnings([]):
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
