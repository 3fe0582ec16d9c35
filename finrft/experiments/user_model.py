"""A user's MuJoCo model in the medium, as an experiment (finrft.experiment): RFT `attach`ed to the named bodies of
an MJCF file, run as a robot (``finrft run MODEL.xml --scene FILE.toml``, `run_robot`): any joints, free ones
included; zero or more prescribed joints (`UserScene.drive`, ``[[drive]]``) held on their profile exactly as the
plate's base is moved (`stepping.Prescribed`: a very large armature, impulses at reversals; a sine through the
feed-forward force that lands each step on the profile's velocity); zero or more actuators driven by the scene
(``[[control]]``: constant, sine, a CSV table; each with a ramp-in) or by a Python controller ``control(t, data) ->
ctrl``. It reports the centre of mass's mean velocity, the medium's mean force, the drives' loads, the actuators'
power and the cost of transport over the window [sim.settle, duration] (`RobotSummary`).

The model itself, RFT attached and the drives' armatures, is built by `attached_model.build_attached`.
"""

from __future__ import annotations

import argparse
import csv
import math
from dataclasses import dataclass
from typing import Any, Callable

import mujoco
import numpy as np

from ..attach import attached_bodies
from ..errors import SimulationFailed, UsageError
from ..experiment import Compared, Plot, Quantity, Result, run
from ..files import read_text
from .. import methods
from ..convergence import ROBOT_HEADLINE, ErrorLimits
from ..models import ARMATURE_RATIO, compile_spec, mjcf_path
from ..scene import Control, JointDrive, SceneError, UserScene, drive_timing, load_scene, parse_override, repose
from ..stepping import DRIVE_LAG, jump_velocities
from ..surfaces.deforming import DeformingSurface
from .attached_model import (DRIVEN, AttachedModel, StepPower, applied_state, build_attached, driven_joint,
                             medium_forces, record_forward, scene_spec)
from .command import Command, choice_lines, register, steps_line
from .flags import add_max_error, add_result_files, add_scene_flags

# ---------------------------------------------------------------------------------------------------------
# Robot runs: the schedule, the drives' profiles, the controls

@dataclass(frozen=True)
class Schedule:
    """A robot run's grid of reversals (`scene.drive_timing`): ``strokes`` strokes of ``stroke_time`` each."""

    stroke_time: float
    strokes: int

    @property
    def duration(self) -> float:
        return self.stroke_time * self.strokes


def drive_velocity(j: JointDrive, stroke_time: float, t: float, k: int) -> float:
    """The profile's velocity at time t in stroke k of the run's grid (a constant drive's reversals and its stop
    after its cycles fall on the grid's stroke starts)."""
    if j.profile == "sine":
        return 2 * math.pi * j.frequency * j.amplitude * math.cos(2 * math.pi * j.frequency * t + j.phase)
    if j.stroke == 0:
        return j.speed
    own = 1 if j.cycles == 0 else 2 * j.cycles
    return 0.0 if k >= own else (j.speed if k % 2 == 0 else -j.speed)


def drive_position(j: JointDrive, stroke_time: float, t: float) -> float:
    """The profile's position at time t."""
    if j.profile == "sine":
        return j.start + j.amplitude * math.sin(2 * math.pi * j.frequency * t + j.phase)
    if j.stroke == 0:
        return j.start + j.speed * t
    own = 1 if j.cycles == 0 else 2 * j.cycles
    k = min(int(t / stroke_time + 1e-9), own)
    if k >= own:
        return j.start + (j.stroke if own == 1 else 0.0)
    into = t - k * stroke_time
    return j.start + (j.speed * into if k % 2 == 0 else j.stroke - j.speed * into)


def drive_scale(j: JointDrive, duration: float) -> float:
    """The length a drive's lag is measured against: its stroke, its travel over the run, or its amplitude."""
    if j.profile == "sine":
        return abs(j.amplitude)
    return j.stroke if j.stroke > 0 else abs(j.speed) * duration


def read_table(path: str, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A control table's times (s, increasing) and values; SceneError in one line when missing or ill-formed."""
    if not path:
        raise SceneError(f"{where}.table: give the CSV file (columns time_s,ctrl) of kind = 'table'")
    text = read_text(path, f"{where}.table")  # whole and bounded: a device or a huge file is refused
    rows = [row for row in csv.reader(text.splitlines()) if row and any(cell.strip() for cell in row)]
    if not rows or [c.strip() for c in rows[0]] != ["time_s", "ctrl"]:
        raise SceneError(f"{where}.table {path}: the first line must be the header time_s,ctrl")
    try:
        values = np.array([[float(c) for c in row] for row in rows[1:]], dtype=float).reshape(-1, 2)
    except ValueError:
        raise SceneError(f"{where}.table {path}: every row after the header must be two numbers, time_s,ctrl")\
            from None
    if len(values) == 0 or not np.all(np.isfinite(values)) or np.any(np.diff(values[:, 0]) <= 0):
        raise SceneError(f"{where}.table {path}: needs at least one row of finite numbers, times strictly "
                         f"increasing")
    return values[:, 0], values[:, 1]


def ramp_factor(c: Control, t: float) -> tuple[float, float]:
    """The ramp-in's factor at time t and its rate (1/s)."""
    if c.ramp > 0 and t < c.ramp:
        return t / c.ramp, 1 / c.ramp
    return 1.0, 0.0


def reference(c: Control, t: float) -> tuple[float, float]:
    """A sine's ctrl, or a pd or sensor entry's reference, at time t and its rate: offset + amplitude sin(2 pi
    frequency t + phase), ramped in (``ramps = "all"``: the whole of it, as the ramp always did; ``oscillation``: the
    sine's part only, the offset held from t = 0)."""
    f, rate = ramp_factor(c, t)
    w = 2 * math.pi * c.frequency
    wave, slope = c.amplitude * math.sin(w * t + c.phase), c.amplitude * w * math.cos(w * t + c.phase)
    if c.ramps == "all":
        return (c.offset + wave) * f, (c.offset + wave) * rate + slope * f
    return c.offset + wave * f, wave * rate + slope * f


def control_value(c: Control, table: tuple[np.ndarray, np.ndarray] | None, t: float) -> float:
    """An open-loop actuator's ctrl at time t: its profile, times the ramp-in (`reference` for a sine)."""
    if c.kind == "sine":
        return reference(c, t)[0]
    value = c.value if c.kind == "constant" else float(np.interp(t, *table))
    return value * ramp_factor(c, t)[0]


def closed_loop(c: Control, t: float, measured: float, rate: float) -> float:
    """A pd or sensor entry's ctrl: kp (r - y) + kd (r' - y') for the reference r (`reference`) and the measured
    y (the joint's position, the sensor's reading) and its rate y'."""
    r, r_rate = reference(c, t)
    return c.kp * (r - measured) + c.kd * (r_rate - rate)


def control_reach(c: Control, table: tuple[np.ndarray, np.ndarray] | None) -> float:
    """The largest |ctrl| a control entry asks for at any time (the ramp only scales it down)."""
    if c.kind == "constant":
        return abs(c.value)
    if c.kind == "sine":
        return abs(c.offset) + abs(c.amplitude)
    if c.kind == "table":
        return float(np.max(np.abs(table[1])))
    return 0.0  # a closed loop's ctrl depends on the state: a bad value stops the run (`stepping.void_run`)


Controller = Callable[[float, mujoco.MjData], Any]


class RobotTrial:
    """One robot run on one MjData: its drives held on their profiles, its actuators' ctrl set at every step
    (``control``, MuJoCo's control callback), and at each recorded instant the state the summaries need."""

    def __init__(self, experiment: UserModel, scene: UserScene, built: AttachedModel, d: mujoco.MjData,
                 companion: bool) -> None:
        m = built.model
        self.m, self.d, self.built, self.scene = m, d, built, scene
        stroke_time, _ = drive_timing(scene)
        self.stroke_time, duration = stroke_time, scene.duration
        self.dofs, qpos, self.armature = list(built.drive_dofs), list(built.drive_qpos), built.armature
        self.sines = [i for i, j in enumerate(scene.drive) if j.profile == "sine"]
        self.scales = [drive_scale(j, duration) for j in scene.drive]
        if scene.model.keyframe:
            key = m.key(scene.model.keyframe)
            d.qpos[:], d.qvel[:], d.act[:] = key.qpos, key.qvel, key.act
        for i, j in enumerate(scene.drive):
            d.qpos[qpos[i]] = drive_position(j, stroke_time, 0.0)
        self.actuators = [m.actuator(c.actuator).id for c in scene.control]
        self.tables = experiment.tables
        self.loops = experiment.loops
        # the open-loop entries, a function of time alone: taken once per instant, though MuJoCo's control callback
        # runs at each forward pass (a newton step's, then the recording's at the same state: a tenth of a run)
        self._open = [i for i, loop in enumerate(self.loops) if loop is None]
        self._closed = [i for i, loop in enumerate(self.loops) if loop is not None]
        self._open_actuators = np.array([self.actuators[i] for i in self._open], dtype=int)
        self._open_at: tuple[float, np.ndarray] = (math.nan, np.zeros(len(self._open)))
        # a sensor loop's last reading (time, value, rate): its rate is the change over the last step
        self._readings: dict[int, tuple[float, float, float]] = {}
        self.controller = experiment.control
        if self.controller is not None:
            mujoco.mj_forward(m, d)
            self._checked(self.controller(0.0, d))
        self.watch = [i for i in range(m.nv) if i not in self.dofs]
        force = medium_forces(built)
        self.forward = record_forward(built, scene.sim.method)
        bodies = np.arange(1, m.nbody)

        def state(d: mujoco.MjData) -> dict[str, np.ndarray]:
            if companion:  # a companion steps without mj_forward; its positions and forces need it here
                mujoco.mj_forward(m, d)
            mujoco.mj_subtreeVel(m, d)
            self._lag(d)
            # the medium's force and the drives' loads as the last step applied them (`applied_state`)
            at = self._applied(d)
            return {"com_position": d.subtree_com[0].copy(), "com_velocity": d.subtree_linvel[0].copy(),
                    "body_position": d.xpos[built.bodies].copy(), "medium_force": force(at),
                    "link_position": d.xpos[bodies].copy(), "link_quat": d.xquat[bodies].copy(),
                    "drive_position": d.qpos[qpos].copy(), "drive_velocity": d.qvel[self.dofs].copy(),
                    # What each drive applies: the feed-forward force, less what its armature takes.
                    "drive_load": at.qfrc_applied[self.dofs] - self.armature * at.qacc[self.dofs],
                    "actuator_force": d.actuator_force.copy(), "actuator_velocity": d.actuator_velocity.copy(),
                    "ctrl": d.ctrl.copy(), "sensor": d.sensordata.copy()}

        self.reads = {"state": lambda d: np.concatenate([v.ravel() for v in state(d).values()])}
        self._unpack = lambda flat: _unpack(flat, m, len(built.bodies), len(self.dofs))

        step_power = StepPower(m, scene.sim.method)

        def rates(d: mujoco.MjData, at: mujoco.MjData, velocity: np.ndarray, t: float) -> np.ndarray:
            # what the window means integrate, at a state of time t as `state` reads it (WindowMeans.parts)
            load = at.qfrc_applied[self.dofs] - self.armature * at.qacc[self.dofs]
            power = step_power(d, t)
            return np.concatenate([force(at).ravel(), load, np.maximum(load * velocity, 0), power,
                                   np.maximum(power, 0), d.sensordata])

        self.means = WindowMeans(scene.sim.settle, len(built.bodies), len(self.dofs), m.nu, m.nsensordata)
        method = methods.get(scene.sim.method)
        # MuJoCo's explicit step leaves in d the forces and actuator velocities of the state it started from (its
        # forward pass): read there, with the drives' velocities the control callback kept, they are what a
        # recording of that state reads, without a second forward pass per step.
        self._start_velocity = np.zeros(len(self.dofs))
        self._explicit = not (method.implicit or method.adaptive) and built.backend == "native"
        # the longest interval between after_step's calls, twice: the value just before the window opens is needed,
        # and a fixed step's actuator power needs the state before it (`StepPower`)
        self._span = (scene.sim.max_step if method.adaptive else 0.0) + 2 * scene.sim.dt
        forward = self.forward

        def after_step(d: mujoco.MjData) -> None:
            if self._explicit:
                if d.time - m.opt.timestep + self._span > scene.sim.settle:
                    t = d.time - m.opt.timestep
                    self.means.add(t, rates(d, d, self._start_velocity, t), d.subtree_com[0].copy())
            elif d.time + self._span > scene.sim.settle:
                forward(m, d)
                self.means.add(d.time, rates(d, self._applied(d), d.qvel[self.dofs], d.time), d.subtree_com[0].copy())

        self.surface = deforming_surface(built, scene, d)
        self._applied = applied_state(built, scene.sim.method, self.surface)
        self._surface_record: SurfaceRecord | None = None
        if self.surface is not None:
            surface, stepped = self.surface, after_step
            # its error estimate compares positions and forces; the surface is the run's record: a copy of its
            # heights as the run starts and after each change, at most one every record_dt (and the last), not at
            # every recorded instant (a wheel's 121 x 121 grid at 632 instants, 74 MB, was a tenth of its run)
            record = None if companion else SurfaceRecord(surface, scene.sim.record_dt, d.time)
            self._surface_record = record

            def after_step(d: mujoco.MjData) -> None:
                surface.step_model(built.attached, m, d)
                if record is not None:
                    record.after_step(d.time)
                stepped(d)

        self.after_step = after_step
        # the run's last state, after its recording's forward pass: the explicit step's value at the window's end
        self._close = lambda d: self.means.add(d.time, rates(d, self._applied(d), d.qvel[self.dofs], d.time))

    def _checked(self, ctrl: Any) -> np.ndarray:
        try:
            values = np.asarray(ctrl, dtype=float).ravel()
        except (TypeError, ValueError):
            raise SceneError(f"control(t, data) returned {type(ctrl).__name__} {str(ctrl)[:40]!r}: give one number "
                             f"per actuator ({self.m.nu})") from None
        if not np.all(np.isfinite(values)):
            raise SceneError(f"control(t, data) returned a value that is not finite at t = {self.d.time:g} s: "
                             f"{values}")
        if np.any(np.abs(values) > mujoco.mjMAXVAL):
            raise SceneError(f"control(t, data) returned a value beyond MuJoCo's limit +-{mujoco.mjMAXVAL:g} at t = "
                             f"{self.d.time:g} s (MuJoCo would zero every ctrl): give ctrl in the actuator's unit")
        if values.shape != (self.m.nu,):
            raise SceneError(f"control(t, data) returned {values.size} values: give one ctrl per actuator "
                             f"({self.m.nu})")
        return values

    def control(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """MuJoCo's control callback: the actuators' ctrl, and each sine drive's feed-forward force; nothing on
        another MjData of the model (`applied_state`'s, which holds the run's own)."""
        if d._address != self.d._address:
            return
        t = d.time
        if self.controller is not None:
            d.ctrl[:] = self._checked(self.controller(t, d))
        if self._open:
            if self._open_at[0] != t:
                self._open_at = (t, np.array([control_value(self.scene.control[i], self.tables[i], t)
                                              for i in self._open]))
            d.ctrl[self._open_actuators] = self._open_at[1]
        for i in self._closed:
            a, c, loop = self.actuators[i], self.scene.control[i], self.loops[i]
            if c.kind == "pd":
                d.ctrl[a] = closed_loop(c, t, d.qpos[loop[0]], d.qvel[loop[1]])
            else:
                d.ctrl[a] = closed_loop(c, t, *self._reading(i, d.sensordata[loop[0]], t))
        self._start_velocity[:] = d.qvel[self.dofs]
        # The force that makes this step end on the sine: the velocity v = (q(t + h) - q) / h that MuJoCo's
        # (semi-implicit) position update takes there, reached by armature x (v - qvel) / h. It tracks the profile
        # from the actual state, so no error accumulates; the drive's load, feed-forward less the armature's
        # share, is what the rest of the system takes (its rounding in the feed-forward cancels in it).
        h = m.opt.timestep
        for i in self.sines:
            j, dof = self.scene.drive[i], self.dofs[i]
            target = (drive_position(j, 0.0, t + h) - d.qpos[self.built.drive_qpos[i]]) / h
            d.qfrc_applied[dof] = self.armature[i] * (target - d.qvel[dof]) / h

    def _reading(self, i: int, value: float, t: float) -> tuple[float, float]:
        """Sensor loop i's reading and its rate, the change since the last step's (0 at the first; a second call
        at the same time keeps the rate)."""
        last = self._readings.get(i)
        rate = 0.0 if last is None else last[2] if t <= last[0] else (value - last[1]) / (t - last[0])
        if last is None or t > last[0]:
            self._readings[i] = (t, float(value), rate)
        return float(value), rate

    def on_stroke(self, k: int) -> None:
        """At each stroke of the grid, the constant drives take their stroke's velocity (an impulse at a
        reversal or a stop; the sines their profile's velocity at t = 0)."""
        m, d = self.m, self.d
        target = np.array([drive_velocity(j, self.stroke_time, d.time, k) for j in self.scene.drive])
        if not len(target):
            return
        if k == 0:
            # A sine starts as if it had run before: the velocity its feed-forward keeps, (q(0) - q(-h)) / h.
            h = m.opt.timestep
            for i in self.sines:
                j = self.scene.drive[i]
                target[i] = (drive_position(j, 0.0, 0.0) - drive_position(j, 0.0, -h)) / h
            d.qvel[self.dofs] = target
            return
        jump = np.where([j.profile == "constant" for j in self.scene.drive], target - d.qvel[self.dofs], 0.0)
        if np.any(jump):
            jump_velocities(m, d, self.dofs, self.armature, jump)

    def _lag(self, d: mujoco.MjData) -> None:
        for i, j in enumerate(self.scene.drive):
            lag = abs(d.qpos[self.built.drive_qpos[i]] - drive_position(j, self.stroke_time, d.time))
            if self.scales[i] > 0 and lag > DRIVE_LAG * self.scales[i]:
                rotary = self.m.jnt_type[self.m.dof_jntid[self.dofs[i]]] == mujoco.mjtJoint.mjJNT_HINGE
                raise SimulationFailed(
                    f"drive.{i} ({j.joint}) is {np.degrees(lag) if rotary else 1e3 * lag:.3g} "
                    f"{'deg' if rotary else 'mm'} off its prescribed motion at t = {d.time:.4g} s "
                    f"({100 * lag / self.scales[i]:.2g} % of its {'amplitude' if j.profile == 'sine' else 'stroke'}"
                    f"; at most {100 * DRIVE_LAG:g} %): the load outweighs the drive's armature "
                    f"({self.armature[i]:.3g} {'kg m^2' if rotary else 'kg'}, {ARMATURE_RATIO:g} times what it "
                    f"moves), so the reported motion would be wrong: give the driven body more mass, or lighten "
                    f"the load")

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        m = self.m
        if self.means.time < d.time - 1e-12:
            self._close(d)
        series = self._unpack(readings["state"])
        if self._surface_record is not None:
            series["surface_time"], series["surface_height"] = self._surface_record.finish(d.time)
        return series, {"model_size": self.built.size, "model_mass": float(m.body_mass.sum()),
                        "gravity": float(np.linalg.norm(m.opt.gravity)), "window_means": self.means.parts(d.time)}


class SurfaceRecord:
    """A deforming surface's heights over a run where they change: they change only as the surface steps, so a
    copy as the run starts, after a change once record_dt has passed since the last copy, and at the end (when
    changed since) give the surface at every instant to within record_dt, as a copy at each recorded instant did,
    at the cost of the changes alone."""

    def __init__(self, surface: DeformingSurface, record_dt: float, start: float) -> None:
        self.surface, self.record_dt = surface, record_dt
        self.times, self.heights = [start], [surface.heights.copy()]
        self._seen = surface.updates

    def after_step(self, time: float) -> None:
        if self.surface.updates != self._seen and time >= self.times[-1] + self.record_dt * (1 - 1e-9):
            self._take(time)

    def _take(self, time: float) -> None:
        self.times.append(time)
        self.heights.append(self.surface.heights.copy())
        self._seen = self.surface.updates

    def finish(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """The instants (s) and the heights (m, instants x rows x columns)."""
        if self.surface.updates != self._seen:
            self._take(time)
        return np.array(self.times), np.stack(self.heights)


def deforming_surface(built: AttachedModel, scene: UserScene, d: mujoco.MjData) -> DeformingSurface | None:
    """The run's deforming surface, from its field's original heights (None on any other surface), stepped with the
    C twins under the native backend and with numpy under the Python one: its level is the field's heights (the
    Python backend's depths), set in the native plugin's instances as it steps."""
    attached = built.attached
    field = attached.free_surface
    if field.kind != "deforming":
        return None
    p = field.parameters
    instances = ([int(built.model.body_plugin[built.model.body(s.body).id]) for s in attached.surfaces]
                 if attached.backend == "native" else [])
    return DeformingSurface(p["original"], p["size"], repose(scene.medium), p["centre"], p["frame"],
                            p["pile_factor"], native=attached.backend == "native", level=p["heights"],
                            instances=instances, compaction=scene.medium.compaction, berm=scene.medium.berm,
                            tolerance=scene.medium.relax_tolerance,
                            move=scene.medium.surface_update).installed(built.model, d)


class WindowMeans:
    """Time averages over the window [start, end] of values taken at every step (`RobotTrial.after_step`), the
    trapezoid rule between them, so that a mean does not depend on record_dt: the means of recorded samples alias
    what changes within a sample interval (the example swimmer's actuator power came out 0.320 W from samples
    every 10 ms against 0.292 W over every step). Each value holds, in this order, the medium's force on each
    attached body (B, 3), the drives' loads (D), their positive power (D), the actuators' power (U) and its
    positive part (U), the model's sensors' readings (S, MuJoCo's sensordata): positive power is clipped at every
    step, not after averaging."""

    def __init__(self, start: float, bodies: int, drives: int, actuators: int, sensors: int = 0) -> None:
        self.start, self.shape = start, (bodies, drives, actuators, sensors)
        self.time = -math.inf
        self.value: np.ndarray | None = None
        self.total: np.ndarray | None = None
        self.com: np.ndarray | None = None      # the centre of mass at the last time added
        self.opening: np.ndarray | None = None  # and at the window's start

    def add(self, t: float, value: np.ndarray, com: np.ndarray | None = None) -> None:
        """The values at time t (after those at every earlier time), and the centre of mass there: its position
        where the window opens is kept (linear between the steps around it), so that the mean velocity does not
        depend on the instants a run records (a companion's every fourth)."""
        if self.value is not None and t > self.start:
            if self.total is None:
                self.total = np.zeros_like(value)
            before = self.value
            if self.time <= self.start:  # the window opens between two steps: linear between them
                share = (self.start - self.time) / (t - self.time)
                before = self.value + (value - self.value) * share
                if com is not None and self.com is not None:
                    self.opening = self.com + (com - self.com) * share
            self.total += 0.5 * (t - max(self.time, self.start)) * (before + value)
        self.time, self.value, self.com = t, value, com

    def parts(self, end: float) -> dict[str, np.ndarray]:
        """The means over [start, end], by name (SI units)."""
        bodies, drives, actuators, sensors = self.shape
        total = self.total if self.total is not None else np.zeros(3 * bodies + 2 * drives + 2 * actuators + sensors)
        mean = total / (end - self.start)
        cuts = np.cumsum([3 * bodies, drives, drives, actuators, actuators])
        force, load, drive_power, power, positive, readings = np.split(mean, cuts)
        return {"medium_force": force.reshape(bodies, 3), "drive_load": load, "drive_positive_power": drive_power,
                "actuator_power": power, "actuator_positive_power": positive, "sensor": readings,
                "com_start": self.opening}


def _unpack(flat: np.ndarray, m: mujoco.MjModel, attached: int, drives: int) -> dict[str, np.ndarray]:
    """The recorded state's series from its flat rows (RobotTrial.reads)."""
    shapes = {"com_position": (3,), "com_velocity": (3,), "body_position": (attached, 3),
              "medium_force": (attached, 3), "link_position": (m.nbody - 1, 3), "link_quat": (m.nbody - 1, 4),
              "drive_position": (drives,), "drive_velocity": (drives,), "drive_load": (drives,),
              "actuator_force": (m.nu,), "actuator_velocity": (m.nu,), "ctrl": (m.nu,), "sensor": (m.nsensordata,)}
    out, at = {}, 0
    for name, shape in shapes.items():
        size = int(np.prod(shape))
        out[name] = flat[:, at:at + size].reshape(len(flat), *shape)
        at += size
    return out


def window_mean(time: np.ndarray, values: np.ndarray, start: float) -> np.ndarray:
    """The time average of recorded samples over [start, time[-1]] (trapezoid rule; linear between samples)."""
    inside = time > start
    t = np.r_[start, time[inside]]
    first = np.array([np.interp(start, time, column) for column in values.reshape(len(time), -1).T])
    v = np.concatenate([first.reshape(1, *values.shape[1:]), values[inside]])
    return np.trapezoid(v, t, axis=0) / (time[-1] - start)


# Below this horizontal speed of the centre of mass (m/s) a run "does not move": its cost of transport is not
# reported. A robot standing still creeps at most 0.1 mm/s (issue 23's benchmark).
STILL_SPEED = 1e-4


SIGN_CONVENTION = (
    "World frame, z up; the medium lies below z = medium.surface_z. A drive's load is what it applies to its joint "
    "along (about) the joint's axis; medium_force is the medium's force on each attached body; com_* is the "
    "model's centre of mass.")


@dataclass(frozen=True, eq=False)
class UserModel:
    """A user's MJCF model (`UserScene`) in the medium, run as a robot: its ``[[drive]]`` joints prescribed, its
    ``[[control]]`` actuators driven (or every actuator by ``control(t, data) -> ctrl``, a Python controller).
    ``UserModel.of(scene)`` reads and checks the model. Its result's series, SI units, world frame:
    ``com_position``, ``com_velocity`` (T, 3); ``body_position``, ``medium_force`` (T, B, 3) per attached body;
    ``link_position`` (T, N, 3), ``link_quat`` (T, N, 4, w x y z) of every body but the world;
    ``drive_position``, ``drive_velocity``, ``drive_load`` (T, D) per drive (m, m/s, N for a slide joint; rad,
    rad/s, N m for a hinge); ``actuator_force``, ``actuator_velocity``, ``ctrl`` (T, U) per actuator."""

    joints: tuple[str, ...] = ()          # each drive's joint kind: "slide" or "hinge"
    links: tuple[str, ...] = ()           # every body but the world, by name (or body<id>)
    actuators: tuple[str, ...] = ()       # every actuator, by name (or actuator<id>)
    tables: tuple = ()                    # each [[control]]'s table (times, values), or None
    control: Controller | None = None     # the Python controller, if any
    bodies: tuple[str, ...] = ()          # the attached bodies: model.bodies, then those of model.geoms
    loops: tuple = ()                     # each [[control]]'s closed loop: pd (qpos address, dof), sensor (address,)
    sensors: tuple[str, ...] = ()         # every MJCF <sensor>, by name (or sensor<id>)
    sensor_dims: tuple[int, ...] = ()     # each sensor's number of values in sensordata
    name = "run"
    schema = "finrft.user/2"
    sign_convention = SIGN_CONVENTION

    @classmethod
    def of(cls, scene: UserScene, control: Controller | None = None) -> UserModel:
        """The experiment of a scene, its model read and every name the scene gives checked (SceneError)."""
        drive_timing(scene)
        spec = scene_spec(scene)
        kinds = tuple(DRIVEN[int(driven_joint(spec, j.joint, f"drive.{i}.joint").type)]
                      for i, j in enumerate(scene.drive))
        m = compile_spec(spec)
        for b in scene.model.bodies:
            if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b) < 0:
                raise SceneError(f"model.bodies: the model has no body named {b!r}")
        bodies = attached_bodies(spec, scene.model.bodies, scene.model.geoms)
        if not bodies:
            raise SceneError("model.bodies and model.geoms are empty: name the bodies (or geoms) the medium acts on")
        actuators = tuple(m.actuator(i).name or f"actuator{i}" for i in range(m.nu))
        for i, c in enumerate(scene.control):
            if c.actuator not in actuators:
                raise SceneError(f"control.{i}.actuator: the model has no actuator named {c.actuator!r} (its "
                                 f"actuators: {', '.join(actuators) or 'none'})")
        if len({c.actuator for c in scene.control}) < len(scene.control):
            raise SceneError("an actuator has two [[control]] entries: give each one entry")
        if control is not None and scene.control:
            raise SceneError("give the actuators' ctrl by [[control]] or by a controller, not both: run the "
                             "controller on scene.without_controls() to let it take the [[control]] entries' place")
        keys = tuple(m.key(i).name for i in range(m.nkey))
        if scene.model.keyframe and scene.model.keyframe not in keys:
            raise SceneError(f"model.keyframe: the model has no keyframe named {scene.model.keyframe!r} (its "
                             f"keyframes: {', '.join(repr(k) for k in keys if k) or 'none'})")
        if scene.model.keyframe:
            check_keyframe(m, scene.model.keyframe)
        check_reach(scene, m, bodies)
        tables = tuple(read_table(c.table, f"control.{i}") if c.kind == "table" else None
                       for i, c in enumerate(scene.control))
        for i, (c, table) in enumerate(zip(scene.control, tables)):
            reach = control_reach(c, table)
            if not reach <= mujoco.mjMAXVAL:
                raise SceneError(f"control.{i}: its ctrl reaches {reach:g}, beyond MuJoCo's limit +-"
                                 f"{mujoco.mjMAXVAL:g} (MuJoCo would zero every ctrl): give it in the actuator's unit")
        links = tuple(m.body(i).name or f"body{i}" for i in range(1, m.nbody))
        sensors = tuple(m.sensor(i).name or f"sensor{i}" for i in range(m.nsensor))
        loops = tuple(closed_loop_address(m, c, f"control.{i}", sensors) for i, c in enumerate(scene.control))
        return cls(kinds, links, actuators, tables, control, tuple(bodies), loops, sensors,
                   tuple(int(n) for n in m.sensor_dim))

    def sensor_columns(self) -> list[str]:
        """A name for each value of the model's sensordata: the sensor's name, with its component's index for a
        sensor of several values (``head_pos.2``)."""
        return [name if n == 1 else f"{name}.{k}" for name, n in zip(self.sensors, self.sensor_dims) for k in range(n)]

    def unit(self, i: int) -> tuple[str, str, str]:
        """Drive i's position, velocity and load units."""
        return ("rad", "rad/s", "N m") if self.joints[i] == "hinge" else ("m", "m/s", "N")

    def build(self, scene: UserScene) -> AttachedModel:
        return build_attached(scene_spec(scene), [j.joint for j in scene.drive], scene.model.bodies,
                              scene.medium, scene.sim, scene.model.geoms)

    def drive_for(self, scene: UserScene) -> Schedule:
        return Schedule(*drive_timing(scene))

    def quantities(self, scene: UserScene) -> dict[str, Quantity]:
        bodies, joints = ",".join(self.bodies), ",".join(j.joint for j in scene.drive)
        world = {"frame": "world"}
        out = {
            "com_position": Quantity("m", "the model's centre of mass", attrs=world,
                                     plot=Plot("com/position", "Centre of mass (mm)", "com", "mm", "axis")),
            "com_velocity": Quantity("m/s", "velocity of the model's centre of mass", attrs=world),
            "body_position": Quantity("m", "origin of each attached body", attrs={**world, "bodies": bodies}),
            "medium_force": Quantity("N", "resultant of the medium's force on each attached body",
                                     attrs={**world, "bodies": bodies}),
            "link_position": Quantity("m", "origin of every body but the world",
                                      attrs={**world, "bodies": ",".join(self.links)}),
            "link_quat": Quantity("", "orientation of every body but the world, quaternion w x y z",
                                  attrs={**world, "bodies": ",".join(self.links)}),
        }
        if scene.drive:
            units = [self.unit(i) for i in range(len(scene.drive))]
            out.update({
                "drive_position": Quantity(",".join(u[0] for u in units), f"position of each driven joint "
                                           f"({joints})", attrs={"joints": joints}),
                "drive_velocity": Quantity(",".join(u[1] for u in units), "velocity of each driven joint",
                                           attrs={"joints": joints}),
                "drive_load": Quantity(",".join(u[2] for u in units), "force (torque) each drive applies to its "
                                       "joint along (about) its axis", attrs={"joints": joints},
                                       plot=Plot("drive/load", "Drive loads (N or N m)", "drive load", "",
                                                 "drive", tuple(j.joint for j in scene.drive))),
            })
        if scene.medium.surface == "deforming":
            out["surface_time"] = Quantity("s", "simulated time of each record of the deforming surface: as the run "
                                           "starts, after a change once sim.record_dt has passed since the last, "
                                           "and at the end", per="surface_time")
            out["surface_height"] = Quantity("m", "height of the deforming free surface at each point of its grid "
                                             "(rows along the grid's y, columns along its x; medium.surface_point, "
                                             "hfield_extent, hfield_spacing), along its z axis, against gravity, at "
                                             "each surface_time (it holds until the next)", per="surface_time",
                                             attrs=world)
        if self.actuators:
            names = {"actuators": ",".join(self.actuators)}
            out.update({
                "actuator_force": Quantity("N or N m", "each actuator's force (torque) on its joint or tendon",
                                           attrs=names, plot=Plot("actuator/force", "Actuator forces (N or N m)",
                                                                  "actuator", "", "actuator", self.actuators)),
                "actuator_velocity": Quantity("m/s or rad/s", "each actuator's velocity", attrs=names),
                "ctrl": Quantity("actuator's unit", "each actuator's control input", attrs=names),
            })
        if self.sensors:
            columns = self.sensor_columns()
            out["sensor"] = Quantity("the sensor's own (MuJoCo: SI)", "each value of the model's <sensor> readings "
                                     "(MuJoCo's sensordata), by sensor", attrs={"sensors": ",".join(columns)},
                                     plot=Plot("sensor", "Sensors (their own units)", "sensor", "", "sensor",
                                               tuple(columns)))
        return out

    def compared(self, scene: UserScene) -> tuple[Compared, ...]:
        """The attached bodies' positions and the centre of mass (mm), its velocity (mm/s); `relative_differences`
        adds the positions in percent of the run's scale, which --max-error bounds."""
        return (Compared("position_mm", ("body_position", "com_position"), 1e3),
                Compared("velocity_mm_s", ("com_velocity",), 1e3))

    def relative_differences(self, result: Result, differences: dict[str, float]) -> dict[str, float]:
        return {"position_percent": 100 * 1e-3 * differences["position_mm"] / run_scale(result)}

    # The reported figures the error estimate covers one by one (`robot_summary`), and those bounded by default;
    # from the companion at half the step alone (`convergence.checked`).
    headline = ROBOT_HEADLINE
    coarse_companion = False

    def figures(self, scene: UserScene) -> tuple[str, ...]:
        return ("com_velocity_m_s", "com_speed_m_s", "com_position_m", "medium_force_N", "body_medium_force_N",
                "drive_load", "actuator_power_W", "positive_power_W", "cost_of_transport", "sensors")

    def start(self, scene: UserScene, built: AttachedModel, d: mujoco.MjData, companion: bool) -> RobotTrial:
        return RobotTrial(self, scene, built, d, companion)

    def check(self, result: Result) -> None:
        pass

    def attrs(self) -> dict[str, Any]:
        return {"drive_joint_types": ",".join(self.joints), "controller": "python" if self.control else "scene"}

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        return []

    def summary(self, run: Result) -> dict[str, Any]:
        """The figures of `RobotSummary`, SI units."""
        return robot_summary(self, run)

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from ..views import draw_model
        return draw_model(rec, run, times, prefix)


def run_scale(run: Result) -> float:
    """The length a robot run's position errors are measured against (`ErrorLimits.position_percent`): the
    farthest its attached bodies or its centre of mass get from where they started, or the model's size."""
    travel = max(float(np.max(np.linalg.norm(run.body_position - run.body_position[0], axis=-1))),
                 float(np.max(np.linalg.norm(run.com_position - run.com_position[0], axis=-1))))
    return max(travel, run.model_size)


def robot_summary(experiment: UserModel, run: Result) -> dict[str, Any]:
    """What a robot run reports over the window [sim.settle, end] (`finrft run --json`; SI units):

    - ``com_velocity_m_s``: the centre of mass's mean velocity, its displacement over the window / the window;
      ``com_speed_m_s``: its horizontal magnitude; ``com_position_m``: where it ends.
    - ``medium_force_N``: the mean total force of the medium on the attached bodies; ``body_medium_force_N``: per
      body.
    - ``drive_load``: per [[drive]], the mean force (N) or torque (N m) it applies (``drive_load_units``).
    - ``actuator_power_W``: the mean mechanical power of the actuators, the sum over them of the force each step
      applied times the actuator's velocity (`attached_model.StepPower`; negative: they absorb work).
    - ``sensors`` (a model with MJCF ``<sensor>``s only): each sensor's mean reading, a list of its values in its
      own unit, by its name (``sensor<id>`` when it has none).
    - ``chatter``: null, or where the chatter probe saw chatter that came and went (`stepping.Chattering`): the
      share of its probes that chattered, when the first did and its largest swing over the chatter speed.
    - ``cost_of_transport``: P+ / (m g v), with P+ the mean positive power of the actuators and the drives (each
      one's power clipped at 0: work they absorb is not recovered), m the model's mass, g gravity's magnitude and
      v the centre of mass's mean horizontal speed; null, with ``cost_of_transport_note`` saying why, when the
      robot does not move (v < STILL_SPEED) or there is no gravity.

    Means over every step (`WindowMeans`), whatever record_dt; the centre of mass's velocity is exact.
    """
    scene = run.scene
    t, settle = run.time, scene.sim.settle
    com = run.com_position
    means = run.window_means
    start = means.get("com_start")
    if start is None:  # a window the steps did not open (settle 0)
        start = np.array([np.interp(settle, t, com[:, i]) for i in range(3)])
    velocity = (com[-1] - start) / (t[-1] - settle)
    body_force = means["medium_force"]
    out: dict[str, Any] = {
        "model": scene.model.path, "bodies": list(experiment.bodies),
        "drives": [j.joint for j in scene.drive], "actuators": list(experiment.actuators),
        "window_s": [settle, float(t[-1])],
        "com_velocity_m_s": velocity.tolist(), "com_position_m": com[-1].tolist(),
        "medium_force_N": body_force.sum(axis=0).tolist(),
        "body_medium_force_N": {b: body_force[i].tolist() for i, b in enumerate(experiment.bodies)},
        "drive_load": [], "drive_load_units": [], "actuator_power_W": 0.0}
    positive = 0.0
    if scene.drive:
        out["drive_load"] = means["drive_load"].tolist()
        out["drive_load_units"] = [experiment.unit(i)[2] for i in range(len(scene.drive))]
        positive += float(means["drive_positive_power"].sum())
    if experiment.actuators:
        out["actuator_power_W"] = float(means["actuator_power"].sum())
        positive += float(means["actuator_positive_power"].sum())
    out["positive_power_W"] = positive
    if experiment.sensors:
        readings, at = means["sensor"], np.cumsum([0, *experiment.sensor_dims])
        out["sensors"] = {name: readings[at[i]:at[i + 1]].tolist() for i, name in enumerate(experiment.sensors)}
    mass, gravity = run.model_mass, run.gravity
    speed = float(np.hypot(*velocity[:2]))
    if gravity == 0:
        cot, note = None, "no gravity: the weight m g is 0"
    elif speed < STILL_SPEED:
        cot, note = None, (f"the robot does not move: its centre of mass's horizontal speed {1e3 * speed:.3g} mm/s "
                           f"< {1e3 * STILL_SPEED:g} mm/s")
    else:
        cot, note = positive / (mass * gravity * speed), (f"positive power {positive:.4g} W / (mass {mass:.4g} kg "
                                                          f"x g {gravity:.4g} m/s^2 x speed {speed:.4g} m/s)")
    out.update(com_speed_m_s=speed, cost_of_transport=cot, cost_of_transport_note=note, model_size_m=run.model_size,
               scale_m=run_scale(run))
    seen = run.chattering
    out["chatter"] = None if seen is None or seen.share == 0 else {
        "share": seen.share, "first_s": seen.first, "largest_swing": seen.worst}
    return out


def run_robot(scene: UserScene, *, control: Controller | None = None, progress: Callable[[float], None] | None = None,
              max_error: ErrorLimits | None = ErrorLimits()) -> Result:
    """Run a user's model as a robot (`UserModel`): ``control(t, data) -> ctrl`` (one value per actuator, called
    at every step) drives its actuators instead of the scene's [[control]]. The result carries its error
    estimate as every run (`finrft.run`); `robot_summary` says what ``result.summary()`` reports. Under
    ``sim.method = "auto"`` (the default) the run chooses its method and step first (`finrft.choice`:
    ``result.method_choice``)."""
    if not isinstance(scene, UserScene):
        raise SceneError(f"run_robot: the scene must be a finrft.UserScene (finrft.load_scene(path, cls=UserScene)), "
                         f"got {type(scene).__name__} {scene!r:.60}")
    if control is not None and not callable(control):
        raise SceneError(f"run_robot: control must be a callable control(t, data) -> ctrl, or None, got "
                         f"{type(control).__name__} {control!r:.60}")
    return run(UserModel.of(scene, control), scene, progress=progress, max_error=max_error)


def closed_loop_address(m: mujoco.MjModel, c: Control, where: str, sensors: tuple[str, ...]) -> tuple[int, ...] | None:
    """Where a closed-loop [[control]] reads the model: a pd entry's joint's (qpos address, dof address), a sensor
    entry's sensordata address; None for an open loop. SceneError naming a bad joint, sensor or index."""
    if c.kind == "pd":
        joints = [m.joint(i).name for i in range(m.njnt)]
        if c.joint not in joints or not c.joint:
            raise SceneError(f"{where}.joint: the model has no joint named {c.joint!r} (its joints: "
                             f"{', '.join(j for j in joints if j) or 'none named'})")
        j = m.joint(c.joint)
        if int(j.type[0]) not in DRIVEN:
            raise SceneError(f"{where}.joint {c.joint!r} is a {mujoco.mjtJoint(int(j.type[0])).name} joint: a pd "
                             f"entry tracks a slide or hinge joint's position")
        return int(j.qposadr[0]), int(j.dofadr[0])
    if c.kind == "sensor":
        if c.sensor not in sensors or not c.sensor:
            raise SceneError(f"{where}.sensor: the model has no sensor named {c.sensor!r} (its sensors: "
                             f"{', '.join(sensors) or 'none'})")
        sensor = m.sensor(c.sensor)
        if c.index >= int(sensor.dim[0]):
            raise SceneError(f"{where}.index = {c.index}: sensor {c.sensor!r} has {int(sensor.dim[0])} value(s), "
                             f"indices 0..{int(sensor.dim[0]) - 1}")
        return (int(sensor.adr[0]) + c.index,)
    return None


def check_keyframe(m: mujoco.MjModel, name: str) -> None:
    """SceneError naming the first value of keyframe ``name`` that is not finite (MuJoCo takes nan and inf from a
    <key>, and the run would fail later with advice that cannot help)."""
    key = m.key(name)
    for entry in ("qpos", "qvel", "act", "ctrl", "mpos", "mquat"):
        values = np.asarray(getattr(key, entry)).ravel()
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise SceneError(f"model.keyframe {name!r}: its {entry}[{bad[0]}] is {values[bad[0]]}: every value of a "
                             f"keyframe must be a finite number; fix the model's <key name=\"{name}\">")


# How far (in the attached bodies' extents) the attached geoms may start from the free surface, beyond the fall
# that gravity gives them over the run: RFT's fits cover intrusions of the order of the intruder's size, and a
# surface a hundred sizes away is a slip (mm for m, a sign) rather than a burrowing or a drop.
REACH = 100.0


def check_reach(scene: UserScene, m: mujoco.MjModel, bodies: list[str]) -> None:
    """SceneError when medium.surface_z is so far from the attached geoms at the start (the keyframe's pose, or
    the model's own) that they cannot reach the medium (above it by more than `REACH` extents plus a free fall of
    the whole run, g T^2 / 2) or lie deeper than `REACH` extents below it."""
    if scene.medium.surface != "flat":
        return  # the slip it catches is surface_z's, in mm for m; another surface is placed by its own keys
    d = mujoco.MjData(m)
    if scene.model.keyframe:
        d.qpos[:] = m.key(scene.model.keyframe).qpos
    mujoco.mj_kinematics(m, d)
    geoms = np.flatnonzero(np.isin(m.geom_bodyid, [m.body(b).id for b in bodies]))
    if not geoms.size:
        return
    low = (d.geom_xpos[geoms] - m.geom_rbound[geoms, None]).min(axis=0)
    high = (d.geom_xpos[geoms] + m.geom_rbound[geoms, None]).max(axis=0)
    size = float(np.linalg.norm(high - low))
    surface = scene.medium.surface_z
    fall = 0.5 * float(np.linalg.norm(m.opt.gravity)) * scene.duration ** 2
    if low[2] - surface > REACH * size + fall:
        raise SceneError(f"medium.surface_z = {surface:g} m lies {low[2] - surface:.3g} m below the attached geoms' "
                         f"lowest point, which cannot reach it in the run ({REACH:g} times their extent "
                         f"{size:.3g} m plus a {fall:.3g} m fall at most): give surface_z in metres, near the model")
    if surface - high[2] > REACH * size:
        raise SceneError(f"medium.surface_z = {surface:g} m lies {surface - high[2]:.3g} m above the attached geoms, "
                         f"more than {REACH:g} times their extent ({size:.3g} m) deep: no RFT fit covers that; give "
                         f"surface_z in metres, near the model")


# The example robots shipped in finrft.mjcf, each a model, its scene and a TOML scene for a robot run (their
# physics: tests/test_robots.py; their figures: docs/guide/robots.md).
EXAMPLES = ("sand_swimmer", "hexapod", "wheel_rig")


def example(name: str) -> str:
    """The TOML scene of an example robot (`EXAMPLES`), as a path `load_scene` reads."""
    if name not in EXAMPLES:
        raise SceneError(f"no example robot named {name!r} (the examples: {', '.join(EXAMPLES)})")
    return str(mjcf_path(f"{name}.toml"))


def robot_scene(args: argparse.Namespace) -> UserScene:
    """The robot scene of a command's flags: --scene FILE.toml or --example NAME, then --set (design keys too),
    --backend and the MODEL.xml argument where the command has them."""
    if bool(args.scene) == bool(args.example):
        raise UsageError("give the scene: --scene FILE.toml, or --example NAME (one of "
                         f"{', '.join(EXAMPLES)})")
    overrides = dict(parse_override(item, UserScene) for item in args.set)
    if getattr(args, "backend", None):
        overrides["sim.backend"] = args.backend
    if getattr(args, "model", None):
        overrides["model.path"] = args.model
    return load_scene(args.scene or example(args.example), overrides=overrides, cls=UserScene)


# ---------------------------------------------------------------------------------------------------------
# The command: finrft run

@register
class RunCommand(Command):
    name = "run"
    help = "RFT on your own MuJoCo model: a robot driven by its actuators and prescribed joints"
    description = ("Attach granular RFT (medium.law: li2013, rft3d, ...) to bodies of an MJCF model and run it as "
                   "a robot for sim.duration seconds: any joints, free ones included; [[drive]] entries hold slide "
                   "or hinge joints on a prescribed profile (constant speed with strokes and cycles, or a sine) "
                   "exactly (a very large armature) and record the force (torque) each needs; [[control]] entries "
                   "drive actuators by name (a constant, a sine, a CSV table of time_s,ctrl; each with a linear "
                   "ramp-in). It reports, averaged over [sim.settle, sim.duration], the centre of mass's velocity, "
                   "the medium's force on each attached body, the drives' loads, the actuators' power and the cost "
                   "of transport, with the run's estimated discretisation error. The scene (SI units) has [model] "
                   "(path, bodies), [medium] (law, name or the law's keys, surface_z, element_size), [[drive]], "
                   "[[control]] and [sim] (dt, method, duration, settle, backend, record_dt); the text output "
                   "speaks mm, mm/s and degrees, --json SI.")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("model", nargs="?", metavar="MODEL.xml", help="the MJCF file (overrides model.path)")
        g = add_scene_flags(p, "user-model", "drive.0.speed=0.05", backend="where the RFT force is computed "
                            "(overrides sim.backend)")
        g.add_argument("--example", choices=EXAMPLES, help="an example robot shipped with finrft instead of "
                       "--scene: its model and TOML scene (mjcf/NAME.toml)")
        add_max_error(p)
        add_result_files(p)

    def scene(self, args: argparse.Namespace) -> UserScene:
        return robot_scene(args)

    def jobs(self, args: argparse.Namespace, scene: UserScene) -> list[tuple[UserModel, UserScene]]:
        return [(UserModel.of(scene), scene)]

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        run, = runs
        scene, s = run.scene, run.summary()
        mm = ", ".join
        lines = [f"{scene.model.path}: RFT ({scene.medium.law}) on {', '.join(run.experiment.bodies)} ({run.backend}; "
                 f"{scene.sim.method}, dt {scene.sim.dt:g} s): {s['sim_time_s']:.4g} s simulated, "
                 f"{steps_line(s)} in {run.wall_s:.2f} s",
                 f"over {s['window_s'][0]:g}..{s['window_s'][1]:.4g} s: centre of mass velocity (mm/s) "
                 f"{mm(f'{1e3 * v:+.3f}' for v in s['com_velocity_m_s'])}; at the end (mm) "
                 f"{mm(f'{1e3 * v:.2f}' for v in s['com_position_m'])}",
                 f"medium's mean force (N) {mm(f'{v:+.4g}' for v in s['medium_force_N'])}"]
        lines[1:1] = choice_lines(run)
        for body, force in s["body_medium_force_N"].items():
            lines.append(f"  on {body} (N) " + mm(f"{v:+.4g}" for v in force))
        for joint, load, unit, q in zip(s["drives"], s["drive_load"], s["drive_load_units"],
                                        run.drive_position[-1] if scene.drive else ()):
            end = f"{math.degrees(q):.2f} deg" if unit == "N m" else f"{1e3 * q:.2f} mm"
            lines.append(f"drive {joint}: mean load {load:+.4g} {unit}, at the end {end}")
        if s["actuators"]:
            lines.append(f"actuators' mean power {s['actuator_power_W']:+.4g} W")
        if s.get("sensors"):
            lines.append("sensors' means (their units): " + "; ".join(
                f"{name} {mm(f'{v:.4g}' for v in values)}" for name, values in s["sensors"].items()))
        cot = s["cost_of_transport"]
        lines.append(f"cost of transport {cot:.4g} ({s['cost_of_transport_note']})" if cot is not None
                     else f"cost of transport: none ({s['cost_of_transport_note']})")
        if s["chatter"]:
            c = s["chatter"]
            lines.append(f"chatter in {100 * c['share']:.2g} % of the probes, from t = {c['first_s']:.3g} s (at most "
                         f"{c['largest_swing']:.3g} times the chatter speed): too little to stop the run; the error "
                         f"estimate judges its figures")
        e = s["error_estimate"]
        lines.append(f"estimated discretisation error (companion run at {s['error_companion']}): positions "
                     f"{e['position_mm']:.2g} mm ({e['position_percent']:.2g} % of the run's scale, "
                     f"{1e3 * s['scale_m']:.3g} mm), centre of mass velocity {e['velocity_mm_s']:.2g} mm/s; its "
                     f"mean (mm/s) {mm(f'{1e3 * v:.2g}' for v in e['com_velocity_m_s'])}, speed "
                     f"{1e3 * e['com_speed_m_s']:.2g} mm/s"
                     + ("" if e.get("cost_of_transport") is None
                        else f", cost of transport {e['cost_of_transport']:.2g}")
                     + f", positive power {e['positive_power_W']:.2g} W")
        return "\n".join(lines)
