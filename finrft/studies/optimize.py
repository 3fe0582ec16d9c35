"""Gait and design optimisation of the robot with CMA-ES (pycma).

The search runs over any robot scene keys, each between bounds, in coordinates normalised to [0, 1] (positive
quantities whose bounds span more than a decade are searched in log space). The objective is the paper's:
minimise 1 - eta over one flap cycle; a gait that cannot be simulated, or whose power stroke barely moves the
body forward, scores 2.

After each generation the HDF5 log (`finrft.searchlog`) holds every evaluation and the optimiser's state as plain
numbers. A run resumes by replaying the logged generations through a new optimiser of the same seed, which gives
back pycma's whole state; the replay must reproduce every logged point and state exactly, so a resumed run is the
uninterrupted one bit for bit. Same seed, same result: the objective is deterministic and the optimiser's private
random generator is the only randomness.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import time
import warnings
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .. import batch, design, files
from . import bounds, searchlog
from ..convergence import ErrorLimits, SimulationFailed, check_limits
from ..files import provenance, read_toml
from ..experiments.swim import RobotScene
from ..errors import UsageError
from ..scene import SceneError, UserScene, field_of, key_unit, key_value, scene_from_dict, to_toml
from ..experiments.swim import swim

FAILED = 2.0
# numpy's legacy generator, which pycma's sampling follows, takes seeds below 2**32.
MAX_SEED = 2**32 - 1
# More evaluations than any search runs (days of them at a million a day); a log's counts stay in int64.
MAX_BUDGET = 10**9
# eta = (D1 - D2) / D1 grows without bound as D1 -> 0: a power stroke that moves the body forward by less than
# this scores as a failed gait, so the search cannot chase a vanishing denominator.
MIN_FORWARD_MM = 1.0


@dataclass(frozen=True)
class Variable:
    """One searched scene key, between bounds in the key's SI unit."""

    key: str
    low: float
    high: float

    @property
    def log(self) -> bool:
        return self.low > 0 and self.high / self.low > 10

    def to_unit(self, value: float) -> float:
        if self.log:
            return math.log(value / self.low) / math.log(self.high / self.low)
        return (value - self.low) / (self.high - self.low)

    def from_unit(self, u: float) -> float:
        if self.log:
            return self.low * (self.high / self.low) ** u
        return self.low + u * (self.high - self.low)


# The paper's search: theta1 in [0, 90] deg, theta2 in [-90, 0] deg, arm length in [60, 85] mm.
DEFAULT_VARIABLES = (Variable("gait.theta1", 0.0, math.pi / 2), Variable("gait.theta2", -math.pi / 2, 0.0),
                     Variable("arm.length", 0.060, 0.085))
# The paper's start, (50 deg, -50 deg, 75 mm).
PAPER_START = {"gait.theta1": math.radians(50), "gait.theta2": math.radians(-50), "arm.length": 0.075}


def check_variables(scene: Any, variables: Sequence[Variable], cls: type = RobotScene) -> None:
    """``scene`` must be a ``cls``; ``variables`` Variables, of numeric scene keys, each once, with bounds ordered
    and inside the schema's limits."""
    if not isinstance(scene, cls):
        raise SceneError(f"the scene must be a finrft.{cls.__name__} (from finrft.preset or finrft.load_scene), got "
                         f"{type(scene).__name__} {scene!r:.60}")
    if isinstance(variables, (str, Variable)) or not all(isinstance(v, Variable) for v in variables):
        raise SceneError(f"the searched variables must be a list of finrft.Variable, got {variables!r:.60}")
    if not variables:
        raise SceneError("at least one variable must be searched")
    seen = set()
    for v in variables:
        # a design key is a number of the model's (finrft.design): its element and index are checked as it is read
        f = None if cls is UserScene and design.is_key(v.key) else field_of(cls, v.key)
        if f is not None and f.type not in ("float", float):
            raise SceneError(f"{v.key} is not a real-valued key (a whole number or a choice) and cannot be searched")
        if v.key in seen:
            raise SceneError(f"{v.key} is listed twice")
        seen.add(v.key)
        if not all(isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)
                   for x in (v.low, v.high)):
            raise SceneError(f"bounds of {v.key} must be numbers, got {v.low!r} and {v.high!r}")
        if not (math.isfinite(v.low) and math.isfinite(v.high)) or v.low >= v.high:
            raise SceneError(f"bounds of {v.key}: lower ({v.low:g}) must be below upper ({v.high:g})")
        scene.replace(**{v.key: v.low})
        scene.replace(**{v.key: v.high})


def evaluation_scene(scene: RobotScene) -> RobotScene:
    """The scene a gait evaluation runs: the body recorded at the drive's reversals only. Eta needs nothing else,
    and every sample in between would cut an adaptive step to land on it (a third of an evaluation's steps)."""
    g = scene.gait
    return scene.replace(**{"sim.record_dt": (g.theta1 - g.theta2) / g.omega})


def evaluate(scene: RobotScene, max_error: ErrorLimits = ErrorLimits()) -> dict[str, float]:
    """One gait evaluation: gait.cycles flap cycles from rest, eta and the distances (steady: finrft.swim.steady)
    and the estimate of eta's discretisation error (points); failures, including an estimate above ``max_error``,
    are marked, not raised: an optimiser must not climb a discretisation error."""
    try:
        run = swim(evaluation_scene(scene), scene.gait.cycles, max_error=max_error)
    except (SimulationFailed, SceneError) as exc:
        return {"eta": float("nan"), "D1_mm": float("nan"), "D2_mm": float("nan"), "eta_error_points": float("nan"),
                "error": str(exc)}
    summary = run.summary()
    return {"eta": summary["eta_steady"], "D1_mm": summary["D1_mm_steady"], "D2_mm": summary["D2_mm_steady"],
            "eta_error_points": run.error_estimate["eta_points"], "error": ""}


def _evaluate_job(job: tuple[RobotScene, ErrorLimits]) -> dict[str, float]:
    return evaluate(*job)


@dataclass
class Search:
    """The outcome of a CMA-ES search."""

    variables: tuple[Variable, ...]
    best: dict[str, float]         # scene key -> value (SI)
    cost: float
    evaluations: int
    generations: int
    wall_s: float
    stop: dict[str, Any]
    best_cost_per_generation: list[float]
    seed: int
    budget: int


# evaluate(values (population x variables, SI)) -> (costs, extra per-evaluation columns to log)
Evaluate = Callable[[np.ndarray], tuple[list[float], dict[str, np.ndarray]]]

def _state_series(n: int) -> dict[str, searchlog.Series]:
    """The optimiser's state after each generation, logged to check a rebuilt optimiser against."""
    S = searchlog.Series
    return {"mean": S("1", "distribution mean in pycma's coordinates (before its transform onto the bounds)", (n,)),
            "sigma": S("1", "step size"),
            "C": S("1", "covariance matrix", (n, n)),
            "countiter": S("1", "generations told", dtype="i8"),
            "countevals": S("1", "evaluations told", dtype="i8"),
            "rng_key": S("1", "MT19937 key of the sampling generator (numpy RandomState.get_state)", (624,), "u4"),
            "rng_pos": S("1", "position in the MT19937 key", dtype="i8"),
            "rng_has_gauss": S("1", "1 when a normal deviate is cached", dtype="i8"),
            "rng_cached_gaussian": S("1", "the cached normal deviate")}


def _row_series(variables: Sequence[Variable], units: str, cost_units: str,
                columns: dict[str, tuple[str, int, str]]) -> dict[str, searchlog.Series]:
    """Every evaluation: its generation, the asked point, its cost and the caller's columns."""
    S, n = searchlog.Series, len(variables)
    return {"generation": S("1", "generation of each evaluation", dtype="i8"),
            "unit": S("1", "asked point, each variable normalised to [0, 1] between its bounds (in log space when "
                      "they span more than a decade)", (n,)),
            "x": S(units, "asked point, one column per variable (root attribute variables)", (n,)),
            "cost": S(cost_units, "objective"),
            **{name: S(unit, text, (width,) if width else ()) for name, (unit, width, text) in columns.items()}}


def _options(dimension: int, budget: int, rng: np.random.RandomState) -> dict[str, Any]:
    # pycma samples from numpy's global generator when given a seed: anything else drawing from it would change
    # the search, and its state is not the optimiser's to save. A private generator of the same seed draws the
    # same samples.
    options = {"bounds": [0.0, 1.0], "maxfevals": budget, "seed": math.nan, "randn": rng.randn, "verbose": -9,
               "verb_log": 0, "verb_disp": 0}
    if dimension == 1:
        # pycma 4.5 fails in one dimension when it caps the step size to the bound range
        options["maxstd_boundrange"] = math.inf
    return options


def _values(variables: Sequence[Variable], unit: np.ndarray) -> np.ndarray:
    """Points in normalised coordinates (population x variables) as the variables' values."""
    return np.array([[v.from_unit(float(u)) for v, u in zip(variables, x)] for x in unit])


# A log's root attributes a search reads, and what each must be.
_ATTRIBUTES = {"seed": ("a whole number from 1 to 2**32 - 1", lambda v: isinstance(v, int) and 1 <= v <= MAX_SEED),
               "budget": (f"a whole number from 1 to {MAX_BUDGET}", lambda v: isinstance(v, int)
                          and 1 <= v <= MAX_BUDGET),
               "sigma0": ("a positive number", lambda v: isinstance(v, float) and 0 < v < math.inf),
               "variables": ("a list of scene keys", lambda v: isinstance(v, list) and v
                             and all(isinstance(k, str) for k in v)),
               "cma_version": ("a version", lambda v: isinstance(v, str)),
               "scene_toml": ("a scene (TOML)", lambda v: isinstance(v, str))}


def _check_attributes(path: str | Path, attrs: dict[str, Any]) -> None:
    """SceneError naming the first attribute a search reads that a log lacks or holds damaged."""
    for name, (what, ok) in _ATTRIBUTES.items():
        if name not in attrs or isinstance(attrs[name], bool) or not ok(attrs[name]):
            raise SceneError(f"{path}: its attribute {name} is {'missing' if name not in attrs else 'damaged'} "
                             f"(it must be {what})")


def _state(es: Any, rng: np.random.RandomState) -> dict[str, np.ndarray]:
    _, key, pos, has_gauss, cached = rng.get_state()
    return {"mean": np.array(es.mean, dtype=float), "sigma": np.float64(es.sigma), "C": np.array(es.sm.C),
            "countiter": np.int64(es.countiter), "countevals": np.int64(es.countevals), "rng_key": key,
            "rng_pos": np.int64(pos), "rng_has_gauss": np.int64(has_gauss),
            "rng_cached_gaussian": np.float64(cached)}


def si_units(cls: type, variables: Sequence[Variable]) -> list[str]:
    """The SI unit of each variable's scene key ("1" when dimensionless)."""
    return [key_unit(cls, v.key) or "1" for v in variables]


def cmaes(evaluate: Evaluate, variables: Sequence[Variable], *, budget: int | None = None, seed: int | None = None,
          start: dict[str, float] | None = None, log: str | Path | None = None, resume: bool = False,
          replace: bool = False,
          schema: str = searchlog.OPTIMIZE, units: Sequence[str] | None = None, problem: dict[str, Any] | None = None,
          tables: dict[str, searchlog.Dataset] | None = None,
          columns: dict[str, tuple[str, int, str]] | None = None,
          on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None = None) -> Search:
    """Minimise a population cost over ``variables`` with CMA-ES (normalised to [0, 1], sigma0 = 0.25, from
    ``start`` where it lies within the bounds, else the middle of the bounds).

    ``log`` (HDF5, schema ``schema``), a new file (an existing one only with ``replace``), owned by this run
    (`finrft.files.locked`: another run on it refuses), is rewritten after each generation with every evaluation, its ``columns``
    (name -> (unit, width (0 for one value), description)) and the optimiser's state, next to the variables (SI
    ``units``), ``problem`` (root attributes: the scene, the objective and its units) and ``tables`` (datasets:
    what was fitted). ``resume`` continues it: the problem must be the logged one, the seed is the log's (None, or the
    same), ``budget`` is the new total (None: the log's; CMA-ES finishes the generation that reaches it, so a log may
    hold more evaluations than its budget). Without a log, budget and seed default to 300 and 1. The seed is a whole
    number from 1 to 2**32 - 1 (numpy's and pycma's generators take no other)."""
    check_seed(seed)
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, np.integer))
                               or not 1 <= budget <= MAX_BUDGET):
        raise SceneError(f"the budget must be a whole number of evaluations from 1 to {MAX_BUDGET}, got {budget!r}")
    with (files.locked(log, "search log") if log is not None else contextlib.nullcontext()):
        return _cmaes(evaluate, variables, budget, seed, start, log, resume, replace, schema, units, problem, tables,
                      columns, on_generation)


def check_seed(seed: Any) -> None:
    """SceneError unless ``seed`` is None or a whole number from 1 to MAX_SEED."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or not 1 <= seed <= MAX_SEED):
        raise SceneError(f"the seed must be a whole number from 1 to {MAX_SEED} (2**32 - 1), got {seed!r}")


def _cmaes(evaluate: Evaluate, variables: Sequence[Variable], budget: int | None, seed: int | None,
           start: dict[str, float] | None, log: str | Path | None, resume: bool, replace: bool, schema: str,
           units: Sequence[str] | None, problem: dict[str, Any] | None, tables: dict[str, searchlog.Dataset] | None,
           columns: dict[str, tuple[str, int, str]] | None,
           on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None) -> Search:
    """`cmaes` in a run that owns its log."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*matplotlib.*")
        import cma
    variables = tuple(variables)
    n = len(variables)
    path = Path(log) if log is not None else None
    unit_text = ", ".join(units or ["SI"] * n)
    rows = _row_series(variables, unit_text, (problem or {}).get("objective_units", "1"), columns or {})
    states = _state_series(n)
    fixed = {"bounds": searchlog.Dataset(np.array([[v.low, v.high] for v in variables]), unit_text,
                                         "lower and upper bound of each variable (one row each)"),
             **(tables or {})}
    start_time = time.perf_counter()
    if resume:
        if path is None:
            raise SceneError("resuming needs the log to resume from")
        attrs, x0 = _load(path, schema, variables, problem or {}, fixed, rows, states, seed)
        budget = attrs["budget"] if budget is None else budget
        attrs["budget"] = budget
    else:
        if path is not None and os.path.lexists(path) and not replace:
            raise UsageError(f"search log {path} exists: continue it (--resume, resume=True), or replace it "
                             f"(--force, replace=True)")
        budget = 300 if budget is None else budget
        seed = 1 if seed is None else seed
        # a start outside its variable's bounds (the paper's, under narrower --bounds) gives way to their middle
        x0 = np.array([v.to_unit(x) if v.low <= (x := (start or {}).get(v.key, v.from_unit(0.5))) <= v.high else 0.5
                       for v in variables])
        attrs = {"schema": schema, **provenance(), "cma_version": cma.__version__, "seed": seed,
                 "budget": budget, "sigma0": 0.25, "variables": [v.key for v in variables], **(problem or {})}
    if budget < 1:
        raise SceneError(f"the budget must be at least 1 evaluation, got {budget}")
    rng = np.random.RandomState(attrs["seed"])
    es = cma.CMAEvolutionStrategy(list(x0), attrs["sigma0"], _options(n, budget, rng))
    generations = len(states["sigma"].blocks)
    _replay(es, rng, variables, rows, states, f"{path}: ", attrs["cma_version"])

    def write() -> None:
        if path is not None:
            searchlog.write(path, attrs, {**fixed, "x0": searchlog.Dataset(x0, "1", "start point, normalised"),
                                          **{k: s.dataset() for k, s in rows.items()},
                                          **{f"state/{k}": s.dataset() for k, s in states.items()}})

    write()
    while not es.stop():
        asked = es.ask()
        unit = np.array(asked)
        values = _values(variables, unit)
        costs, extras = evaluate(values)
        es.tell(asked, list(costs))
        block = {"generation": np.full(len(unit), generations), "unit": unit, "x": values,
                 "cost": np.asarray(costs, dtype=float), **extras}
        for name, series in rows.items():
            series.blocks.append(np.asarray(block[name]))
        for name, value in _state(es, rng).items():
            states[name].blocks.append(np.asarray(value)[None])
        write()
        if on_generation is not None:
            on_generation(generations, values, extras, es)
        generations += 1
    best = {v.key: v.from_unit(float(u)) for v, u in zip(variables, es.result.xbest)}
    return Search(variables=variables, best=best, cost=float(es.result.fbest), evaluations=es.result.evaluations,
                  generations=generations, wall_s=time.perf_counter() - start_time, stop=dict(es.stop()),
                  best_cost_per_generation=[float(c.min()) for c in rows["cost"].blocks], seed=attrs["seed"],
                  budget=budget)


def _load(path: Path, schema: str, variables: Sequence[Variable], problem: dict[str, Any],
          fixed: dict[str, searchlog.Dataset], rows: dict[str, searchlog.Series],
          states: dict[str, searchlog.Series], seed: int | None) -> tuple[dict[str, Any], np.ndarray]:
    """Fill ``rows`` and ``states`` from a log of this very problem, one block per generation; its attributes and
    start point."""
    attrs, datasets = searchlog.read(path, schema)
    if "digest" not in attrs:
        raise SceneError(f"{path} carries no digest of its contents (a log of an older finrft, or edited): it "
                         f"cannot be checked, so it is not continued")
    _check_attributes(path, attrs)
    if attrs.get("variables") != [v.key for v in variables] or not np.array_equal(datasets["bounds"].data,
                                                                                  fixed["bounds"].data):
        raise SceneError(f"{path} searched other variables or bounds: "
                         + ", ".join(f"{k} {lo:g}:{hi:g}" for k, (lo, hi) in zip(attrs.get("variables", []),
                                                                                 datasets["bounds"].data)))
    for name, value in problem.items():
        if attrs.get(name) != value:
            raise SceneError(f"{path} was run with another {name.replace('_', ' ')}")
    for name, table in fixed.items():
        if name not in datasets or not np.array_equal(datasets[name].data, table.data):
            raise SceneError(f"{path} was run on other data ({name})")
    missing = sorted(set(rows) - set(datasets))
    if missing:
        raise SceneError(f"{path} does not log {', '.join(missing)}")
    if seed is not None and seed != attrs["seed"]:
        raise SceneError(f"seed {seed} differs from the seed of {path}, {attrs['seed']}: a continued run keeps its "
                         "seed")
    generation = datasets["generation"].data
    count = len(datasets["state/sigma"].data)
    for name, series in rows.items():
        series.blocks = [datasets[name].data[generation == g] for g in range(count)]
    for name, series in states.items():
        series.blocks = [datasets[f"state/{name}"].data[g:g + 1] for g in range(count)]
    return attrs, datasets["x0"].data


def _replay(es: Any, rng: np.random.RandomState, variables: Sequence[Variable], rows: dict[str, searchlog.Series],
            states: dict[str, searchlog.Series], where: str, logged_version: str) -> None:
    """Bring a new optimiser of the logged seed to the logged state: ask and tell every logged generation again,
    checking that it asks the logged points, that they are the logged values of the variables, and that it ends
    each generation in the logged state."""
    import cma
    for g, (unit, cost) in enumerate(zip(rows["unit"].blocks, rows["cost"].blocks)):
        es.stop()  # as the logged run called it, in case it keeps state
        asked = es.ask()
        if not np.array_equal(np.array(asked), unit):
            raise SceneError(f"{where}generation {g} asks other points than logged: pycma {cma.__version__} cannot "
                             f"continue a log of pycma {logged_version}")
        if not np.array_equal(_values(variables, unit), rows["x"].blocks[g]):
            raise SceneError(f"{where}generation {g} logs other values of the variables than its points give: the "
                             f"log was edited")
        es.tell(asked, list(cost))
        if any(not np.array_equal(value, states[name].blocks[g][0]) for name, value in _state(es, rng).items()):
            raise SceneError(f"{where}the optimiser rebuilt from the log differs from its logged state after "
                             f"generation {g} (pycma {cma.__version__}, the log's {logged_version})")


def read_log(path: str | Path, schema: str = searchlog.OPTIMIZE) -> dict[str, Any]:
    """A log's datasets by name, its root attributes ("attrs"), the datasets' other attributes than units and
    description ("dataset_attrs") and its variables; SceneError when the file is not a finrft log of this
    ``schema``."""
    attrs, datasets = searchlog.read(path, schema)
    _check_attributes(path, attrs)
    missing = sorted({"bounds", "x", "generation", "state/sigma"} - set(datasets))
    if missing:
        raise SceneError(f"{path} is not a complete finrft log: it lacks {', '.join(missing)}")
    if datasets["bounds"].data.shape != (len(attrs["variables"]), 2):
        raise SceneError(f"{path}: its bounds do not match its variables")
    out: dict[str, Any] = {name: d.data for name, d in datasets.items()}
    out["attrs"] = attrs
    out["dataset_attrs"] = {name: d.attrs for name, d in datasets.items()}
    out["variables"] = [Variable(k, float(lo), float(hi)) for k, (lo, hi) in zip(attrs["variables"],
                                                                                 out["bounds"])]
    return out


def logged_problem(path: str | Path) -> tuple[RobotScene, list[Variable]]:
    """The scene and variables of an optimisation log, to continue it."""
    log = read_log(path)
    return scene_from_dict(read_toml(log["attrs"]["scene_toml"], f"{path}: its scene"), RobotScene), log["variables"]


def optimize(scene: RobotScene, *, variables: Sequence[Variable] = DEFAULT_VARIABLES, budget: int | None = None,
             seed: int | None = None, log: str | Path | None = None, resume: bool = False, replace: bool = False,
             executor: Executor | None = None, workers: int | None = None, max_error: ErrorLimits = ErrorLimits(),
             on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None = None) -> Search:
    """Maximise the robot's eta over ``variables`` with CMA-ES, minimising 1 - eta (failed gaits, gaits whose
    estimated error exceeds ``max_error``, and power strokes that move the body forward by less than
    MIN_FORWARD_MM: 2). Budget, seed, log, resume and replace as `cmaes`; `logged_problem` gives the scene and variables
    to resume a log with."""
    check_variables(scene, variables)
    check_limits(max_error, optional=False)

    def population(values: np.ndarray) -> tuple[list[float], dict[str, np.ndarray]]:
        scenes = [scene.replace(**{v.key: float(x) for v, x in zip(variables, row)}) for row in values]
        results = batch.map_jobs(_evaluate_job, [(s, max_error) for s in scenes], executor=pool, workers=1)
        etas = np.array([r["eta"] for r in results])
        forward = np.array([r["D1_mm"] for r in results])
        usable = np.isfinite(etas) & (forward >= MIN_FORWARD_MM)
        return [1.0 - e if ok else FAILED for e, ok in zip(etas, usable)], {
            "eta": etas, "D1": np.array([r["D1_mm"] for r in results]) / 1e3,
            "D2": np.array([r["D2_mm"] for r in results]) / 1e3,
            "eta_error": np.array([r["eta_error_points"] for r in results])}

    with batch.pool_for(executor, workers) as pool:
        search = cmaes(population, variables, budget=budget, seed=seed, start=PAPER_START, log=log, resume=resume,
                       replace=replace, units=si_units(RobotScene, variables),
                       problem={"scene_toml": to_toml(scene), "objective": "1 - eta over one flap cycle from rest "
                                f"(failed gaits, estimated errors above the limit and power strokes under "
                                f"{MIN_FORWARD_MM} mm: 2)", "objective_units": "1",
                                "error_limit_points": max_error.eta_points},
                       columns={"eta": ("1", 0, "swimming efficiency (D1 - D2) / D1; NaN when the gait failed"),
                                "D1": ("m", 0, "distance forward in the power stroke"),
                                "D2": ("m", 0, "distance back in the recovery stroke"),
                                "eta_error": ("points", 0, "estimated discretisation error of eta (finrft.convergence)")},
                       on_generation=on_generation)
    if search.cost >= FAILED:
        raise SimulationFailed(f"none of the {search.evaluations} gaits evaluated gave a usable eta (each failed, "
                               f"exceeded the error limit, or moved the body forward by less than "
                               f"{MIN_FORWARD_MM} mm): check the scene and the bounds")
    return search


def best_gait(scene: RobotScene, result: Search, max_error: ErrorLimits = ErrorLimits()) -> tuple[Any, dict[str, Any]]:
    """The search's best gait run again (one cycle, with its error estimate) and the search's summary: the best
    gait in degrees and mm, its eta, the estimate, and the search's figures."""
    best_scene = scene.replace(**result.best)
    best = swim(best_scene, 1, max_error=max_error)
    g = best_scene.gait
    return best, {"theta1_deg": math.degrees(g.theta1), "theta2_deg": math.degrees(g.theta2),
                  "arm_length_mm": 1e3 * best_scene.arm.length, "eta": 1 - result.cost, "best": result.best,
                  "error_estimate": best.error_estimate, "error_companion": best.error_companion,
                  "evaluations": result.evaluations, "generations": result.generations, "wall_s": result.wall_s,
                  "seed": result.seed, "budget": result.budget, "stop": {k: str(v) for k, v in result.stop.items()}}


def best_gait_text(summary: dict[str, Any]) -> str:
    # the gait always; any other key searched (a fin's design, say) as well, in the CLI's units
    others = [bounds.shown(RobotScene, key, value) for key, value in summary["best"].items()
              if key not in ("gait.theta1", "gait.theta2", "arm.length")]
    return (f"best eta {100 * summary['eta']:.2f} % at theta1 {summary['theta1_deg']:.1f} deg, theta2 "
            f"{summary['theta2_deg']:.1f} deg, arm {summary['arm_length_mm']:.1f} mm"
            f"{''.join(', ' + text for text in others)} after {summary['evaluations']} evaluations in "
            f"{summary['wall_s']:.1f} s")


# ---------------------------------------------------------------------------------------------------------
# Any robot scene (finrft optimize --scene ROBOT.toml --objective FIGURE): any figure, any keys

# Costs of the evaluations that rank below every feasible one: CMA-ES ranks, so their size is only an order. An
# infeasible one ranks by its constraints' violation; a failed run (unstable, or over --max-error) below all.
INFEASIBLE = 1e9
FAILED_RUN = 2e9
# The most candidates the end of a search refines (`refine`): the best and those whose estimates overlap its.
REFINED = 4


@dataclass(frozen=True)
class Objective:
    """A figure of the run's JSON by path (`finrft.studies.figures`), maximised or minimised."""

    figure: str
    maximize: bool = True

    @classmethod
    def parse(cls, text: str) -> Objective:
        """``FIGURE[:max|min]`` (max when left out)."""
        figure, sep, sense = text.strip().partition(":")
        if sep and sense not in ("max", "min"):
            raise SceneError(f"--objective {text}: give FIGURE, FIGURE:max or FIGURE:min")
        return cls(figure.strip(), sense != "min")

    def __str__(self) -> str:
        return f"{self.figure}:{'max' if self.maximize else 'min'}"


@dataclass(frozen=True)
class Constraint:
    """A figure held below (``<=``) or above (``>=``) a bound, in its SI unit."""

    figure: str
    upper: bool
    bound: float

    @classmethod
    def parse(cls, text: str) -> Constraint:
        for op in ("<=", ">="):
            figure, sep, bound = text.partition(op)
            if sep:
                try:
                    value = float(bound)
                except ValueError:
                    value = math.nan
                if not math.isfinite(value) or not figure.strip():
                    break
                return cls(figure.strip(), op == "<=", value)
        raise SceneError(f"--constraint {text}: give FIGURE<=VALUE or FIGURE>=VALUE, VALUE a number in the "
                         f"figure's SI unit (e.g. cost_of_transport<=5)")

    def violation(self, value: float) -> float:
        """How far ``value`` lies beyond the bound, relative to it (0: met; inf: not reported)."""
        if not math.isfinite(value):
            return math.inf
        over = value - self.bound if self.upper else self.bound - value
        return max(over, 0.0) / max(abs(self.bound), 1e-12)

    def __str__(self) -> str:
        return f"{self.figure}{'<=' if self.upper else '>='}{self.bound!r}"


@dataclass
class SceneSearch:
    """A robot scene's search (`optimize_scene`): the search itself, and its best after refinement."""

    search: Search
    objective: Objective
    best: dict[str, float]                # the searched keys' values (SI)
    best_objective: float                 # the objective figure at the best, refined (`refine`)
    best_objective_estimate: float        # its estimated discretisation error
    best_ambiguous: bool                  # the refined candidates' estimates still overlap: the best is not certain
    refined: list[dict[str, Any]]         # each refined candidate: its keys, value and estimate, before and after
    best_scene: UserScene
    flagged: int                          # evaluations whose estimate overlapped a neighbour's in their generation
    infeasible: int
    failed: int


def _costs(objective: Objective, constraints: Sequence[Constraint], results: list[dict[str, Any]]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each evaluation's cost (minimised), the objective figure and its estimate, and its flag: 1 where its
    estimate could swap it with its neighbour in the ranking (their error bars overlap) or move it across a
    constraint's bound."""
    sign = -1.0 if objective.maximize else 1.0
    values = np.array([r["figures"].get(objective.figure, math.nan) for r in results])
    errors = np.array([r["estimates"].get(objective.figure, math.nan) for r in results])
    costs, flags = np.empty(len(results)), np.zeros(len(results), dtype=np.int64)
    for i, r in enumerate(results):
        violation = sum(c.violation(r["figures"].get(c.figure, math.nan)) for c in constraints)
        if r["error"] or not math.isfinite(values[i]) or math.isinf(violation):
            costs[i] = FAILED_RUN
        elif violation > 0:
            costs[i] = INFEASIBLE * (1 + min(violation, 1e6) / 1e6)
        else:
            costs[i] = sign * values[i]
        for c in constraints:
            value, error = r["figures"].get(c.figure, math.nan), r["estimates"].get(c.figure, 0.0)
            if abs(value - c.bound) < error:
                flags[i] = 1
    feasible = np.flatnonzero(costs < INFEASIBLE)
    ranked = feasible[np.argsort(costs[feasible], kind="stable")]
    for a, b in zip(ranked[:-1], ranked[1:]):
        if abs(values[a] - values[b]) < np.nan_to_num(errors[a]) + np.nan_to_num(errors[b]):
            flags[a] = flags[b] = 1
    return costs, values, errors, flags


def _start(scene: UserScene, variables: Sequence[Variable]) -> dict[str, float]:
    """The scene's own values of the searched keys (a design key the scene leaves alone: the model's)."""
    from ..experiments.attached_model import scene_spec
    spec = scene_spec(scene)
    out = {}
    for v in variables:
        value = key_value(scene, v.key)
        out[v.key] = design.current(spec, v.key) if value is None else float(value)
    return out


def check_scene_problem(scene: UserScene, variables: Sequence[Variable], objective: Objective,
                        constraints: Sequence[Constraint]) -> None:
    """SceneError, before anything runs, for a key, bound, name, index or figure the scene cannot take: each
    variable at both its bounds is read into the model (`UserModel.of`), and every figure named is one a run of
    the scene reports."""
    from ..experiments.user_model import UserModel
    from .figures import check_path
    check_variables(scene, variables, UserScene)
    experiment = None
    for v in variables:
        for value in (v.low, v.high):
            experiment = UserModel.of(scene.replace(**{v.key: value}))
    for path in (objective.figure, *(c.figure for c in constraints)):
        check_path(path, scene, experiment.bodies)


def scene_problem(scene: UserScene, objective: Objective, constraints: Sequence[Constraint],
                  max_error: ErrorLimits | None) -> dict[str, Any]:
    """A robot scene's search as a log's root attributes: what a resumed run must match."""
    limits = "" if max_error is None else json.dumps(dataclasses.asdict(max_error))
    return {"scene_toml": to_toml(scene), "objective": str(objective), "objective_units": "the figure's SI unit",
            "constraints": " ".join(str(c) for c in constraints), "max_error": limits}


def logged_scene_problem(path: str | Path) -> tuple[UserScene, list[Variable], Objective, list[Constraint],
                                                    ErrorLimits | None]:
    """The scene, variables, objective, constraints and error limits of a robot scene's search log, to continue
    it."""
    from ..convergence import FigureLimit
    log = read_log(path, searchlog.SCENE)
    attrs = log["attrs"]
    scene = scene_from_dict(read_toml(attrs["scene_toml"], f"{path}: its scene"), UserScene)
    try:
        limits = json.loads(attrs["max_error"]) if attrs.get("max_error") else None
        if limits is not None:
            figures = limits.pop("figures")
            limits = ErrorLimits(**limits, figures=None if figures is None else tuple(FigureLimit(**f)
                                                                                      for f in figures))
        objective = Objective.parse(attrs["objective"])
        constraints = [Constraint.parse(c) for c in attrs["constraints"].split()]
    except (KeyError, TypeError, ValueError, AttributeError):
        raise SceneError(f"{path}: its objective, constraints or error limits are damaged") from None
    return scene, log["variables"], objective, constraints, limits


def optimize_scene(scene: UserScene, variables: Sequence[Variable], objective: Objective,
                   constraints: Sequence[Constraint] = (), *, budget: int | None = None, seed: int | None = None,
                   log: str | Path | None = None, resume: bool = False, replace: bool = False,
                   executor: Executor | None = None, workers: int | None = None,
                   max_error: ErrorLimits | None = None,
                   on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None = None,
                   backend: str = "native") -> SceneSearch:
    """Optimise any figure of a robot scene's run over any of its keys (schema keys, ``control.*.frequency``,
    design keys of its model) with CMA-ES, under ``constraints``, from the scene's own values (the middle of the
    bounds where they lie outside).

    Every evaluation runs with its error estimate (``max_error`` None: reported, not bounded; a run over a limit
    given counts as failed). The estimate is respected twice: an evaluation whose error bar overlaps its
    neighbour's in its generation's ranking, or a constraint's bound, is flagged (logged ``ambiguous``); at the
    end the best and every evaluation whose error bar overlaps the best's (`REFINED` at most, the closest first)
    are run again at half the step (`refine`), and the best is chosen by the refined figures, flagged
    ``best_ambiguous`` when their error bars still overlap. Budget, seed, log (schema `searchlog.SCENE`), resume,
    replace, executor and workers as `optimize`. ``backend`` "warp": each generation the worlds of one batched
    rollout on MuJoCo Warp (`finrft.warp.population`: medium and open-loop control keys, the centre of mass's
    figures); the refinement runs natively."""
    from .figures import evaluate_job
    from .sweep import BACKENDS, warp_population
    check_limits(max_error)
    check_scene_problem(scene, variables, objective, constraints)
    if backend not in BACKENDS:
        raise SceneError(f"a search's backend is one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "warp":
        worlds = warp_population()
        worlds.check_keys(scene, [v.key for v in variables])
        for figure in (objective.figure, *(c.figure for c in constraints)):
            if figure.partition(".")[0] not in worlds.FIGURES:
                raise SceneError(f"--backend warp reports {', '.join(worlds.FIGURES)}, not {figure}: use "
                                 f"--backend native")
    seen: list[dict[str, np.ndarray]] = []

    def population(values: np.ndarray) -> tuple[list[float], dict[str, np.ndarray]]:
        scenes = [scene.replace(**{v.key: float(x) for v, x in zip(variables, row)}) for row in values]
        results = worlds.evaluate(scene, scenes, max_error) if backend == "warp" else \
            batch.map_jobs(evaluate_job, [(s, max_error) for s in scenes], executor=pool, workers=1)
        costs, figure, error, flags = _costs(objective, constraints, results)
        columns = {"objective": figure, "objective_error": error, "ambiguous": flags,
                   "usable": (costs < INFEASIBLE).astype(np.int64)}
        seen.append({"x": values, "cost": costs, **columns})
        for c in constraints:
            columns[f"constraint/{c.figure}"] = np.array([r["figures"].get(c.figure, math.nan) for r in results])
        return list(costs), columns

    columns = {"objective": ("the figure's SI unit", 0, f"{objective.figure}; NaN when the run failed"),
               "objective_error": ("the figure's SI unit", 0, "its estimated discretisation error"),
               "ambiguous": ("1", 0, "1 where the estimate overlaps the next evaluation's in the generation's "
                                     "ranking, or a constraint's bound"),
               "usable": ("1", 0, "1 where the run succeeded and met every constraint")}
    for c in constraints:
        columns[f"constraint/{c.figure}"] = ("the figure's SI unit", 0, f"the constrained figure ({c})")
    with batch.pool_for(executor, workers) as pool:
        search = cmaes(population, variables, budget=budget, seed=seed, start=_start(scene, variables), log=log,
                       resume=resume, replace=replace, schema=searchlog.SCENE, units=si_units(UserScene, variables),
                       problem=scene_problem(scene, objective, constraints, max_error),
                       columns=columns, on_generation=on_generation)
        if log is not None:  # every evaluation, a resumed run's earlier ones too
            data = read_log(log, searchlog.SCENE)
            rows = {k: data[k] for k in ("x", "cost", "objective", "objective_error", "ambiguous")}
        else:
            rows = {k: np.concatenate([block[k] for block in seen]) for k in seen[0]}
        return refine(scene, search, objective, constraints, rows, pool, max_error)


def refine(scene: UserScene, search: Search, objective: Objective, constraints: Sequence[Constraint],
           rows: dict[str, np.ndarray], pool: Executor | None,
           max_error: ErrorLimits | None) -> SceneSearch:
    """The search's best, refined: the best evaluation and those whose error bars overlap its own (`REFINED` at
    most, nearest first) run again at half the step (`convergence.FINER`; an adaptive method at a quarter of its
    tolerance), each with a fresh estimate; the best of them by the refined figures, ``best_ambiguous`` where its
    error bar still overlaps another's."""
    from ..convergence import FINER, _companion
    from .figures import evaluate_job
    feasible = np.flatnonzero(rows["cost"] < INFEASIBLE)
    if not len(feasible):
        raise SimulationFailed(f"none of the {search.evaluations} evaluations was usable (each failed, exceeded "
                               f"the error limit or broke a constraint): check the scene, the bounds and the "
                               f"constraints")
    best = feasible[np.argmin(rows["cost"][feasible])]
    error = np.nan_to_num(rows["objective_error"])
    gap = np.abs(rows["objective"][feasible] - rows["objective"][best])
    close = feasible[(gap < error[feasible] + error[best]) | (feasible == best)]
    close = close[np.argsort(np.abs(rows["objective"][close] - rows["objective"][best]), kind="stable")][:REFINED]
    # each point once (CMA-ES may ask one twice near convergence)
    _, first = np.unique(rows["x"][close], axis=0, return_index=True)
    close = close[np.sort(first)]
    variables = search.variables
    scenes = [scene.replace(**{v.key: float(x) for v, x in zip(variables, rows["x"][i])}) for i in close]
    finer = [_companion(s, FINER, s.sim.record_dt)[0] for s in scenes]
    results = batch.map_jobs(evaluate_job, [(s, max_error) for s in finer], executor=pool, workers=1)
    costs, values, errors, _ = _costs(objective, constraints, results)
    order = np.argsort(costs, kind="stable")
    if costs[order[0]] >= INFEASIBLE:
        order = np.array([0])  # none refined usable: the search's own best, its figures as the search had them
        values, errors = rows["objective"][close], rows["objective_error"][close]
    top = order[0]
    ambiguous = any(abs(values[top] - values[j]) < np.nan_to_num(errors[top]) + np.nan_to_num(errors[j])
                    for j in order[1:] if costs[j] < INFEASIBLE)
    refined = [{"values": {v.key: float(x) for v, x in zip(variables, rows["x"][i])},
                "search_objective": float(rows["objective"][i]),
                "search_objective_estimate": float(rows["objective_error"][i]),
                "refined_objective": float(values[k]), "refined_objective_estimate": float(errors[k]),
                "error": results[k]["error"]} for k, i in enumerate(close)]
    flags = rows["ambiguous"]
    return SceneSearch(search=search, objective=objective, best=refined[top]["values"],
                       best_objective=float(values[top]), best_objective_estimate=float(errors[top]),
                       best_ambiguous=bool(ambiguous), refined=refined, best_scene=scenes[top],
                       flagged=int(flags.sum()), infeasible=int(np.sum((rows["cost"] >= INFEASIBLE)
                                                                       & (rows["cost"] < FAILED_RUN))),
                       failed=int(np.sum(rows["cost"] >= FAILED_RUN)))


def plot_scene_search(path: str | Path, log: dict[str, Any], objective: Objective) -> None:
    """A robot scene's search as a chart: each evaluation's objective with its estimate as an error bar, by
    generation (flagged ones hollow, unusable ones left out), and the best so far."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    generation, value, error = log["generation"], log["objective"], np.nan_to_num(log["objective_error"])
    usable, flagged = log["usable"] > 0, log["ambiguous"] > 0
    fig, ax = plt.subplots(figsize=(6, 4))
    for mask, face, label in ((usable & ~flagged, "C0", "evaluation"),
                              (usable & flagged, "none", "flagged: its estimate overlaps a neighbour's")):
        if np.any(mask):
            ax.errorbar(generation[mask], value[mask], yerr=error[mask], fmt="o", mfc=face, mec="C0", ecolor="C0",
                        capsize=2, label=label)
    pick = np.fmax.accumulate if objective.maximize else np.fmin.accumulate
    gens = np.arange(int(generation.max()) + 1) if len(generation) else np.zeros(0, int)
    per = np.array([(np.nanmax if objective.maximize else np.nanmin)(np.where(usable & (generation == g), value,
                                                                               np.nan))
                    if np.any(usable & (generation == g)) else np.nan for g in gens])
    ax.plot(gens, pick(per), "k-", label="best so far")
    ax.set_xlabel("generation")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_ylabel(f"{objective.figure} (SI)")
    ax.set_title(f"CMA-ES: {objective}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with files.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
