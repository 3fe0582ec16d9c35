"""A wheel in sand on a single-wheel rig (issue 24; the smooth-wheel experiments of Yu and Pavlov, CMU, in
finrft's wheel data): the hub moved at speed v along a direction at slip angle beta to the wheel's heading, the
wheel spun at the rate its slip s asks, and its vertical axis either held at a sinkage or free under a load.

The rig is the example wheel rig (mjcf/wheel_rig.xml is `rig_xml` of the default wheel, and mjcf/wheel_rig.toml its
robot-runner scene, whose [medium] and [sim] method this experiment starts from, at its own step `DT`). From the
world to the wheel: ``carriage`` slides along +x (the hub's velocity, prescribed); ``lift`` slides along +z
(prescribed at minus the sinkage, or free with the load); ``slip_angle`` turns about -z (prescribed at beta, so a
wheel at beta > 0 heads to the right of its travel); ``axle`` spins the body ``wheel`` about its y axis (prescribed
at omega). The wheel is generated (radius, width, straight grousers) or is the body ``wheel`` of a user's MJCF,
turned by its hinge ``axle`` through the body's origin along its y axis. It runs as a robot
(`user_model.RobotTrial`: the drives, the stepping, the error estimate); `wheel_summary` turns the medium's mean
force into the data's frame.

Slip, as the data defines it (v the hub's total speed, R the rim's radius): driving s = 1 - v / (omega R), braking
s = omega R / v - 1; s = -1 a locked wheel dragged, 0 pure rolling.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import mujoco
import numpy as np

from .. import laws
from ..attach import MAX_ELEMENTS
from ..convergence import ErrorLimits
from ..errors import SceneError, SimulationFailed, UsageError
from ..experiment import Compared, Quantity, Result, run
from ..files import read_text
from ..models import compile_spec, mjcf_path
from ..scene import (JointDrive, Medium, Model, RobotSim, Sections, UserScene, check_medium, check_sim, drive_timing,
                     load_scene, parse_override, register_scene)
from ..schema import field as _f
from .attached_model import AttachedModel, build_attached, medium_forces, read_spec
from .command import Command, Output, choice_lines, register, result_files, steps_line
from .flags import add_max_error, add_result_files, add_scene_flags, number
from .user_model import RobotTrial, Schedule, UserModel, window_mean

GRAVITY = 9.81  # m/s^2, MuJoCo's default, which the rig keeps
# The rig's parts other than the wheel and the load (the fork), and the generated wheel's mass.
FORK_MASS, WHEEL_MASS = 0.1, 0.5  # kg
RIG = "wheel_rig"  # the example robot this experiment is (mjcf/wheel_rig.xml, .toml)


@dataclass(frozen=True)
class WheelRig:
    radius: float = _f(0.0625, "m", "the generated wheel's rim radius, which the slip is defined with unless "
                       "wheel.slip_radius is set (a user's wheel's: its outer radius, measured)", minimum=0.0)
    width: float = _f(0.06, "m", "the generated wheel's width", minimum=0.0)
    grousers: int = _f(0, "", "straight grousers across the generated wheel's rim, evenly spaced",
                       minimum=0, exclusive=False)
    grouser_height: float = _f(0.0, "m", "their height above the rim", minimum=0.0, exclusive=False)
    grouser_thickness: float = _f(0.004, "m", "their thickness along the rim (boxes: their faces across the rim "
                                  "are parallel)", minimum=0.0)
    slip_radius: float = _f(0.0, "m", "the radius R the slip and the rim speed omega R are defined with; 0: the "
                            "generated wheel's rim radius, a user's wheel's outer radius (measured)", minimum=0.0,
                            exclusive=False)
    model: str = _f("", "", "a user's MJCF holding a body 'wheel' on a hinge 'axle' (instead of the generated "
                    "wheel)")
    slip: float = _f(0.5, "", "slip s: driving 1 - v/(omega R), braking omega R/v - 1; -1 locked, 0 rolling",
                     minimum=-1.0, exclusive=False, maximum=0.999, why_maximum="s = 1 spins the wheel infinitely fast")
    slip_angle: float = _f(0.0, "rad", "beta, from the wheel's heading to the hub's velocity (the wheel then heads "
                           "to the right of its travel)", minimum=-math.pi / 2, exclusive=False,
                           maximum=math.pi / 2, why_maximum="beyond 90 deg the wheel runs backwards")
    speed: float = _f(0.01, "m/s", "the hub's speed v (the experiments': 10 mm/s)", minimum=0.0)
    sinkage: float = _f(0.0, "m", "depth of the wheel's lowest point below the free surface, held; 0: the "
                        "vertical axis is free under wheel.load and the sinkage is predicted", minimum=0.0,
                        exclusive=False)
    load: float = _f(21.0, "N", "the weight the free vertical axis carries, wheel included (the experiments': "
                     "about 21 N)", minimum=0.0)
    start: str = _f("equilibrium", "", "where the free wheel starts: equilibrium, at the sinkage where the sand "
                    "carries the load with the wheel moving as driven and no vertical motion (its steady state); "
                    "surface, its lowest point at the free surface (it then settles over about its contact length)",
                    choices=("equilibrium", "surface"))


@dataclass(frozen=True)
class WheelScene(Sections):
    """A wheel on the single-wheel rig in the medium (`finrft wheel`)."""

    wheel: WheelRig = field(default_factory=WheelRig)
    medium: Medium = field(default_factory=Medium)
    sim: RobotSim = field(default_factory=RobotSim)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_sim(self.sim)
        check_medium(self.medium)
        if self.wheel.grouser_height > 0 and self.wheel.grousers == 0:
            raise SceneError("wheel.grouser_height is set but wheel.grousers = 0: give the number of grousers")
        if not self.wheel.model:
            check_generated(self.wheel, self.medium.element_size)


def check_generated(rig: WheelRig, element_size: float) -> None:
    """SceneError, before anything is built, for a generated wheel whose grousers have no height, do not fit on
    its rim or would cut into more surface elements than `finrft.attach` takes, or whose load is lighter than the
    wheel and the fork it includes."""
    if rig.grousers and not rig.grouser_height > 0:
        raise SceneError(f"wheel.grousers = {rig.grousers} needs their height: set wheel.grouser_height (--grouser-"
                         f"height MM), or grousers = 0 for a smooth wheel")
    t = rig.grouser_thickness
    fit = math.floor(2 * math.pi * rig.radius / t)
    if rig.grousers > fit:
        raise SceneError(f"wheel.grousers = {rig.grousers}: at most {fit} fit side by side on the rim "
                         f"({1e3 * 2 * math.pi * rig.radius:.4g} mm round, each {1e3 * t:g} mm thick)")
    if rig.grousers and not t < 2 * rig.radius:
        raise SceneError(f"wheel.grouser_thickness = {1e3 * t:g} mm is wider than the rim "
                         f"({1e3 * 2 * rig.radius:g} mm across): give a thinner grouser (--grouser-thickness MM)")
    # each grouser's outer face alone is cut into this many elements (its other faces and the rim add more)
    least = rig.grousers * math.ceil(rig.width / element_size - 1e-9) * math.ceil(t / element_size - 1e-9)
    if least > MAX_ELEMENTS:
        raise SceneError(f"wheel.grousers = {rig.grousers} at medium.element_size = {element_size:g} m gives more "
                         f"than {least} surface elements, above {MAX_ELEMENTS}: use fewer grousers or a larger "
                         f"element_size")
    carried = FORK_MASS + WHEEL_MASS
    if not rig.load > carried * GRAVITY:
        raise SceneError(f"wheel.load = {rig.load:g} N must exceed the weight of the generated wheel and the fork it "
                         f"includes ({carried * GRAVITY:.4g} N; --load N)")


register_scene(WheelScene, title="A wheel on a single-wheel rig: `finrft wheel`; `finrft.WheelScene`")


# A wheel's run: held, its forces are steady from the start (the law has no memory; the smooth wheel's elements
# turning with it leave a ripple); free, it starts at its equilibrium and stays (it drifts 0.06 mm in 3 s at slip
# angle 45 deg; docs/results/wheel.md). From the surface it would take about 20 s (200 mm of travel) to settle.
DURATION, SETTLE = 3.0, 1.0  # s
# The wheel's step: the rig example's (62.5 ms) holds its steady drive at slip 0.5 within 0.6 %; the conditions of
# the data reach from locked to spinning wheels, slip angles to 90 deg and wheels settling from the surface, and
# their study is converged at 10 ms (docs/results/wheel.md), its runs as short as 0.3 s.
DT = 0.01  # s
MAX_SINKAGE = 1.0  # m: deeper, a free wheel has no equilibrium worth reporting


# The deforming surface's grid under the wheel (`finrft wheel --surface deforming`): 2.5 mm apart (the wheel group's
# height map's), from 100 mm behind the hub's start to 200 mm ahead and 150 mm to either side, room for the rut
# and berms of a wheel at any slip angle over a few seconds at 10 mm/s.
DEFORMING_GRID = {"medium.surface_point": (0.05, 0.0, 0.0), "medium.hfield_extent": 0.15,
                  "medium.hfield_spacing": 0.0025}


# The wheels of the wheel group's experiments (finrft/data/wheel/README.md), `finrft wheel --wheel NAME`: the smooth
# one (the defaults) and the grousered one, as their mesh has it (qishuny/3D-RFT-wheel at cdd8f8f,
# data/grousered_wheel_125.mat, measured by scripts/wheel_grouser_data.py): a 57.5 mm rim, 60 mm wide, 24 grousers
# 5 mm high to a 62.5 mm tip radius, each a sector 7.55 deg wide (7.6 mm at the rim, 8.2 mm at the tips; here a box
# 7.9 mm thick, its width at mid-height), the slip taken at the tips as their code takes it (omega = rim speed /
# 62.5 mm, RFT3D/testRFT3D.m). Their 1.5 mm root fillets are left out.
GROUSERED = {"wheel.radius": 0.0575, "wheel.grousers": 24, "wheel.grouser_height": 0.005,
             "wheel.grouser_thickness": 0.0079, "wheel.slip_radius": 0.0625}
WHEELS = {"smooth": {key: getattr(WheelRig(), key.removeprefix("wheel.")) for key in GROUSERED},
          "grouser": GROUSERED}


def default_scene(**overrides: Any) -> WheelScene:
    """The wheel rig's own scene (mjcf/wheel_rig.toml): its [medium] and its [sim]'s method at a step of DT, run
    for DURATION averaged from SETTLE, with dotted-key overrides."""
    rig = load_scene(mjcf_path(f"{RIG}.toml"), cls=UserScene)
    sim = dataclasses.replace(rig.sim, dt=DT, record_dt=DT, duration=DURATION, settle=SETTLE)
    return WheelScene(medium=rig.medium, sim=sim).replace(**overrides)


def rim_speed(slip: float, speed: float) -> float:
    """omega R (m/s) of a slip s at hub speed v: v / (1 - s) driving (s > 0), v (1 + s) braking (s <= 0)."""
    return speed / (1 - slip) if slip > 0 else speed * (1 + slip)


def slip_of(rim: float, speed: float) -> float:
    """The slip of a rim speed omega R at hub speed v: the inverse of `rim_speed`."""
    return 1 - speed / rim if rim > speed else rim / speed - 1


# ---------------------------------------------------------------------------------------------------------
# The rig's model

HEADER = """<!--
  A single-wheel test rig (the smooth-wheel experiments of Yu and Pavlov, CMU: finrft's wheel data), generated by
  finrft.experiments.wheel.rig_xml: {what}.

  Joints, from the world to the wheel:
    carriage     slide along +x: the hub's travel, prescribed (10 mm/s in the experiments);
    lift         slide along +z, free: the wheel sinks under its load; everything it carries (the load, the fork,
                 the wheel) weighs {mass:g} kg, {weight:.3g} N, the load measured in the experiments;
    slip_angle   hinge about -z, prescribed at speed 0 from its start: the slip angle beta between the wheel's
                 heading and the hub's velocity (+x), so a wheel at beta > 0 heads to the right of its travel;
    axle         hinge about the wheel's y axis, prescribed: omega > 0 rolls the wheel towards +x; the slip
                 s = 1 - v / (omega R) when driving.
  The joints' reactions are the forces of the experiments: the carriage's is the wheel's resistance along its
  travel, the axle's the driving torque. No floor: the sand (finrft's RFT on the wheel, mjcf/wheel_rig.toml) holds it.
  The wheel starts with its lowest point at the free surface z = 0. mjcf/wheel_rig_scene.xml adds the surface,
  light and camera.
-->
"""


def grouser_base(rig: WheelRig) -> float:
    """The distance from the axle of a generated grouser's inner face: its edges on the rim, so that its faces
    across the rim stand on the rim from the rim to its top, none of them inside the cylinder (where `attach` would
    keep or drop a whole element row by where its centre falls)."""
    return math.sqrt(rig.radius ** 2 - (rig.grouser_thickness / 2) ** 2)


def wheel_body(rig: WheelRig) -> str:
    """The generated wheel: a cylinder about its y axis and straight grousers across its rim (boxes from the rim
    to grouser_height above it, `grouser_base`; attach drops the faces and the rim they cover)."""
    r, half = rig.radius, rig.width / 2
    lines = [f'<geom name="wheel" type="cylinder" size="{r!r} {half!r}" quat="0.7071068 0.7071068 0 0" '
             f'mass="{WHEEL_MASS!r}"\n                  rgba="0.75 0.75 0.78 1"/>']
    h, t = rig.grouser_height, rig.grouser_thickness
    for k in range(rig.grousers if h > 0 else 0):
        a = 2 * math.pi * k / rig.grousers
        base = grouser_base(rig)
        centre = (base + r + h) / 2
        lines.append(f'<geom name="grouser{k}" type="box" size="{t / 2!r} {half!r} {(r + h - base) / 2!r}" '
                     f'pos="{centre * math.sin(a)!r} 0 {centre * math.cos(a)!r}" '
                     f'euler="0 {a!r} 0" mass="0" rgba="0.6 0.6 0.65 1"/>')
    # A mark on the side, to see the wheel turn: a site, so the medium does not act on it.
    lines.append(f'<site name="mark" type="box" size="{0.8 * r!r} 0.001 0.004" pos="0 {half + 0.0005!r} 0" '
                 f'rgba="0.8 0.2 0.1 1"/>')
    lines.append('<site name="hub"/>')
    return "\n            ".join(lines)


def rig_xml(rig: WheelRig, *, wheel: bool = True) -> str:
    """The rig's MJCF with the generated wheel (``wheel=False``: the fork empty, for a user's wheel); its lowest
    point at the surface at lift = 0; the load's mass makes the whole carried weight wheel.load."""
    outer = rig.radius + rig.grouser_height
    load = rig.load / GRAVITY - FORK_MASS - WHEEL_MASS
    what = (f"a smooth wheel, radius {1e3 * rig.radius:g} mm, {1e3 * rig.width:g} mm wide" if not rig.grousers else
            f"a wheel of radius {1e3 * rig.radius:g} mm, {1e3 * rig.width:g} mm wide, {rig.grousers} grousers "
            f"{1e3 * rig.grouser_height:g} mm high, {1e3 * rig.grouser_thickness:g} mm thick")
    body = (f"""<body name="wheel">
            <joint name="axle" type="hinge" axis="0 1 0"/>
            {wheel_body(rig)}
          </body>""" if wheel else "")
    fork = max(rig.width / 2 + 0.015, 0.045)
    return HEADER.format(what=what, mass=round(rig.load / GRAVITY, 6), weight=rig.load) + f"""\
<mujoco model="wheel rig">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" integrator="implicitfast">
    <flag contact="disable"/>
  </option>

  <default>
    <default class="rig">
      <geom contype="0" conaffinity="0" rgba="0.45 0.45 0.5 1"/>
      <site type="sphere" size="0.003" rgba="0.9 0.2 0.2 1"/>
    </default>
  </default>

  <worldbody>
    <body name="carriage" pos="0 0 {outer!r}" childclass="rig">
      <joint name="carriage" type="slide" axis="1 0 0"/>
      <!-- prescribed: its mass loads only its drive -->
      <inertial pos="0 0 0.2" mass="0.5" diaginertia="1e-3 1e-3 1e-3"/>
      <geom name="rail" type="box" size="0.04 0.02 0.005" pos="0 0 0.2"/>
      <body name="load">
        <joint name="lift" type="slide" axis="0 0 1"/>
        <!-- the load: with the fork and the wheel, the weight the vertical axis carries -->
        <inertial pos="0 0 0.1" mass="{round(load, 6)!r}" diaginertia="0.005 0.005 0.005"/>
        <geom name="post" type="capsule" fromto="0 0 0.195 0 0 {outer + 0.0075!r}" size="0.006"/>
        <body name="fork">
          <joint name="slip_angle" type="hinge" axis="0 0 -1"/>
          <geom name="fork" type="box" size="0.008 {fork!r} 0.004" pos="0 0 {outer + 0.0075!r}" mass="{FORK_MASS!r}"/>
          <geom name="fork_left" type="box" size="0.008 0.004 0.035" pos="0 {fork!r} 0.035" mass="0"/>
          <geom name="fork_right" type="box" size="0.008 0.004 0.035" pos="0 {-fork!r} 0.035" mass="0"/>
          {body}
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def outer_radius(model: mujoco.MjModel, wheel: int) -> float:
    """The largest distance from the axle of the wheel's geoms' surface: rays cast towards the axle from outside,
    every degree around it and at 21 stations across the wheel's extent (any geom, meshes included)."""
    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    hub, frame = d.xpos[wheel], d.xmat[wheel].reshape(3, 3)
    axis = frame[:, 1]
    geoms = np.flatnonzero(model.geom_bodyid == wheel)
    reach = max(float(np.linalg.norm(d.geom_xpos[g] - hub) + model.geom_rbound[g]) for g in geoms) + 0.01
    group = np.zeros(6, dtype=np.uint8)
    group[:] = 1
    found, hit = 0.0, np.zeros(1, dtype=np.int32)
    for a in np.radians(np.arange(360)):
        radial = math.cos(a) * frame[:, 0] + math.sin(a) * frame[:, 2]
        for y in np.linspace(-reach, reach, 21):
            start = hub + y * axis + reach * radial
            distance = mujoco.mj_ray(model, d, start, -radial, group, 1, -1, hit)
            if distance >= 0 and model.geom_bodyid[hit[0]] == wheel:
                found = max(found, reach - distance)
    if found <= 0:
        raise SceneError("wheel.model: the body 'wheel' has no geom the medium could act on")
    return found


@dataclass(frozen=True)
class WheelModel:
    """The rig's spec with its wheel, and what the experiment needs of it: the rim radius the slip uses, the
    outer radius the sinkage is measured from, and the sign of the axle's axis along the wheel's y."""

    spec: mujoco.MjSpec
    radius: float
    outer: float
    spin_sign: float


def user_wheel(rig: WheelRig) -> mujoco.MjSpec:
    """The rig with a user's wheel: the body 'wheel' of ``rig.model`` (and its subtree) in the fork, its origin
    at the hub."""
    user = read_spec(rig.model)
    body = user.body("wheel")
    if body is None:
        raise SceneError(f"wheel.model {rig.model}: no body named 'wheel' (the wheel, on a hinge named 'axle')")
    joint = user.joint("axle")
    if joint is None or joint.parent.name != "wheel" or int(joint.type) != int(mujoco.mjtJoint.mjJNT_HINGE):
        raise SceneError(f"wheel.model {rig.model}: the body 'wheel' must turn on a hinge named 'axle'")
    if len(body.joints) != 1:
        raise SceneError(f"wheel.model {rig.model}: the body 'wheel' must have one joint, the hinge 'axle' (the rig "
                         f"moves it)")
    spec = mujoco.MjSpec.from_string(rig_xml(rig, wheel=False))
    body.pos = [0, 0, 0]
    spec.body("fork").add_frame().attach_body(body, "user:", "")
    # The rig drives them by these names.
    spec.body("user:wheel").name, spec.joint("user:axle").name = "wheel", "axle"
    return spec


def wheel_model(rig: WheelRig, surface_z: float = 0.0) -> WheelModel:
    """The rig's spec with its wheel, the carriage raised so that the wheel's lowest point is at the free surface
    (``surface_z``) at lift = 0; SceneError when a user's wheel does not turn about its y axis through its
    origin."""
    if not rig.model:
        spec = mujoco.MjSpec.from_string(rig_xml(rig))
        outer = rig.radius + rig.grouser_height
        spec.body("carriage").pos = [0, 0, outer + surface_z]
        return WheelModel(spec, rig.slip_radius or rig.radius, outer, 1.0)
    spec = user_wheel(rig)
    model = compile_spec(spec)
    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    wheel, joint = model.body("wheel").id, model.joint("axle").id
    y = d.xmat[wheel].reshape(3, 3)[:, 1]
    along = float(np.dot(d.xaxis[joint], y))
    if abs(abs(along) - 1) > 1e-6 or np.linalg.norm(d.xanchor[joint] - d.xpos[wheel]) > 1e-6:
        raise SceneError(f"wheel.model {rig.model}: the hinge 'axle' must turn the body 'wheel' about its own y axis "
                         f"through its origin")
    outer = outer_radius(model, wheel)
    spec.body("carriage").pos = [0, 0, outer + surface_z]
    # The load's mass makes the carried weight wheel.load, whatever the user's wheel weighs.
    carried = model.body_subtreemass[model.body("load").id] - model.body_mass[model.body("load").id]
    load = rig.load / GRAVITY - carried
    if load <= 0:
        raise SceneError(f"wheel.load {rig.load:g} N is less than the weight of the fork and the wheel "
                         f"({carried * GRAVITY:.3g} N)")
    spec.body("load").mass = load
    return WheelModel(spec, rig.slip_radius or outer, outer, math.copysign(1, along))


def robot_scene(scene: WheelScene, radius: float, spin_sign: float) -> UserScene:
    """The robot run the wheel is: its drives (carriage at v, axle at omega, slip angle held at beta, lift held at
    minus the sinkage or free), its medium and numerics; the model is the experiment's own, not a file."""
    w = scene.wheel
    omega = spin_sign * rim_speed(w.slip, w.speed) / radius
    drives = [JointDrive(joint="carriage", speed=w.speed, stroke=0.0),
              JointDrive(joint="axle", speed=omega, stroke=0.0),
              JointDrive(joint="slip_angle", speed=0.0, stroke=0.0, start=w.slip_angle)]
    if w.sinkage > 0:  # at lift 0 the wheel's lowest point is at the surface
        drives.append(JointDrive(joint="lift", speed=0.0, stroke=0.0, start=-w.sinkage))
    return UserScene(model=Model(bodies=("wheel",)), medium=scene.medium, drive=tuple(drives), sim=scene.sim)


# ---------------------------------------------------------------------------------------------------------
# The experiment

SIGN_CONVENTION = (
    "Forces of the sand on the wheel in the wheel's frame, as the smooth-wheel data: X the wheel's heading "
    "(horizontal, perpendicular to the axle), Z up, Y = Z x X along the axle to the left; Fx > 0 drawbar pull, "
    "Fz > 0 support. The hub moves at speed v along (cos beta, sin beta, 0) of that frame. The series are the robot "
    "run's (world frame: the hub's velocity along +x, z up); sinkage is the depth of the wheel's lowest point below "
    "the free surface.")


@dataclass(frozen=True, eq=False)
class Wheel:
    """The wheel of a `WheelScene` on its rig, run as a robot (`UserModel`'s series: ``medium_force`` (T, 1, 3)
    on the wheel, ``body_position`` (T, 1, 3) its hub, ``drive_load`` per drive: carriage (N), axle (N m), slip
    angle (N m) and, at a held sinkage, lift (N)). ``Wheel.of(scene)`` reads and checks the wheel."""

    robot: UserModel
    radius: float       # m, the rim radius the slip is defined with
    outer: float        # m, the wheel's outer radius: its lowest point is this far below the hub
    spin_sign: float    # +1 when the axle's axis is the wheel's +y
    condition: Condition | None = None  # the row of a conditions file it runs (--data), with its measurements
    name = "wheel"
    schema = "finrft.wheel/1"
    sign_convention = SIGN_CONVENTION

    @classmethod
    def of(cls, scene: WheelScene) -> Wheel:
        if not isinstance(scene, WheelScene):  # read before run() checks the scene's type
            raise SceneError(f"wheel: the scene must be a finrft.WheelScene (from finrft.preset or "
                             f"finrft.load_scene), got {type(scene).__name__} {scene!r:.60}")
        w = wheel_model(scene.wheel, scene.medium.surface_z)
        m = compile_spec(w.spec)
        drives = robot_scene(scene, w.radius, w.spin_sign).drive
        kinds = tuple("hinge" if m.jnt_type[m.joint(j.joint).id] == mujoco.mjtJoint.mjJNT_HINGE else "slide"
                      for j in drives)
        links = tuple(m.body(i).name or f"body{i}" for i in range(1, m.nbody))
        return cls(UserModel(kinds, links, (), (), None, ("wheel",)), w.radius, w.outer, w.spin_sign)

    @property
    def bodies(self) -> tuple[str, ...]:
        return self.robot.bodies

    @property
    def links(self) -> tuple[str, ...]:
        return self.robot.links

    def robot_scene(self, scene: WheelScene) -> UserScene:
        return robot_scene(scene, self.radius, self.spin_sign)

    def build(self, scene: WheelScene) -> AttachedModel:
        spec = wheel_model(scene.wheel, scene.medium.surface_z).spec
        return build_attached(spec, [j.joint for j in self.robot_scene(scene).drive], ("wheel",), scene.medium,
                              scene.sim)

    def drive_for(self, scene: WheelScene) -> Schedule:
        return Schedule(*drive_timing(self.robot_scene(scene)))

    def start(self, scene: WheelScene, built: AttachedModel, d: mujoco.MjData, companion: bool) -> RobotTrial:
        trial = RobotTrial(self.robot, self.robot_scene(scene), built, d, companion)
        if scene.wheel.sinkage == 0 and scene.wheel.start == "equilibrium":
            d.qpos[built.model.joint("lift").qposadr[0]] = -equilibrium_sinkage(scene, built, self)
        return trial

    def quantities(self, scene: WheelScene) -> dict[str, Quantity]:
        return self.robot.quantities(self.robot_scene(scene))

    def compared(self, scene: WheelScene) -> tuple[Compared, ...]:
        """The robot run's positions (the hub: its sinkage) and the medium's force on the wheel (N, reported)."""
        return (*self.robot.compared(self.robot_scene(scene)), Compared("force_N", ("medium_force",)))

    def relative_differences(self, result: Result, differences: dict[str, float]) -> dict[str, float]:
        return self.robot.relative_differences(result, differences)

    def figures(self, scene: WheelScene) -> tuple[str, ...]:
        """The reported figures estimated one by one (`wheel_summary`); none bounded by default."""
        return ("Fx_N", "Fy_N", "Fz_N", "sinkage_mm", "axle_torque_Nm")

    def check(self, result: Result) -> None:
        pass

    def attrs(self) -> dict[str, Any]:
        return {"radius_m": self.radius, "outer_radius_m": self.outer}

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        return []

    def summary(self, run: Result) -> dict[str, Any]:
        return wheel_summary(self, run)

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from ..views import draw_model
        return draw_model(rec, run, times, prefix)


def equilibrium_sinkage(scene: WheelScene, built: AttachedModel, wheel: Wheel) -> float:
    """The sinkage (m) at which the sand's vertical force on the wheel, moving as driven with no vertical motion,
    equals the load: the free wheel's steady state, by bisection to 1 um of the held wheel's force (which grows with
    depth). A wheel the sand cannot carry within its diameter (one that trenches: the data's at slip angle 90 deg)
    is looked for deeper, to MAX_SINKAGE; SimulationFailed beyond."""
    m = built.model
    d = mujoco.MjData(m)
    rs = wheel.robot_scene(scene)
    for j, qpos, dof in zip(rs.drive, built.drive_qpos, built.drive_dofs):
        d.qpos[qpos], d.qvel[dof] = j.start, j.speed
    lift = m.joint("lift").qposadr[0]
    force = medium_forces(built)

    def excess(sinkage: float) -> float:
        d.qpos[lift] = -sinkage
        with built.attached.installed(m):  # the Python backend's model refuses a forward without its callback
            mujoco.mj_forward(m, d)
        return float(force(d)[0, 2]) - scene.wheel.load

    low, high = 0.0, 2 * wheel.outer
    while excess(high) < 0:
        if high >= MAX_SINKAGE:
            raise SimulationFailed(f"the sand cannot carry {scene.wheel.load:g} N: the wheel would sink beyond "
                                   f"{1e3 * MAX_SINKAGE:.3g} mm")
        low, high = high, 2 * high
    while high - low > 1e-6:
        middle = (low + high) / 2
        low, high = (middle, high) if excess(middle) < 0 else (low, middle)
    return (low + high) / 2


def wheel_frame(beta: float) -> np.ndarray:
    """Rows X (heading), Y (along the axle, left), Z (up) of the wheel's frame in the world, at slip angle beta
    (the hub's velocity along world +x)."""
    c, s = math.cos(beta), math.sin(beta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def wheel_summary(experiment: Wheel, run: Result) -> dict[str, Any]:
    """What ``finrft wheel --json`` reports, means over [sim.settle, end]: ``Fx_N``, ``Fy_N``, ``Fz_N`` the
    sand's force on the wheel in the data's frame (`SIGN_CONVENTION`), ``sinkage_mm`` the depth of its lowest
    point, ``slip``, ``slip_angle_deg``; the run's own keys (error_estimate, ...) are added by `Result.summary`."""
    scene = run.scene
    w, t, settle = scene.wheel, run.time, scene.sim.settle
    # the force and loads over every step (`user_model.WindowMeans`), the sinkage over the recorded samples
    force = wheel_frame(w.slip_angle) @ run.window_means["medium_force"][0]
    depth = experiment.outer + scene.medium.surface_z - run.body_position[:, 0, 2]
    loads = run.window_means["drive_load"]
    rim = rim_speed(w.slip, w.speed)
    return {"Fx_N": float(force[0]), "Fy_N": float(force[1]), "Fz_N": float(force[2]),
            "sinkage_mm": 1e3 * float(window_mean(t, depth, settle)), "slip": w.slip,
            "slip_angle_deg": math.degrees(w.slip_angle), "mode": "sinkage" if w.sinkage > 0 else "load",
            "load_N": float(force[2]) if w.sinkage > 0 else w.load, "speed_mm_s": 1e3 * w.speed,
            "rim_speed_mm_s": 1e3 * rim, "omega_rad_s": rim / experiment.radius, "radius_mm": 1e3 * experiment.radius,
            "axle_torque_Nm": experiment.spin_sign * float(loads[1]), "window_s": [settle, float(t[-1])],
            "medium": scene.medium.name, "law": scene.medium.law}


def run_wheel(scene: WheelScene, *, progress: Callable[[float], None] | None = None,
              max_error: ErrorLimits | None = ErrorLimits()) -> Result:
    """Run the wheel of a scene (`Wheel`); ``result.summary()`` holds `wheel_summary`'s figures."""
    return run(Wheel.of(scene), scene, progress=progress, max_error=max_error)


# ---------------------------------------------------------------------------------------------------------
# Conditions from a file (--data): every row a run, the predictions against the measurements

@dataclass(frozen=True)
class Condition:
    """One row of a conditions file (the format of smooth_wheel_by_condition.csv), SI units."""

    slip_angle: float        # rad
    slip: float              # slip_meas_mean when the file has it (what the rig ran), else slip_model
    sinkage: float           # m
    measured: np.ndarray     # Fx, Fy, Fz (N), the data's frame


DATA_COLUMNS = ("beta_deg", "sinkage_mm", "Fx_meas_N", "Fy_meas_N", "Fz_meas_N")


def read_conditions(path: str) -> list[Condition]:
    """The rows of a conditions file; SceneError in one line when it is missing or ill-formed."""
    # read whole and bounded, as every file finrft reads: a device, a huge or a binary file is refused in one line
    text = read_text(path, "--data")
    reader = csv.DictReader(text.splitlines())
    columns = set(reader.fieldnames or ())
    missing = [c for c in DATA_COLUMNS if c not in columns]
    slip = next((c for c in ("slip_meas_mean", "slip_model") if c in columns), None)
    if missing or slip is None:
        raise SceneError(f"--data {path}: needs the columns {', '.join(DATA_COLUMNS)} and slip_meas_mean or "
                         f"slip_model (missing: {', '.join(missing + ([] if slip else ['slip']))})")
    rows = []
    for i, row in enumerate(reader, start=2):
        try:
            values = {c: float(row[c]) for c in (*DATA_COLUMNS, slip)}
        except (TypeError, ValueError):
            raise SceneError(f"--data {path} line {i}: every one of {', '.join(DATA_COLUMNS)}, {slip} must be "
                             f"a number") from None
        if not all(map(math.isfinite, values.values())) or not -1 <= values[slip] < 1 \
                or not 0 <= values["beta_deg"] <= 90 or values["sinkage_mm"] < 0:
            raise SceneError(f"--data {path} line {i}: needs finite numbers, -1 <= slip < 1, 0 <= beta_deg <= 90, "
                             f"sinkage_mm >= 0")
        rows.append(Condition(math.radians(values["beta_deg"]), values[slip], 1e-3 * values["sinkage_mm"],
                              np.array([values["Fx_meas_N"], values["Fy_meas_N"], values["Fz_meas_N"]])))
    if not rows:
        raise SceneError(f"--data {path}: no rows")
    return rows


def condition_scene(scene: WheelScene, c: Condition, mode: str) -> WheelScene:
    """The scene of one condition: its slip angle and slip, and its sinkage held (mode "sinkage") or its
    measured load carried (mode "load"); mode "" keeps the scene's own sinkage and load."""
    updates: dict[str, Any] = {"wheel.slip_angle": c.slip_angle, "wheel.slip": min(c.slip, 0.999)}
    if mode == "sinkage":
        updates["wheel.sinkage"] = c.sinkage
    elif mode == "load":
        updates.update({"wheel.sinkage": 0.0, "wheel.load": float(c.measured[2])})
    return scene.replace(**updates)


# The experimenters' figures cover beta <= 60 deg (at 75 and 90 deg the wheel trenches).
BETA_LIMIT = math.radians(60)


def statistics(predicted: np.ndarray, measured: np.ndarray) -> dict[str, float]:
    """RMSE, bias (mean of predicted - measured) and Pearson's r of one component; r is None for a constant."""
    error = predicted - measured
    spread = np.std(predicted) * np.std(measured)
    r = float(np.mean((predicted - predicted.mean()) * (measured - measured.mean())) / spread) if spread > 0 else None
    return {"rmse": float(np.sqrt(np.mean(error ** 2))), "bias": float(np.mean(error)), "r": r, "n": len(error)}


def compare(conditions: list[Condition], summaries: list[dict[str, Any]]) -> dict[str, Any]:
    """Per component (Fx_N, Fy_N, Fz_N, sinkage_mm), the statistics of the predictions against the measurements
    over beta <= 60 deg and over every row."""
    betas = np.array([c.slip_angle for c in conditions])
    out: dict[str, Any] = {}
    for subset, rows in (("beta_le_60", betas <= BETA_LIMIT + 1e-9), ("all", np.ones(len(betas), bool))):
        if not rows.any():
            continue
        part = {}
        for i, key in enumerate(("Fx_N", "Fy_N", "Fz_N")):
            part[key] = statistics(np.array([s[key] for s in summaries])[rows],
                                   np.array([c.measured[i] for c in conditions])[rows])
        part["sinkage_mm"] = statistics(np.array([s["sinkage_mm"] for s in summaries])[rows],
                                        1e3 * np.array([c.sinkage for c in conditions])[rows])
        out[subset] = part
    return out


def plot_conditions(conditions: list[Condition], summaries: list[dict[str, Any]], path: str | Path,
                    title: str = "") -> None:
    """Measured (points) and predicted (lines) Fx, Fy and sinkage against slip, one column per slip angle."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    betas = sorted({round(math.degrees(c.slip_angle), 6) for c in conditions})
    # Each panel its own scale: at 90 deg the forces and sinkage are several times those at small angles.
    fig, axes = plt.subplots(3, len(betas), figsize=(2.4 * len(betas) + 1, 7), sharex=True, squeeze=False)
    rows = (("Fx_N", 0, "Fx (N)"), ("Fy_N", 1, "Fy (N)"), ("sinkage_mm", None, "sinkage (mm)"))
    for j, beta in enumerate(betas):
        chosen = sorted((c.slip, c, s) for c, s in zip(conditions, summaries)
                        if round(math.degrees(c.slip_angle), 6) == beta)
        slips = [x[0] for x in chosen]
        for i, (key, k, label) in enumerate(rows):
            ax = axes[i, j]
            measured = [1e3 * c.sinkage if k is None else c.measured[k] for _, c, _ in chosen]
            ax.plot(slips, measured, "o", color="k", ms=4, label="measured")
            ax.plot(slips, [s[key] for _, _, s in chosen], "-s", color="tab:red", ms=3, label="finrft")
            ax.grid(True, alpha=0.3)
            if j == 0:
                ax.set_ylabel(label)
            if i == 0:
                ax.set_title(f"beta = {beta:g} deg", fontsize=9)
            if i == 2:
                ax.set_xlabel("slip s")
    axes[0, 0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=90)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------------
# The command: finrft wheel

MM = 1e-3


@register
class WheelCommand(Command):
    name = "wheel"
    help = "a wheel in sand on a single-wheel rig: its forces at a slip and slip angle, or against a data file"
    description = ("Drive a wheel through the medium on a single-wheel rig (the example wheel rig, mjcf/"
                   "wheel_rig.xml): the hub at wheel.speed (10 mm/s) along a direction at slip angle beta to the "
                   "wheel's heading, the wheel spun at the rate its slip s asks (driving s = 1 - v/(omega R), braking "
                   "s = omega R/v - 1; -1 locked, 0 rolling), its vertical axis held at --sinkage or free under "
                   "--load. The wheel is generated (--wheel smooth or grouser, --radius, --width, --grousers, "
                   "--grouser-height, --grouser-thickness) or is the body "
                   "'wheel' on the hinge 'axle' of --model. It reports, averaged over [sim.settle, sim.duration], "
                   "the sand's force on the wheel in the wheel's frame (X heading, Y along the axle to the left, Z "
                   "up) and the sinkage, with the run's estimated discretisation error. --data runs every row of a "
                   "conditions file (smooth_wheel_by_condition.csv's columns) and compares. The flags speak mm, N "
                   "and degrees; --set and --json SI (the JSON's keys name their unit).")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        g = p.add_argument_group("the run")
        g.add_argument("--slip", type=number("", minimum=-1.0, inclusive=True), metavar="S",
                       help="slip s, -1 (locked) to < 1 (default 0.5, driven, or the --scene's wheel.slip)")
        g.add_argument("--slip-angle", type=number("deg", minimum=-90.0, inclusive=True), metavar="DEG",
                       help="slip angle beta in degrees, -90..90 (default 0)")
        g.add_argument("--sinkage", type=number("mm", inclusive=True), metavar="MM",
                       help="hold the wheel's lowest point this deep (mm) below the free surface (default: "
                       "free under --load)")
        g.add_argument("--load", type=number("N"), metavar="N", help="free vertical axis under this load (N, the "
                       "wheel included; default 21, the experiments')")
        g = p.add_argument_group("the wheel")
        g.add_argument("--radius", type=number("mm"), metavar="MM", help="rim radius, mm (default 62.5)")
        g.add_argument("--width", type=number("mm"), metavar="MM", help="width, mm (default 60)")
        g.add_argument("--grousers", type=number("", minimum=0, inclusive=True, integer=True), metavar="N",
                       help="straight grousers across the rim (default 0)")
        g.add_argument("--grouser-height", type=number("mm", inclusive=True), metavar="MM",
                       help="their height above the rim, mm")
        g.add_argument("--grouser-thickness", type=number("mm"), metavar="MM",
                       help="their thickness along the rim, mm (default 4)")
        g.add_argument("--wheel", choices=tuple(WHEELS), help="the wheel group's wheel: smooth (the default: "
                       "radius 62.5 mm) or grouser (a 57.5 mm rim, 24 grousers 5 mm high and 7.9 mm thick, the "
                       "slip at the tips' 62.5 mm); --radius and the grouser flags change it")
        g.add_argument("--model", metavar="WHEEL.xml", help="your wheel instead: the body 'wheel' on the hinge "
                       "'axle' of this MJCF (radius: its outer radius, measured)")
        g = p.add_argument_group("data")
        g.add_argument("--data", metavar="CONDITIONS.csv", help="run every row of a conditions file (columns "
                       "beta_deg, slip_meas_mean or slip_model, sinkage_mm, Fx_meas_N, Fy_meas_N, Fz_meas_N) and "
                       "compare: per component RMSE, bias and r over beta <= 60 deg and over all")
        mode = g.add_mutually_exclusive_group()
        mode.add_argument("--sinkage-from-data", action="store_true", help="hold each row's sinkage (the default "
                          "with --data)")
        mode.add_argument("--load-from-data", action="store_true", help="free vertical axis under each row's "
                          "measured Fz")
        g.add_argument("--plot", metavar="FILE.png", help="with --data: measured and predicted Fx, Fy and sinkage "
                       "against slip, one panel per slip angle")
        s = add_scene_flags(p, "wheel", "medium.zeta=0.5", scene_help="wheel scene file in SI units ([wheel], "
                            "[medium], [sim]; default: the example wheel rig's medium and method, "
                            "mjcf/wheel_rig.toml, at dt = 10 ms)")
        s.add_argument("--medium", metavar="NAME", help="a catalogued medium (finrft medium --list); sets "
                       "medium.name")
        s.add_argument("--surface", choices=("flat", "deforming"), help="the free surface: flat (default), or "
                       "deforming, sand the wheel displaces into a rut and berms, relaxed to the medium's angle of "
                       "repose (medium.surface; its grid by default the wheel's: DEFORMING_GRID)")
        add_max_error(p)
        add_result_files(p)  # --out and --rrd: one run, not --data

    def scene(self, args: argparse.Namespace) -> WheelScene:
        if args.data:
            for flag, value in (("--slip", args.slip), ("--slip-angle", args.slip_angle), ("--out", args.out),
                                ("--rrd", args.rrd)):
                if value is not None:
                    raise UsageError(f"{flag} does not go with --data (each row gives its own; the results go to "
                                     f"--json and --plot)")
            if (args.sinkage_from_data or args.load_from_data) and (args.sinkage is not None or args.load):
                raise UsageError("give --sinkage/--load or --sinkage-from-data/--load-from-data, not both")
        elif args.sinkage_from_data or args.load_from_data or args.plot:
            raise UsageError("--sinkage-from-data, --load-from-data and --plot go with --data")
        if args.sinkage is not None and args.load is not None:
            raise UsageError("give --sinkage MM (held) or --load N (free vertical axis), not both")
        overrides: dict[str, Any] = dict(WHEELS[args.wheel]) if args.wheel else {}
        for key, value, scale in (("wheel.slip", args.slip, 1.0), ("wheel.radius", args.radius, MM),
                                  ("wheel.width", args.width, MM), ("wheel.grousers", args.grousers, None),
                                  ("wheel.grouser_height", args.grouser_height, MM),
                                  ("wheel.grouser_thickness", args.grouser_thickness, MM),
                                  ("wheel.sinkage", args.sinkage, MM), ("wheel.load", args.load, 1.0)):
            if value is not None:
                overrides[key] = value if scale is None else value * scale
        if args.slip_angle is not None:
            if args.slip_angle > 90:
                raise UsageError(f"--slip-angle must be within -90..90 deg, got {args.slip_angle:g}")
            overrides["wheel.slip_angle"] = math.radians(args.slip_angle)
        if args.load is not None:
            overrides["wheel.sinkage"] = 0.0
        if args.model:
            if args.wheel:
                raise UsageError("give --wheel or --model, not both (--model is your own wheel)")
            overrides["wheel.model"] = args.model
        if args.medium:
            overrides["medium.name"] = args.medium
        if args.backend:
            overrides["sim.backend"] = args.backend
        if args.surface:
            overrides["medium.surface"] = args.surface
            if args.surface == "deforming" and not args.scene:
                overrides.update(DEFORMING_GRID)
        overrides.update(parse_override(item, WheelScene) for item in args.set)
        if args.scene:
            return load_scene(args.scene, overrides=overrides, cls=WheelScene)
        return default_scene(**overrides)

    def jobs(self, args: argparse.Namespace, scene: WheelScene) -> list[tuple[Wheel, WheelScene]]:
        if not args.data:
            return [(Wheel.of(scene), scene)]
        mode = "load" if args.load_from_data else "" if args.sinkage is not None or args.load else "sinkage"
        jobs = []
        for c in read_conditions(args.data):
            s = condition_scene(scene, c, mode)
            jobs.append((dataclasses.replace(Wheel.of(s), condition=c), s))
        return jobs

    def job_name(self, experiment: Wheel, scene: WheelScene) -> str:
        c = experiment.condition
        return "" if c is None else f"slip {c.slip:.3g}, slip angle {np.degrees(c.slip_angle):.3g} deg"

    def outputs(self, args: argparse.Namespace) -> list[Output]:
        if args.data:
            return [Output("--plot", args.plot, ".png", "figure",
                           lambda runs, path: plot_conditions([r.experiment.condition for r in runs],
                                                              [r.summary() for r in runs], path, _title(runs)))]
        return result_files(args)

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        if not args.data:
            run, = runs
            s = run.summary()
            e = s["error_estimate"]
            mode = (f"held at sinkage {s['sinkage_mm']:.2f} mm" if s["mode"] == "sinkage" else
                    f"free under {s['load_N']:.4g} N: sinkage {s['sinkage_mm']:.2f} mm")
            return "\n".join([
                f"wheel, radius {s['radius_mm']:.4g} mm, slip {s['slip']:+.3f}, slip angle {s['slip_angle_deg']:g} "
                f"deg, hub {s['speed_mm_s']:g} mm/s, rim {s['rim_speed_mm_s']:.4g} mm/s ({run.scene.medium.law}; "
                f"{run.scene.sim.method}, dt {run.scene.sim.dt:g} s): {steps_line(s)} in {run.wall_s:.2f} s",
                *choice_lines(run),
                f"over {s['window_s'][0]:g}..{s['window_s'][1]:.4g} s, {mode}",
                f"sand on the wheel (N): Fx {s['Fx_N']:+.3f} (heading), Fy {s['Fy_N']:+.3f} (axle, left), "
                f"Fz {s['Fz_N']:+.3f} (up); axle torque {s['axle_torque_Nm']:+.4g} N m",
                f"estimated discretisation error (companion run at {s['error_companion']}): force "
                f"{e['force_N']:.2g} N, positions {e['position_mm']:.2g} mm"])
        stats = compare([r.experiment.condition for r in runs], [r.summary() for r in runs])
        lines = [f"{len(runs)} conditions of {args.data}, {_title(runs)}"]
        for subset, part in stats.items():
            lines.append(f"{'beta <= 60 deg' if subset == 'beta_le_60' else 'all beta'} ({part['Fx_N']['n']} rows): "
                         + "; ".join(f"{key} RMSE {v['rmse']:.3g}, bias {v['bias']:+.3g}, r "
                                     f"{'-' if v['r'] is None else format(v['r'], '.3f')}"
                                     for key, v in part.items()))
        return "\n".join(lines)

    def to_json(self, runs: list[Result]) -> Any:
        if runs[0].experiment.condition is None:
            return runs[0].summary()
        conditions, summaries = [r.experiment.condition for r in runs], [r.summary() for r in runs]
        rows = [{**s, "measured": dict(zip(("Fx_N", "Fy_N", "Fz_N"), c.measured.tolist()),
                                       sinkage_mm=1e3 * c.sinkage)} for c, s in zip(conditions, summaries)]
        return {"compared": compare(conditions, summaries), "rows": rows, "conditions": len(rows)}


def _title(runs: list[Result]) -> str:
    """What a --data study ran: the law and medium, the mode, the numerics."""
    scene, s = runs[0].scene, runs[0].summary()
    medium = scene.medium
    given = ", ".join(f"{k} {v:g}" for k, v in laws.module(medium.law, laws.SURFACE).given(medium).items()
                      if v is not None)
    what = ", ".join(filter(None, (medium.name, given, f"drft_lambda {medium.drft_lambda:g}"
                                   if medium.drft_lambda else "")))
    mode = "sinkage held as measured" if s["mode"] == "sinkage" else "free under the measured load"
    return (f"{medium.law} ({what or 'generic'}), {mode}; {scene.sim.method} dt {scene.sim.dt:g} s, "
            f"{scene.sim.duration:g} s averaged from {scene.sim.settle:g} s")
