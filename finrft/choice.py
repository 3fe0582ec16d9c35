"""``sim.method = "auto"`` (`methods.AUTO`, a robot's default): the run chooses the method and the step that meet
its error limits (`convergence.ErrorLimits`: ``--max-error``, by default the experiment's headline figures) at the
least cost, and says what it chose and why (`MethodChoice`, ``method_choice`` in a result's summary).

No method wins everywhere: the implicit steps win on light links, whose explicit step must stay below about
2 m v_reg / F (the example sand-swimmer's 10 g links chatter down to 6.6 µs), and MuJoCo's explicit step wins
2.5-5 times on heavy, slow robots, as an implicit step costs about ten explicit ones. Which one a robot is shows
in its first moments, so the choice is measured, not predicted: pilot runs over the run's first `window` (past
the controls' ramp-in, a tenth of the rest or a sine's period, whole strokes), each candidate at its step and at
half of it, their reported figures compared as the run's companion compares them
(`convergence.companion_estimate`):

- ``newton-midpoint`` at sim.dt runs once, which prices the implicit step;
- ``explicit`` from sim.dt down, halving while it chatters, goes unstable or misses the limits, for as long as its
  cost, predicted from its cost per step so far, stays below that price;
- the implicit methods where they could cost less than the explicit step that met the limits:
  ``newton-midpoint`` (second order for a robot's quasi-static motion) and ``newton`` (where its step costs
  visibly less) at sim.dt; where neither meets the limits, the closer one at the step its error asks for, at most
  `HALVINGS` halvings down (and the explicit ladder goes on below that step's cost).

The cheapest candidate whose pilot met the limits runs, with its companion estimate as every run has; should that
estimate refuse it (a pilot's window is not the whole run), the next one runs. The pilots' wall time counts in
the result's ``wall_s`` (``method_choice.pilot_wall_s``). An explicit candidate whose chatter comes and goes
(`stepping.Chattering`) and leaves its figures within their limits is chosen, and its run reports the chatter.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from .convergence import FINER, ErrorLimits, companion_estimate, magnitude
from .errors import InaccurateResult, SimulationUnstable

# The pilots' window (`window`): the controls' ramp-in and this share of the rest of the run (or a sine's
# period), at least PILOT_STEPS steps of sim.dt.
PILOT_SHARE = 0.1
PILOT_STEPS = 16
IMPLICIT = ("newton-midpoint", "newton")
HALVINGS = 3             # the implicit methods at sim.dt down to sim.dt / 8
EXPLICIT_HALVINGS = 8    # the explicit step from sim.dt down to sim.dt / 256, while it is the cheaper
# The share of its limit an implicit step's estimate is aimed at, where the one at sim.dt exceeds it.
SAFE = 0.8
# newton is tried beside newton-midpoint where its step costs less than this share of newton-midpoint's: where it
# does not, newton-midpoint (the more accurate on a robot in sand) is not worth a second pilot.
NEWTON_SAVING = 0.85
# A run's cost against its pilot's: the run itself and its companion at half the step (`convergence.checked`).
COMPANION_COST = 1 + 1 / FINER


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
    """What ``sim.method = "auto"`` chose, why, and the candidates it weighed (`Candidate`)."""

    method: str
    dt: float
    reason: str
    candidates: list[Candidate]
    window_s: float
    pilot_wall_s: float

    def line(self) -> str:
        """The choice in one line of text."""
        return (f"method auto: {self.method} at dt {self.dt:g} s ({self.reason}; {len(self.candidates)} candidates, "
                f"pilots over the first {self.window_s:.3g} s took {self.pilot_wall_s:.2f} s)")

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "dt": self.dt, "reason": self.reason, "window_s": self.window_s,
                "pilot_wall_s": self.pilot_wall_s, "candidates": [c.to_json() for c in self.candidates]}


def window(scene: Any, duration: float, stroke_time: float, strokes: int) -> tuple[float, float]:
    """The pilots' run and the start of the window their figures average over (s): past the controls' longest
    ramp-in (a run's start is a transient unlike its gait), one period of the slowest sine control or drive (the
    sand-swimmer's explicit step chatters from 1.46 s on, a second after its ramp, and its speed is then 2-4 %
    off at 0.25 ms, where its first 0.65 s were within 0.4 %), and at least `PILOT_SHARE` of the rest and
    `PILOT_STEPS` steps of sim.dt; whole strokes where the run has several."""
    ramp = max((c.ramp for c in getattr(scene, "control", ())), default=0.0)
    sines = [c.frequency for c in getattr(scene, "control", ()) if c.kind == "sine"]
    sines += [j.frequency for j in getattr(scene, "drive", ()) if j.profile == "sine"]
    span = ramp + max(PILOT_SHARE * (duration - ramp), PILOT_STEPS * scene.sim.dt, 1 / min(sines, default=math.inf))
    if strokes > 1:
        span = math.ceil(span / stroke_time - 1e-9) * stroke_time
    span = min(span, duration)
    return span, min(ramp, scene.sim.settle, span / 2)


Pilot = Callable[[Any, bool, Callable[[float], None]], Any]


class Chooser:
    """The pilots of one run: ``pilot(scene, companion, progress)`` runs a scene without an estimate (a companion
    records the state only) on the model ``prepare(scene)`` built, each candidate's figures judged by ``limits``;
    its cost is measured in CPU seconds (`cost`)."""

    def __init__(self, scene: Any, limits: ErrorLimits, pilot: Pilot, prepare: Callable[[Any], Any],
                 duration: float, stroke_time: float, strokes: int) -> None:
        self.scene, self.limits, self.pilot, self.prepare = scene, limits, pilot, prepare
        self.duration = duration
        self.window, self.settle = window(scene, duration, stroke_time, strokes)
        # A run of one stroke is cut short by shortening its stroke (the same motion up to the window's end); one
        # of several keeps its whole strokes (`window`).
        cut = self.window / stroke_time if strokes == 1 else 1.0
        self.strokes = {f"drive.{i}.stroke": j.stroke * cut for i, j in enumerate(getattr(scene, "drive", ()))
                        if j.profile == "constant" and j.stroke > 0 and cut < 1}
        self.candidates: list[Candidate] = []
        # the implicit methods extend MuJoCo's implicitfast integrator; with another, the explicit step alone
        self.allowed = IMPLICIT if scene.sim.integrator == "implicitfast" else ()
        self.wall = 0.0
        self.found: Candidate | None = None  # the explicit step that met the limits, once found
        self._runs: dict[tuple[str, float], Any] = {}    # each pilot that ran (or its failure), for reuse
        self._rates: dict[tuple[str, float], float] = {}  # its CPU time per simulated second, as far as it got

    def at(self, method: str, dt: float) -> Any:
        """The scene of a candidate's pilot."""
        return self.scene.replace(**{"sim.method": method, "sim.dt": dt, "sim.duration": self.window,
                                     "sim.settle": self.settle, **self.strokes})

    def _run(self, method: str, dt: float, companion: bool) -> Any:
        key = (method, dt)
        if key not in self._runs:
            reached = [0.0]
            start = time.perf_counter()
            scene = self.at(method, dt)
            self.prepare(scene)  # the model's build, outside the cost of a step
            # CPU time, not wall time: the choice must not follow the load of other processes on the machine
            cpu = time.process_time()
            try:
                self._runs[key] = self.pilot(scene, companion, lambda f: reached.__setitem__(0, f))
                reached[0] = 1.0
            except SimulationUnstable as exc:  # the step's failure; any other is the scene's, at every step
                self._runs[key] = exc
            cpu = time.process_time() - cpu
            self.wall += time.perf_counter() - start
            self._rates[key] = cpu / (reached[0] * self.window) if reached[0] > 0 else math.nan
        return self._runs[key]

    def cost(self, method: str, dt: float) -> float:
        """The predicted time of the whole run with its companion (CPU s, the wall time of an idle machine), from the
        pilot at dt (NaN: none got far)."""
        return self._rates.get((method, dt), math.nan) * self.duration * COMPANION_COST

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
        run = self._run(method, dt, False)
        candidate.cost_s = self.cost(method, dt)
        if isinstance(run, Exception):
            candidate.failed = _first_line(run)
        elif not candidate.cost_s < cheaper_than:
            candidate.skipped = dearer
        else:
            candidate.skipped = ""
            fine = self._run(method, dt * FINER, True)
            if isinstance(fine, Exception):
                candidate.failed = f"its pilot at half the step failed: {_first_line(fine)}"
            else:
                candidate.measured = True
                self._judge(candidate, run, fine)
        candidate.pilot_wall_s = self.wall - start
        return candidate

    def _judge(self, candidate: Candidate, run: Any, fine: Any) -> None:
        estimate = companion_estimate(run, fine, FINER)
        figures, headline = run.figure_values(), run.headline()
        limits = {f.key: f for f in (headline if self.limits.figures is None else self.limits.figures)}
        candidate.error = {key: magnitude(estimate[key]) for key in limits if estimate.get(key) is not None}
        candidate.over = self.limits.exceeded(estimate, figures, headline)
        candidate.excess = max((error / limits[key].allowed(figures[key]) for key, error in candidate.error.items()
                                if figures.get(key) is not None), default=0.0)

    def implicit(self, allowed: tuple[str, ...], bound: float) -> Candidate | None:
        """The cheapest implicit candidate that meets the limits and costs less than ``bound`` (s; None: none did),
        from sim.dt down: each method at sim.dt, then the more accurate one at the step its error asks for (first
        order: the step times the limit over the estimate, at most `HALVINGS` halvings in all)."""
        dt = self.scene.sim.dt
        tried = [self.try_step(allowed[0], dt, bound)]
        for method in allowed[1:]:
            saving = NEWTON_SAVING * tried[0].cost_s if tried[0].cost_s > 0 else math.inf
            tried.append(self.try_step(method, dt, min(bound, saving), f"its step costs more than "
                                       f"{NEWTON_SAVING:.0%} of {tried[0].method}'s, or than the explicit one"))
        halvings = 0
        while True:
            passed = [c for c in tried if c.passed]
            if passed:
                return min(passed, key=lambda c: c.cost_s)
            best = min(tried, key=lambda c: c.excess)
            need = math.ceil(math.log2(best.excess / SAFE)) if math.isfinite(best.excess) else 1
            if halvings + max(1, need) > HALVINGS:
                return None
            halvings += max(1, need)
            finer = best.cost_s / FINER ** halvings
            if finer >= bound:  # dearer than the explicit step that met the limits
                return None
            if self.found is None and finer > 0:  # the explicit ladder, below what the finer step will cost
                self.found = self.explicit(finer)
                if self.found is not None:
                    return None
            tried = [self.try_step(best.method, self.scene.sim.dt * FINER ** halvings, bound)]

    def explicit(self, bound: float) -> Candidate | None:
        """The explicit step from sim.dt down, while its predicted cost (from the cost of a step so far) stays below
        ``bound`` (s): the first that meets the limits, or None."""
        dt, per_step = self.scene.sim.dt, math.nan  # the whole run's predicted cost times its step
        for _ in range(EXPLICIT_HALVINGS + 1):
            if per_step / dt >= bound:
                known = [c for c in self.candidates if (c.method, c.dt) == ("explicit", dt)]
                if not known:
                    self.candidates.append(Candidate("explicit", dt, cost_s=per_step / dt, skipped="not run: "
                                                     "predicted from its cost per step to cost more than the "
                                                     "implicit one"))
                return None
            candidate = self.try_step("explicit", dt, bound)
            if candidate.passed:
                return candidate
            for step in (dt, dt * FINER):  # the finest pilot that got anywhere
                if not math.isnan(self.cost("explicit", step)):
                    per_step = self.cost("explicit", step) * step
            dt *= FINER
        return None


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def choose(scene: Any, limits: ErrorLimits | None, pilot: Pilot, prepare: Callable[[Any], Any], duration: float,
           stroke_time: float, strokes: int) -> tuple[list[Candidate], Chooser]:
    """The candidates that met the limits, cheapest first (the closest to them where none did), and the chooser that
    measured them. The implicit step's cost at sim.dt bounds the explicit ladder, which runs first: where the
    explicit step meets the limits for less, the implicit ones are measured only where they could cost less
    still; where the implicit step needs a finer step than sim.dt, the explicit ladder goes on below its cost."""
    chooser = Chooser(scene, limits or ErrorLimits(), pilot, prepare, duration, stroke_time, strokes)
    allowed = chooser.allowed
    bound = math.inf
    if allowed:
        first = chooser.try_step(allowed[0], scene.sim.dt, 0.0, "measured after the explicit step")
        bound = first.cost_s if first.cost_s > 0 else math.inf  # NaN (it failed at once): no bound
    chooser.found = chooser.explicit(bound)
    implicit = chooser.implicit(allowed, math.inf if chooser.found is None else chooser.found.cost_s) \
        if allowed else None
    explicit = chooser.found
    if explicit is None and allowed:
        costs = [c.cost_s for c in chooser.candidates if c.method != "explicit" and c.cost_s > 0]
        # below the implicit step that met the limits, or, where none did, twice the dearest one tried
        again = implicit.cost_s if implicit is not None else 2 * max(costs, default=math.inf)
        if again > bound:
            explicit = chooser.explicit(again)
    passed = sorted((c for c in (implicit, explicit) if c is not None), key=lambda c: c.cost_s)
    if not passed:  # the closest: the smallest excess, then the finest step
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
             full: Callable[[Any], Any], duration: float, stroke_time: float, strokes: int) -> Any:
    """Choose (`choose`), then run the choice at the whole length with ``full(scene)`` (its companion estimate
    included); where its estimate refuses it or it goes unstable, the next candidate that met the limits, or, after
    the explicit step, the implicit one measured then (a failure of the scene's own, a drive that cannot hold its
    profile, is raised as it comes). The result carries ``method_choice``, and the pilots' wall time in its
    ``wall_s``."""
    passed, chooser = choose(scene, limits, pilot, prepare, duration, stroke_time, strokes)
    fell_back: list[str] = []
    while True:
        chosen, *passed = passed
        try:
            return _chosen(full, scene, chosen, chooser, fell_back)
        except (InaccurateResult, SimulationUnstable) as exc:
            why = ("its estimate exceeded the limits" if isinstance(exc, InaccurateResult)
                   else _first_line(exc).split(" (")[0])
            chosen.failed = f"run whole, it was refused: {why}"
            fell_back.append(f"{chosen.method} at {chosen.dt:g} s, run whole, was refused: {why}")
            if not passed and chosen.method == "explicit" and chooser.allowed:
                implicit = chooser.implicit(chooser.allowed, math.inf)
                passed = [] if implicit is None else [implicit]
            if not passed:
                raise


def _chosen(full: Callable[[Any], Any], scene: Any, chosen: Candidate, chooser: Chooser,
            fell_back: list[str]) -> Any:
    result = full(scene.replace(**{"sim.method": chosen.method, "sim.dt": chosen.dt}))
    result.method_choice = MethodChoice(chosen.method, chosen.dt, reason(chosen, chooser, fell_back),
                                        chooser.candidates, chooser.window, chooser.wall)
    result.wall_s += chooser.wall
    return result
