"""Stepping any experiment through its run: drives that hold joints on a prescribed profile (`Prescribed`), the
step schedule of a drive (`schedule`), and the loop that steps, records and stops loudly on an unstable or
chattering run (`step_through`). `experiment.run` uses it for every experiment."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from . import callbacks, interrupts, methods
from .convergence import MAX_STEPS, check_resolution, check_size, record_every
from .drive import Drive
from .errors import Chatter, NotConverged, SceneError, SimulationFailed, SimulationUnstable, StepUnderflow
from .attach import Attached
from .integrate import SURFACE_SPEED, LoadPeak, Stepper
from .models import ForceGroup
from .native import Code, captured_warnings
from .scene import ExplicitSim

_BAD_STATE = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)
_W = mujoco.mjtWarning
# MuJoCo's other warnings, each a run that goes on with a wrong result: what happened, and what to do. MuJoCo zeroes
# every ctrl of the model when one is bad (NaN or beyond mjMAXVAL, 1e10), drops the contacts or constraints beyond
# its arena, and a singular mass matrix gives arbitrary accelerations. (The bad-state ones are `unstable`.)
_VOID = {
    int(_W.mjWARN_BADCTRL): ("ctrl of actuator {name} is NaN or beyond +-{max:g}, so MuJoCo zeroed every ctrl of "
                             "the model", "give ctrl values in the actuator's unit, within +-{max:g}"),
    int(_W.mjWARN_CONTACTFULL): ("MuJoCo's contact buffer is full, so contacts were dropped",
                                 "give the model more memory (<size memory=\"...\"/>) or fewer colliding geoms"),
    int(_W.mjWARN_CNSTRFULL): ("MuJoCo's constraint buffer is full, so constraints were dropped",
                               "give the model more memory (<size memory=\"...\"/>)"),
    int(_W.mjWARN_INERTIA): ("the mass matrix is singular at dof {index}",
                             "give every moving body a positive mass and inertia"),
}


def void_run(m: mujoco.MjModel, d: mujoco.MjData) -> SimulationFailed | None:
    """The failure a MuJoCo warning raised on ``d`` since it was made or reset means (`_VOID`), or None: a run
    that raised one is no result, whatever it recorded."""
    for kind, (what, advice) in _VOID.items():
        stat = d.warning[kind]
        if stat.number:
            index = int(stat.lastinfo)
            name = (m.actuator(index).name or str(index)) if kind == _W.mjWARN_BADCTRL and 0 <= index < m.nu \
                else str(index)
            fill = {"name": repr(name), "index": index, "max": mujoco.mjMAXVAL}
            return SimulationFailed(f"{what.format(**fill)} ({stat.number} time(s), by t = {d.time:.4g} s): the "
                                    f"run is void; {advice.format(**fill)}")
    return None

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
    joints), and its instantaneous force or torque is -armature * qacc. Each stroke's peak load (`peak`) and its
    change to the neighbouring steps (`peak_change`) are the stroke's `LoadPeak` (``load_peak``): taken as the
    stroke starts (after the reversal's jump) and, by a stepper given it (`integrate.stepper`), at every step's
    state, whatever samples the run records. A stroke whose joints end more than DRIVE_LAG of the stroke off the
    prescribed motion stops the run (SimulationFailed).
    """

    def __init__(self, dofs: Sequence[int], qpos: Sequence[int], armature: float, drive: Drive) -> None:
        self.dofs, self.qpos, self.armature, self.drive = list(dofs), list(qpos), armature, drive
        self.impulse = np.zeros(drive.strokes)
        self.peak = np.zeros(drive.strokes)
        self.peak_change = np.zeros(drive.strokes)
        self.load_peak = LoadPeak(self.dofs, armature)
        self._stroke_velocity = np.zeros(len(self.dofs))
        self._stroke = 0
        self._stroke_start = (0.0, np.zeros(len(self.qpos)))  # the time and the joints' positions as it started

    def start_stroke(self, m: mujoco.MjModel, d: mujoco.MjData, k: int) -> None:
        if k:
            self._close(m, d)
            d.qpos[self.qpos] = self.drive.stroke_start(k)
            jump_velocities(m, d, self.dofs, self.armature, self.drive.stroke_velocity(k) - d.qvel[self.dofs])
        else:
            d.qvel[self.dofs] = self.drive.stroke_velocity(0)
        self._stroke, self._stroke_velocity = k, d.qvel[self.dofs].copy()
        self._stroke_start = (d.time, d.qpos[self.qpos].copy())
        self.load_peak.restart()
        self.load_peak.take(m, d)

    def finish(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        self._close(m, d)

    def load(self, d: mujoco.MjData) -> np.ndarray:
        """What each joint's drive applies now (after mj_forward): N or N m."""
        return -self.armature * d.qacc[self.dofs]

    def _close(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        self.load_peak.flush(m, d)
        self.peak[self._stroke], self.peak_change[self._stroke] = self.load_peak.peak, self.load_peak.change
        self.impulse[self._stroke] = -self.armature * np.sum(d.qvel[self.dofs] - self._stroke_velocity)
        start, q0 = self._stroke_start
        lag = float(np.max(np.abs(d.qpos[self.qpos] - q0 - self.drive.stroke_velocity(self._stroke) *
                                  (d.time - start))))
        if lag > DRIVE_LAG * self.drive.stroke:
            # The load moves the armature by load x time^2 / armature: a slow drive's long stroke drifts, though the
            # armature is already `models.ARMATURE_RATIO` times what it moves.
            rotary, drive = self.drive.kind == "rotate", self.drive
            scale, unit = (math.degrees(1), "deg") if rotary else (1e3, "mm")
            flags = "--omega, --amplitude" if rotary else "--speed, --distance"
            raise SimulationFailed(
                f"the drive ended stroke {self._stroke + 1} {scale * lag:.3g} {unit} off its prescribed motion "
                f"({100 * lag / drive.stroke:.2g} % of the stroke; at most {100 * DRIVE_LAG:g} %): its stroke of "
                f"{scale * drive.stroke:.4g} {unit} at {scale * drive.speed:.4g} {unit}/s lasts "
                f"{drive.stroke_time:.4g} s, long enough for the load to move the drive's armature "
                f"({self.armature:.3g} {'kg m^2' if rotary else 'kg'}; the lag grows as load x time^2 / armature), so the reported travel "
                f"would be wrong: drive faster or over a shorter stroke ({flags}), or lighten the load")



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
        f"the RFT force chatters at t = {t:.4g} s (it reverses within a few steps, most of the time: the velocities "
        f"overshoot) with method {sim.method}, dt = {sim.dt:g} s: {advice}")


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


# The chatter probe of a fixed-step run (`ChatterProbe`): every PROBE_DT of simulated time (at least PROBE_STEPS + 1
# steps apart) the PROBE_STEPS steps before are taken one by one. A watched dof chatters there when its velocity
# reverses at every one of them, each time by more than its chatter speed (`chatter_speeds`): the step's own
# instability, whatever its size (the wheel rig's load axis past its limit); or when it swings back and forth by
# more than CHATTER_SWING chatter speeds per step (its total variation over the steps less its net change, over
# their number): a hop every few steps, a body at rest on the medium kicked up by one step's force and falling back
# over the next few (a limit cycle). A motion the steps resolve turns at most once in PROBE_STEPS steps, and by
# little; a mode near the step's limit rings by about one chatter speed (the wheel rig at its own step, 0.7-1.4,
# within 0.6 % of converged), while the runs below swing by a median 12-43 of them. The run stops as soon as more
# than half of the probes of the last CHATTER_WINDOW chatter (the whole run when shorter; at least CHATTER_SAMPLES
# probes): steady chatter, CHATTER_WINDOW / 2 after its onset. Chatter that comes and goes (a robot's landing, a
# leg's strike) finishes, reported (`Chattering`); the error estimate judges what it did to the figures. Measured
# (20 ms probes, 1 s windows): the runs whose figures chatter moves (the 10 g sand-swimmer at explicit 0.5 ms, speed
# -9 %; a 40 g one at 0.2 ms, -3 %; blocks at rest hopping at 0.1 ms, mean force +24 % as recorded) chatter in
# 57-100 % of their probes, in all of some second's; those within 0.4 % of the converged speed (the hexapod at
# explicit 0.2 ms, the sand-swimmer at 50 us, the examples at their defaults) in 4-13 %, at most 30 % of a
# second's (the hexapod's landing).
PROBE_DT = 0.02
PROBE_STEPS = 8
CHATTER_WINDOW = 1.0
CHATTER_SAMPLES = 3
CHATTER_SWING = 3.0
# The probes are judged in batches of this much simulated time (s): a run that chatters stops at most that later.
PROBE_BATCH = 0.25
# A native stepper that traces the probe's velocities (`integrate.Trace`) steps at most this many steps a call.
TRACE_STEPS = 1000
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


@dataclass(frozen=True)
class Chattering:
    """What the chatter probe saw over a run that finished: the share of its probes that chattered (0 to 1), when
    the first did (s; NaN: none), and the largest swing per step over the dof's chatter speed."""

    share: float
    first: float
    worst: float


class ChatterProbe:
    """The chatter probe of a fixed-step run of ``steps`` steps of ``dt`` (the constants above): `steps`, the steps
    whose velocities it takes (`store`), in order; the probes whose steps would cross a stroke's start (``starts``: a
    reversal jumps the velocities on purpose) are left out. The probes are judged together, as soon as those of
    PROBE_BATCH of simulated time are complete (a run's last ones by `flush`): numpy's cost is per call."""

    def __init__(self, watch: Sequence[int], speeds: np.ndarray | None, steps: int, starts: np.ndarray,
                 dt: float) -> None:
        self.watch, self.dt = list(watch), dt
        self.limit = np.full(len(self.watch), CHATTER_DV) if speeds is None else np.asarray(speeds, dtype=float)
        self._per_swing = 1 / (PROBE_STEPS * self.limit)  # a swing per step in chatter speeds
        every = max(PROBE_STEPS + 1, round(PROBE_DT / dt))
        ends = np.arange(every, steps + 1, every)
        stroke = np.searchsorted(starts, ends - PROBE_STEPS, side="right")
        self.ends = ends[stroke == np.searchsorted(starts, ends, side="right")]
        self.steps = (self.ends[:, None] + np.arange(-PROBE_STEPS, 1)).ravel()
        self.window = max(CHATTER_SAMPLES, min(round(CHATTER_WINDOW / (every * dt)), len(self.ends)))
        self._batch = max(1, round(PROBE_BATCH / (every * dt)))
        # The probes stored and not judged yet, each in its slot of a ring that holds a batch and one call's trace
        # (`integrate.Trace`); flat: one row per step.
        slots = self._batch + TRACE_STEPS // (PROBE_STEPS + 1) + 2
        self._velocity = np.empty((slots, PROBE_STEPS + 1, len(self.watch)))
        self._flat = self._velocity.reshape(-1, len(self.watch))
        self._stored = 0                    # the velocities stored: those of steps[:_stored]
        self._chattered: list[bool] = []
        self._swing: list[float] = []       # each probe's largest swing per step over its dof's chatter speed

    def store(self, first: int, velocities: np.ndarray) -> bool:
        """The watched dofs' velocities at `steps` ``first``, ``first`` + 1, ... (one row each, at most a trace's
        TRACE_STEPS; every step once, in order); True when the run is to stop."""
        self._stored = first + len(velocities)
        start = first % len(self._flat)
        if start + len(velocities) <= len(self._flat):
            self._flat[start:start + len(velocities)] = velocities
        else:
            self._flat[np.arange(first, self._stored) % len(self._flat)] = velocities
        complete = self._stored // (PROBE_STEPS + 1)
        return complete - len(self._chattered) >= self._batch and self._judge(complete)

    def flush(self) -> bool:
        """Judge the probes complete and not judged yet (a run's end); True when the run is to stop."""
        return self._judge(self._stored // (PROBE_STEPS + 1))

    def _judge(self, probes: int) -> bool:
        """Judge the probes up to ``probes``; True as soon as the run is to stop."""
        # numpy's ufuncs and their reductions, not its methods and functions, whose Python layers cost more here
        velocity = self._velocity[np.arange(len(self._chattered), probes) % len(self._velocity)]
        moves = velocity[:, 1:] - velocity[:, :-1]
        size = np.abs(moves)
        swing = (np.add.reduce(size, axis=1) - np.abs(velocity[:, -1] - velocity[:, 0])) * self._per_swing
        flips = np.logical_and.reduce(size > self.limit, axis=1) & np.logical_and.reduce(
            moves[:, 1:] * moves[:, :-1] < 0, axis=1)
        chattered = np.logical_or.reduce(flips | (swing > CHATTER_SWING), axis=1).tolist()
        self._swing.extend(np.maximum.reduce(swing, axis=1).tolist())
        if not any(chattered):  # no probe that could tip a window
            self._chattered.extend(chattered)
            return False
        for one in chattered:
            self._chattered.append(one)
            if sum(self._chattered[-self.window:]) * 2 > self.window:
                return True
        return False

    @property
    def onset(self) -> float:
        """When the chatter that stops the run began: the first chattering probe of the last window (s)."""
        recent = self._chattered[-self.window:]
        first = recent.index(True)
        return float(self.ends[len(self._chattered) - len(recent) + first] * self.dt)

    def seen(self) -> Chattering:
        """What the probes saw over the run."""
        hits = np.flatnonzero(self._chattered)
        return Chattering(share=len(hits) / max(1, len(self._chattered)),
                          first=float(self.ends[hits[0]] * self.dt) if len(hits) else math.nan,
                          worst=max(self._swing, default=0.0))


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
                 speeds: np.ndarray | None = None, on_step: Callable[[], None] | None = None) -> Chattering | None:
    """Step a model through a run: ``on_stroke(k)`` as stroke k starts, ``on_sample(i)`` (after ``forward(m, d)``,
    mj_forward or the trial's own; None: only the state is current) at recorded step ``samples[i]``; ``advance``
    steps in chunks in between. Stops loudly if the state blows up, or as soon as the ``watch`` dofs chatter most of
    the time (fixed-step methods: `ChatterProbe`), each by more than its chatter speed in ``speeds``
    (`chatter_speeds`; None: CHATTER_DV); what the probe saw of chatter that came and went is returned (None: no
    probe).
    An adaptive method steps to each event's `instants` (the drive's strokes last ``stroke_time``) and restarts its
    step size at each reversal. ``on_step()``, when given, is called after every step (the fixed-step methods
    then step one at a time; an adaptive method at every instant of a grid of its largest step: `_walk`)."""
    adaptive = methods.get(scene.sim.method).adaptive
    if adaptive:
        check_adaptive_budget(scene.sim, steps * scene.sim.dt)
    probe = ChatterProbe(watch, speeds, steps, starts, scene.sim.dt) if len(watch) and not adaptive else None
    # A stepper that traces the probe's velocities steps past the probe's steps (in calls of at most TRACE_STEPS);
    # other steppers stop at each of them.
    trace = None if probe is None or on_step is not None else getattr(advance, "traced", lambda *_: None)(
        probe.watch, TRACE_STEPS)
    events = samples if probe is None else np.union1d(samples, probe.steps if trace is None else
                                                      np.arange(0, steps, TRACE_STEPS))
    events = np.union1d(events, starts)
    stroke_of = np.searchsorted(starts, events, side="right") - 1
    times = instants(events, steps, starts, scene.sim, stroke_time)
    if probe is not None:
        # Per event: the first of the probe's steps at or after it, whether one is there, and whether that one is
        # taken there, from the state (traced, only at a stroke's start, whose reversal the trace has not seen) or
        # from the trace of the call that ends there. (`probed`: the probe's steps and one that is none, as a run too
        # short for a probe has none.)
        probed = np.r_[probe.steps, -1]
        first = np.searchsorted(probe.steps, events)
        there = probed[first] == events
        at_event = there if trace is None else there & (events == starts[stroke_of])
        # The probe's steps each call from an event to the next steps through (traced): lo to hi, rows from the
        # trace's row r when they follow one another (a probe's steps do), else None.
        lo, hi = first + there, np.r_[first[1:] + (there & ~at_event)[1:], 0]
        ends = probed[np.clip(np.c_[lo, hi - 1], 0, len(probe.steps))]
        row = np.where(ends[:, 1] - ends[:, 0] == hi - lo - 1, ends[:, 0] - events - 1, -1)
        past = [(a, b, r if r >= 0 else None) for a, b, r in zip(lo.tolist(), hi.tolist(), row.tolist())]
        first, at_event = first.tolist(), at_event.tolist()
    counts = d.warning.number
    bad = [int(w) for w in _BAD_STATE]
    messages: list[str] = []
    sample = 0
    with captured_warnings(messages), callbacks.deferred():
        for i, step in enumerate(events):
            interrupts.check()
            k = stroke_of[i]
            if step == starts[k]:
                on_stroke(k)
                if adaptive and k:
                    advance.restart()
            if probe is not None and at_event[i] and probe.store(first[i], d.qvel[probe.watch][None]):
                raise chatter(scene, probe.onset)
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
            if code:
                raise unstable(scene, d.time, messages, code)
            if trace is not None:  # the probe's steps the call stepped through
                a, b, r = past[i]
                if b > a and probe.store(a, trace.rows[probe.steps[a:b] - step - 1] if r is None else
                                         trace.rows[r:r + b - a]):
                    raise chatter(scene, probe.onset)
            if any(counts[w] for w in bad):
                raise unstable(scene, d.time, messages, 1)
            failure = void_run(m, d)
            if failure is not None:
                raise failure
        failure = void_run(m, d)  # the last sample's forward pass
        if failure is not None:
            raise failure
        if probe is not None and probe.flush():
            raise chatter(scene, probe.onset)
    return None if probe is None else probe.seen()
