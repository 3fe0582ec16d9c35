"""Every run estimates its own discretisation error, and a result whose error exceeds a limit is never returned.

The estimate repeats the whole run at another resolution, a companion run, and compares the two at the same
instants. The companion normally takes steps COARSER = 5 times longer (the adaptive method: a tolerance 25 times
looser and a largest step 5 times longer, as its steps grow with the square root of the tolerance) and records a
quarter of the run's instants, which with its own model costs about a quarter of the run (`finrft bench`). Every
method converges at least at first order in the step over a run with stroke reversals (the drive's velocity jumps
there), so by Richardson's argument the run's own error is about |run - companion| / (5 - 1), reported
times a safety factor SAFETY = 2 (where the error falls slower than the step, Richardson underestimates it); for
a method of higher order this overestimates. Where the coarse companion would
resolve a stroke in fewer than MIN_STROKE_STEPS steps, cannot run (it goes unstable, or its Newton solve fails),
or gives an estimate above the limit, a fine companion takes steps half as long instead and the error is
SAFETY |run - companion| / (1 - 1/2): a coarse companion can be outside the range where the error falls with the step
(an explicit feedback that needs the run's step), and only the fine one refuses a run. An adaptive run whose coarse
estimate is within a limit but above CONFIRM of it is compared with the fine companion as well, and reports the
larger of the two estimates: its error can fall much slower than its largest step. An experiment whose figures
are estimated one by one (a robot's means, `Result.figure_values`) takes the fine companion alone: on the three
example robots the coarse one put their estimates at 0.1 to 95 times the error measured at 1/8 of the step, the
fine one at 1.5 to 5.3 times (docs/guide/methods.md).

A result reports ``error_estimate``: the largest estimated error of each quantity it reports, named with its
unit (``angle_deg``; ``force_N`` or ``torque_Nm``, the per-stroke mean drive load, and ``peak_force_N`` or
``peak_torque_Nm``, its peak, at least the run's own `resolution` of it; ``eta_points``, ``body_mm``;
``position_mm`` and ``velocity_mm_s``, a user's model's bodies and centre of mass, and ``position_percent``, the
same positions as a share of the run's scale), and each figure a robot's or a wheel's summary reports under its
own key (`FIGURES`: its summary against the companion's). `ErrorLimits` bounds the angles, eta, that share and
the figures it names (`FigureLimit`: relative to the figure's magnitude or in its unit), by default the
experiment's headline figures; the loads and the absolute positions are reported, not bounded, as their scale is
the scene's.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol, TypeVar

import numpy as np

from . import methods
# The run's failures, importable from here as before (their home is finrft.errors).
from .errors import InaccurateResult, SceneError, SimulationFailed, SimulationUnstable
from .drive import real
from .scene import ExplicitSim

COARSER = 5
FINER = 0.5
MIN_STROKE_STEPS = 8
COMPARE_EVERY = 4
# Richardson's estimate holds once the error falls as the step's first power; at stroke reversals, stops and
# stiff arms it can fall slower or not at all (the paper robot's adaptive steps near theta = 90 deg: 0.80 -> 0.97
# points of eta when the largest step halves). The estimate is multiplied by a safety factor, as Roache's grid
# convergence index does for a two-grid study.
SAFETY = 2.0
# The adaptive method's error can fall much slower than its largest step where a stop engages or the arm sweeps
# near 90 deg: a coarse companion's estimate of 0.46 points of eta passed the 0.5 limit where the run was 0.54 off
# the converged eta (theta 90/-90, a 60 mm arm, rigid fin). An adaptive run whose coarse estimate exceeds CONFIRM
# of a limit is compared with the fine companion too, and reports the larger of the two estimates.
CONFIRM = 0.25


# The figures a run's summary reports and estimates (`Result.figure_values`), each under its own key in
# ``error_estimate``, in its unit: the robot's (`user_model.robot_summary`) and the wheel's (`wheel.wheel_summary`).
FIGURES = ("com_velocity_m_s", "com_speed_m_s", "com_position_m", "medium_force_N", "body_medium_force_N", "drive_load",
           "actuator_power_W", "positive_power_W", "cost_of_transport", "Fx_N", "Fy_N", "Fz_N", "sinkage_mm",
           "axle_torque_Nm", "sensors")
# The share of a run's scale its positions may be off where neither the limits nor the experiment name figures.
POSITION_PERCENT = 5.0


@dataclass(frozen=True)
class FigureLimit:
    """The largest estimated error of one reported figure: ``value`` percent of the figure's magnitude (the norm of
    all its components) where ``relative``, else ``value`` in the figure's unit; never below ``floor`` (the
    figure's unit), which keeps a figure near 0 (a robot that hardly moves) from asking for no error at all."""

    key: str
    value: float
    relative: bool = True
    floor: float = 0.0

    def __post_init__(self) -> None:
        if self.key not in FIGURES:
            raise SceneError(f"max_error: no reported figure is named {self.key!r} (the figures: "
                             f"{', '.join(FIGURES)}; and angle_deg, eta_points, position_percent)")
        value = real(f"max_error {self.key}", self.value, "%" if self.relative else "the figure's unit")
        if not value > 0:
            raise SceneError(f"max_error {self.key} must be > 0, got {value!r}")
        object.__setattr__(self, "value", value)

    def allowed(self, figure: Any) -> float:
        """The largest error accepted on a figure of this value."""
        return max(self.value * magnitude(figure) / 100 if self.relative else self.value, self.floor)

    def __str__(self) -> str:
        return f"{self.key}={self.value:g}{'%' if self.relative else ''}"


# A robot's headline figures, bounded where the limits name none (`ErrorLimits.figures`): its mean horizontal
# speed and its cost of transport, each to 2 % (what a lab compares gaits by), the speed never below 0.1 mm/s (a
# robot that does not move, `user_model.STILL_SPEED`). The estimate is 1-5 times the actual error, so the figures
# are then within 0.4-2 % of the converged run. The speed, not the velocity: the example hexapod's heading turns
# with the step (its velocity 2.9 % off at 1 ms) while its speed is 0.18 % off.
ROBOT_HEADLINE = (FigureLimit("com_speed_m_s", 2.0, floor=1e-4), FigureLimit("cost_of_transport", 2.0))


def magnitude(figure: Any) -> float:
    """The norm of a figure's components (a number, a list, or a dict of them; None: 0)."""
    return float(np.linalg.norm(components(figure))) if figure is not None else 0.0


def components(figure: Any) -> np.ndarray:
    """A figure's numbers, flattened in order (a dict by its keys' order)."""
    if isinstance(figure, dict):
        return np.concatenate([components(v) for v in figure.values()]) if figure else np.zeros(0)
    return np.ravel(np.asarray(figure, dtype=float))


def figure_difference(a: Any, b: Any) -> Any:
    """|a - b| component by component, in the figures' own shape; where only one of them is defined (a cost of
    transport where the other run does not move), the defined one's size: the estimate cannot be smaller."""
    if a is None or b is None:
        return None if a is None else abs(magnitude(a))
    return figure_map(lambda x, y: abs(x - y), a, b)


def figure_map(function: Callable[..., float], *figures: Any) -> Any:
    """``function`` applied to the matching numbers of figures of one shape."""
    first = figures[0]
    if first is None:
        return None
    if isinstance(first, dict):
        return {key: figure_map(function, *(f[key] for f in figures)) for key in first}
    if isinstance(first, (list, tuple)):
        return [figure_map(function, *items) for items in zip(*figures)]
    return float(function(*figures))


@dataclass(frozen=True)
class ErrorLimits:
    """The largest estimated discretisation error a result may carry."""

    angle_deg: float = 0.5      # any reported angle (segment, hinge)
    eta_points: float = 0.5     # the swimming efficiency, percentage points
    # A user's model (finrft run): its attached bodies' origins and its centre of mass, in percent of the run's
    # scale, max(the farthest any of them gets from where it started, the model's size: the diagonal of its
    # attached geoms' bounding spheres' box at t = 0). An absolute limit cannot serve every robot: 0.5 mm made a
    # wheel rolling 200 mm step at 50 us, and lets a hexapod walking 2 m at 1 ms no error at all. 5 %: the estimate
    # (SAFETY times Richardson's, from a companion half or five times the step) overstates a robot's error 2-4
    # times: the example swimmer at 1 ms is estimated at 2.4 % and its mean speed is 1.1 % from a run at 1/8 of the
    # step (`finrft bench robots` measures each example's); 5 % keeps the true error near the 2 % robots need.
    # None: POSITION_PERCENT where the experiment bounds no headline figures (the wheel), else unbounded (a robot:
    # its figures are what it reports, and its positions' estimate refused a hexapod whose speed was 0.18 % off).
    position_percent: float | None = None
    # The reported figures bounded (`FigureLimit`); None: the experiment's headline figures (`ROBOT_HEADLINE`). A
    # figure a run does not report (a cost of transport where the robot does not move) bounds nothing.
    figures: tuple[FigureLimit, ...] | None = None

    def __post_init__(self) -> None:
        units = {"angle_deg": "degrees", "eta_points": "points", "position_percent": "percent"}
        for name, unit in units.items():
            if name == "position_percent" and self.position_percent is None:
                continue
            value = real(f"max_error {name}", getattr(self, name), unit)
            if not value > 0:
                raise SceneError(f"max_error {name} must be > 0 {unit}, got {value!r}")
            object.__setattr__(self, name, value)
        if self.figures is not None:
            if not all(isinstance(f, FigureLimit) for f in self.figures):
                raise SceneError(f"max_error figures must be finrft.convergence.FigureLimit entries, got "
                                 f"{self.figures!r:.60}")
            object.__setattr__(self, "figures", tuple(self.figures))

    @classmethod
    def uniform(cls, value: float) -> ErrorLimits:
        """The same number for every bounded quantity: degrees for angles, points for eta, percent of the run's
        scale for a user's model's positions (the experiment's headline figures keep their own limits)."""
        return cls(angle_deg=value, eta_points=value, position_percent=value)

    def scaled(self, factor: float) -> ErrorLimits:
        """Every limit times ``factor``."""
        return ErrorLimits(angle_deg=factor * self.angle_deg, eta_points=factor * self.eta_points,
                           position_percent=None if self.position_percent is None
                           else factor * self.position_percent,
                           figures=None if self.figures is None else tuple(
                               dataclasses.replace(f, value=factor * f.value, floor=factor * f.floor)
                               for f in self.figures))

    def exceeded(self, estimate: dict[str, Any], figures: dict[str, Any] | None = None,
                 headline: tuple[FigureLimit, ...] = ()) -> list[str]:
        """The bounded quantities of an estimate that exceed their limit, as 'name = value > limit': the angles,
        eta and positions, and the reported ``figures`` (key -> the run's value) the limits name, or else the
        experiment's ``headline`` ones."""
        position = self.position_percent
        if position is None and not headline:
            position = POSITION_PERCENT
        limits = {"angle_deg": self.angle_deg, "eta_points": self.eta_points, "position_percent": position}
        over = [f"{key} = {estimate[key]:.3g} > {limit:g}" for key, limit in limits.items()
                if limit is not None and key in estimate and not estimate[key] <= limit]
        for f in (headline if self.figures is None else self.figures):
            value = (figures or {}).get(f.key)
            if value is None or estimate.get(f.key) is None:
                continue
            error, allowed = magnitude(estimate[f.key]), f.allowed(value)
            if not error <= allowed:
                share = f" ({100 * error / magnitude(value):.3g} %)" if magnitude(value) > 0 else ""
                over.append(f"{f.key} = {error:.3g}{share} > {allowed:.3g} ({f})")
        return over


@dataclass(kw_only=True)
class Estimated:
    """The error estimate a result carries, filled by `checked`."""

    error_estimate: dict[str, float] | None = None  # quantity (its unit in the name) -> estimate; None: not made
    error_companion: str = ""                       # the companion run the estimate came from
    error_wall_s: float = 0.0                       # the companion run's wall time


class Checked(Protocol):
    """What a result offers the check: its scene, its shortest stroke, and its differences from a companion."""

    scene: Any
    error_estimate: dict[str, float] | None
    error_companion: str
    error_wall_s: float

    @property
    def stroke_time(self) -> float: ...

    def differences(self, other: Any) -> dict[str, Any]: ...

    def resolution(self) -> dict[str, float]: ...

    def figure_values(self) -> dict[str, Any]: ...

    @property
    def coarse_companion(self) -> bool: ...

    def headline(self) -> tuple[FigureLimit, ...]: ...


R = TypeVar("R", bound=Checked)
M = TypeVar("M")


def _companion(scene: Any, ratio: float, record_interval: float) -> tuple[Any, str]:
    """The scene at ``ratio`` times the step (the adaptive method: ratio^2 times the tolerance, ratio times the
    largest step), recording at the run's own instants."""
    sim = scene.sim
    if methods.get(sim.method).adaptive:
        updates = {"sim.tolerance": sim.tolerance * ratio ** 2, "sim.max_step": sim.max_step * ratio}
        label = f"tolerance {sim.tolerance * ratio ** 2:g}, largest step {sim.max_step * ratio:g} s"
    else:
        updates = {"sim.dt": sim.dt * ratio}
        label = f"dt {sim.dt * ratio:g} s"
    # Not scene.replace, nor dataclasses.replace of the scene, which validate: a tolerance above the users' limit is
    # the coarse companion's purpose.
    companion = copy.copy(scene)
    object.__setattr__(companion, "sim", dataclasses.replace(scene.sim, **{k.split(".")[1]: v
                                                                           for k, v in updates.items()},
                                                             record_dt=record_interval))
    return companion, label


def check_limits(limits: Any, optional: bool = True) -> None:
    """SceneError unless ``limits`` is an `ErrorLimits` (or, where ``optional``, None: the estimate reported only)."""
    if not isinstance(limits, ErrorLimits) and not (optional and limits is None):
        raise SceneError(f"max_error must be a finrft.convergence.ErrorLimits (ErrorLimits.uniform(x): one number "
                         f"for all, as --max-error x){' or None' if optional else ''}, got {type(limits).__name__} "
                         f"{limits!r:.40}")


def record_every(dt: float, record_dt: float) -> int:
    """Steps between recorded samples: ``record_dt`` rounded to whole steps."""
    return max(1, round(record_dt / dt))


def companion_estimate(run: Checked, other: Checked, ratio: float) -> dict[str, Any]:
    """The error estimate of ``run`` from a companion at ``ratio`` times its step: Richardson's, SAFETY |run -
    companion| / |ratio - 1| for each difference, never below what the run knows of its own resolution."""
    estimate = {key: figure_map(lambda v: SAFETY * v / abs(ratio - 1), value)
                for key, value in run.differences(other).items()}
    for key, floor in run.resolution().items():
        estimate[key] = max(estimate.get(key, 0.0), floor)
    return estimate


def checked(build: Callable[[Any], M], run_once: Callable[[Any, M, Callable[[float], None] | None, bool], R],
            scene: Any, progress: Callable[[float], None] | None = None,
            limits: ErrorLimits | None = ErrorLimits(), estimate: bool = True) -> R:
    """``run_once(scene, build(scene), progress, companion)`` with ``error_estimate`` filled from a companion run;
    InaccurateResult when it exceeds ``limits`` (None: report only); ``estimate=False``: the run alone.

    A companion (``companion`` True) records the state only, at instants the run records too, and takes no chatter
    probe: its comparison with the run is the check. A model depends on the numerics only through the step, so
    the adaptive method's companion (another tolerance on the same step) reuses the run's. A coarse companion can
    leave the range where the error falls with the step (an explicit feedback that needs the run's step, a stroke
    barely resolved): an estimate above the limit is confirmed by the fine companion before the run is refused."""
    check_limits(limits)
    models: dict[float, M] = {}

    def once(scene: Any, progress: Callable[[float], None] | None, companion: bool) -> R:
        if scene.sim.dt not in models:
            models[scene.sim.dt] = build(scene)
        return run_once(scene, models[scene.sim.dt], progress, companion)

    if not estimate:
        return once(scene, progress, False)
    sim = scene.sim
    run = once(scene, None if progress is None else lambda f: progress(0.8 * f), False)
    start = time.perf_counter()
    every = record_every(sim.dt, sim.record_dt)
    tail = None if progress is None else lambda f: progress(0.8 + 0.2 * f)
    # A companion records every COMPARE_EVERY-th instant the run records (the adaptive one keeps the time grid, a
    # coarse one samples where both grids meet): its samples are much of its cost, and they bound its steps.
    adaptive = methods.get(sim.method).adaptive
    coarse = COMPARE_EVERY * (every if adaptive else math.lcm(every, COARSER)) * sim.dt
    ratios = [(FINER, COMPARE_EVERY * every * sim.dt)]
    if run.coarse_companion and (adaptive or run.stroke_time >= MIN_STROKE_STEPS * COARSER * sim.dt):
        ratios.insert(0, (COARSER, coarse))
    kept: tuple[dict[str, float], str] | None = None  # a coarse estimate near its limit, which the fine one checks
    for n, (ratio, interval) in enumerate(ratios, start=1):
        companion, label = _companion(scene, ratio, interval)
        try:
            other = once(companion, tail, True)
        except (SimulationFailed, SceneError):
            if n < len(ratios):
                continue
            raise
        estimate = companion_estimate(run, other, ratio)
        if kept is not None:
            estimate = {key: value if kept[0].get(key) is None else figure_map(max, value, kept[0][key])
                        for key, value in estimate.items()}
            label = f"{kept[1]} and {label}"
        run.error_estimate, run.error_companion = estimate, label
        figures, headline = run.figure_values(), run.headline()
        over = [] if limits is None else limits.exceeded(estimate, figures, headline)
        if n == len(ratios):
            break
        # without limits (report only), the default ones say which estimate needs confirming: it is reported alike
        if not over and adaptive and (limits or ErrorLimits()).scaled(CONFIRM).exceeded(estimate, figures, headline):
            kept = (estimate, label)
            continue
        if not over:
            break
    run.error_wall_s = time.perf_counter() - start
    if over:
        raise InaccurateResult(f"the estimated discretisation error is too large ({', '.join(over)}; from a "
                               f"companion run at {label}): {advice(scene)}, or raise the limit ({raising(over)})")
    return run


def raising(over: list[str]) -> str:
    """How --max-error raises the limits ``over`` names ('name = value > limit', `ErrorLimits.exceeded`): a reported
    figure's only by its name, which a bare number does not bound."""
    names = dict.fromkeys(item.split(" = ")[0] for item in over)
    forms = " ".join(f"--max-error {name}=X%" if name in FIGURES else f"--max-error {name}=X" for name in names)
    return (f"{forms}; a bare --max-error X bounds angles, eta and positions only, a reported figure NAME=X% in "
            f"percent of it or NAME=X in its unit")


def paired(time: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the samples two runs share (the same instant within 1 ns), and always their last samples: both
    end where the drive ends, whatever whole steps their grids round it to."""
    j = np.clip(np.searchsorted(other, time), 0, len(other) - 1)
    j = np.where(np.abs(other[j - 1] - time) < np.abs(other[j] - time), j - 1, j)
    same = np.abs(other[j] - time) < 1e-9
    same[-1] = True
    return np.flatnonzero(same), np.r_[j[same][:-1], len(other) - 1]


def advice(scene: Any) -> str:
    """What to change for a finer result."""
    sim = scene.sim
    method = methods.get(sim.method)
    if method.adaptive:
        return f"tighten sim.tolerance (now {sim.tolerance:g}) or sim.max_step (now {sim.max_step:g} s)"
    if method.newton or isinstance(sim, ExplicitSim):  # an ExplicitSim scene has no other method
        return f"reduce sim.dt (now {sim.dt:g} s)"
    return f"reduce sim.dt (now {sim.dt:g} s) or use sim.method = 'newton'"


def max_difference(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| over arrays of the same shape (0 for empty ones); inf where exactly one is not finite."""
    if a.size == 0:
        return 0.0
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))))


def require_finite(values: dict[str, Any], what: str) -> None:
    """SimulationUnstable naming the first entry of a result that is NaN or infinite."""
    for key, value in values.items():
        if isinstance(value, dict):
            require_finite(value, what)
            continue
        array = np.asarray(value)
        if array.dtype.kind in "fc" and not np.all(np.isfinite(array)):
            raise SimulationUnstable(f"{what}: {key} is not finite")


# What one run may ask for: MuJoCo counts steps in a C int, and every recorded sample holds the state and forces.
MAX_STEPS = 10**9
MAX_SAMPLES = 200_000


def check_size(steps: int, samples: int, dt: float, duration: float) -> None:
    """SceneError when a run would take more steps or record more samples than one run may."""
    if steps > MAX_STEPS:
        raise SceneError(f"the run would take {steps:.3g} steps ({duration:.4g} s at sim.dt = {dt:g} s), more than "
                         f"{MAX_STEPS:.0e}: check the speed and distance units (mm/s, mm), or raise sim.dt")
    if samples > MAX_SAMPLES:
        raise SceneError(f"the run would record {samples:.3g} samples, more than {MAX_SAMPLES}: raise "
                         f"sim.record_dt (now every {duration / samples:.3g} s), or check the speed and distance")


def check_resolution(stroke_time: float, dt: float, what: str = "stroke") -> int:
    """The whole steps a stroke takes; SceneError when dt cannot resolve it: fewer than MIN_STROKE_STEPS steps
    (a step longer than the stroke among them), or rounding the stroke to whole steps would change its length by
    more than 1 %."""
    if dt > stroke_time / MIN_STROKE_STEPS:
        longer = "is longer than" if dt > stroke_time else f"leaves fewer than {MIN_STROKE_STEPS} steps in"
        raise SceneError(f"sim.dt = {dt:g} s {longer} a {what} of {stroke_time:.4g} s: use sim.dt <= "
                         f"{stroke_time / MIN_STROKE_STEPS:.3g} s")
    steps = round(stroke_time / dt)
    if abs(steps * dt - stroke_time) > 0.01 * stroke_time:
        raise SceneError(f"sim.dt = {dt:g} s does not resolve a {what} of {stroke_time:.4g} s: in {steps} whole "
                         f"steps it would run {100 * (steps * dt / stroke_time - 1):+.1f} % of its length; use "
                         f"sim.dt <= {stroke_time / 50:.3g} s")
    return steps
