"""Stepping any experiment through its run: drives that hold joints on a prescribed profile (`Prescribed`), the
step schedule of a drive (`schedule`), and the loop that steps, records and stops loudly on an unstable or
chattering run (`step_through`). `experiment.run` uses it for every experiment."""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from . import callbacks, interrupts, methods
from .convergence import MAX_STEPS, check_resolution, check_size, record_every
from .drive import Drive
from .errors import Chatter, NotConverged, SceneError, SimulationFailed, SimulationUnstable, StepUnderflow
from .attach import Attached
from .integrate import SURFACE_SPEED, Stepper
from .models import ARMATURE_RATIO, ForceGroup
from .native import Code, captured_warnings
from .scene import ExplicitSim

_BAD_STATE = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)

# The largest distance a prescribed drive may fall behind (or run ahead of) its motion within a stroke, as a share
# of the stroke. Its armature holds it there only while the load is small against armature / time^2: a light driven
# body under a large force (a user's 1 g plate dragged 500 mm: 0.7 %) drifts, and the run would report the wrong
# travel. The presets drift by at most 1.3e-5 (the paper plate at 10 mm/s); the plate fit's widest coefficients
# (C_S 100 N, b 100 N m s/rad) by 8.5e-4, which shifts its angles far less than the data's scatter.
DRIVE_LAG = 1e-3


class Prescribed:
    """Joints that follow a `Drive` exactly: a very large armature holds their speed within a stroke, and at
    each reversal the rest of the system takes the impulse an ideal kinematic constraint would give it.

    The drive's impulse over a stroke is exactly -armature times the change of its velocity (summed over the
    joints), and its instantaneous force or torque is -armature * qacc. Called after every step (`track`), it keeps
    each stroke's peak load, the largest instantaneous load at any step's state (the reversal's, after its jump,
    included) whatever samples the run records, and how much the load changes between that step and its
    neighbours (`peak_change`): the load's largest value between steps is within about that of the steps',
    where a companion run's comparison can miss it (the paper plate's peak at its stop converges unevenly in dt).
    A stroke whose joints end more than DRIVE_LAG of the stroke off the prescribed motion stops the run
    (SimulationFailed).
    """

    def __init__(self, dofs: Sequence[int], qpos: Sequence[int], armature: float, drive: Drive) -> None:
        self.dofs, self.qpos, self.armature, self.drive = list(dofs), list(qpos), armature, drive
        self.impulse = np.zeros(drive.strokes)
        self.peak = np.zeros(drive.strokes)
        self.peak_change = np.zeros(drive.strokes)
        self._load = math.nan        # the load at the last step (NaN: none yet in this stroke)
        self._after_peak = False     # the last step set its stroke's peak
        self._stroke_velocity = np.zeros(len(self.dofs))
        self._stroke = 0
        self._stroke_start = (0.0, np.zeros(len(self.qpos)))  # the time and the joints' positions as it started

    def start_stroke(self, m: mujoco.MjModel, d: mujoco.MjData, k: int) -> None:
        if k:
            self._close(d)
            d.qpos[self.qpos] = self.drive.stroke_start(k)
            jump_velocities(m, d, self.dofs, self.armature, self.drive.stroke_velocity(k) - d.qvel[self.dofs])
        else:
            d.qvel[self.dofs] = self.drive.stroke_velocity(0)
        self._stroke, self._stroke_velocity = k, d.qvel[self.dofs].copy()
        self._stroke_start = (d.time, d.qpos[self.qpos].copy())
        self._load, self._after_peak = math.nan, False
        self.track(m, d)

    def track(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """After a step (and as a stroke starts): the stroke's peak load, and its change to the neighbouring
        steps, take the load at this state."""
        mujoco.mj_forward(m, d)
        qacc = d.qacc
        load = self.armature * max(abs(qacc[i]) for i in self.dofs)
        k = self._stroke
        if self._after_peak:
            self.peak_change[k] = max(self.peak_change[k], abs(self.peak[k] - load))
        higher = load > self.peak[k]
        if higher:
            self.peak[k] = load
            self.peak_change[k] = 0.0 if math.isnan(self._load) else abs(load - self._load)
        # a peak at the stroke's first state is at its instant exactly: nothing earlier in the stroke to miss, and
        # the load falling after it (a light plate relaxing to the new velocity in microseconds) is no error
        self._after_peak = higher and not math.isnan(self._load)
        self._load = load

    def finish(self, d: mujoco.MjData) -> None:
        self._close(d)

    def load(self, d: mujoco.MjData) -> np.ndarray:
        """What each joint's drive applies now (after mj_forward): N or N m."""
        return -self.armature * d.qacc[self.dofs]

    def _close(self, d: mujoco.MjData) -> None:
        self.impulse[self._stroke] = -self.armature * np.sum(d.qvel[self.dofs] - self._stroke_velocity)
        start, q0 = self._stroke_start
        lag = float(np.max(np.abs(d.qpos[self.qpos] - q0 - self.drive.stroke_velocity(self._stroke) *
                                  (d.time - start))))
        if lag > DRIVE_LAG * self.drive.stroke:
            rotary = self.drive.kind == "rotate"
            raise SimulationFailed(
                f"the drive ended stroke {self._stroke + 1} {np.degrees(lag) if rotary else 1e3 * lag:.3g} "
                f"{'deg' if rotary else 'mm'} off its prescribed motion ({100 * lag / self.drive.stroke:.2g} % of "
                f"the stroke; at most {100 * DRIVE_LAG:g} %): the load outweighs the drive's armature "
                f"({self.armature:.3g} {'kg m^2' if rotary else 'kg'}, {ARMATURE_RATIO:g} times what it moves), so "
                f"the reported travel would be wrong: give the driven body more mass, or lighten the load")



def jump_velocities(m: mujoco.MjModel, d: mujoco.MjData, dofs: Sequence[int], armature: float | np.ndarray,
                    jump: np.ndarray) -> None:
    """Velocity jumps ``jump`` on prescribed joints (``dofs``, each carrying its drive's ``armature``), the rest of
    the system taking the impulse an ideal kinematic constraint would give it: M0 dq = E mu with E^T dq = jump,
    where M0 is the mass matrix without the drives' armature."""
    mujoco.mj_forward(m, d)
    mass = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, mass)
    mass[dofs, dofs] -= armature
    columns = np.linalg.solve(mass, np.eye(m.nv)[:, dofs])
    d.qvel[:] += columns @ np.linalg.solve(columns[dofs], jump)


# What a scene that offers MuJoCo's step only (ExplicitSim) can change; such scenes have no other method.
_EXPLICIT_ONLY = "reduce sim.dt or raise the inertias"


def regularisation(scene: Any) -> str:
    """The scene's key of the speed its rate-independent forces fade out below: a chain's ``rft.v_reg``, or for
    attached surfaces ``medium.v_reg`` where the scene has it; "" when it has none."""
    if hasattr(scene, "rft"):
        return "rft.v_reg"
    return "medium.v_reg" if hasattr(getattr(scene, "medium", None), "v_reg") else ""


def unstable(scene: Any, t: float, messages: list[str], code: int = 1) -> SimulationUnstable:
    sim, key = scene.sim, regularisation(scene)
    if code == Code.STEP_TOO_SMALL:
        return StepUnderflow(
            f"the adaptive step fell below 1e-9 s at t = {t:.4g} s (tolerance {sim.tolerance:g}): raise "
            f"sim.tolerance{f' or {key}' if key else ''}, or use sim.method = 'newton'")
    if code == Code.ARENA_FULL:
        return SimulationUnstable(
            f"the native step's workspace does not fit in MuJoCo's arena at t = {t:.4g} s: use sim.backend = "
            f"'python'")
    if code == Code.NOT_CONVERGED:
        return NotConverged(
            f"Newton's method of the implicit step did not converge at t = {t:.4g} s (dt = {sim.dt:g} s): reduce "
            f"sim.dt{f' or raise {key}' if key else ''}")
    what = messages[0].rstrip(".") if messages else "the velocity became NaN or Inf"
    if isinstance(sim, ExplicitSim):
        advice = _EXPLICIT_ONLY
    elif not methods.get(sim.method).implicit:
        advice = f"reduce sim.dt, raise the inertias{f' or {key}' if key else ''}, or use sim.method = 'newton'"
    else:
        advice = f"reduce sim.dt (or sim.max_step){f', or raise {key}' if key else ''}"
    return SimulationUnstable(f"simulation went unstable at t = {t:.4g} s ({what}) with method {sim.method}, "
                              f"integrator {sim.integrator}, dt = {sim.dt:g} s: {advice}")


def chatter(scene: Any, t: float) -> Chatter:
    sim = scene.sim
    if isinstance(sim, ExplicitSim):
        advice = _EXPLICIT_ONLY
    elif methods.get(sim.method).newton:
        advice = "reduce sim.dt: a light body's mode overshoots even the solved step there"
    else:
        advice = "use sim.method = 'newton', or reduce sim.dt"
    return Chatter(
        f"the RFT force chatters at t = {t:.4g} s (it reverses every step: the velocities overshoot) with method "
        f"{sim.method}, dt = {sim.dt:g} s: {advice}")


def schedule(drive: Drive, dt: float, record_dt: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Step count, the steps at which each stroke starts, and the steps recorded (always the first and last);
    SceneError when dt cannot resolve a stroke, or the run would take too many steps."""
    check_size(drive.duration / dt, 0, dt, drive.duration)  # first: a tiny dt overflows a count of whole steps
    check_resolution(drive.stroke_time, dt)
    steps = max(1, round(drive.duration / dt))
    every = record_every(dt, record_dt)
    check_size(steps, steps // every + 1, dt, drive.duration)
    starts = np.array([round(k * drive.stroke_time / dt) for k in range(drive.strokes)])
    samples = np.unique(np.r_[np.arange(0, steps, every), steps])
    return steps, starts, samples


def instants(events: np.ndarray, steps: int, starts: np.ndarray, sim: Any, stroke_time: float) -> np.ndarray:
    """When the scheduled steps ``events`` fall: on the grid of ``sim.dt``; with an adaptive method, a reversal
    and the end exactly on the drive's instants, multiples of ``stroke_time``, as its steps can land anywhere:
    a stroke's length rounded to whole steps is felt in eta (~1e-4 for 7 µs on the physical robot)."""
    times = np.asarray(events, dtype=float) * sim.dt
    if methods.get(sim.method).adaptive:
        stroke = np.searchsorted(starts, events, side="right") - 1
        times = np.where(np.asarray(events) == starts[stroke], stroke * stroke_time, times)
        times = np.where(np.asarray(events) == steps, len(starts) * stroke_time, times)
    return times


# A recorded sample chatters when some watched dof's velocity, over the three steps before it, moves one way, back,
# and that way again, each time by more than the dof's chatter speed (`chatter_speeds`): an overshoot every step (the
# RFT force reversing each step), which no oscillation the steps resolve can do. Every PROBE_EVERY-th sample is
# checked (each check costs three single steps); CHATTER_SAMPLES checked samples in a row stop the run.
CHATTER_SAMPLES = 3
PROBE_EVERY = 2
# The chatter speed of a dof that moves no point the medium acts on (rad/s or m/s): no RFT force can reverse there.
# A hinge resting on a MuJoCo limit jitters by ~2e-3 rad/s, which is no chatter.
CHATTER_DV = 1e-2


def chatter_speeds(m: mujoco.MjModel, d: mujoco.MjData, groups: Sequence[ForceGroup], attached: Attached | None,
                   watch: Sequence[int]) -> np.ndarray:
    """Per watched dof, the smallest swing of its velocity that counts as chatter, at the positions of ``d``: the
    regularisation speed of the forces on the points it moves (a segment group's v_reg; an attached surface's
    v_reg, or `integrate.SURFACE_SPEED` when unweighted) over the largest speed those points take per unit velocity
    of the dof (its lever: 1 for a slide, the distance from a hinge's axis; for a body's elements, the speed of its
    origin plus its largest arm times its angular velocity). A swing below it keeps every point within the law's
    linear range, where the force does not reverse and an explicit step damps the swing out; above it the force
    flips each step. So a body resting on the medium (its velocities settled to within v_reg) passes, whatever its
    size, while the absolute threshold this replaces (CHATTER_DV for every dof) stopped a hexapod standing still
    (0.026 rad/s on 3e-5 kg m^2 at 25 µs) and would pass a chattering 1 m lever. Dofs that move no such point keep
    CHATTER_DV."""
    watch = list(watch)
    speeds = np.full(len(watch), np.inf)
    if not watch:
        return speeds
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for group in groups:
        for site in group.sites:
            mujoco.mj_jacSite(m, d, jacp, None, site)
            lever = np.linalg.norm(jacp[:, watch], axis=0)
            speeds = np.minimum(speeds, group.law.v_reg / np.where(lever > 0, lever, np.nan))
    if attached is not None:
        speed = attached.v_reg if attached.v_reg > 0 else SURFACE_SPEED
        for surface in attached.surfaces:
            mujoco.mj_jacBody(m, d, jacp, jacr, m.body(surface.body).id)
            reach = np.linalg.norm(surface.centre, axis=1).max(initial=0.0)
            lever = np.linalg.norm(jacp[:, watch], axis=0) + reach * np.linalg.norm(jacr[:, watch], axis=0)
            speeds = np.minimum(speeds, speed / np.where(lever > 0, lever, np.nan))
    return np.where(np.isfinite(speeds), speeds, CHATTER_DV)


def check_adaptive_budget(sim: Any, duration: float) -> None:
    """SceneError when an adaptive method would take more than MAX_STEPS steps of at most ``sim.max_step`` over a
    run of ``duration`` s: the steps it must take at least, which its loop has no other bound on."""
    if duration / sim.max_step > MAX_STEPS:
        raise SceneError(f"sim.max_step = {sim.max_step:g} s would take at least {duration / sim.max_step:.3g} "
                         f"steps over the run's {duration:.4g} s, more than {MAX_STEPS:.0e}: raise sim.max_step")


def _walk(advance: Stepper, d: mujoco.MjData, step: int, end: int, end_time: float, sim: Any, adaptive: bool,
          on_step: Callable[[], None]) -> int:
    """From scheduled step ``step`` to ``end`` (at ``end_time``) one step at a time, ``on_step()`` after each; an
    adaptive method, whose steps are its own, to every instant of a grid of its largest step instead (sim.max_step
    rounded to whole steps of sim.dt, at least one), which cuts its steps there but keeps their size. The stepper's
    code at the first failure, else 0."""
    stride = max(1, round(sim.max_step / sim.dt)) if adaptive else 1
    for k in [*range((step // stride + 1) * stride, end, stride), end]:
        interrupts.check()
        code = advance.until(d, end_time if k == end else k * sim.dt) if adaptive else advance(d, 1)
        if code:
            return code
        on_step()
    return 0


def step_through(m: mujoco.MjModel, d: mujoco.MjData, scene: Any, advance: Stepper, steps: int,
                 starts: np.ndarray, samples: np.ndarray, on_stroke: Callable[[int], None],
                 on_sample: Callable[[int], None], progress: Callable[[float], None] | None = None,
                 watch: Sequence[int] = (),
                 forward: Callable[[mujoco.MjModel, mujoco.MjData], None] | None = mujoco.mj_forward,
                 stroke_time: float = 0.0,
                 speeds: np.ndarray | None = None, on_step: Callable[[], None] | None = None) -> None:
    """Step a model through a run: ``on_stroke(k)`` as stroke k starts, ``on_sample(i)`` (after ``forward(m, d)``,
    mj_forward or the trial's own; None: only the state is current) at recorded step ``samples[i]``; ``advance``
    steps in chunks in between. Stops loudly if the state blows up, or if the ``watch`` dofs chatter (fixed-step
    methods: the three steps before every PROBE_EVERY-th sample are taken one by one and checked when the run ends),
    each by more than its chatter speed in ``speeds`` (`chatter_speeds`; None: CHATTER_DV).
    An adaptive method steps to each event's `instants` (the drive's strokes last ``stroke_time``) and restarts its
    step size at each reversal. ``on_step()``, when given, is called after every step (the fixed-step methods
    then step one at a time; an adaptive method at every instant of a grid of its largest step: `_walk`)."""
    adaptive = methods.get(scene.sim.method).adaptive
    if adaptive:
        check_adaptive_budget(scene.sim, steps * scene.sim.dt)
    probe = len(watch) > 0 and not adaptive
    # velocity[i, j]: the watched velocities 3 - j steps before sample i (j = 3: at the sample)
    velocity = np.full((len(samples), 4, len(watch)), np.nan)
    slot: dict[int, list[tuple[int, int]]] = {}
    for i, s in enumerate(samples if probe else []):
        for j in range(4 if i % PROBE_EVERY == 0 else 0):
            slot.setdefault(int(s) - 3 + j, []).append((i, j))
    events = np.union1d(np.union1d(samples, starts), np.array([s for s in slot if s >= 0], dtype=int))
    stroke_of = np.searchsorted(starts, events, side="right") - 1
    times = instants(events, steps, starts, scene.sim, stroke_time)
    counts = d.warning.number
    bad = [int(w) for w in _BAD_STATE]
    messages: list[str] = []
    sample = 0
    with captured_warnings(messages):
        for i, step in enumerate(events):
            interrupts.check()
            k = stroke_of[i]
            if step == starts[k]:
                on_stroke(k)
                if adaptive and k:
                    advance.restart()
            for at in slot.get(step, ()):
                velocity[at] = d.qvel[watch]
            if sample < len(samples) and step == samples[sample]:
                if forward is not None:
                    forward(m, d)
                on_sample(sample)
                sample += 1
                if progress is not None:
                    progress(step / steps)
            if step == steps:
                break
            if on_step is None:
                code = advance.until(d, times[i + 1]) if adaptive else advance(d, int(events[i + 1] - step))
            else:
                code = _walk(advance, d, step, int(events[i + 1]), times[i + 1], scene.sim, adaptive, on_step)
            callbacks.check(m)
            if code or any(counts[w] for w in bad):
                raise unstable(scene, d.time, messages, code or 1)
    if probe:
        # Samples whose three steps before lie in one stroke (a reversal jumps the velocities on purpose).
        inside = np.searchsorted(starts, samples - 3, side="right") == np.searchsorted(starts, samples, side="right")
        moves = np.diff(velocity, axis=1)
        limit = np.full(len(watch), CHATTER_DV) if speeds is None else np.asarray(speeds)
        flips = np.any(np.all(np.abs(moves) > limit, axis=1) & np.all(moves[:, 1:] * moves[:, :-1] < 0, axis=1),
                       axis=1) & inside
        probed = np.arange(0, len(samples), PROBE_EVERY)
        runs = np.convolve(flips[probed], np.ones(CHATTER_SAMPLES, int), mode="valid")
        if np.any(runs == CHATTER_SAMPLES):
            first = probed[int(np.argmax(runs == CHATTER_SAMPLES)) + CHATTER_SAMPLES - 1]
            raise chatter(scene, samples[first] * scene.sim.dt)
