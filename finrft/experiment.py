"""One protocol for every experiment, and one way to run it.

An experiment (in the spirit of dm_control's tasks) builds its model from a scene, prescribes its drive (the
strokes, and what happens as each starts), names the series it records with their SI units, says which of them
the error check compares, and summarises a result. `run` does the rest for any experiment: the stepping
(`stepping.step_through`), the finite checks, the discretisation-error estimate (`convergence.checked`), and a `Result` that
holds the named series; `record.write_h5` and `record.write_rrd` write any result. The plate tests
(`simulate.PlateTest`) and the robot's swim (`swim.Swim`) are two experiments.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Protocol

import mujoco
import numpy as np

from . import geometry, interrupts, laws, methods, native
from .choice import run_auto
from .convergence import (ErrorLimits, Estimated, FigureLimit, checked, figure_difference, max_difference, paired,
                          require_finite)
from .callbacks import controlled, installed
from .coupling import PythonCoupling
from .drive import Drive
from .errors import SceneError
from .integrate import stepper
from .scene import Sections
from .stepping import chatter_speeds, instants, schedule, step_through


@dataclass(frozen=True)
class Plot:
    """How a series is shown in a rerun recording: under ``entity`` (a series of several columns: one entity
    ``entity/{part}{i + 1}`` per column, labelled ``{label} {i + 1}``, or by ``names`` where they are given), in ``unit`` ("deg", "mm" or SI as is),
    in a time-series view named ``title``."""

    entity: str
    title: str
    label: str
    unit: str = ""
    part: str = ""
    names: tuple[str, ...] = ()  # the columns' own names (the model's): ``entity/{name}``, labelled ``{label} {name}``


# SI to the units the recordings show.
DISPLAY: dict[str, Callable[[np.ndarray], np.ndarray]] = {"deg": np.degrees, "mm": lambda x: 1e3 * x}


@dataclass(frozen=True)
class Quantity:
    """A recorded series: its SI unit, what it is, and what it is indexed by ("sample": one value per recorded
    instant; "stroke", "cycle", ...: one per stroke or cycle)."""

    unit: str
    description: str
    per: str = "sample"
    plot: Plot | None = None
    attrs: dict[str, str] = field(default_factory=dict)  # further HDF5 attributes of the dataset


@dataclass(frozen=True)
class Compared:
    """A quantity the error check compares with a companion run: the largest difference of the named series
    (at the instants both runs record, for per-sample series; whole, for per-stroke ones) times ``scale``,
    reported as ``key`` (its unit in the name)."""

    key: str
    series: tuple[str, ...]
    scale: float = 1.0


class Trial(Protocol):
    """One run of an experiment on one MjData: what it reads at each recorded instant, what it does as a stroke
    starts, the dofs watched for chatter, and the series it makes of its readings when the run ends."""

    reads: dict[str, Callable[[mujoco.MjData], Any]]  # readings at every recorded instant (after mj_forward)
    watch: list[int]                                  # dofs the chatter probe watches
    # Optional: ``control(m, d)``, MuJoCo's control callback for the run (ctrl and qfrc_applied at every step);
    # ``peak``, an `integrate.LoadPeak` the stepper takes the drive's load into at every step (a peak from every
    # step, not the recorded samples); ``after_step(d)``, called after every step (means over every step);
    # ``forward(m, d)``, the forward pass before each reading (default mj_forward).

    def on_stroke(self, k: int) -> None: ...

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                  dict[str, float]]: ...


class Experiment(Protocol):
    """What an experiment defines; everything else (stepping, checks, estimate, files) is generic."""

    name: str               # what the experiment is, in messages: "drag", "swim", ...
    schema: str             # the HDF5 schema name
    sign_convention: str    # the files' statement of directions and signs

    def build(self, scene: Any) -> Any:
        """The compiled model: an object with ``model`` (MjModel), ``backend`` and ``groups`` (force groups; a model
        whose forces are not segment groups offers ``python_forces()``, its Python backend's callback)."""

    def drive_for(self, scene: Any) -> Drive:
        """The schedule: strokes, their length and the duration."""

    def start(self, scene: Any, built: Any, d: mujoco.MjData, companion: bool) -> Trial:
        """Put ``d`` in the initial state and return the run's trial (a companion reads the state only)."""

    def quantities(self, scene: Any) -> dict[str, Quantity]:
        """Every series a result holds, in file order."""

    def compared(self, scene: Any) -> tuple[Compared, ...]:
        """What the error check compares."""

    def check(self, result: Result) -> None:
        """Raise SimulationFailed when the run gives no result (eta undefined, say); before the finite check,
        which a quantity undefined by design (NaN) would fail with a less helpful message."""

    def cycle_table(self, result: Result) -> list[dict[str, float]]:
        """Figures per cycle ([] for an experiment without cycles)."""

    def summary(self, result: Result) -> dict[str, Any]:
        """The experiment's own figures; `Result.summary` adds the run's."""

    def attrs(self) -> dict[str, Any]:
        """Further HDF5 root attributes (the drive, the cycles)."""

    def draw(self, rec: Any, result: Result, times: Any, prefix: str) -> list[Any]:
        """Log the experiment's 3D view to a rerun recording and return its blueprint views."""


@dataclass
class Result(Estimated):
    """The results of one run of any experiment, SI units: the named series (``result.series``, also as
    attributes: ``run.segment_angle``), the experiment's scalars (``result.values``: ``run.peak_drive_force``)
    and its parameters (``run.drive``, ``run.cycles``), with the run's cost and error estimate."""

    experiment: Any
    scene: Any
    time: np.ndarray                 # (T,) s
    series: dict[str, np.ndarray]
    values: dict[str, float]
    steps: int                       # steps taken (the adaptive method's accepted steps)
    wall_s: float                    # the run's own, with sim.method = "auto" its pilots' too (not the companion's)
    backend: str = "python"
    steps_rejected: int = 0          # the adaptive method's rejected steps, and newton's halved ones
    chattering: Any = None           # what the chatter probe saw of chatter that came and went (`Chattering`)
    method_choice: Any = None        # what sim.method = "auto" chose and why (`choice.MethodChoice`); None: not auto

    def __getattr__(self, name: str) -> Any:
        # Only for names that are not fields; the guard keeps unpickling (no fields yet) from recursing.
        if name.startswith("_") or name in ("series", "values", "experiment"):
            raise AttributeError(name)
        for source in (self.series, self.values):
            if name in source:
                return source[name]
        if hasattr(self.experiment, name):
            return getattr(self.experiment, name)
        raise AttributeError(f"{type(self.experiment).__name__} result has no {name!r}")

    @property
    def quantities(self) -> dict[str, Quantity]:
        return self.experiment.quantities(self.scene)

    @property
    def stroke_time(self) -> float:
        return self.experiment.drive_for(self.scene).stroke_time

    def differences(self, other: Result) -> dict[str, Any]:
        """Largest differences from a run of the same experiment at another resolution (`Compared`), and the
        differences of its reported figures (`figure_values`)."""
        i, j = paired(self.time, other.time)
        quantities = self.quantities
        out = {}
        for c in self.experiment.compared(self.scene):
            out[c.key] = float(c.scale * max(
                max_difference(self.series[s][i], other.series[s][j]) if quantities[s].per == "sample"
                else max_difference(self.series[s], other.series[s]) for s in c.series))
        # An experiment may add differences relative to its own scale (a robot's travel or size).
        relative = getattr(self.experiment, "relative_differences", None)
        if relative is not None:
            out.update(relative(self, out))
        # and each figure its summary reports, summary against summary, in the figure's unit and shape
        theirs = other.figure_values()
        out.update({key: figure_difference(value, theirs.get(key)) for key, value in self.figure_values().items()
                    if value is not None or theirs.get(key) is not None})
        return out

    def figure_values(self) -> dict[str, Any]:
        """The figures of the summary the error estimate covers one by one (the experiment's ``figures(scene)``,
        keys of `convergence.FIGURES`), by key."""
        # Once per result: the error check takes them for each companion's differences and for the limits.
        if "_figure_values" not in self.__dict__:
            figures = getattr(self.experiment, "figures", None)
            summary = {} if figures is None else self.experiment.summary(self)
            self.__dict__["_figure_values"] = {key: summary[key] for key in (figures(self.scene) if figures else ())
                                               if key in summary}
        return self.__dict__["_figure_values"]

    @property
    def coarse_companion(self) -> bool:
        """Whether the error estimate may come from a companion at longer steps (`convergence.checked`): not for an
        experiment that says so (``coarse_companion = False``: a robot, whose means a coarse step can miss either
        way)."""
        return bool(getattr(self.experiment, "coarse_companion", True))

    def headline(self) -> tuple[FigureLimit, ...]:
        """The figures bounded by default (`ErrorLimits.figures` None): the experiment's ``headline``, if any."""
        return tuple(getattr(self.experiment, "headline", ()))

    def resolution(self) -> dict[str, float]:
        """Errors the run knows without a companion (the experiment's ``resolution(result)``, if it has one)."""
        own = getattr(self.experiment, "resolution", None)
        return {} if own is None else own(self)

    def cycle_table(self) -> list[dict[str, float]]:
        return self.experiment.cycle_table(self)

    def summary(self) -> dict[str, Any]:
        """The figures ``finrft ... --json`` prints, as plain Python numbers."""
        out = self.experiment.summary(self)
        out.update(steps=int(self.steps), steps_rejected=int(self.steps_rejected), sim_time_s=float(self.time[-1]),
                   wall_s=float(self.wall_s), backend=self.backend, integrator=self.scene.sim.integrator,
                   dt=float(self.scene.sim.dt))
        if self.error_estimate is not None:
            out.update(error_estimate=dict(self.error_estimate), error_companion=self.error_companion)
        if self.method_choice is not None:
            out["method_choice"] = self.method_choice.to_json()
        return out


def run(experiment: Experiment, scene: Any, *, progress: Callable[[float], None] | None = None,
        max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Result:
    """Run an experiment on a scene, with an estimate of its discretisation error (``result.error_estimate``,
    from a companion run: see finrft.convergence). Raises SimulationUnstable rather than return a diverged run,
    and InaccurateResult when the estimate exceeds ``max_error`` (None: report it only). ``estimate_error=False``
    skips the estimate, for studies that measure the error themselves. A scene whose law can feed energy in (the
    paper's model) runs, with a warning once per process (`laws.FeedsEnergy`)."""
    if not callable(getattr(experiment, "build", None)) or not callable(getattr(experiment, "drive_for", None)):
        raise SceneError(f"run: the experiment must be a finrft.Experiment (PlateTest, Swim, UserModel, Intrusion, "
                         f"Wheel), got {type(experiment).__name__} {experiment!r:.60}")
    expected = getattr(experiment, "scene_type", Sections)
    if not isinstance(scene, expected):
        raise SceneError(f"{experiment.name}: the scene must be a finrft.{expected.__name__} (from finrft.preset or "
                         f"finrft.load_scene), got {type(scene).__name__} {scene!r:.60}")
    if progress is not None and not callable(progress):
        raise SceneError(f"run: progress must be a callable progress(fraction) or None, got {type(progress).__name__} "
                         f"{progress!r:.60}")
    if not isinstance(estimate_error, (bool, np.bool_)):
        raise SceneError(f"run: estimate_error must be True or False, got {type(estimate_error).__name__} "
                         f"{estimate_error!r:.60}")
    # A record_dt given longer than the run would record its start and end alone (the default on a short run does,
    # and passes: the user gave none)
    duration = experiment.drive_for(scene).duration
    given = scene.sim.record_dt != next(f.default_factory() for f in fields(scene) if f.name == "sim").record_dt
    if given and scene.sim.record_dt > duration:
        raise SceneError(f"sim.record_dt = {scene.sim.record_dt:g} s is longer than the run ({duration:.4g} s): set "
                         f"sim.record_dt <= {duration:.4g} s (s, not ms?)")
    laws.warn_if_feeds_energy(geometry.segment_law(scene))
    # A companion on the run's model (the adaptive methods') steps the run's MjData again, reset: a new one costs
    # a tenth of a physical gait's companion (the bindings' wrappers).
    datas: dict[int, mujoco.MjData] = {}

    def once(s: Any, built: Any, p: Callable[[float], None] | None, companion: bool) -> Result:
        d = datas.get(id(built.model))
        if d is None:
            d = datas[id(built.model)] = mujoco.MjData(built.model)
        else:
            mujoco.mj_resetData(built.model, d)
        return _once(experiment, s, built, d, p, companion)
    # The model depends on the numerics only through the step (`convergence.checked`): sim.method = "auto"'s pilots
    # and the run share their models, and one at another step is the first one at that step where the built model
    # can say so (its ``at_step``; None: built again).
    models: dict[float, Any] = {}

    def build(s: Any) -> Any:
        if s.sim.dt not in models:
            first = next(iter(models.values()), None)
            again = getattr(first, "at_step", lambda dt: None)(s.sim.dt)
            models[s.sim.dt] = again if again is not None else experiment.build(s)
        return models[s.sim.dt]
    # A signal is raised between the run's steps (`interrupts.check` in step_through), never inside MuJoCo's calls.
    with interrupts.deferred():
        if methods.chooses(scene.sim.method):
            drive = experiment.drive_for(scene)
            return run_auto(scene, max_error, lambda s, companion, p: once(s, build(s), p, companion), build,
                            lambda s: checked(build, once, s, progress, max_error, estimate_error),
                            drive.duration, drive.stroke_time, drive.strokes, lambda s: _left(build(s), datas))
        return checked(build, once, scene, progress, max_error, estimate_error)


def _left(built: Any, datas: dict[int, mujoco.MjData]) -> tuple | None:
    """The state the last run on a built model left (`choice.explicit_limit`'s arguments), None before any."""
    d = datas.get(id(built.model))
    return None if d is None else (built.model, d, built.groups, getattr(built, "attached", None))


def python_forces(built: Any) -> Callable[[mujoco.MjModel, mujoco.MjData], None]:
    """The Python backend's passive-force callback of a built model: its own (``built.python_forces()``, a model
    with `attach`ed surfaces), or the coupling of its segment force groups."""
    own = getattr(built, "python_forces", None)
    return own() if own is not None else PythonCoupling(built.groups)


def _once(experiment: Experiment, scene: Any, built: Any, d: mujoco.MjData, progress: Callable[[float], None] | None,
          companion: bool) -> Result:
    """One run of an experiment on a built model, from the state of ``d``, an MjData of it new or reset."""
    start = time.perf_counter()
    m = built.model
    dt = scene.sim.dt
    drive = experiment.drive_for(scene)
    steps, starts, samples = schedule(drive, dt, scene.sim.record_dt)
    trial = experiment.start(scene, built, d, companion)
    readings: dict[str, np.ndarray] = {}

    def on_sample(i: int) -> None:
        for name, read in trial.reads.items():
            value = read(d)
            if name not in readings:
                readings[name] = np.zeros((len(samples), *np.shape(value)))
            readings[name][i] = value

    attached = getattr(built, "attached", None)
    advance = stepper(m, scene.sim, built.backend, built.groups, attached, getattr(trial, "peak", None))
    watch = [] if companion else trial.watch
    speeds = chatter_speeds(m, d, built.groups, attached, watch)
    after_step = getattr(trial, "after_step", None)
    with installed(m, python_forces(built) if built.backend == "python" else None), native.untimed(), \
            controlled(m, getattr(trial, "control", None)):
        seen = step_through(m, d, scene, advance, steps, starts, samples, trial.on_stroke, on_sample, progress,
                            watch, forward=None if companion else getattr(trial, "forward", mujoco.mj_forward),
                            stroke_time=drive.stroke_time, speeds=speeds,
                            on_step=None if after_step is None else lambda: after_step(d))
    series, values = trial.finish(d, readings)
    result = Result(experiment=experiment, scene=scene,
                    time=instants(samples, steps, starts, scene.sim, drive.stroke_time), series=series, values=values,
                    steps=advance.taken, wall_s=time.perf_counter() - start, backend=built.backend,
                    steps_rejected=advance.rejected, chattering=seen)
    experiment.check(result)
    require_finite(series, f"{experiment.name} at dt {dt:g} s")
    return result
