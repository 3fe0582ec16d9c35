"""A user's MJCF model with RFT attached and prescribed joints, compiled and run: what `finrft run` (`user_model`)
and `finrft intrude` (`intrusion`) build on. `build_attached` gives the model its numerics, each driven joint its
armature and the named bodies (and geoms) the medium; `JointTrial` runs one joint on a prescribed profile."""

from __future__ import annotations

import copy
import ctypes
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence
from xml.etree import ElementTree

import mujoco
import numpy as np

from .. import design, laws, methods, native
from ..attach import Attached, SurfaceForces, attach
from ..drive import Drive
from ..files import check_regular, not_a_file, read_text
from ..models import ARMATURE_RATIO, INTEGRATORS, compile_spec
from ..scene import Medium, SceneError
from ..stepping import Prescribed
from ..surfaces import deforming, hfield

_J = mujoco.mjtJoint
DRIVEN = {int(_J.mjJNT_SLIDE): "slide", int(_J.mjJNT_HINGE): "hinge"}


@dataclass(frozen=True, eq=False)
class AttachedModel:
    """A compiled model with RFT attached, and the indices of its prescribed joints (in the order named)."""

    model: mujoco.MjModel
    attached: Attached
    drive_dofs: np.ndarray
    drive_qpos: np.ndarray
    armature: np.ndarray       # each driven joint's armature (kg or kg m^2)
    bodies: np.ndarray         # ids of the attached bodies, in the order named
    size: float                # the attached bodies' size at rest (m, `rest_size`)
    groups: tuple = ()         # no segment force groups: the forces are the attached surfaces'

    @property
    def backend(self) -> str:
        return self.attached.backend

    def python_forces(self) -> SurfaceForces:
        return self.attached.callback(self.model)

    def at_step(self, dt: float) -> AttachedModel | None:
        """The same model at another time step (s), for a run's companion and `auto`'s pilots: the step is all that
        differs between theirs, and building the surface elements again cost the hexapod 0.3 s a step (its meshes'
        inside tests), the wheel rig 27 ms; None on the warp backend, whose model is built with it."""
        if self.attached.backend == "warp":
            return None
        model = copy.copy(self.model)
        model.opt.timestep = dt
        return replace(self, model=model)


def read_spec(path: str) -> mujoco.MjSpec:
    """An MJCF file's spec; SceneError in one line when it is missing or MuJoCo cannot parse it."""
    if not path:
        raise SceneError("no model: give the MJCF file (finrft run MODEL.xml, or model.path in the scene)")
    if not Path(path).is_file():
        raise SceneError(f"cannot read model file {path}: {not_a_file(path)}")
    check_model_files(Path(path))
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise SceneError(f"model file {path}: {' '.join(str(exc).split())}") from None


def scene_spec(scene: Any) -> mujoco.MjSpec:
    """A user's scene's model as its spec, with the scene's design edits made (`finrft.design`: SceneError for a
    name or index the model does not have)."""
    spec = read_spec(scene.model.path)
    design.apply(spec, scene.model.design)
    return spec


# The largest file a model may name (a mesh, a texture): far above a detailed robot's meshes.
MAX_ASSET_BYTES = 2**30


def check_model_files(path: Path) -> None:
    """SceneError unless the MJCF file and every file it names (its includes, recursively, and their meshes,
    textures, height fields and skins) that exists is a regular file of bounded size, as every file finrft reads:
    MuJoCo reads them itself, and would wait forever on a named pipe or read a device without end. Where a named
    file is looked for depends on the compiler's asset folders, so each place it may be is checked."""
    folder, seen, todo = path.parent, set(), [path]
    dirs: set[str] = {""}
    while todo:
        xml = todo.pop()
        if xml in seen:
            continue
        seen.add(xml)
        try:
            root = ElementTree.fromstring(read_text(xml, "model file"))
        except ElementTree.ParseError:
            return  # MuJoCo's parser says what is wrong, in its words
        for compiler in root.iter("compiler"):
            dirs.update(compiler.get(key) for key in ("meshdir", "texturedir", "assetdir") if compiler.get(key))
        for element in root.iter():
            named = element.get("file")
            if not named:
                continue
            if element.tag == "include":
                todo.append(folder / named)
                continue
            for place in {folder / d / named for d in dirs}:
                try:
                    info = os.stat(place)
                except OSError:
                    continue
                check_regular(info, place, f"model asset ({element.tag})", MAX_ASSET_BYTES)


def driven_joint(spec: mujoco.MjSpec, name: str, key: str = "drive.joint") -> mujoco.MjsJoint:
    """The named slide or hinge joint of a spec; SceneError naming the joints there are."""
    joint = spec.joint(name) if name else None
    if joint is None:
        names = ", ".join(j.name for j in spec.joints if j.name) or "none named"
        raise SceneError(f"{key}: the model has no joint named {name!r} (its joints: {names})")
    if int(joint.type) not in DRIVEN:
        raise SceneError(f"{key} {name!r} is a {_J(joint.type).name.removeprefix('mjJNT_').lower()} joint: "
                         f"drive a slide or hinge joint")
    return joint


def build_attached(spec: mujoco.MjSpec, joints: Sequence[str], bodies: tuple[str, ...], medium: Medium,
                   sim: Any, geoms: tuple[str, ...] = ()) -> AttachedModel:
    """Give ``spec`` the numerics, each driven joint its armature and RFT the bodies (all their geoms) and the
    geoms named, and compile it. The attached bodies are ``bodies``, then those of ``geoms``."""
    if not bodies and not geoms:
        raise SceneError("model.bodies is empty: name the bodies the medium acts on")
    driven = [driven_joint(spec, name, f"drive.{i}.joint") for i, name in enumerate(joints)]
    if len(set(joints)) < len(joints):
        raise SceneError(f"a joint is driven twice: {', '.join(joints)}")
    spec.option.timestep = sim.dt
    spec.option.integrator = INTEGRATORS[sim.integrator]
    # The armature is relative to what the joint moves (its diagonal of the mass matrix at qpos0), as the plate's.
    plain = compile_spec(spec)
    d = mujoco.MjData(plain)
    mujoco.mj_forward(plain, d)
    mass = np.zeros((plain.nv, plain.nv))
    mujoco.mj_fullM(plain, d, mass)
    for joint, name in zip(driven, joints):
        dof = int(plain.jnt_dofadr[plain.joint(name).id])
        joint.armature = ARMATURE_RATIO * mass[dof, dof]
    law = laws.module(medium.law, laws.SURFACE)
    attached = attach(spec, list(bodies), geoms=list(geoms), law=medium.law, surface_z=medium.surface_z,
                      element_size=medium.element_size, backend=sim.backend, medium=medium.name or None,
                      drft_lambda=medium.drft_lambda, v_reg=medium.v_reg,
                      bulk_density=None if law.DENSITY else medium.bulk_density or None,
                      bed_depth=medium.bed_depth, **surface_arguments(medium, spec.option.gravity),
                      **law.given(medium))
    model = compile_spec(spec)
    ids = [model.joint(name).id for name in joints]
    dofs = np.array([model.jnt_dofadr[j] for j in ids], dtype=int)
    attached_bodies = np.array([model.body(s.body).id for s in attached.surfaces], dtype=int)
    return AttachedModel(model, attached, dofs, np.array([model.jnt_qposadr[j] for j in ids], dtype=int),
                         np.array(model.dof_armature[dofs], dtype=float), attached_bodies,
                         rest_size(model, attached_bodies))


def rest_size(m: mujoco.MjModel, bodies: np.ndarray) -> float:
    """The diagonal (m) of the box around ``bodies``' geoms' bounding spheres at the model's rest pose: computed
    once a build, as a new MjData costs 3-9 ms (the wheel rig's, made for each of its ten pilots)."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    geoms = np.flatnonzero(np.isin(m.geom_bodyid, bodies))
    low = (d.geom_xpos[geoms] - m.geom_rbound[geoms, None]).min(axis=0)
    high = (d.geom_xpos[geoms] + m.geom_rbound[geoms, None]).max(axis=0)
    return float(np.linalg.norm(high - low))


def surface_arguments(medium: Medium, gravity: Sequence[float]) -> dict[str, Any]:
    """`attach`'s arguments of a scene's free surface (``[medium] surface`` and its keys): a heightfield generated
    from the hfield_ keys when the scene names no <hfield> of the model."""
    if medium.surface == "deforming":
        grid = hfield.generated(medium.hfield_shape, gravity, medium.surface_point, medium.hfield_extent,
                                medium.hfield_spacing, medium.hfield_slope, medium.hfield_height,
                                medium.hfield_length, medium.hfield_seed, medium.hfield_heading)
        return {"surface": deforming.field(grid, medium.pile_factor or None)}
    if medium.surface == "hfield" and not medium.hfield:
        return {"surface": hfield.generated(medium.hfield_shape, gravity, medium.surface_point, medium.hfield_extent,
                                            medium.hfield_spacing, medium.hfield_slope, medium.hfield_height,
                                            medium.hfield_length, medium.hfield_seed, medium.hfield_heading)}
    return {"surface": medium.surface, "surface_point": medium.surface_point,
            "surface_normal": medium.surface_normal, "hfield": medium.hfield}


def medium_forces(built: AttachedModel) -> Callable[[mujoco.MjData], np.ndarray]:
    """The resultant of the medium's force on each attached body (B, 3), world frame, from the backend in use
    (after mj_forward: as that pass applied it)."""
    wrenches = built.attached.wrenches(built.model, applied=True, every_call=False)
    return lambda d: wrenches(d)[:, 3:]


def _applied_lag(m: mujoco.MjModel, method: str) -> float:
    """How far (s) before a step's end the fixed-step implicit ``method`` took the medium's force, at its new
    velocity: (1 - midpoint) dt; 0 for the methods that take it at the state itself."""
    chosen = methods.get(method)
    return (1 - chosen.midpoint) * m.opt.timestep if chosen.implicit and not chosen.adaptive else 0.0


def applied_state(built: AttachedModel, method: str,
                  surface: deforming.DeformingSurface | None = None) -> Callable[[mujoco.MjData], mujoco.MjData]:
    """Where the forces of the step that led to an MjData's state were taken, as an MjData after mj_forward: with a
    fixed-step implicit ``method``, its new velocity v at the positions the method took the medium's force at, the
    step's start or half a step ahead (newton-midpoint): q - (1 - midpoint) dt v from the positions q after it,
    at that time (exact for newton; newton-midpoint's own midpoint is dt/2 times the step's velocity change away),
    with the state's ctrl, applied forces and activations (a scratch MjData: MuJoCo's control callback must leave
    it alone); else the MjData itself. A force read at the state itself instead (one that ripples as elements enter
    the medium, correlated with the velocity it drives) averages to other than the impulse the steps applied, by an
    amount first order in dt: the wheel rig free under its 21 N load came out 0.12 N short at 20 ms. With the run's
    deforming ``surface``, its level (the instances' plugin state, most of it) is copied only when the surface has
    set it since the last copy from the same MjData."""
    m = built.model
    lag = _applied_lag(m, method)
    if lag == 0:
        return lambda d: d
    where = mujoco.MjData(m)
    # the plugin state's ranges the surface sets (each instance's level), and the rest, copied at every call
    levels = [slice(int(m.plugin_stateadr[i]), int(m.plugin_stateadr[i] + m.plugin_statenum[i]))
              for i in (surface.instances if surface is not None else ())]
    others, start = [], 0
    for kept in sorted(levels, key=lambda r: r.start):
        others.append(slice(start, kept.start))
        start = kept.stop
    others = [r for r in others + [slice(start, m.npluginstate)] if r.stop > r.start]
    copied: list[Any] = [None, -1]  # the MjData and the surface's level_sets of the last copy of the levels
    names = ("qpos", "qvel", "act", "ctrl", "qfrc_applied", "xfrc_applied", "mocap_pos", "mocap_quat")
    # what the last call read: a run asks again at the same state (a recorded instant that is also a step of the
    # means' window), a quarter of the calls of a wheel's run, and gets the same MjData without a forward pass
    last: list[Any] = [None]

    def applied(d: mujoco.MjData) -> mujoco.MjData:
        state = (d.time, *(getattr(d, name) for name in names), *(d.plugin_state[r] for r in others))
        if (last[0] is not None and last[0][0] is d and copied[1] == (surface.level_sets if levels else -1)
                and state[0] == last[0][1] and all(np.array_equal(a, b) for a, b in zip(state[1:], last[0][2:]))):
            return where
        where.time = d.time - lag
        for name in names:
            getattr(where, name)[:] = getattr(d, name)
        for r in others:  # plugin_state: the native plugins' state
            where.plugin_state[r] = d.plugin_state[r]
        if levels and (copied[0] is not d or copied[1] != surface.level_sets):
            for r in levels:
                where.plugin_state[r] = d.plugin_state[r]
            copied[:] = [d, surface.level_sets]
        mujoco.mj_integratePos(m, where.qpos, where.qvel, -lag)
        mujoco.mj_forward(m, where)
        last[0] = (d, state[0], *(np.copy(a) for a in state[1:]))
        return where
    return applied


def record_forward(built: AttachedModel, method: str) -> Callable[[mujoco.MjModel, mujoco.MjData], None]:
    """The forward pass before a recording of a run that reads the medium's force and the drives' loads at
    `applied_state`: with the native backend, where that is not the state itself, without the medium's force,
    which the recording does not read there; else mj_forward."""
    if built.backend != "native" or _applied_lag(built.model, method) == 0:
        return mujoco.mj_forward
    pause = native.function("finrft_pause_medium", None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int)

    def forward(m: mujoco.MjModel, d: mujoco.MjData) -> None:
        pause(m._address, d._address, 1)
        try:
            mujoco.mj_forward(m, d)
        finally:
            pause(m._address, d._address, 0)
    return forward


class StepPower:
    """Each actuator's power over the step that led to a state (W): the force that step applied times the
    actuator's velocity at the state (positions move by dt times the new velocity). A fixed step takes an
    actuator's force at its start, and an implicit integrator its slope in the actuator's velocity at the new
    velocity: the force applied is the start's plus that slope times the velocity's change (`actuator_slope`). The
    force read at the state itself instead is a stiff servo's kp (ctrl - q) with q a step further on: the example
    sand-swimmer's (10 g links, kp = 50 N m/rad, kv = 0.5 N m s/rad) positive power came out 0.366 W at 1 ms
    against 0.318 W at 1/8 ms (+15 %); as applied, 0.319 W. The adaptive methods, which take many steps between two
    states read, read the state's own."""

    def __init__(self, m: mujoco.MjModel, method: str) -> None:
        self.slope = actuator_slope(m, method)
        self._start: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # the last state read: its force,
        self._last: tuple[float, np.ndarray] = (math.nan, np.zeros(m.nu))    # velocity and slope; its power

    def __call__(self, d: mujoco.MjData, t: float) -> np.ndarray:
        """The power at the state of ``d``, whose time is ``t``, over the step that led to it from the state read
        before (the same state read twice gives the same power)."""
        if t == self._last[0]:
            return self._last[1]
        force, velocity = d.actuator_force.copy(), d.actuator_velocity.copy()
        applied = force
        if self._start is not None:
            start, moved, slope = self._start
            applied = start + slope * (velocity - moved)
        if self.slope is not None:
            self._start = (force, velocity, self.slope(d))
        self._last = (t, applied * velocity)
        return self._last[1]


def actuator_slope(m: mujoco.MjModel, method: str) -> Callable[[mujoco.MjData], np.ndarray] | None:
    """The slope of each actuator's force in its velocity that a step of ``method`` takes implicitly, at a state (N
    s/m or N m s/rad): finrft's implicit steppers, an affine bias's (kv) on a joint; MuJoCo's own step on its
    implicit integrators, the affine bias's and gain's (times ctrl, or the activation), none where the force is
    clamped at its range; on Euler, none. None: no step leads to a state alone (the adaptive methods, RK4)."""
    chosen = methods.get(method)
    integrator = mujoco.mjtIntegrator
    if chosen.adaptive or (not chosen.implicit and m.opt.integrator == integrator.mjINT_RK4):
        return None
    bias = np.where(m.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE, m.actuator_biasprm[:, 2], 0.0)
    if chosen.implicit:
        joint = np.where(m.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT, bias, 0.0)
        return lambda d: joint
    if m.opt.integrator not in (integrator.mjINT_IMPLICIT, integrator.mjINT_IMPLICITFAST):
        none = np.zeros(m.nu)
        return lambda d: none
    gain = np.where(m.actuator_gaintype == mujoco.mjtGain.mjGAIN_AFFINE, m.actuator_gainprm[:, 2], 0.0)
    active = m.actuator_dyntype != mujoco.mjtDyn.mjDYN_NONE
    last_act = np.maximum(m.actuator_actadr + m.actuator_actnum - 1, 0)
    limited = m.actuator_forcelimited.astype(bool)
    low, high = m.actuator_forcerange.T

    def slope(d: mujoco.MjData) -> np.ndarray:
        scale = np.where(active, d.act[last_act], d.ctrl) if m.na else d.ctrl
        clamped = limited & ((d.actuator_force <= low) | (d.actuator_force >= high))
        return np.where(clamped, 0.0, bias + gain * scale)
    return slope


class JointTrial:
    """One run of an attached model with one prescribed joint on one MjData: the joint on its constant-speed
    profile from ``drive.start``; read at each recorded instant: the joint's position and the load its drive
    applies, each attached body's origin and the resultant of the medium's force on it."""

    def __init__(self, built: AttachedModel, drive: Drive, d: mujoco.MjData, companion: bool) -> None:
        m = built.model
        dof, qpos = int(built.drive_dofs[0]), int(built.drive_qpos[0])
        self.model, self.prescribed = m, Prescribed([dof], [qpos], float(built.armature[0]), drive)
        d.qpos[qpos] = drive.start
        self.on_stroke = lambda k: self.prescribed.start_stroke(m, d, k)
        self.watch = [i for i in range(m.nv) if i != dof]
        force = medium_forces(built)

        def bodies(d: mujoco.MjData) -> np.ndarray:
            if companion:  # a companion steps without mj_forward; its positions and forces need it here
                mujoco.mj_forward(m, d)
            return np.concatenate([d.xpos[built.bodies], force(d)], axis=1)

        # In this order: "bodies" brings a companion's kinematics up to date for "drive".
        self.reads = {"bodies": bodies, "drive": lambda d: np.array([d.qpos[qpos], self.prescribed.load(d)[0]])}

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        self.prescribed.finish(self.model, d)
        bodies, drive = readings["bodies"], readings["drive"]
        return ({"drive_position": drive[:, 0], "drive_load": drive[:, 1], "body_position": bodies[..., :3],
                 "rft_force": bodies[..., 3:], "stroke_impulse": self.prescribed.impulse}, {})
