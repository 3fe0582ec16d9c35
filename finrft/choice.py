"""``sim.method = "auto"`` (`methods.AUTO`, a robot's default): the run chooses the method and the step that meet
its error limits (`convergence.ErrorLimits`: ``--max-error``, by default the experiment's headline figures) at the
least cost, and says what it chose and why (`MethodChoice`, ``method_choice`` in a result's summary).

No method wins everywhere: the implicit steps win on light links, whose explicit step must stay below about
2 m v_reg / F (the example sand-swimmer's 10 g links chatter down to 6.6 µs), and MuJoCo's explicit step wins
on heavy, slow robots, as an implicit step costs several explicit ones. Which one a robot is shows as it runs, so
the choice is measured, not predicted: pilot runs over the run's first `window` (past the controls' ramp-in, a
tenth of the rest or a sine's period, whole strokes; the whole run where that would be a fifth of it or more), each
candidate at its step and at half of it, their reported figures compared as the run's companion compares them
(`convergence.companion_estimate`). The candidates are ``explicit`` and, on MuJoCo's implicitfast integrator,
``newton-midpoint`` and ``newton``, each on a ladder of steps from `START` x sim.dt down (`Chooser.search`):

- each method is priced by the start of its first pilot (the second half of `PRICE_SHARE` of the run, no further
  than shows it dearer than a method priced before it), its other steps by its cost per step, as it went with the
  step between two whole pilots of the method (`PER_STEP`);
- the method whose verdict is predicted cheapest is measured next (`Chooser.verdict`: the pilots it has still to
  run, and its run where the pilots are not); one that misses the limits gives its method's next step, half of
  it: its pilot at half the step is there already, and the one that judges it is the run of the next. An implicit
  method is ranked by the step its error asks for (first order, aimed at `SAFE` of the limit), reached halving by
  halving: a leap there needs pilots at it and half of it, which cost more than the halvings between (the
  sandfish's newton-midpoint, estimated 3.3 % off at 2 ms, was sent to 0.5 ms where 1 ms is within 0.3 %), and a
  method far off is not walked down (its newton, estimated 19 % off at 2 ms, would need 0.125 ms);
- an explicit step beyond the bodies' explicit limit (`window_limit`, over the implicit methods' pilots so far,
  which are priced first) is neither priced nor piloted: its candidate is skipped, and the ladder goes on below
  the limit;
- a pilot at half a candidate's step stops once its robot's speed since the settling, over whole periods of its
  gait, is far off its pilot at the step's (`OFF_LIMIT`): the candidate misses the limits, and the rest of the
  pilot would only confirm it;
- once one meets the limits, only candidates predicted to cost less than `SAVING` of it are measured, and the
  cheapest that met them is tried at twice its step while its estimate is below `COARSEN` of its limit; where the
  pilots are whole runs, the first that meets them is chosen: its run and its companion are made, and any other
  would cost more.

A step longer than the scene's own keeps the medium's mean force within 2 % too (`LONGER`). Where the pilots were
whole runs, the chosen candidate's pilot is the run and its pilot at half the step its companion: nothing runs
twice. Else the cheapest candidate runs whole, with its companion estimate as every run has; should that
estimate refuse it or the run chatter (a pilot's window is not the whole run), the next one runs, or the search goes
on past it (`run_auto`). The pilots' wall time counts in the result's ``wall_s`` (``method_choice.pilot_wall_s``).
An explicit candidate whose chatter comes and goes (`stepping.Chattering`) and leaves its figures within their
limits is chosen, and its run reports the chatter.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from .convergence import FINER, SAFETY, ErrorLimits, FigureLimit, companion_estimate, magnitude
from .errors import InaccurateResult, SceneError, SimulationUnstable

# The pilots' window (`window`): the controls' ramp-in and this share of the rest of the run (or a sine's
# period), at least PILOT_STEPS steps of sim.dt.
PILOT_SHARE = 0.1
PILOT_STEPS = 16
# A window that would span this share of the run spans all of it: the pilots are then whole runs, and the chosen
# candidate's pilot and its pilot at half the step are the run and its companion (no run is made twice). A pilot's
# figures are means over its window, and their errors over a window shorter than the run's were 0.1 to 10 times
# the whole run's: the sand-swimmer's cost of transport by newton-midpoint at 2 ms estimated 5.3 % off over its
# 1.5 s window, 1.8 % over its run (a transient's offset weighs more on a short mean), the quadruped's explicit step
# at 2 ms 1.6 % and 7.0 % (its drift grows over the run). A window of a fifth of the run costs, at its step and half
# of it, 0.6 of the run and its companion, and a run whole that its pilots misjudged costs them all again: on the
# battery of `finrft bench robots` `auto` took a median 1.8 times the fastest run within 2 % at this share, 2.5 at
# one half (`scripts/auto_against_sweep.py`).
WHOLE_SHARE = 0.2
IMPLICIT = ("newton-midpoint", "newton")
# Every ladder starts at START times sim.dt: a scene's step is often set with room to spare (eight of the eleven
# robots of `finrft bench robots --battery` meet 2 % fastest at twice it), and the pilot at START x sim.dt shares
# its pilot at half the step with the one at sim.dt, so it costs half a run at sim.dt.
START = 2.0
HALVINGS = 4             # the implicit methods at START x sim.dt down to sim.dt / 8
EXPLICIT_HALVINGS = 9    # the explicit step from START x sim.dt down to sim.dt / 256, while it is the cheaper
# The cheapest candidate that met the limits is tried at twice its step while its estimate is below this share of
# its limit (first order: the error doubles), up to COARSEST x sim.dt; its pilot at half the step is the one run.
COARSEN = 0.45
COARSEST = 4.0
# A step longer than the scene's own is taken only where the medium's mean force on the robot is estimated within
# this too, whatever the limits: the headline figures alone let a box resting on the sand hop out of it at twice
# its step (its speed 0, its cost of transport not reported).
LONGER = (FigureLimit("medium_force_N", 2.0),)
# The share of its limit an implicit step's estimate is aimed at, where the one at sim.dt exceeds it: the step its
# method is ranked by (`Chooser.search`).
SAFE = 0.8
# Once a candidate met the limits, another is measured only where it is predicted to cost less than this share of
# it: a pilot that would save less is not worth its risk of missing the limits.
SAVING = 0.85
# The share of the run a short pilot prices a candidate over before any is run whole (`Chooser.price`), timed over
# its second half: a robot's first moments (a sled landing on the sand) can cost a Newton step several times its
# gait's (the paddle sled's newton-midpoint priced at 4 times its cost from its first 5 %).
PRICE_SHARE = 0.1
# An explicit step's price stops in the first half of its stretch, before the half it times, where at its pace so
# far the half it times would cost EARLY times its budget (`Chooser.price`): the sandfish's explicit step at 4 us
# spent 0.9 s of its 4.4 s choice on the half it does not time. Not a Newton method's: there a landing can cost
# several times the gait (stopped so at 4 times, the paddle sled's newton at 0.5 ms was priced at 3 times its
# cost, and newton-midpoint, 24 times over the limits, ran first: 12.5 s against 5.7).
EARLY = 4.0
# An explicit candidate whose step exceeds this share of the bodies' explicit limit (`window_limit`) is not
# piloted: beyond it a light link's velocity reverses each step, and its figures are off however they pass the
# chatter probe and their estimate (the sandfish's 10 g links, their limit 3 us: its speed 25-27 % low from 8 us to
# 0.25 ms, estimated 1.8-5.9 % off; MuJoCo's explicit step at 2.5 and 1 us agrees with newton at 10 us to 0.05 %).
EXPLICIT_ROOM = 1.0
# The bodies' explicit limit is taken over the implicit pilots' run (`window_limit`), not at one instant: sampled
# LIMIT_SAMPLES times over the pilots' window, in stretches of LIMIT_STRETCH of it, each stretch's the median over
# the bodies moving at MOVING of the fastest one's speed or more. A foot standing in the sand (the quadruped's,
# 7-60 mm/s against its swinging feet's 200-1000 mm/s) sets a limit of 0.01-0.8 ms where its explicit step at 2 ms
# is 1.6 % off; one instant's limit is a foot's or a joint's reversal, or the start of the ramp-in, or neither.
# A body slower than STILL counts as standing too: the rover's 150 g wheels starting from rest at 3-7 mm/s set
# 0.04-0.18 ms where its explicit step at 0.5 ms is within 2 %, the hexapod's 4 g legs at 9-12 mm/s 0.1 ms where
# its explicit step at 0.5 ms is 1 % off; the slowest gaits here are 30 mm/s.
LIMIT_SAMPLES = 40
LIMIT_STRETCH = 0.1
MOVING = 0.25
STILL = 0.02
# The power of the step a step's cost goes with, as measured between two pilots of a method (`Chooser.predicted`),
# kept within these: a Newton step costs less where it is shorter (fewer iterations: the sand-swimmer's `newton` at
# 1 ms costs 0.82 of its step at 2 ms), none costs more. The power holds over one halving past the steps it was
# measured between: a step costs at least one iteration (the sandfish's `newton` per step: 0.87, 0.68, 0.54 and
# 0.55 ms of CPU at 2, 1, 0.5 and 0.25 ms; the power of its first halving taken three halvings on put the step at
# 0.125 ms at 0.31 ms).
PER_STEP = (0.0, 1.0)
# A Newton method's price is held within ALIKE times the cost of the other's whole pilot at its step, where that
# ran (`Chooser.cost`): over the sweep of `finrft bench robots --battery`, newton-midpoint's run with its companion
# cost 0.63-1.71 times newton's at the same step, while a price times the run's start alone, where one of them may
# struggle: the sandfish's newton-midpoint at 2 ms, priced over its landing at 2.6-2.9 times its cost and scaled by
# newton's whole pilot over its price (`calibration`, 0.6-1.4 between runs) to up to 4 times, was at times ranked
# above newton's walk down to 0.125 ms, which ran instead (11-14 s of CPU against 3.4-4.3).
ALIKE = 2.0
# Before either has run a pilot through (both known by their prices, and by pilots that failed at their start),
# newton-midpoint's pilot at a step is run before newton's only where it is predicted cheaper by more than this
# factor. The two cost alike (the spoke hexapod's: 0.573 s of CPU a simulated second each at 2 ms), their prices
# over a tenth of the run differed by up to 1.2 times either way, and which ran first decided the choice's cost
# (the paddle sled's 1.3 or 2.5 times the fastest run that passes) and at times the choice (the whegs', whose
# Newton methods both chatter at 2 ms, at 1 ms: newton-midpoint's run there costs 1.6 times newton's): among equals
# the pilots go in one order, newton's first, the L-stable step whose first-order error each halving halves.
NEWTON_FIRST = 1.5
# A run's cost against its pilot's: the run itself and its companion at half the step (`convergence.checked`).
COMPANION_COST = 1 + 1 / FINER
# A pilot at half the step stops once the horizontal speed its robot has made since the settling, over a whole
# number of its gait's periods (`period`), is estimated off its pilot at the step's over as long (as the companion
# estimates it, SAFETY / (1 - FINER) times the difference) by over OFF_LIMIT times what the speed's limit allows
# (`Chooser._off`): its candidate misses the limits, and the rest of its pilot would only confirm it. Over whole
# periods such differences held (the sandfish's newton at 2 ms: 4.4-5.0 % of its speed over its window's first
# tenth to its end; the sand-swimmer's 2.8-3.1 %); over parts of a period they swing with the gait's phase, which
# the step shifts (the eel's newton at 1 ms: 0.3-2.3 % over parts of its 1 s period, 0.24 % over all of it).
OFF_LIMIT = 3.0


@dataclass
class Candidate:
    """One method at one step, as the pilots found it: its predicted cost (the run with its companion, s) and, where
    its pilots ran, their wall time, the estimated error of each bounded figure and the limits it exceeds."""

    method: str
    dt: float
    cost_s: float = math.nan
    measured: bool = False
    pilot_wall_s: float = 0.0
    error: dict[str, float] = field(default_factory=dict)
    over: list[str] = field(default_factory=list)
    failed: str = ""
    skipped: str = ""         # why its pilot at half the step did not run
    excess: float = math.inf  # the largest estimate over its limit (below 1: within the limits)
    estimate: dict[str, Any] = field(default_factory=dict, repr=False)  # its pilots' whole error estimate

    @property
    def passed(self) -> bool:
        return self.measured and not self.failed and not self.over

    @property
    def why_not(self) -> str:
        if self.failed:
            return self.failed
        if self.over:
            return "; ".join(self.over)
        return self.skipped

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "dt": self.dt, "predicted_cost_s": None if math.isnan(self.cost_s)
                else self.cost_s, "measured": self.measured, "pilot_wall_s": self.pilot_wall_s,
                "error_estimate": dict(self.error), "within_limits": self.passed, "why_not": self.why_not}


@dataclass
class MethodChoice:
    """What ``sim.method = "auto"`` chose, why, and the candidates it weighed (`Candidate`); the wall time of its
    pilots and of the runs whole it refused (s), both part of the result's ``wall_s``."""

    method: str
    dt: float
    reason: str
    candidates: list[Candidate]
    window_s: float
    pilot_wall_s: float
    refused_wall_s: float = 0.0

    def line(self) -> str:
        """The choice in one line of text."""
        return (f"method auto: {self.method} at dt {self.dt:g} s ({self.reason}; {len(self.candidates)} candidates, "
                f"pilots over the first {self.window_s:.3g} s took {self.pilot_wall_s:.2f} s)")

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "dt": self.dt, "reason": self.reason, "window_s": self.window_s,
                "pilot_wall_s": self.pilot_wall_s, "refused_wall_s": self.refused_wall_s,
                "candidates": [c.to_json() for c in self.candidates]}


def window(scene: Any, duration: float, stroke_time: float, strokes: int) -> tuple[float, float]:
    """The pilots' run and the start of the window their figures average over (s): past the controls' longest
    ramp-in (a run's start is a transient unlike its gait), one period of the slowest sine control or drive (the
    sand-swimmer's explicit step chatters from 1.46 s on, a second after its ramp, and its speed is then 2-4 %
    off at 0.25 ms, where its first 0.65 s were within 0.4 %), and at least `PILOT_SHARE` of the rest and
    `PILOT_STEPS` steps of sim.dt; whole strokes where the run has several. The figures average from the ramp's
    end, the run's settle or half the window, whichever comes first; with no ramp-in, the run starts at once, a
    transient of its own: from half the window (the wheel rig's drive, from rest at its steady depth, rings its
    2.1 kg axis on the sand's stiffness for about half a second: over its whole first second its cost of transport
    was estimated 29 % off at 125 ms, 0.3 % over its second half, and its whole run at 125 ms 0.03 %)."""
    ramp = max((c.ramp for c in getattr(scene, "control", ())), default=0.0)
    span = ramp + max(PILOT_SHARE * (duration - ramp), PILOT_STEPS * scene.sim.dt, period(scene))
    if strokes > 1:
        span = math.ceil(span / stroke_time - 1e-9) * stroke_time
    if span >= WHOLE_SHARE * duration:
        return duration, scene.sim.settle
    return span, min(ramp if ramp > 0 else math.inf, scene.sim.settle, span / 2)


def period(scene: Any) -> float:
    """The period of the slowest sine control or drive (s; 0 where there is none): a gait's."""
    sines = [c.frequency for c in getattr(scene, "control", ()) if c.kind == "sine"]
    sines += [j.frequency for j in getattr(scene, "drive", ()) if j.profile == "sine"]
    return 1 / min(sines) if sines and min(sines) > 0 else 0.0


Pilot = Callable[[Any, bool, Callable[[float], None]], Any]
# The state the bodies' explicit limit is taken at: (model, data, force groups, attached surfaces or None), or None
State = Callable[[Any], Any]


def explicit_limit(m: Any, d: Any, groups: Any, attached: Any) -> float:
    """The longest explicit step that keeps every RFT body's velocity from reversing in one step (s; inf where no
    element carries a force), at the positions and velocities of ``d``: min over the bodies of 2 m / k, m the body's
    mass and k the medium force's slope, sum over its elements of |F| / max(|v|, v_reg) (a rate-independent law's
    force turns with the velocity: its slope across it is |F| / |v|, F / v_reg inside the regularisation), and of
    the limit of its faces' leading-face switch (`_switch_limit`). An explicit step damps a damper of slope k on a
    mass m only for dt < 2 m / k."""
    return float(body_limits(m, d, groups, attached)[0].min(initial=math.inf))


def window_limit(samples: list[tuple[float, Any, Any]], span: float) -> float:
    """The bodies' explicit limit over a run (s; inf where no body moved in the sand), from ``samples`` (time s,
    and each body's `body_limits` then) over a run of ``span`` s: the least over stretches of `LIMIT_STRETCH` x
    ``span`` of the median limit of the bodies moving there, at least `MOVING` times the fastest body's speed of
    their instant and `STILL`. A median ignores one foot that stands in the sand and one link reversing; the least
    stretch is the harshest phase of the gait: the ramp-in, where the links move slowly against the full force."""
    import numpy as np
    stretches: dict[int, list[Any]] = {}
    for t, limits, speeds in samples:
        held = np.isfinite(limits)
        moving = held & (speeds >= max(MOVING * speeds[held].max(initial=0.0), STILL))
        if not moving.any():
            continue
        stretches.setdefault(int(t / (LIMIT_STRETCH * span)), []).append(limits[moving])
    return min((float(np.median(np.concatenate(v))) for v in stretches.values()), default=math.inf)


def body_limits(m: Any, d: Any, groups: Any, attached: Any) -> tuple[Any, Any]:
    """Each body's explicit limit 2 m / k (`explicit_limit`; inf where none of its elements carries a force) and
    its speed, the force-weighted mean of its elements' (m/s; 0 where none does), at the state of ``d``, indexed
    by body id."""
    import mujoco
    import numpy as np

    from . import laws
    from .integrate import SURFACE_SPEED
    slope, force, power = np.zeros(m.nbody), np.zeros(m.nbody), np.zeros(m.nbody)
    mujoco.mj_kinematics(m, d)  # positions and velocities alone: no force (a Python callback) runs
    mujoco.mj_comPos(m, d)
    mujoco.mj_comVel(m, d)
    jacp = np.zeros((3, m.nv))
    for group in groups:
        sites = np.asarray(group.sites, dtype=int)
        v = np.empty((len(sites), 3))
        for i, site in enumerate(sites):
            mujoco.mj_jacSite(m, d, jacp, None, site)
            v[i] = jacp @ d.qvel
        frames = d.site_xmat[sites].reshape(-1, 3, 3)
        fn = np.linalg.norm(laws.bind(group.law)(v, frames[:, :, 0], frames[:, :, 1]), axis=1)
        vn = np.linalg.norm(v, axis=1)
        bodies = m.site_bodyid[sites]
        np.add.at(slope, bodies, fn / np.maximum(vn, group.law.v_reg))
        np.add.at(force, bodies, fn)
        np.add.at(power, bodies, fn * vn)
    switch = np.full(m.nbody, np.inf)
    if attached is not None:
        mujoco.mj_crb(m, d)  # the mass matrix, for the bodies' mobility (`_switch_limit`)
        mujoco.mj_factorM(m, d)
        forces = attached.callback(m)
        floor = attached.v_reg if attached.v_reg > 0 else SURFACE_SPEED
        twists = [np.zeros(6) for _ in forces.bodies]
        for (body, _), twist in zip(forces.bodies, twists):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, body, twist, 0)
        for (body, _), (f, v, slopes, normals) in zip(forces.bodies, forces.limit_terms(d, twists, floor)):
            fn, vn = np.linalg.norm(f, axis=1), np.linalg.norm(v, axis=1)
            slope[body] += float(np.sum(fn / np.maximum(vn, floor)))
            force[body] += float(fn.sum())
            power[body] += float(fn @ vn)
            switch[body] = _switch_limit(m, d, body, slopes, normals)
    held = slope > 0
    limits = np.full(m.nbody, np.inf)
    limits[held] = 2 * m.body_mass[held] / slope[held]
    limits = np.minimum(limits, switch)
    speeds = np.zeros(m.nbody)
    speeds[force > 0] = power[force > 0] / force[force > 0]
    return limits, speeds


def _switch_limit(m: Any, d: Any, body: int, slopes: Any, normals: Any) -> float:
    """The longest explicit step that keeps a body's faces from switching their force on and off each step (s; inf
    where none can): 2 / the largest eigenvalue of A K, K = sum over its elements of slope n n^T (their slopes
    across the leading-face switch, `SurfaceForces.limit_terms`) and A = J M^-1 J^T the mobility of the body's
    origin (m/s per N s): a face grazing the medium, as a plate's top and bottom swimming level, switches its whole
    force on at a normal speed of v_reg, and a body free to move along its normal, the sandfish's 10 g links
    floating in the sand, chatters there unless dt < about 2 m v_reg / F (3 us where MuJoCo's explicit step needs
    2.5 us, and at 8 us to 0.25 ms swims 25-27 % slower than newton-midpoint's converged run, its cost of transport
    under half of it, each estimated 1.8-5.9 % off); one held along it by the rest of the robot (a wheel's sides,
    by the chassis on its axle) does not."""
    import mujoco
    import numpy as np
    if not np.any(slopes > 0):
        return math.inf
    jac = np.zeros((3, m.nv))
    mujoco.mj_jacBody(m, d, jac, None, body)
    solved = jac.copy()
    mujoco.mj_solveM(m, d, solved, jac)
    stiffness = (normals * slopes[:, None]).T @ normals
    largest = float(np.max(np.linalg.eigvals((jac @ solved.T) @ stiffness).real))
    return 2 / largest if largest > 0 else math.inf


class Chooser:
    """The pilots of one run: ``pilot(scene, companion, progress)`` runs a scene without an estimate (a companion
    records the state only) on the model ``prepare(scene)`` built, each candidate's figures judged by ``limits``;
    its cost is measured in CPU seconds (`cost`)."""

    def __init__(self, scene: Any, limits: ErrorLimits, pilot: Pilot, prepare: Callable[[Any], Any],
                 duration: float, stroke_time: float, strokes: int, state: State | None = None) -> None:
        self.scene, self.limits, self.pilot, self.prepare = scene, limits, pilot, prepare
        self.state = state
        self._samples: list[tuple[float, Any, Any]] = []  # `body_limits` over the implicit pilots (`window_limit`)
        self._slots: set[int] = set()                       # the sampled times, in 1 / LIMIT_SAMPLES of the window
        self.duration, self.stroke_time, self.strokes_n = duration, stroke_time, strokes
        self.window, self.settle = window(scene, duration, stroke_time, strokes)
        # A run of one stroke is cut short by shortening its stroke (the same motion up to the window's end); one
        # of several keeps its whole strokes (`window`).
        cut = self.window / stroke_time if strokes == 1 else 1.0
        self.strokes = {f"drive.{i}.stroke": j.stroke * cut for i, j in enumerate(getattr(scene, "drive", ()))
                        if j.profile == "constant" and j.stroke > 0 and cut < 1}
        self.candidates: list[Candidate] = []
        # the implicit methods extend MuJoCo's implicitfast integrator; with another, the explicit step alone
        self.allowed = IMPLICIT if scene.sim.integrator == "implicitfast" else ()
        self.wall = 0.0          # the pilots' wall time (s)
        self.refused_wall = 0.0  # the wall time of the runs whole that were refused (`run_auto`, s)
        self.whole = self.window >= duration  # the pilots are whole runs (`WHOLE_SHARE`)
        self.budget = math.inf                 # the CPU time a pilot may take before it stops (`_timed`)
        self.top = START * scene.sim.dt       # the longest step tried first
        self._runs: dict[tuple[str, float], Any] = {}    # each pilot that ran (or its failure), for reuse
        self._rates: dict[tuple[str, float], float] = {}  # its CPU time per simulated second, as far as it got
        self._walls: dict[tuple[str, float], float] = {}  # its wall time
        self._whole: set[tuple[str, float]] = set()       # the pilots timed over the window, not a price's stretch
        self._bounds: set[tuple[str, float]] = set()      # the prices stopped dearer than another (`price`)
        self._priced: dict[tuple[str, float], float] = {}  # each price's own rate (`calibration`)
        self._partial: set[tuple[str, float]] = set()      # the rates of a failed run's start alone (`predicted`)
        self._tracks: dict[tuple[str, float], list] = {}  # each whole pilot's robot's track (`_off`)

    def at(self, method: str, dt: float) -> Any:
        """The scene of a candidate's pilot."""
        window = {} if self.whole else {"sim.duration": self.window, "sim.settle": self.settle, **self.strokes}
        return self.scene.replace(**{"sim.method": method, "sim.dt": dt, **window})

    def _run(self, method: str, dt: float, against: tuple[str, float] | None = None) -> Any:
        """A candidate's pilot at dt (its result, or its step's failure), run once; its robot's track kept, and,
        ``against`` the pilot of another step, stopped where it is off by far (`_off`: its `Off` is returned, the
        pilot is not kept)."""
        key = (method, dt)
        if key in self._runs:
            return self._runs[key]
        start = time.perf_counter()
        try:
            scene = self.at(method, dt)
            self.prepare(scene)  # the model's build, outside the cost of a step
            track: list[tuple[float, float, float]] = []
            run, self._rates[key] = self._timed(scene, self.window, sample=method in IMPLICIT,
                                                watch=self._off(scene, track, against))
            if not isinstance(run, SimulationUnstable):
                self._whole.add(key)
            elif key in self._priced:  # its price's stretch, past its start (a price that failed is its pilot)
                self._rates[key] = self._priced[key]
            else:
                self._partial.add(key)
            if not isinstance(run, Off):
                self._runs[key], self._tracks[key] = run, track
        except SceneError as exc:  # a step longer than the scene's that does not resolve its strokes
            if not dt > self.scene.sim.dt:
                raise
            run = self._runs[key] = exc
            self._rates[key] = math.nan
        self._walls[key] = time.perf_counter() - start
        self.wall += self._walls[key]
        return run

    def _off(self, scene: Any, track: list[tuple[float, float, float]],
             against: tuple[str, float] | None) -> Callable[[], None] | None:
        """What a pilot does at each of its samples: keeps its robot's track (time, centre of mass x and y) and,
        ``against`` another step's pilot, raises `Off` where its speed since the settling over whole periods of its
        gait is estimated off by more than `OFF_LIMIT` times the speed's limit (None: no robot's state to read, or no
        gait's period to compare over)."""
        every = period(scene)
        if self.state is None or not every > 0:
            return None
        import numpy as np
        other = self._runs.get(against) if against is not None else None
        limit, theirs = None, None
        settle = scene.sim.settle
        if other is not None and not isinstance(other, Exception) and against in self._tracks:
            named = other.headline() if self.limits.figures is None else self.limits.figures
            speed_limit = next((f for f in named if f.key == "com_speed_m_s"), None)
            speed = other.figure_values().get("com_speed_m_s")
            past = np.array(self._tracks[against])
            if speed_limit is not None and speed is not None and len(past) and past[0, 0] <= settle:
                limit = speed_limit.allowed(speed)
                theirs = lambda t: np.array([np.interp(t, past[:, 0], past[:, k]) for k in (1, 2)])  # noqa: E731
        start: list[Any] = []  # the robot's position at the settling
        periods = [1]          # the next whole number of periods to check at

        def watch() -> None:
            _, d, *_ = self.state(scene)
            t, here = d.time, d.subtree_com[0][:2].copy()
            if not start and t >= settle and track and track[-1][0] <= settle:
                before, at = track[-1][0], np.array(track[-1][1:])
                start.append(at + (here - at) * ((settle - before) / (t - before) if t > before else 1.0))
            track.append((t, *here))
            if theirs is None or not start or t < settle + periods[0] * every:
                return
            periods[0] = math.floor((t - settle) / every) + 1
            ours = np.hypot(*(here - start[0])) / (t - settle)
            off = SAFETY / (1 - FINER) * abs(ours - np.hypot(*(theirs(t) - theirs(settle))) / (t - settle))
            if off > OFF_LIMIT * limit:
                raise Off(f"com_speed_m_s: its pilot at half the step, stopped at {t:.3g} s, was off by an "
                          f"estimated {off:.3g} m/s, over {OFF_LIMIT:g} times its limit {limit:.3g}",
                          "com_speed_m_s", float(off), float(off / limit))
        return watch

    def reused(self, candidate: Candidate) -> Any:
        """The chosen candidate's run, where its pilots were whole runs: its pilot, with the estimate from its pilot
        at half the step as its companion's (`convergence.checked`); None where they were not whole."""
        if not (self.whole and candidate.passed):
            return None
        run, fine = self._runs[(candidate.method, candidate.dt)], (candidate.method, candidate.dt * FINER)
        run.error_estimate, run.error_companion = dict(candidate.estimate), f"dt {fine[1]:g} s"
        run.error_wall_s = self._walls[fine]
        run.wall_s = self.wall - run.error_wall_s  # the pilots' and the run's own, not its companion's
        return run

    def cost(self, method: str, dt: float) -> float:
        """The predicted time of the whole run with its companion (CPU s, the wall time of an idle machine), from the
        pilot at dt (NaN: none got far), a price's times its kind's `calibration`, and an implicit method's within
        `ALIKE` times the other's whole pilot at its step, where that ran."""
        key = (method, dt)
        rate = self._rates.get(key, math.nan)
        if key not in self._whole:
            rate *= self.calibration(method)
            rival = next((self._rates[(m, dt)] for m in IMPLICIT if m != method and (m, dt) in self._whole), None)
            if method in IMPLICIT and rival is not None and rate == rate:
                rate = min(max(rate, rival / ALIKE), rival * ALIKE)
        return rate * self.duration * COMPANION_COST

    def calibration(self, method: str) -> float:
        """What a price's rate is to be multiplied by to be a whole pilot's: the geometric mean, over the candidates
        of ``method``'s kind (the explicit step, or the implicit methods) both priced and then run as whole pilots
        (not failed), of the whole pilot's rate over its price's; 1 where none is. A price times its run's start,
        which may cost other than the rest: the eel's, where its gait ramps in, cost its Newton methods 0.20-0.21 s
        a simulated second, their whole pilots 0.43-0.47; priced as they were, newton-midpoint's pilots at 2 ms were
        ranked below newton's at 0.5 ms, which cost less, measured after newton's at 2 ms."""
        explicit = method == "explicit"
        ratios = [math.log(self._rates[key] / rate) for key, rate in self._priced.items()
                  if (key[0] == "explicit") == explicit and key in self._whole and rate > 0 and self._rates[key] > 0]
        return math.exp(sum(ratios) / len(ratios)) if ratios else 1.0

    def try_step(self, method: str, dt: float, cheaper_than: float = math.inf,
                 dearer: str = "predicted to cost more than the cheapest that met the limits") -> Candidate:
        """A candidate's pilot at dt and, where it runs through and costs less than ``cheaper_than``, at dt / 2
        (else it is not measured, ``dearer`` says why); a candidate tried before and not measured is tried again."""
        known = [c for c in self.candidates if (c.method, c.dt) == (method, dt)]
        if known and (known[0].measured or known[0].failed):
            return known[0]
        candidate = known[0] if known else Candidate(method, dt)
        if not known:
            self.candidates.append(candidate)
        start = self.wall - candidate.pilot_wall_s
        run = self._run(method, dt)
        candidate.cost_s = self.cost(method, dt)
        if isinstance(run, Exception):
            candidate.failed = _first_line(run)
        elif not candidate.cost_s < cheaper_than:
            candidate.skipped = dearer
        else:
            candidate.skipped = ""
            fine = self._run(method, dt * FINER, against=(method, dt))
            if isinstance(fine, Off):
                candidate.measured = True
                candidate.error, candidate.excess, candidate.over = {fine.key: fine.off}, fine.excess, [str(fine)]
            elif isinstance(fine, Exception):
                candidate.failed = f"its pilot at half the step failed: {_first_line(fine)}"
            else:
                candidate.measured = True
                self._judge(candidate, run, fine)
        candidate.pilot_wall_s = self.wall - start
        return candidate

    def _judge(self, candidate: Candidate, run: Any, fine: Any) -> None:
        estimate = candidate.estimate = companion_estimate(run, fine, FINER)
        figures, headline = run.figure_values(), run.headline()
        limits = {f.key: f for f in (headline if self.limits.figures is None else self.limits.figures)}
        candidate.error = {key: magnitude(estimate[key]) for key in limits if estimate.get(key) is not None}
        candidate.over = self.limits.exceeded(estimate, figures, headline)
        if candidate.dt > self.scene.sim.dt * (1 + 1e-9):  # longer than the scene's own: its medium force kept too
            candidate.over += ErrorLimits(figures=LONGER).exceeded(estimate, figures)
        candidate.excess = max((error / limits[key].allowed(figures[key]) for key, error in candidate.error.items()
                                if figures.get(key) is not None), default=0.0)

    def price(self, method: str, dt: float, dearer_than: float = math.inf) -> float:
        """The predicted cost of a candidate (`cost`) from the first `PRICE_SHARE` of its pilot (at least
        `PILOT_STEPS` steps), where no pilot of it ran: to rank candidates before any is run whole. Its start,
        not a shortened run: a shortened ramp-in is another, harsher motion (the quadruped's newton-midpoint at 2 ms
        chatters under a 25 ms ramp, not under its own 0.5 s). A price stops once it shows the candidate costs more
        than ``dearer_than``: its cost is then a bound below, priced again further where it comes to rank first (the
        sandfish's explicit step at 4 us, priced whole at 48 s against 1 s of the implicit methods, took 1.6 s of
        its 4.9 s choice)."""
        key = (method, dt)
        if key not in self._rates or (key in self._bounds and self.cost(method, dt) < dearer_than):
            start = time.perf_counter()
            share = min(1.0, max(PRICE_SHARE * self.duration, PILOT_STEPS * dt) / self.window)
            # the CPU its timed stretch (its second half) would take at the cost of ``dearer_than``
            self.budget = (dearer_than / self.calibration(method) / (self.duration * COMPANION_COST) * share / 2
                           * self.window)
            try:
                scene = self.at(method, dt)
                self.prepare(scene)
                run, self._rates[key] = self._timed(scene, self.window, share, share / 2, sample=method in IMPLICIT,
                                                    early=method == "explicit")
            except SceneError as exc:  # as `_run`
                if not dt > self.scene.sim.dt:
                    raise
                run, self._rates[key] = exc, math.nan
            finally:
                self.budget = math.inf
            self._bounds.discard(key)
            self._priced[key] = self._rates[key]
            if isinstance(run, SimulationUnstable):
                self._partial.add(key)
            if isinstance(run, _Enough):  # stopped dearer: its rate so far
                self._bounds.add(key)
            elif run is not None:  # it failed there, or ran through: the pilot itself, the same run
                self._runs[key] = run
            self._walls[key] = time.perf_counter() - start
            self.wall += self._walls[key]
        return self.cost(method, dt)

    def _timed(self, scene: Any, span: float, share: float = 1.0, skip: float = 0.0,
               sample: bool = False, watch: Callable[[], None] | None = None,
               early: bool = False) -> tuple[Any, float]:
        """A pilot's result (or its step's failure; None where it stopped at ``share`` of its run) and its CPU time
        per simulated second, from its first recorded sample at or past ``skip`` of it on (a run's set-up, a fixed
        cost, would weigh on a short stretch) as far as it got (NaN: nowhere). CPU time, not wall time: the choice
        must not follow the load of other processes. With ``sample``, the bodies' limits (`body_limits`) are
        sampled as it goes, outside its timing, once in `LIMIT_SAMPLES` of the window; ``watch`` is called at each
        sample (`_off`). With ``early``, the budget holds before ``skip`` too, as `EARLY` times it."""
        marks: list[tuple[float, float]] = []
        first: list[tuple[float, float]] = []  # the first sample
        spent = [0.0]  # CPU time spent sampling

        def clock() -> float:
            return time.process_time() - spent[0]
        sample = sample and self.state is not None and bool(self.allowed)

        def progress(fraction: float) -> None:
            if sample:
                start = time.process_time()
                self._sample(scene, fraction * span)
                spent[0] += time.process_time() - start
            if not marks or marks[0][1] < skip:  # the first sample at or past ``skip`` opens the stretch timed
                marks[:] = [(clock(), fraction)]
            marks[1:] = [(clock(), fraction)]
            first[:] = first or marks[:1]
            if fraction >= share and share < 1:
                raise _Enough
            # a stretch timed past ``skip`` is held to the budget from its opening (a price's first half, a
            # robot's landing, would weigh on it unlike on the prices it is compared with)
            if marks[0][1] >= skip:
                over = marks[1][0] - (marks[0][0] if skip > 0 else begin) > self.budget
            else:  # before it, the explicit step: where the stretch it times would cost EARLY times the budget at
                # its pace since its first sample (the run's set-up before it, a fixed cost, is not its pace)
                ran = fraction - first[0][1]
                over = early and ran > 0 and (marks[1][0] - first[0][0]) / ran * (share - skip) > EARLY * self.budget
                if over:  # its rate: its pace since
                    marks[:] = [first[0], marks[1]]
            if over:
                raise _Enough(f"stopped at {fraction * span:.3g} s: it cost more than {self.budget:.3g} s, more "
                              f"than the cheaper candidate that met the limits")
            if watch is not None:
                watch()
        begin = clock()
        try:
            run: Any = self.pilot(scene, False, progress)
            marks[1:] = [(clock(), 1.0)]
        except SimulationUnstable as exc:  # the step's failure; any other is the scene's, at every step
            run = exc
        except _Enough as exc:
            run = exc if exc.args else None
        if not marks:
            return run, math.nan
        if marks[1][1] <= marks[0][1]:  # one sample: the whole time over the whole stretch reached
            return run, float((marks[1][0] - begin) / (marks[1][1] * span)) if marks[1][1] > 0 else math.nan
        return run, float((marks[1][0] - marks[0][0]) / ((marks[1][1] - marks[0][1]) * span))

    def predicted(self, method: str, dt: float, dearer_than: float = math.inf) -> float:
        """A candidate's predicted cost (s): from its own pilot, else from the nearest step of its method that ran,
        its cost per step scaled as a power of the step measured between the two nearest whole pilots of the method,
        over one halving at most (a Newton step costs less where it is shorter: fewer iterations; `PER_STEP`), else
        priced (`price`, no further than shows it costs more than ``dearer_than``) where it is the method's first.
        A pilot that failed counts by its price where it had one, else not at all: its own rate is its run's start
        alone (the whegs' explicit step at 0.5 ms, failed in its first 0.1 s, cost there 0.6 of its price's cost a
        step, and its run at 0.25 ms was predicted at half its cost, below newton's at 1 ms, which cost less)."""
        known = sorted((h for (m, h), rate in self._rates.items()
                        if m == method and not math.isnan(rate) and (m, h) not in self._partial),
                       key=lambda h: abs(math.log(h / dt)))
        if (method, dt) in self._rates or not known:
            return self.price(method, dt, dearer_than)
        near = known[0]
        whole = [h for h in known if (method, h) in self._whole and h != near]
        power = 0.0
        step = (self.cost(method, near) * near, self.cost(method, whole[0]) * whole[0]) if whole else (0.0, 0.0)
        if (method, near) in self._whole and min(step) > 0:  # per step, alike
            power = min(max(math.log(step[0] / step[1]) / math.log(near / whole[0]), PER_STEP[0]), PER_STEP[1])
        reach = min(max(dt / near, FINER), 1 / FINER)
        return self.cost(method, near) * near / dt * reach ** power

    def verdict(self, method: str, dt: float, aim: float, run: float, dearer_than: float = math.inf) -> float:
        """The predicted cost (s) of knowing whether ``method`` meets the limits at ``aim``, walked down from its
        ladder's ``dt``: its pilots not run yet, at each step from dt to aim and at half of aim, and, where the pilots
        are not whole runs, ``run``, the run at aim with its companion (`predicted`). A method aimed far down costs
        its walk there, not its last step's alone (the sandfish's newton, 19 % off at 2 ms, aimed at 0.125 ms: pilots
        at 0.5 ms to 62.5 us, a quarter more than its run at 0.125 ms with its companion), and a step whose pilot ran
        as the one that judged the step before it costs its pilot at half the step alone. A price is taken no
        further than shows it costs more than ``dearer_than`` (`price`)."""
        cost, step = 0.0, dt
        while step >= aim * FINER * (1 - 1e-9):
            if (method, step) not in self._runs:
                cost += self.predicted(method, step, dearer_than) / COMPANION_COST * self.window / self.duration
            step *= FINER
        return cost if self.whole else cost + run

    def _sample(self, scene: Any, t: float) -> None:
        """The bodies' limits at time ``t`` of an implicit pilot (`body_limits`), where its state is finite and no
        pilot was sampled within half a `LIMIT_SAMPLES`-th of the window (a pilot at half the step follows its own)."""
        slot = round(t * LIMIT_SAMPLES / self.window)
        state = self.state(scene) if slot not in self._slots else None
        if state is not None and all(math.isfinite(x) for x in state[1].qvel):
            self._slots.add(slot)
            self._samples.append((t, *body_limits(*state)))

    def explicit_limit(self) -> float:
        """The bodies' explicit limit over the implicit pilots so far (`window_limit`, s); inf where none ran."""
        return window_limit(self._samples, self.window)

    def screen(self, dt: float, finest: float) -> float | None:
        """The explicit ladder's next step from ``dt`` within `EXPLICIT_ROOM` of the bodies' explicit limit (None:
        none down to ``finest``); each step beyond it is a candidate skipped, not piloted."""
        found = self.explicit_limit()
        limit = EXPLICIT_ROOM * found
        while dt > limit * (1 + 1e-9):
            if not any((c.method, c.dt) == ("explicit", dt) for c in self.candidates):
                self.candidates.append(Candidate("explicit", dt, skipped=f"skipped: explicit limit "
                                                 f"{found:.3g} s < dt"))
            dt *= FINER
            if dt < finest * (1 - 1e-9):
                return None
        return dt

    def search(self, allowed: tuple[str, ...]) -> list[Candidate]:
        """The candidates of ``allowed`` methods that met the limits, cheapest first, found best first: each method's
        ladder from START x sim.dt down, the cheapest predicted candidate measured next, until none left could cost
        less than `SAVING` of the cheapest that met the limits (before either implicit method is piloted, newton
        first among equals: `NEWTON_FIRST`). A step that misses them goes down one halving; its implicit method is
        ranked by the predicted cost of a verdict at the step its error asks for (first order, aimed at SAFE of the
        limit; `verdict`), the explicit step by its next one: its error can fall much faster, as a body's stability
        margin is crossed (the quadruped's: 6.5 % off at 2 ms, 0.95 % at 1 ms; a 2 kg sled's: 79 % off at 1 ms,
        0.02 % at 0.5 ms)."""
        finest = {m: self.top * FINER ** (EXPLICIT_HALVINGS if m == "explicit" else HALVINGS) for m in allowed}
        ladder: dict[str, float | None] = {m: self.top for m in allowed}
        aim = dict(ladder)  # the step each method is ranked by
        best: Candidate | None = None
        while True:
            options = []
            # the implicit methods priced first: their pilots sample the bodies' explicit limit, and the explicit
            # step is priced at the first of its ladder within it, not at steps that will be skipped
            for m in sorted(ladder, key=lambda m: m == "explicit"):
                if m == "explicit" and ladder[m] is not None:
                    ladder[m] = self.screen(ladder[m], finest[m])
                if ladder[m] is not None:
                    target = min(aim[m], ladder[m])
                    # a price goes no further than shows its candidate dearer than another priced, or than SAVING of
                    # the cheapest that met the limits: past that it would not be measured
                    cheapest = min([o[1] for o in options] + [SAVING * best.cost_s if best else math.inf])
                    cost = self.predicted(m, target, cheapest)
                    if cost != cost:  # NaN: it failed at once, its pilot is all it costs
                        options.append((0.0, 0.0, m, ladder[m]))
                    else:
                        options.append((self.verdict(m, ladder[m], target, cost, cheapest), cost, m, ladder[m]))
            dearer = [o for o in options if best is not None and not o[1] < SAVING * best.cost_s]
            for _, cost, method, dt in dearer:
                if not any((c.method, c.dt) == (method, dt) for c in self.candidates):
                    self.candidates.append(Candidate(method, dt, cost_s=cost, skipped="not run: predicted to "
                                                     "cost more than the cheapest that met the limits"))
            options = [o for o in options if o not in dearer]
            if not options:
                break
            fresh = not any(m in IMPLICIT for m, _ in self._whole)
            _, cost, method, dt = min(options, key=lambda o: _rank(o, options, fresh))
            # once one met the limits, a pilot stops where it has cost what a cheaper candidate's pilots may
            self.budget = math.inf if best is None else SAVING * best.cost_s * (1 - 1 / COMPANION_COST)
            candidate = self.try_step(method, dt)
            self.budget = math.inf
            if candidate.passed:
                best = candidate if best is None or candidate.cost_s < best.cost_s else best
                ladder[method] = None  # its finer steps cost more
                if self.whole:  # its run and its companion are made: any other would cost more
                    break
                continue
            need = 1
            if method != "explicit" and candidate.measured and SAFE < candidate.excess < math.inf:
                need = max(1, math.ceil(math.log2(candidate.excess / SAFE)))
            # an aim past the finest step still walks the ladder, ranked as the finest: from a coarse step the error
            # can fall much faster than first order (the sand-swimmer's newton-midpoint: estimated 44 % off at 2 ms,
            # 6 % at 0.5 ms)
            aim[method] = max(dt * FINER ** need, finest[method])
            finer = dt * FINER
            ladder[method] = finer if finer >= finest[method] * (1 - 1e-9) else None
        return sorted((c for c in self.candidates if c.passed and c.method in allowed), key=lambda c: c.cost_s)

    def coarsen(self, chosen: Candidate) -> Candidate:
        """The chosen candidate at twice its step, while its estimate is below `COARSEN` of its limit and the
        step at most `COARSEST` x sim.dt: the coarsest that meets the limits (its pilot at half the step is the
        one that ran)."""
        while chosen.excess < COARSEN and 2 * chosen.dt <= COARSEST * self.scene.sim.dt * (1 + 1e-9):
            # its pilot should cost half the chosen's run: one that struggles (Newton's halvings, a step that chatters
            # before its probe says so) stops at the whole of it
            self.budget = chosen.cost_s / COMPANION_COST
            coarser = self.try_step(chosen.method, 2 * chosen.dt, 1.25 * chosen.cost_s)
            self.budget = math.inf
            if not (coarser.passed and coarser.cost_s < chosen.cost_s):
                break
            chosen = coarser
        return chosen


def _rank(option: tuple[float, float, str, float], options: list[tuple[float, float, str, float]],
          fresh: bool) -> float:
    """An option's rank in `Chooser.search` (its verdict's predicted cost, its cost, its method, its step): its
    verdict's cost, newton-midpoint's times `NEWTON_FIRST` where newton is an option at the same step and neither
    implicit method has run a pilot through (``fresh``)."""
    verdict, _, method, dt = option
    tied = fresh and method == "newton-midpoint" and any((o[2], o[3]) == ("newton", dt) for o in options)
    return verdict * NEWTON_FIRST if tied else verdict


class _Enough(Exception):
    """Stops a pilot that prices a candidate (`Chooser.price`) once it has run far enough, or, with a message, one
    that costs more than it may (`Chooser.budget`)."""


class Off(_Enough):
    """Stops a pilot at half a candidate's step once it shows the candidate off by far (`Chooser._off`): the figure's
    key, its estimated error so far and that error over its limit."""

    def __init__(self, message: str, key: str, off: float, excess: float) -> None:
        super().__init__(message)
        self.key, self.off, self.excess = key, off, excess


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def choose(scene: Any, limits: ErrorLimits | None, pilot: Pilot, prepare: Callable[[Any], Any], duration: float,
           stroke_time: float, strokes: int, state: State | None = None) -> tuple[list[Candidate], Chooser]:
    """The candidates that met the limits, cheapest first, the cheapest at the longest step that still does
    (`Chooser.coarsen`), or the closest to them where none did; and the chooser that measured them
    (`Chooser.search`: the explicit step and, on MuJoCo's implicitfast integrator, the implicit methods)."""
    chooser = Chooser(scene, limits or ErrorLimits(), pilot, prepare, duration, stroke_time, strokes, state)
    passed = chooser.search(("explicit", *chooser.allowed))
    if passed and not chooser.whole:  # whole pilots: the run is made, a coarser one would be another
        coarser = chooser.coarsen(passed[0])
        passed = [coarser, *(c for c in passed if c is not coarser)]
    elif not passed:  # the closest: the smallest excess, then the finest step
        passed = [min(chooser.candidates, key=lambda c: (c.excess, c.dt))]
    return passed, chooser


def reason(chosen: Candidate, chooser: Chooser, fell_back: list[str]) -> str:
    """Why this candidate, in words: what it was predicted to cost, the cheapest other that met the limits, and why
    the cheaper ones did not."""
    if not chosen.passed:
        why = "no candidate's pilot met the limits: the closest"
    else:
        why = f"the cheapest that met the limits, predicted {chosen.cost_s:.3g} s"
    others = sorted((c for c in chooser.candidates if c is not chosen and c.passed), key=lambda c: c.cost_s)
    if others:
        why += f", against {others[0].method} at {others[0].dt:g} s, {others[0].cost_s:.3g} s"
    cheaper = [c for c in chooser.candidates if not c.passed and (c.failed or c.measured)
               and not c.cost_s >= chosen.cost_s and not c.failed.startswith("run whole")]  # those: `fell_back`
    if cheaper:
        c = max(cheaper, key=lambda c: c.dt)
        why += f"; {c.method} at {c.dt:g} s: {c.why_not[:120]}"
    if fell_back:
        why += "; " + "; ".join(fell_back)
    return why


def run_auto(scene: Any, limits: ErrorLimits | None, pilot: Pilot, prepare: Callable[[Any], Any],
             full: Callable[[Any], Any], duration: float, stroke_time: float, strokes: int,
             state: State | None = None) -> Any:
    """Choose (`choose`), then run the choice at the whole length with ``full(scene)`` (its companion estimate
    included); where its estimate refuses it or it goes unstable, the search goes on past it: the next candidate that
    met the limits, or a finer step of its method where that is predicted cheaper, the implicit methods alone past
    an explicit step (a pilot over the window can pass where the whole run chatters: the whegs' ``newton`` at 2 ms,
    chattering in 40 % of its probes over its 0.75 s window and in over half of them in its first second). A failure
    of the scene's own, a drive that cannot hold its profile, is raised as it comes. The result carries
    ``method_choice``, and the pilots' and the refused runs' wall time in its ``wall_s``."""
    passed, chooser = choose(scene, limits, pilot, prepare, duration, stroke_time, strokes, state)
    fell_back: list[str] = []
    while True:
        chosen, *passed = passed
        start = time.perf_counter()
        try:
            return _chosen(full, scene, chosen, chooser, fell_back)
        except (InaccurateResult, SimulationUnstable) as exc:
            chooser.refused_wall += time.perf_counter() - start
            why = ("its estimate exceeded the limits" if isinstance(exc, InaccurateResult)
                   else _first_line(exc).split(" (")[0])
            chosen.failed = f"run whole, it was refused: {why}"
            fell_back.append(f"{chosen.method} at {chosen.dt:g} s, run whole, was refused: {why}")
            # The search goes on past the refused one: its method's finer steps, where cheaper than the next passed;
            # past an explicit step, the implicit methods only: its chatter began too late in the window for the
            # probe, which stops a run after half a second of it, and would at every finer step a pilot can afford
            # (the sand-swimmer's explicit step, from 1.26-1.46 s on at 1 to 0.25 ms, in its 1.5 s window; it needs
            # about 10 us)
            passed = chooser.search(chooser.allowed if chosen.method == "explicit" else ("explicit", *chooser.allowed))
            if not passed:
                raise


def _chosen(full: Callable[[Any], Any], scene: Any, chosen: Candidate, chooser: Chooser,
            fell_back: list[str]) -> Any:
    result = chooser.reused(chosen)
    if result is None:
        result = full(scene.replace(**{"sim.method": chosen.method, "sim.dt": chosen.dt}))
        result.wall_s += chooser.wall
    result.wall_s += chooser.refused_wall
    result.method_choice = MethodChoice(chosen.method, chosen.dt, reason(chosen, chooser, fell_back),
                                        chooser.candidates, chooser.window, chooser.wall, chooser.refused_wall)
    return result
