"""Gait and design optimisation of the robot with CMA-ES (pycma).

The search runs over any robot scene keys, each between bounds, in coordinates normalised to [0, 1] (positive
quantities whose bounds span more than a decade are searched in log space). The objective is the paper's:
minimise 1 - eta over one flap cycle; a gait that cannot be simulated, or whose power stroke barely moves the
body forward, scores 2.

Every evaluation is appended to an HDF5 log after each generation, with the optimiser's pickled state, so an
interrupted run resumes bit for bit. Same seed, same result: the objective is deterministic and pycma's own
random state is the only randomness.
"""

from __future__ import annotations

import json
import math
import pickle
import time
import warnings
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import batch
from .convergence import ErrorLimits, SimulationFailed
from .scene import RobotScene, SceneError, field_of, to_toml
from .swim import swim

SCHEMA = "finrft.optimize/1"
FAILED = 2.0
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


def check_variables(scene: RobotScene, variables: Sequence[Variable]) -> None:
    """Bounds must be ordered and inside the schema's limits; keys must be numeric scene keys."""
    if not variables:
        raise SceneError("at least one variable must be searched")
    seen = set()
    for v in variables:
        f = field_of(RobotScene, v.key)
        if f.type not in ("float", float):
            raise SceneError(f"{v.key} is not a number and cannot be searched")
        if v.key in seen:
            raise SceneError(f"{v.key} is listed twice")
        seen.add(v.key)
        if not (math.isfinite(v.low) and math.isfinite(v.high)) or v.low >= v.high:
            raise SceneError(f"bounds of {v.key}: lower ({v.low:g}) must be below upper ({v.high:g})")
        scene.replace(**{v.key: v.low})
        scene.replace(**{v.key: v.high})


def evaluate(scene: RobotScene, max_error: ErrorLimits = ErrorLimits()) -> dict[str, float]:
    """One gait evaluation: one flap cycle from rest, eta, the distances and the estimate of eta's discretisation
    error (points); failures, including an estimate above ``max_error``, are marked, not raised: an optimiser must
    not climb a discretisation error."""
    try:
        run = swim(scene, 1, max_error=max_error)
    except (SimulationFailed, SceneError) as exc:
        return {"eta": float("nan"), "D1_mm": float("nan"), "D2_mm": float("nan"), "eta_error_points": float("nan"),
                "error": str(exc)}
    summary = run.summary()
    return {"eta": summary["eta"], "D1_mm": summary["D1_mm"], "D2_mm": summary["D2_mm"],
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


# evaluate(values (population x variables, SI)) -> (costs, extra per-evaluation columns to log)
Evaluate = Callable[[np.ndarray], tuple[list[float], dict[str, np.ndarray]]]


def _log_new(path: Path, variables: Sequence[Variable], attrs: dict[str, Any],
             columns: dict[str, tuple[str, int]]) -> None:
    import h5py  # here, not at the top: `import finrft` stays light
    with h5py.File(path, "w") as f:
        f.attrs.update(schema=SCHEMA, variables=json.dumps([[v.key, v.low, v.high] for v in variables]), **attrs)
        specs = {"x": ("SI, one column per variable", len(variables)), "cost": ("1", 0), "generation": ("", 0),
                 **columns}
        for name, (unit, width) in specs.items():
            shape = (0, width) if width else (0,)
            ds = f.create_dataset(name, shape=shape, maxshape=(None, *shape[1:]),
                                  dtype="i8" if name == "generation" else "f8", chunks=True)
            ds.attrs["units"] = unit
        f.create_dataset("es_state", data=np.zeros(0, dtype=np.uint8))


def _log_append(path: Path, generation: int, rows: dict[str, np.ndarray], es: Any) -> None:
    import h5py
    with h5py.File(path, "a") as f:
        n, count = f["cost"].shape[0], len(rows["cost"])
        for name, data in {**rows, "generation": np.full(count, generation)}.items():
            f[name].resize(n + count, axis=0)
            f[name][n:] = data
        del f["es_state"]
        f.create_dataset("es_state", data=np.frombuffer(pickle.dumps(es), dtype=np.uint8))


def read_log(path: str | Path) -> dict[str, Any]:
    """A log's contents; SceneError when the file is not a finrft optimisation log."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("schema") != SCHEMA:
                raise SceneError(f"{path} is not a finrft optimisation log")
            out = {name: f[name][()] for name in f if name != "es_state"}
            out["variables"] = [Variable(k, lo, hi) for k, lo, hi in json.loads(f.attrs["variables"])]
            out["attrs"] = dict(f.attrs)
            state = f["es_state"][()].tobytes()  # the pickled CMAEvolutionStrategy
            out["es"] = pickle.loads(state) if state else None
            return out
    except (OSError, KeyError, ValueError, pickle.UnpicklingError, EOFError) as exc:
        raise SceneError(f"cannot resume from {path}: {exc}") from None


def cmaes(evaluate: Evaluate, variables: Sequence[Variable], *, budget: int, seed: int,
          start: dict[str, float] | None = None, log: str | Path | None = None, resume: bool = False,
          log_attrs: dict[str, Any] | None = None, columns: dict[str, tuple[str, int]] | None = None,
          on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None = None) -> Search:
    """Minimise a population cost over ``variables`` with CMA-ES (normalised to [0, 1], sigma0 = 0.25, from
    ``start`` or the middle of the bounds). ``log`` (HDF5) records every evaluation with ``columns``
    (name -> (unit, width; 0 for one value)) and the optimiser's state; ``resume`` continues from it."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*matplotlib.*")
        import cma
    variables = tuple(variables)
    if budget < 1:
        raise SceneError(f"the budget must be at least 1 evaluation, got {budget}")
    path = Path(log) if log is not None else None
    start_time = time.perf_counter()
    history: list[float] = []
    if resume:
        if path is None:
            raise SceneError("resuming needs the log to resume from")
        state = read_log(path)
        if [(v.key, v.low, v.high) for v in state["variables"]] != [(v.key, v.low, v.high) for v in variables]:
            raise SceneError(f"{path} searched other variables: {[v.key for v in state['variables']]}")
        es = state["es"]
        if es is None:
            raise SceneError(f"{path} holds no optimiser state yet: start a new run instead")
        generation = int(state["generation"].max()) + 1 if len(state["generation"]) else 0
        history = [float(state["cost"][state["generation"] == g].min()) for g in range(generation)]
    else:
        x0 = [v.to_unit((start or {}).get(v.key, v.from_unit(0.5))) for v in variables]
        options = {"bounds": [0.0, 1.0], "seed": seed, "maxfevals": budget, "verbose": -9, "verb_log": 0,
                   "verb_disp": 0}
        if len(variables) == 1:
            # pycma 4.5 fails in one dimension when it caps the step size to the bound range
            options["maxstd_boundrange"] = math.inf
        es = cma.CMAEvolutionStrategy(x0, 0.25, options)
        generation = 0
        if path is not None:
            _log_new(path, variables, {"seed": seed, "budget": budget, **(log_attrs or {})}, columns or {})
    while not es.stop():
        unit = es.ask()
        values = np.array([[v.from_unit(u) for v, u in zip(variables, x)] for x in unit])
        costs, extras = evaluate(values)
        es.tell(unit, list(costs))
        history.append(float(min(costs)))
        if path is not None:
            _log_append(path, generation, {"x": values, "cost": np.asarray(costs), **extras}, es)
        if on_generation is not None:
            on_generation(generation, values, extras, es)
        generation += 1
    best = {v.key: v.from_unit(float(u)) for v, u in zip(variables, es.result.xbest)}
    return Search(variables=variables, best=best, cost=float(es.result.fbest), evaluations=es.result.evaluations,
                  generations=generation, wall_s=time.perf_counter() - start_time, stop=dict(es.stop()),
                  best_cost_per_generation=history)


def optimize(scene: RobotScene, *, variables: Sequence[Variable] = DEFAULT_VARIABLES, budget: int = 300,
             seed: int = 1, log: str | Path | None = None, resume: bool = False, executor: Executor | None = None,
             workers: int | None = None, max_error: ErrorLimits = ErrorLimits(),
             on_generation: Callable[[int, np.ndarray, dict[str, np.ndarray], Any], None] | None = None) -> Search:
    """Maximise the robot's eta over ``variables`` with CMA-ES, minimising 1 - eta (failed gaits, gaits whose
    estimated error exceeds ``max_error``, and power strokes that move the body forward by less than
    MIN_FORWARD_MM: 2)."""
    check_variables(scene, variables)

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
                       log_attrs={"scene_toml": to_toml(scene), "objective": "1 - eta over one flap cycle from rest "
                                  f"(failed gaits, estimated errors above the limit and power strokes under "
                                  f"{MIN_FORWARD_MM} mm: 2)"},
                       columns={"eta": ("1", 0), "D1": ("m", 0), "D2": ("m", 0), "eta_error": ("points", 0)},
                       on_generation=on_generation)
    if search.cost >= FAILED:
        raise SimulationFailed(f"none of the {search.evaluations} gaits evaluated gave a usable eta (each failed, "
                               f"exceeded the error limit, or moved the body forward by less than "
                               f"{MIN_FORWARD_MM} mm): check the scene and the bounds")
    return search
