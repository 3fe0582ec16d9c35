"""Parameter identification: fit a plate scene to measured segment angles, and RFT coefficients to rigid-plate
forces.

Drag data (the CSV format of the measurements in `finrft.data.plate_drag_dir`): columns ``time_s``, ``displacement_mm``, ``segment1_deg`` ...,
the absolute orientation change of each segment during a drag from flat at constant speed. For each file the plate
is dragged at the file's speed over its duration and its segment angles are compared at the file's times; the
objective is the paper's E: the mean over files of the mean squared error (deg^2) over segments and times.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .. import batch
from . import searchlog
from ..convergence import ErrorLimits, SimulationFailed, check_limits
from ..drive import Drive
from .optimize import Search, Variable, check_variables, cmaes, read_log, si_units
from ..experiment import Result
from ..laws.table import ForceTable
from ..scene import RFT, Scene, SceneError, field_of, read_text, scene_from_dict, split_key, to_toml
from ..experiments.plate import FORCE_COLUMNS, simulate
from ..files import read_toml

# Short names for the paper's parameters, and default bounds (SI).
ALIASES = {"b": "plate.damping", "k": "plate.stiffness", "f_perp": "rft.f_perp", "f_par": "rft.f_par"}
# The paper law's bounds are 0.1..100 N and -2..2 N per segment of the paper plate (33 mm, on the presets' face 55 mm
# tall at 37.5 mm mean depth), per unit area and depth.
PAPER_FACE = 0.033 * 0.055 * (0.010 + 0.055 / 2)
DEFAULT_BOUNDS = {"plate.damping": (0.01, 100.0), "plate.stiffness": (0.01, 100.0),
                  "rft.f_perp": (0.1 / PAPER_FACE, 100.0 / PAPER_FACE),
                  "rft.f_par": (-2.0 / PAPER_FACE, 2.0 / PAPER_FACE)}
FAILED = 1e6  # deg^2: worse than any plate that moved at all
# Drag speeds the model is meant for (m/s); a file outside them most likely has its columns in other units.
SPEEDS = (1e-3, 1.0)
# How far (fraction of the stroke) a drag's displacement may stray from constant speed.
LINEARITY = 0.02


@dataclass(frozen=True)
class DragData:
    """One measured drag: times (s), the base speed (m/s) and the segments' angles (deg, T x N)."""

    path: str
    time: np.ndarray
    speed: float
    angles: np.ndarray

    @property
    def name(self) -> str:
        return Path(self.path).stem

    @property
    def displacement(self) -> np.ndarray:
        return self.speed * self.time


def read_drag(path: str | Path) -> DragData:
    """Read and check a drag data file; SceneError naming the file and line on any problem."""
    path = Path(path)
    lines = read_text(path, "data file").splitlines()
    body = [(n, line) for n, line in enumerate(lines, start=1) if line.strip() and not line.startswith("#")]
    if not body:
        raise SceneError(f"{path}: no data")
    header_line, header = body[0][0], next(csv.reader([body[0][1]]))
    angle_columns = sorted((c for c in header if c.startswith("segment") and c.endswith("_deg")),
                           key=lambda c: int(c[len("segment"):-len("_deg")] or 0))
    if "time_s" not in header or "displacement_mm" not in header or not angle_columns:
        raise SceneError(f"{path}:{header_line}: columns must include time_s, displacement_mm and segment1_deg ...")
    rows = []
    for n, line in body[1:]:
        values = next(csv.reader([line]))
        if len(values) != len(header):
            raise SceneError(f"{path}:{n}: expected {len(header)} values, got {len(values)}")
        try:
            row = dict(zip(header, (float(v) for v in values)))
        except ValueError:
            raise SceneError(f"{path}:{n}: every value must be a number") from None
        if not all(math.isfinite(v) for v in row.values()):
            raise SceneError(f"{path}:{n}: NaN or infinite value")
        rows.append((n, row))
    if len(rows) < 2:
        raise SceneError(f"{path}: needs at least two samples")
    time = np.array([r["time_s"] for _, r in rows])
    for (n, _), step in zip(rows[1:], np.diff(time)):
        if step <= 0:
            raise SceneError(f"{path}:{n}: time_s must increase")
    displacement = np.array([r["displacement_mm"] for _, r in rows]) / 1e3
    line = np.polyfit(time, displacement, 1)
    speed = float(line[0])
    if np.ptp(displacement) == 0:
        raise SceneError(f"{path}: displacement_mm does not change: the plate is not dragged")
    if speed <= 0:
        raise SceneError(f"{path}: displacement_mm must grow with time (a drag along +y)")
    if not SPEEDS[0] <= speed <= SPEEDS[1]:
        hint = (": are the times in ms, or the displacements in m?" if speed < SPEEDS[0] else
                ": are the times in minutes, or the displacements in µm?")
        raise SceneError(f"{path}: its drag speed is {1e3 * speed:.4g} mm/s, outside the {1e3 * SPEEDS[0]:g} to "
                         f"{1e3 * SPEEDS[1]:g} mm/s finrft supports{hint}")
    stray = float(np.abs(displacement - np.polyval(line, time)).max())
    if stray > LINEARITY * (displacement.max() - displacement.min()):
        raise SceneError(f"{path}: displacement_mm strays {1e3 * stray:.3g} mm from constant speed; a fit needs a "
                         f"drag at constant speed")
    angles = np.array([[r[c] for c in angle_columns] for _, r in rows])
    if np.abs(angles).max() > 180:
        worst = angles.flat[np.abs(angles).argmax()]
        raise SceneError(f"{path}: segment angles must lie within -180..180 deg, found {worst:g}")
    return DragData(str(path), time - time[0], speed, angles)


def write_drag(path: str | Path, data: DragData, comment: str = "") -> None:
    """Write drag data in the format `read_drag` reads (e.g. a simulated drag, to test a fit)."""
    n = data.angles.shape[1]
    lines = [f"# {comment}"] if comment else []
    lines.append(",".join(["time_s", "displacement_mm", *[f"segment{i + 1}_deg" for i in range(n)]]))
    for t, x, row in zip(data.time, 1e3 * data.displacement, data.angles):
        lines.append(",".join(repr(float(v)) for v in (t, x, *row)))
    Path(path).write_text("\n".join(lines) + "\n")


def simulated_drag(scene: Scene, speed: float, distance: float, rate: float = 30.0) -> DragData:
    """A drag of ``scene`` from flat, sampled like the measurements (``rate`` Hz)."""
    time = np.arange(0.0, distance / speed + 1e-9, 1.0 / rate)
    return DragData(f"simulated_v{1e3 * speed:g}", time, speed,
                    _angles_at(simulate(scene, Drive(speed=speed, stroke=distance)), time))


def resolve_params(names: Sequence[str], bounds: dict[str, tuple[float, float]] | None = None) -> list[Variable]:
    """Fitted parameters from names (aliases b, k, f_perp, f_par, or any numeric plate-scene key) and bounds
    (keyed by either); SceneError for bounds of a parameter that is not fitted."""
    if isinstance(names, str) or not all(isinstance(name, str) for name in names):
        raise SceneError(f"the fitted parameters must be a list of names (b, k, f_perp, f_par or plate-scene keys), "
                         f"got {names!r:.60}")
    keys = [ALIASES.get(name, name) for name in names]
    if not keys or not all(keys):
        raise SceneError(f"the fitted parameters must be named, one or more, none empty: got {', '.join(names)!r}")
    twice = sorted({k for k in keys if keys.count(k) > 1})
    if twice:
        raise SceneError(f"{', '.join(twice)} listed twice in the fitted parameters")
    bounds = {ALIASES.get(k, k): span for k, span in (bounds or {}).items()}
    stray = [k for k in bounds if k not in keys]
    if stray:
        raise SceneError(f"bounds given for {', '.join(stray)}, which {'is' if len(stray) == 1 else 'are'} not "
                         f"fitted (fitted: {', '.join(keys)})")
    variables = []
    for key in keys:
        split_key(Scene, key)
        if field_of(Scene, key).type not in ("float", float):
            raise SceneError(f"{key} is not a real-valued key (a whole number or a choice) and cannot be fitted")
        low, high = bounds.get(key, DEFAULT_BOUNDS.get(key, (None, None)))
        if low is None:
            raise SceneError(f"{key} has no default bounds: give them with --bounds {key}=LOW:HIGH")
        if not low < high:
            raise SceneError(f"bounds of {key}: lower ({low:g}) must be below upper ({high:g})")
        variables.append(Variable(key, low, high))
    return variables


def drag_for(data: DragData) -> Drive:
    return Drive(speed=data.speed, stroke=data.speed * data.time[-1])


def simulated_angles(scene: Scene, data: DragData, max_error: ErrorLimits | None = ErrorLimits()) -> np.ndarray:
    """The scene's segment angles (deg) at the data's times."""
    return _angles_at(simulate(scene, drag_for(data), max_error=max_error), data.time)


def _angles_at(run: Result, time: np.ndarray) -> np.ndarray:
    """A run's segment angles (deg, T x N) interpolated at ``time``."""
    return np.column_stack([np.interp(time, run.time, np.degrees(a)) for a in run.segment_angle.T])


def mse(scene: Scene, data: DragData, max_error: ErrorLimits = ErrorLimits()) -> float:
    """Mean squared error (deg^2) over segments and times; FAILED when the scene cannot be simulated or its
    estimated discretisation error exceeds ``max_error``: a fit must not fit a discretisation error."""
    try:
        return float(np.mean((simulated_angles(scene, data, max_error) - data.angles) ** 2))
    except (SimulationFailed, SceneError):
        return FAILED


def _mse_job(job: tuple[Scene, DragData, ErrorLimits]) -> float:
    return mse(*job)


@dataclass
class Fit:
    search: Search
    scene: Scene                   # the scene with the fitted values
    rmse_deg: dict[str, float]     # per fitted file
    validate_rmse_deg: dict[str, float]
    error_estimate_deg: dict[str, float]  # per file, fitted and validation: the angles' discretisation error


def fit(scene: Scene, data: Sequence[DragData], variables: Sequence[Variable], *, budget: int | None = None,
        seed: int | None = None, validate: Sequence[DragData] = (), log: str | Path | None = None,
        resume: bool = False, replace: bool = False, workers: int | None = None,
        max_error: ErrorLimits = ErrorLimits(), on_generation: Callable[..., None] | None = None) -> Fit:
    """Fit ``variables`` of a plate scene to drag data with CMA-ES, starting from the scene's own values. Budget,
    seed, log, resume and replace as `finrft.optimize.cmaes`; the log holds the data too, and `logged_problem` gives the
    scene, data and variables to resume it with. Scenes whose estimated discretisation error exceeds
    ``max_error`` score as failed; the fitted scene must meet it on every file (else InaccurateResult)."""
    check_variables(scene, variables, Scene)
    check_limits(max_error, optional=False)
    for what, files in (("data", data), ("validate", validate)):
        if isinstance(files, DragData) or not all(isinstance(d, DragData) for d in files):
            raise SceneError(f"fit {what}: a list of drags read by finrft.read_drag, got {files!r:.60}")
        for d in files:
            if scene.plate.segments != d.angles.shape[1]:
                raise SceneError(f"{d.path} has {d.angles.shape[1]} segments, the scene {scene.plate.segments}")
    if not data:
        raise SceneError("fit data: at least one drag to fit")
    start = {}
    for v in variables:
        section, name = split_key(Scene, v.key)
        start[v.key] = min(max(getattr(getattr(scene, section), name), v.low), v.high)

    def population(values: np.ndarray) -> tuple[list[float], dict[str, np.ndarray]]:
        scenes = [scene.replace(**{v.key: float(x) for v, x in zip(variables, row)}) for row in values]
        jobs = [(s, d, max_error) for s in scenes for d in data]
        errors = np.array(batch.map_jobs(_mse_job, jobs, executor=pool, workers=1))
        errors = errors.reshape(len(scenes), len(data))
        return list(errors.mean(axis=1)), {"rmse": np.sqrt(errors)}

    with batch.pool_for(workers=workers) as pool:
        search = cmaes(population, variables, budget=budget, seed=seed, start=start, log=log, resume=resume,
                       replace=replace, schema=searchlog.FIT, units=si_units(Scene, variables),
                       problem={"scene_toml": to_toml(scene), "objective": "mean over files of the mean squared "
                                "segment-angle error (failed or above the error limit: 1e6)", "objective_units": "deg^2",
                                "error_limit_deg": max_error.angle_deg},
                       tables=_data_tables(data),
                       columns={"rmse": ("deg", len(data), "RMS segment-angle error for each data file")},
                       on_generation=on_generation)
    if search.cost >= FAILED:
        raise SimulationFailed(f"none of the {search.evaluations} parameter sets tried could be simulated within the "
                               f"error limit: check the scene and the bounds")
    fitted = scene.replace(**search.best)
    rmse, errors = {}, {}
    for d in [*data, *validate]:
        run = simulate(fitted, drag_for(d), max_error=max_error)
        rmse[d.name] = math.sqrt(float(np.mean((_angles_at(run, d.time) - d.angles) ** 2)))
        errors[d.name] = run.error_estimate["angle_deg"]
    return Fit(search, fitted, {d.name: rmse[d.name] for d in data}, {d.name: rmse[d.name] for d in validate},
               errors)


def _data_tables(data: Sequence[DragData]) -> dict[str, searchlog.Dataset]:
    """The fitted data as log datasets, data/<i>/time, angles and speed, the file's path as an attribute."""
    tables = {}
    for i, d in enumerate(data):
        tables[f"data/{i}/time"] = searchlog.Dataset(d.time, "s", "sample times from the first", {"path": d.path})
        tables[f"data/{i}/angles"] = searchlog.Dataset(d.angles, "deg", "segment angles (samples x segments)")
        tables[f"data/{i}/speed"] = searchlog.Dataset(np.float64(d.speed), "m/s", "drag speed")
    return tables


def logged_problem(path: str | Path) -> tuple[Scene, list[DragData], list[Variable]]:
    """The scene, data and variables of a fit log, to continue it."""
    log = read_log(path, searchlog.FIT)
    try:
        files = sorted({int(name.split("/")[1]) for name in log if name.startswith("data/")})
        data = [DragData(str(log["dataset_attrs"][f"data/{i}/time"]["path"]), log[f"data/{i}/time"],
                         float(log[f"data/{i}/speed"]), log[f"data/{i}/angles"]) for i in files]
    except (KeyError, IndexError, TypeError, ValueError):
        raise SceneError(f"{path}: its fitted data (data/<i>/time, angles, speed) are incomplete") from None
    if not data:
        raise SceneError(f"{path}: it holds no fitted data")
    return scene_from_dict(read_toml(log["attrs"]["scene_toml"], f"{path}: its scene"), Scene), data, log["variables"]


def plot(fitted: Scene, files: Sequence[tuple[DragData, str]], path: str | Path) -> None:
    """Simulated against measured segment angles over displacement, one panel per file, RMSE in the legend."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(files), figsize=(5 * len(files), 4), squeeze=False, sharey=True)
    for ax, (data, role) in zip(axes[0], files):
        sim = simulated_angles(fitted, data)
        rmse = math.sqrt(float(np.mean((sim - data.angles) ** 2)))
        x = 1e3 * data.displacement
        for i in range(data.angles.shape[1]):
            line, = ax.plot(x, data.angles[:, i], label=f"segment {i + 1} measured")
            ax.plot(x, sim[:, i], "--", color=line.get_color(), label=f"segment {i + 1} simulated")
        ax.set_title(f"{data.name} ({1e3 * data.speed:.0f} mm/s, {role}): RMSE {rmse:.2f} deg")
        ax.set_xlabel("displacement (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0, 0].set_ylabel("segment angle (deg)")
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------------
# RFT identification from rigid-plate drags

def read_forces(path: str | Path) -> np.ndarray:
    """(rows, 3): attack (deg), normal and tangential force (N), one row per angle (repeated identical rows are
    merged); SceneError naming the file and line on any problem, and for repeated angles whose forces differ or
    angles that cannot identify both coefficients."""
    path = Path(path)
    lines = read_text(path, "forces file").splitlines()
    reader = csv.DictReader(line for line in lines if not line.startswith("#"))
    if reader.fieldnames is None or any(c not in reader.fieldnames for c in FORCE_COLUMNS):
        raise SceneError(f"{path}: columns must include {', '.join(FORCE_COLUMNS)}")
    rows: dict[float, tuple[int, list[float]]] = {}
    for n, row in enumerate(reader, start=2):
        try:
            values = [float(row[c]) for c in FORCE_COLUMNS]
        except (TypeError, ValueError):
            raise SceneError(f"{path}:{n}: every value must be a number") from None
        if not all(math.isfinite(v) for v in values) or not 0 <= values[0] <= 90:
            raise SceneError(f"{path}:{n}: values must be finite, attack_deg within 0..90")
        if values[0] in rows and rows[values[0]][1] != values:
            raise SceneError(f"{path}:{n}: attack {values[0]:g} deg again (line {rows[values[0]][0]}) with "
                             f"other forces: keep one row per angle")
        rows.setdefault(values[0], (n, values))
    if not rows:
        raise SceneError(f"{path}: no data")
    attack = np.array(list(rows))
    if not (attack > 0).any() or not (attack < 90).any():
        raise SceneError(f"{path}: needs an angle of attack above 0 deg (for f_perp) and one below 90 deg (for "
                         f"f_par), found only {', '.join(f'{a:g}' for a in sorted(rows))} deg")
    return np.array([values for _, values in rows.values()])


def identify_rft(forces: np.ndarray, segments: int, v_reg: float, speed: float,
                 face: float) -> tuple[RFT, ForceTable]:
    """RFT from a rigid plate of N segments dragged at attack theta, each segment's face ``face`` m^3 (area x mean
    depth, `finrft.geometry.segment_scale`), where each law gives the totals normal = -N face ramp F_perp(theta)
    and tangential = -N face ramp F_par(theta), ramp = tanh(speed / v_reg): the paper law's f_perp, f_par (N/m^3)
    by least squares (F_perp = f_perp sin theta, F_par = f_par cos theta), and the table law (N/m^3) at the
    measured angles, held at its end values out to 0 and 90 degrees."""
    scale = segments * face * math.tanh(speed / v_reg)
    order = np.argsort(forces[:, 0])
    deg, perp, par = forces[order, 0], -forces[order, 1] / scale, -forces[order, 2] / scale
    sin, cos = np.sin(np.radians(deg)), np.cos(np.radians(deg))
    f_perp = float(perp @ sin / (sin @ sin)) if sin @ sin > 0 else 0.0
    f_par = float(par @ cos / (cos @ cos)) if cos @ cos > 0 else 0.0
    if f_perp < 0:
        raise SceneError(f"the normal forces push the plate along its motion (f_perp = {f_perp:.3g} N/m^3 < 0): forces "
                         f"from finrft drag --forces-csv are those of a stroke out along +y; check their sign")
    if deg[0] > 0:
        deg, perp, par = np.r_[0.0, deg], np.r_[perp[0], perp], np.r_[par[0], par]
    if deg[-1] < 90:
        deg, perp, par = np.r_[deg, 90.0], np.r_[perp, perp[-1]], np.r_[par, par[-1]]
    return RFT(law="paper", f_perp=f_perp, f_par=f_par, v_reg=v_reg), ForceTable(deg, perp, par)


def rft_fragment(law: RFT, table_csv: str) -> str:
    """A scene fragment with the identified paper-law coefficients (and the table, as a commented option)."""
    return (f"# RFT identified from rigid-plate drags (finrft fit-rft)\n[rft]\nlaw = \"paper\"\n"
            f"f_perp = {law.f_perp!r}  # [N/m^3] per unit area and depth\nf_par = {law.f_par!r}  # [N/m^3]\n"
            f"v_reg = {law.v_reg!r}  # [m/s]\n# or the tabulated law:\n# law = \"table\"\n"
            f"# table = \"{table_csv}\"\n")


def fit_summary(result: Fit) -> dict[str, Any]:
    return {"params": result.search.best, "rmse_deg": result.rmse_deg, "validate_rmse_deg": result.validate_rmse_deg,
            "error_estimate": {"angle_deg": max(result.error_estimate_deg.values())},
            "evaluations": result.search.evaluations, "seed": result.search.seed, "budget": result.search.budget,
            "wall_s": result.search.wall_s, "mse_deg2": result.search.cost}
