"""Sweeps of a robot scene (``finrft sweep``): variants of one scene over a grid of values of any of its keys, or
drawn at random from a distribution per key (domain randomisation of the medium, the friction, the masses), each
run with its error estimate in parallel processes (or on a Dask cluster), into one table of every figure and its
estimate per variant (`finrft.studies.figures`): CSV, and HDF5 with each variant's resolved scene.

Keys are those of `UserScene.replace`: schema keys (``medium.zeta``), every entry's (``control.*.frequency``) and
design keys of the model (``model.geom.fin.size.0``, `finrft.design`).
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .. import batch, design
from ..convergence import ErrorLimits, check_limits
from ..errors import SceneError
from ..files import atomic_path, hdf5_written, provenance
from ..scene import UserScene, field_of, key_unit, parse_override, to_toml
from ..schema import quantity
from .figures import evaluate_job

# The distributions of --dist KEY=NAME:A,B: their parameters, and a draw from numpy's generator.
DISTRIBUTIONS: dict[str, tuple[str, Callable[[np.random.Generator, float, float], float]]] = {
    "uniform": ("low, high", lambda rng, a, b: rng.uniform(a, b)),
    "loguniform": ("low, high (both > 0)", lambda rng, a, b: math.exp(rng.uniform(math.log(a), math.log(b)))),
    "normal": ("mean, standard deviation", lambda rng, a, b: rng.normal(a, b)),
}
MAX_VARIANTS = 100_000
# Where a population's runs go: native (each variant a whole run, in processes or on Dask) or warp (every
# variant a world of one batched rollout).
BACKENDS = ("native", "warp")


@dataclass(frozen=True)
class Distribution:
    """A key's distribution for random variants, its parameters in the key's SI unit."""

    key: str
    name: str
    a: float
    b: float

    def draw(self, rng: np.random.Generator) -> float:
        return float(DISTRIBUTIONS[self.name][1](rng, self.a, self.b))


def _value(key: str, text: str) -> Any:
    """One value of a key as --set reads it: a number (one with a unit suffix in SI, as the table holds it), or a
    name."""
    value = parse_override(f"{key}={text.strip()}", UserScene)[1]
    numeric = design.is_key(key) or field_of(UserScene, key).type in ("float", float)
    return quantity(value, key_unit(UserScene, key), key) if numeric and isinstance(value, str) else value


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """--grid KEY=A,B,C items as {key: values}; SceneError for one that is not so, or a key given twice."""
    out: dict[str, list[Any]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        key = key.strip()
        if not sep or not key or not values.strip():
            raise SceneError(f"--grid expects KEY=A,B,C, got '{item}'")
        if key in out:
            raise SceneError(f"--grid {key} is given twice: list every value once, as {key}=A,B,C")
        out[key] = [_value(key, v) for v in values.split(",")]
    return out


def parse_dist(items: Sequence[str]) -> dict[str, Distribution]:
    """--dist KEY=NAME:A,B items (NAME one of `DISTRIBUTIONS`; A and B in the key's unit, or with a unit suffix)."""
    out: dict[str, Distribution] = {}
    for item in items:
        key, sep, spec = item.partition("=")
        key = key.strip()
        name, sep2, params = spec.partition(":")
        parts = params.split(",")
        if not sep or not sep2 or name.strip() not in DISTRIBUTIONS or len(parts) != 2:
            raise SceneError(f"--dist expects KEY=NAME:A,B with NAME one of "
                             + "; ".join(f"{n} ({p})" for n, (p, _) in DISTRIBUTIONS.items()) + f", got '{item}'")
        unit = key_unit(UserScene, key)
        a, b = (quantity(p, unit, f"--dist {key}") for p in parts)
        name = name.strip()
        if name != "normal" and not a < b or name == "loguniform" and not a > 0 or name == "normal" and not b > 0:
            raise SceneError(f"--dist {item}: {name} takes {DISTRIBUTIONS[name][0]}"
                             + (", the first below the second" if name != "normal" else ", the deviation > 0"))
        if key in out:
            raise SceneError(f"--dist {key} is given twice")
        out[key] = Distribution(key, name, a, b)
    return out


def grid_variants(grid: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of the grid's values, the last key varying fastest."""
    count = math.prod(len(v) for v in grid.values())
    if count > MAX_VARIANTS:
        raise SceneError(f"the grid makes {count} variants, more than {MAX_VARIANTS}: give fewer values")
    return [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())]


def random_variants(dists: dict[str, Distribution], n: int, seed: int) -> list[dict[str, float]]:
    """``n`` variants, each key drawn from its distribution in turn (numpy's PCG64 of ``seed``: the same seed, the
    same variants)."""
    if not 1 <= n <= MAX_VARIANTS:
        raise SceneError(f"--random takes 1 to {MAX_VARIANTS} variants, got {n}")
    rng = np.random.default_rng(seed)
    return [{key: d.draw(rng) for key, d in dists.items()} for _ in range(n)]


@dataclass
class Sweep:
    """A sweep's variants (the keys' values), their resolved scenes, and each one's figures, estimates and error."""

    keys: list[str]
    variants: list[dict[str, Any]]
    scenes: list[UserScene]
    results: list[dict[str, Any]]

    def figures(self) -> list[str]:
        """Every figure path any variant reports, in the order the runs report them."""
        return list(dict.fromkeys(path for r in self.results for path in r["figures"]))

    def column(self, path: str, estimates: bool = False) -> np.ndarray:
        return np.array([r["estimates" if estimates else "figures"].get(path, math.nan) for r in self.results])


def variant_scenes(scene: UserScene, variants: list[dict[str, Any]]) -> list[UserScene]:
    """Each variant's scene, checked before anything runs: a key, value, name or index the scene or its model
    cannot take is a SceneError naming the variant (`UserModel.of`)."""
    from ..experiments.user_model import UserModel
    scenes = []
    for i, variant in enumerate(variants):
        try:
            s = scene.replace(**variant)
            UserModel.of(s)
        except SceneError as exc:
            raise SceneError(f"variant {i} ({', '.join(f'{k}={v}' for k, v in variant.items())}): {exc}") from None
        scenes.append(s)
    return scenes


def sweep(scene: UserScene, variants: list[dict[str, Any]], *, workers: int | None = None,
          executor: Executor | None = None, max_error: ErrorLimits | None = None,
          progress: Callable[[int, int], None] | None = None, backend: str = "native") -> Sweep:
    """Run every variant of ``scene`` (its keys set as `UserScene.replace`) with its error estimate, on ``workers``
    local processes (default: every core) or ``executor`` (a Dask client's); a variant that fails, or whose
    estimate exceeds ``max_error`` (None: reported only), keeps its row with the reason and no figures.
    ``backend`` "warp": every variant a world of one batched rollout on MuJoCo Warp (`finrft.warp.population`:
    medium and open-loop control keys only; the centre of mass's figures)."""
    check_limits(max_error)
    if not variants:
        raise SceneError("a sweep needs at least one variant")
    if backend not in BACKENDS:
        raise SceneError(f"a sweep's backend is one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "warp":
        population = warp_population()
        population.check_keys(scene, list(variants[0]))
    scenes = variant_scenes(scene, variants)
    if backend == "warp":
        results = population.evaluate(scene, scenes, max_error)
        if progress is not None:
            progress(len(scenes), len(scenes))
    else:
        results = batch.map_jobs(evaluate_job, [(s, max_error) for s in scenes], workers=workers,
                                 executor=executor, progress=progress)
    return Sweep(list(variants[0]), variants, scenes, results)


def warp_population() -> Any:
    """`finrft.warp.population`, or SceneError in one line where the warp extra is absent."""
    try:
        from ..warp import population
    except ImportError as exc:
        raise SceneError(f"--backend warp: {exc}") from None
    return population


def _cell(value: Any) -> Any:
    return repr(value) if isinstance(value, float) else value


def table_csv(result: Sweep) -> str:
    """The table as CSV: a row per variant, its keys (SI), every figure and its estimate (``FIGURE estimate``),
    the run's wall time and why it failed (empty when it did not)."""
    figures = result.figures()
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["variant", *result.keys, *(c for f in figures for c in (f, f"{f} estimate")), "wall_s", "error"])
    for i, (variant, r) in enumerate(zip(result.variants, result.results)):
        w.writerow([i, *(_cell(variant[k]) for k in result.keys),
                    *(_cell(r[part].get(f, math.nan)) for f in figures for part in ("figures", "estimates")),
                    _cell(r["wall_s"]), r["error"]])
    return out.getvalue()


def write_hdf5(path: str | Path, result: Sweep) -> None:
    """The table as HDF5: ``keys/KEY`` (each variant's value), ``figures/PATH`` and ``estimates/PATH`` (NaN where a
    variant does not report it), ``scenes`` (each variant's resolved scene, TOML), ``error``, ``wall_s``."""
    import h5py
    with hdf5_written(path, track_order=True) as f:
        f.attrs.update(schema="finrft.sweep/1", **provenance(), keys=result.keys)
        text = h5py.string_dtype()
        for key in result.keys:
            values = [v[key] for v in result.variants]
            numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
            ds = f.create_dataset(f"keys/{key}", data=np.array(values, dtype=float) if numeric
                                  else np.array([str(v) for v in values], dtype=object), dtype=None if numeric else text)
            ds.attrs["units"] = key_unit(UserScene, key) or "1"
        for path_ in result.figures():
            f.create_dataset(f"figures/{path_}", data=result.column(path_))
            f.create_dataset(f"estimates/{path_}", data=result.column(path_, True))
        f.create_dataset("scenes", data=np.array([to_toml(s) for s in result.scenes], dtype=object), dtype=text)
        f.create_dataset("error", data=np.array([r["error"] for r in result.results], dtype=object), dtype=text)
        f.create_dataset("wall_s", data=np.array([r["wall_s"] for r in result.results]))


def plot(path: str | Path, result: Sweep, key: str, figure: str) -> None:
    """``figure`` against the swept ``key`` with its estimate as error bars, a line per value of the sweep's other
    keys (the first of them; random sweeps: points)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .bounds import DISPLAY, DISPLAY_UNIT
    if key not in result.keys:
        raise SceneError(f"--plot {key}: the sweep's keys are {', '.join(result.keys)}")
    unit = key_unit(UserScene, key) or ""
    x = np.array([float(v[key]) for v in result.variants]) * DISPLAY.get(unit, 1.0)
    y, err = result.column(figure), result.column(figure, True)
    others = [k for k in result.keys if k != key]
    groups: dict[Any, list[int]] = {}
    for i, v in enumerate(result.variants):
        groups.setdefault(v[others[0]] if others else None, []).append(i)
    fig, ax = plt.subplots(figsize=(6, 4))
    lines = len(groups) <= 12
    for label, rows in groups.items():
        rows = sorted(rows, key=lambda i: x[i])
        ax.errorbar(x[rows], y[rows], yerr=np.nan_to_num(err[rows]), marker="o", capsize=3,
                    linestyle="-" if lines else "none",
                    label=None if label is None or not lines else f"{others[0]} = {label:g}"
                    if isinstance(label, float) else f"{others[0]} = {label}")
    ax.set_xlabel(f"{key} ({DISPLAY_UNIT.get(unit, unit) or 'SI'})")
    ax.set_ylabel(f"{figure} (SI)")
    ax.grid(alpha=0.3)
    if others and lines:
        ax.legend(fontsize=8)
    ax.set_title(f"{figure} against {key} (error bars: estimated error)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
