"""`finrft report`: the paper's results regenerated from this package, as figures, tables and recordings.

Every figure comes from the public API a user would call (simulate, run_many, run_experiments, fit, swim, optimize).
``quick`` makes a smaller version (fewer cycles, amplitudes and evaluations) for tests.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .. import batch, record
from ..data import plate_drag_dir
from ..drive import Drive
from ..experiment import Result
from ..experiments.plate import plate_points
from .bounds import unit_of
from .fit import DEFAULT_BOUNDS, DragData, fit, read_drag, resolve_params, simulated_angles
from .optimize import optimize
from ..experiments.swim import RobotScene
from ..scene import Scene, SceneError, preset, resolution
from ..experiments.swim import Swim, steady_cycles, swim
from .table import PAPER_TABLE, PHYSICAL_FITTED, table_markdown, table_rows, table_scenes

COLORS = {"rigid": "black", "soft": "tab:blue", "origami": "tab:red"}
KINDS = ("rigid", "soft", "origami")


def demo_plate() -> Scene:
    """The plate of the force and flapping figures: the paper's plate with inertias of 1e-2 kg m^2 and damping
    0.2 N m s/rad, so that it bends and recovers within a stroke, with the newton method."""
    return preset("paper").replace(**{"plate.segment_inertia": 1e-2, "plate.rod_inertia": 1e-2,
                                      "plate.damping": 0.2, "sim.method": "newton", "sim.dt": 2.5e-4,
                                      "sim.record_dt": 0.005})


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


@contextlib.contextmanager
def _timed(timings: dict[str, float], name: str) -> Iterator[None]:
    start = time.perf_counter()
    yield
    timings[name] = time.perf_counter() - start


def _strokes(run: Result, first_cycle: int):
    """(stroke index, sample mask) for every stroke from ``first_cycle`` (0-based) on."""
    ts = run.drive.stroke_time
    for k in range(2 * first_cycle, run.drive.strokes):
        yield k, (run.time >= k * ts - 1e-9) & (run.time <= (k + 1) * ts + 1e-9)


def forces(out: Path, quick: bool, workers: int | None) -> str:
    """Figure 1: drive force against displacement (drag) and torque against angle (rotate), cycles 2-5 of 5."""
    cycles = 2 if quick else 5
    scene = demo_plate()
    drives = {"drag": Drive(speed=0.03, stroke=0.2, cycles=cycles),
              "rotate": Drive(kind="rotate", speed=math.radians(60), stroke=math.radians(120), cycles=cycles)}
    jobs = [(scene.replace(**{"plate.kind": k}), d) for d in drives.values() for k in KINDS]
    runs = dict(zip([(t, k) for t in drives for k in KINDS], batch.run_many(jobs, workers=workers)))
    record.write_rrd(runs[("drag", "origami")], out / "drag_origami.rrd", force=True)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, test in zip(axes, drives):
        for kind in KINDS:
            run = runs[(test, kind)]
            x = 1e3 * run.displacement if test == "drag" else np.degrees(run.displacement)
            for k, pick in _strokes(run, 1):
                ax.plot(x[pick], run.drive_force[pick], color=COLORS[kind], lw=1.2,
                        ls="-" if k % 2 == 0 else "--",
                        label=f"{kind}, {'recovery' if k % 2 == 0 else 'power'}" if k in (2, 3) else None)
        ax.axhline(0, color="grey", lw=0.5)
        # The origami plate's stops take short impacts as it snaps flat: keep the steady loads readable.
        steady = 1.5 * np.abs(runs[(test, "rigid")].drive_force).max()
        ax.set_ylim(-steady, steady)
        ax.set_xlabel("displacement (mm)" if test == "drag" else "rotation (deg)")
        ax.set_ylabel("drive force (N)" if test == "drag" else "drive torque (N m)")
        ax.set_title(f"{test}: cycles 2-{cycles} of {cycles}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "forces.png", dpi=150)
    plt.close(fig)
    origami = runs[("drag", "origami")].cycle_table()[-1]
    rigid = runs[("drag", "rigid")].cycle_table()[-1]
    return (f"![drive force and torque](forces.png)\n\nThe axes stop at 1.5 x the rigid plate's load. Beyond "
            f"them: the origami plate's hinges slamming into their stops as it snaps flat (drag), and, in rotation, "
            f"the plate ringing on its stops early in the power stroke (its 1e-2 kg m^2 segments on the stiff stop: "
            f"the same at a fifth of the step, and with f_par > 0). The drive force over the last cycle: rigid plate "
            f"{rigid['mean_power_force_N']:+.2f} N in the power stroke, origami {origami['mean_power_force_N']:+.2f} N "
            f"(power) and {origami['mean_recovery_force_N']:+.2f} N (recovery); net impulse per cycle "
            f"{origami['net_impulse_Ns']:+.2f} N s for the origami plate, {rigid['net_impulse_Ns']:+.2f} N s for the "
            f"rigid one. Recording: `drag_origami.rrd`.")


def flapping(out: Path, quick: bool, workers: int | None) -> str:
    """Figure 2: plate shapes over a cycle at small and large amplitude, and net impulse against amplitude."""
    scene = demo_plate()
    small, large = 0.02, 0.2
    shapes = {(k, a): Drive(speed=0.03, stroke=a, cycles=2) for k in ("soft", "origami") for a in (small, large)}
    amplitudes = np.linspace(0.01, 0.2, 4 if quick else 10)
    sweep = [(k, a) for k in KINDS for a in amplitudes]
    jobs = [(scene.replace(**{"plate.kind": k}), d) for (k, _), d in shapes.items()]
    jobs += [(scene.replace(**{"plate.kind": k}), Drive(speed=0.03, stroke=float(a), cycles=2)) for k, a in sweep]
    runs = batch.run_many(jobs, workers=workers)
    plt = _pyplot()
    fig = plt.figure(figsize=(14, 7))
    grid = fig.add_gridspec(2, 4)
    for i, ((kind, amplitude), run) in enumerate(zip(shapes, runs)):
        ax = fig.add_subplot(grid[0, i])
        points = plate_points(run)
        second = np.flatnonzero((run.time >= 2 * run.drive.stroke_time - 1e-9))
        index = second[np.linspace(0, len(second) - 1, 16).astype(int)]
        colors = plt.cm.viridis(np.linspace(0, 1, len(index)))
        for c, j in zip(colors, index):
            ax.plot(1e3 * points[j, :, 0], 1e3 * points[j, :, 1], color=c, lw=1)
        ax.set_title(f"{kind}, amplitude {1e3 * amplitude:.0f} mm (cycle 2)", fontsize=9)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    ax = fig.add_subplot(grid[1, :])
    impulses = {k: [] for k in KINDS}
    for (kind, _), run in zip(sweep, runs[len(shapes):]):
        impulses[kind].append(run.cycle_table()[-1]["net_impulse_Ns"])
    for kind in KINDS:
        ax.plot(1e3 * amplitudes, impulses[kind], "o-", color=COLORS[kind], label=kind)
    origami = np.array(impulses["origami"])
    threshold = 1e3 * amplitudes[np.argmax(origami > 0.1 * origami.max())] if origami.max() > 0 else float("nan")
    ax.axvline(threshold, color=COLORS["origami"], ls=":", label=f"D_f1 ~ {threshold:.0f} mm (origami thrust "
                                                                  f"above 10 % of its largest)")
    ax.set_xlabel("stroke amplitude (mm)")
    ax.set_ylabel("net impulse per cycle, cycle 2 (N s)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "flapping.png", dpi=150)
    plt.close(fig)
    return (f"![effective flapping](flapping.png)\n\nShapes over the second cycle (colour: time, dark to light); "
            f"net impulse per cycle against amplitude. The origami plate's net thrust starts near "
            f"D_f1 = {threshold:.0f} mm; the rigid and soft plates stay near zero.")


def measurements(data_dir: str | Path | None = None) -> list[DragData]:
    """The drags of Figure 3: every CSV in ``data_dir`` (default: the measurements shipped with finrft);
    SceneError when there are none, so that a report never goes without its figure."""
    folder = Path(data_dir) if data_dir is not None else plate_drag_dir()
    if not folder.is_dir():
        raise SceneError(f"--data {folder} is not a folder: give the folder that holds the drag CSV files")
    files = sorted(folder.glob("*.csv"))
    if not files:
        raise SceneError(f"no drag data (*.csv) in {folder}: the model-against-experiment figure needs it")
    return [read_drag(p) for p in files]


# The coefficients of a segment law that the report fits beside k and b: normal, then tangential (positive both).
COEFFICIENTS = {"paper": ("f_perp", "f_par"), "sandswim": ("c_s", "c_f")}


def experiment(out: Path, quick: bool, workers: int | None, data: list[DragData], scene: Scene) -> str:
    """Figure 3: segment angles against displacement, measured and simulated, and the MSE per speed and segment,
    for the paper's procedure (damping only) and for a fit of k, b and the law's normal and tangential
    coefficients (`COEFFICIENTS`) on two speeds."""
    if scene.rft.law not in COEFFICIENTS:
        raise SceneError(f"the report fits the segment law's two coefficients, which rft.law = {scene.rft.law!r} "
                         f"has not: use a plate scene of law {' or '.join(map(repr, COEFFICIENTS))}")
    coefficients = [f"rft.{name}" for name in COEFFICIENTS[scene.rft.law]]
    # around the scene's own values, a decade either way (the paper law's keys have their default bounds)
    bounds = {key: (getattr(scene.rft, key[4:]) / 10, 10 * getattr(scene.rft, key[4:])) for key in coefficients
              if key not in DEFAULT_BOUNDS}
    budget = 20 if quick else 300
    fits = {"paper procedure: b only, all speeds": fit(scene, data, resolve_params(["b"]), budget=budget,
                                                       workers=workers)}
    train = [data[0], data[-1]] if len(data) > 2 else data
    validate = [d for d in data if d not in train]
    fits[f"k, b, {', '.join(k[4:] for k in coefficients)} on {', '.join(d.name for d in train)}"] = fit(
        scene, train, resolve_params(["k", "b", *coefficients], bounds), budget=budget, workers=workers,
        validate=validate)
    plt = _pyplot()
    fig, axes = plt.subplots(len(fits), 2, figsize=(13, 4.5 * len(fits)), squeeze=False,
                             gridspec_kw={"width_ratios": [2, 1]})
    lines = []
    grid = np.linspace(0.0, min(1e3 * d.displacement[-1] for d in data), 200)
    for row, (name, result) in zip(axes, fits.items()):
        simulated = [simulated_angles(result.scene, d) for d in data]
        for i in range(data[0].angles.shape[1]):
            measured = np.mean([np.interp(grid, 1e3 * d.displacement, d.angles[:, i]) for d in data], axis=0)
            sims = np.array([np.interp(grid, 1e3 * d.displacement, s[:, i]) for d, s in zip(data, simulated)])
            line, = row[0].plot(grid, measured, lw=2, label=f"segment {i + 1} measured (mean over speeds)")
            row[0].fill_between(grid, sims.min(axis=0), sims.max(axis=0), color=line.get_color(), alpha=0.25,
                                label=f"segment {i + 1} simulated (range over speeds)")
        row[0].set_title(name, fontsize=10)
        row[0].set_xlabel("displacement (mm)")
        row[0].set_ylabel("segment angle (deg)")
        row[0].grid(alpha=0.3)
        row[0].legend(fontsize=7)
        mse = np.array([np.mean((s - d.angles) ** 2, axis=0) for d, s in zip(data, simulated)])
        width = 0.8 / mse.shape[1]
        for i in range(mse.shape[1]):
            row[1].bar(np.arange(len(data)) + i * width, mse[:, i], width, label=f"segment {i + 1}")
        row[1].set_xticks(np.arange(len(data)) + 0.4 - width / 2, [f"{1e3 * d.speed:.0f} mm/s" for d in data])
        row[1].set_ylabel("MSE (deg^2)")
        row[1].legend(fontsize=7)
        row[1].grid(alpha=0.3, axis="y")
        values = ", ".join(f"{k} = {v:.4g} {unit_of(Scene, k) or ''}".rstrip() for k, v in result.search.best.items())
        rmse = ", ".join(f"{k} {v:.2f} deg" for k, v in {**result.rmse_deg, **result.validate_rmse_deg}.items())
        lines.append(f"- {name}: {values}; RMSE {rmse}" + (" (validation: " + ", ".join(
            result.validate_rmse_deg) + ")" if result.validate_rmse_deg else ""))
    fig.tight_layout()
    fig.savefig(out / "experiment.png", dpi=150)
    plt.close(fig)
    return "![model against experiment](experiment.png)\n\n" + "\n".join(lines)


def robot(out: Path, quick: bool, workers: int | None) -> str:
    """Table I, the optimisation trace with its optimum, and the body's trajectory for each gait."""
    scene = preset("paper", RobotScene)
    if quick:
        scene = scene.replace(**{"sim.dt": 1e-4})
    cycles = 1 if quick else 3
    gaits = table_scenes(scene)
    # Table I is the first cycle from rest, as the paper simulated it; the trajectories go on for more.
    first = batch.run_experiments([(Swim(1), s) for s in gaits], workers=workers)
    rows = table_rows(first)
    runs = batch.run_experiments([(Swim(cycles), s) for s in gaits], workers=workers) if cycles > 1 else first
    generations = []
    search = optimize(scene, budget=12 if quick else 300, seed=1, workers=workers,
                      on_generation=lambda g, values, extras, es: generations.append((values, extras["eta"])))
    best = swim(scene.replace(**search.best), 1)
    error = best.error_estimate["eta_points"]
    record.write_rrd(best, out / "robot_optimum.rrd", force=True)
    record.write_optimization_rrd(out / "optimization.rrd",
                                  [(np.c_[np.degrees(v[:, :2]), 1e3 * v[:, 2:]], e) for v, e in generations],
                                  [v.key for v in search.variables], best)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    trace = 100 * (1 - np.minimum.accumulate(search.best_cost_per_generation))
    axes[0].plot(np.arange(1, len(trace) + 1), trace, "o-")
    g = scene.replace(**search.best).gait
    axes[0].set_title(f"best eta {trace[-1]:.2f} % (estimated error {error:.2g} points) at theta1 "
                      f"{math.degrees(g.theta1):.1f} deg, theta2 {math.degrees(g.theta2):.1f} deg, L_a "
                      f"{1e3 * search.best['arm.length']:.1f} mm", fontsize=9)
    axes[0].set_xlabel("generation")
    axes[0].set_ylabel("best eta so far (%)")
    axes[0].grid(alpha=0.3)
    _trajectories(axes[1], runs, cycles)
    fig.tight_layout()
    fig.savefig(out / "robot.png", dpi=150)
    plt.close(fig)
    return (f"Paper preset ({resolution(scene.sim)}), one flap cycle from rest:\n\n"
            f"{table_markdown(rows)}\n\n![optimisation and trajectories](robot.png)\n\n"
            f"CMA-ES: {search.evaluations} evaluations in {search.wall_s:.1f} s; its optimum, eta "
            f"{100 * (1 - search.cost):.2f} %, carries an estimated discretisation error of {error:.2g} points (every "
            f"evaluation is checked; those above 0.5 points score as failed). Recordings: "
            f"`robot_optimum.rrd`, `optimization.rrd`. See the documentation (docs/guide/robot.md) for why eta is negative on "
            f"the paper's definition and for the optimiser's sensitivity to dt.")


def _trajectories(ax: Any, runs: list[Result], cycles: int) -> None:
    """The body's forward position over time, one line per Table I gait."""
    for (name, *_), run in zip(PAPER_TABLE, runs):
        ax.plot(run.time, 1e3 * run.body_y, label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("body position, forward (mm)")
    ax.set_title(f"body trajectory, {cycles} flap cycle(s) per gait", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def robot_physical(out: Path, quick: bool, workers: int | None) -> str:
    """The physical preset against the experiments of Table I: eta and net speed per gait, model beside
    measurement, and the body's trajectory over four flap cycles (two when ``quick``), eta over cycles 2..4."""
    scene = preset("physical", RobotScene)
    gaits = table_scenes(scene.replace(**{"gait.cycles": 2 if quick else max(4, scene.gait.cycles)}))
    runs = batch.run_experiments([(Swim(s.gait.cycles), s) for s in gaits], workers=workers)
    rows = table_rows(runs, PHYSICAL_FITTED)
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    x = np.arange(len(rows))
    names = [r["gait"] + (" (fitted)" if r["fitted"] else "") for r in rows]
    for ax, key, paper, label in ((axes[0], "eta", "paper_eta_exp", "eta (%)"),
                                  (axes[1], "net_speed_mm_s", "paper_net_speed_exp_mm_s", "net speed (mm/s)")):
        scale = 100 if key == "eta" else 1
        ax.bar(x - 0.2, [scale * r[key] for r in rows], 0.4, label="model (steady cycles)")
        ax.bar(x + 0.2, [scale * r[paper] for r in rows], 0.4, label="measured (Table I)")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(label)
        ax.axhline(0, color="k", lw=0.5)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=8)
    axes[0].set_title("swimming efficiency, model against experiment", fontsize=9)
    axes[1].set_title(f"net speed at the model's omega {math.degrees(scene.gait.omega):.0f} deg/s", fontsize=9)
    _trajectories(axes[2], runs, gaits[0].gait.cycles)
    fig.tight_layout()
    fig.savefig(out / "robot_physical.png", dpi=150)
    plt.close(fig)
    mean = np.mean([abs(r["eta"] - r["paper_eta_exp"]) for r in rows])
    return (f"Physical preset (forces from 3D-RFT in its [medium], {resolution(scene.sim)}), eta over the steady "
            f"{steady_cycles(gaits[0].gait.cycles)}; mean |eta - eta_exp| {100 * mean:.2f} points:\n\n"
            f"{table_markdown(rows)}\n\n![model against experiment, trajectories](robot_physical.png)\n\n"
            f"See the documentation (docs/guide/robot.md) for the model, what was fitted and where it fails.")


def write_report(out: str | Path = "report", *, quick: bool = False, workers: int | None = None,
                 data_dir: str | Path | None = None, plate: Scene | None = None,
                 progress: Callable[[int, int, str], None] | None = None) -> Path:
    """Write out/report.md with its figures and recordings; returns the report's path. ``data_dir``: the drag
    measurements (default: those shipped with finrft); ``plate``: the scene fitted to them (default: the paper
    preset); ``progress(parts done, parts, part starting)``. The files are made in a folder beside ``out`` and
    moved into it only when every part has succeeded."""
    out = Path(out)
    data = measurements(data_dir)
    timings: dict[str, float] = {}
    sections = []
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    parts = (("1. Dragging and rotating", lambda: forces(staging, quick, workers)),
             ("2. Effective flapping", lambda: flapping(staging, quick, workers)),
             ("3. Model against experiment", lambda: experiment(staging, quick, workers, data,
                                                                 plate or preset("paper"))),
             ("4. The robot: Table I, optimisation, trajectories", lambda: robot(staging, quick, workers)),
             ("5. The physical robot against the experiments", lambda: robot_physical(staging, quick, workers)))
    try:
        for i, (title, make) in enumerate(parts):
            if progress is not None:
                progress(i, len(parts), title)
            with _timed(timings, title):
                sections.append(f"## {title}\n\n{make()}\n")
        if progress is not None:
            progress(len(parts), len(parts), "")
        speed = ["| part | wall time (s) |", "|---|---:|"] + [f"| {k} | {v:.1f} |" for k, v in timings.items()]
        speed.append(f"| total | {sum(timings.values()):.1f} |")
        text = [f"# finrft report{' (quick)' if quick else ''}", "",
                "The results of *Compliant Fins for Locomotion in Granular Media* (RA-L 2021) regenerated by "
                "finrft. Units: mm, mm/s, degrees, N and N m.", "", *sections, "## 6. Speed", "", *speed, ""]
        (staging / "report.md").write_text("\n".join(text))
        out.mkdir(exist_ok=True)
        for made in staging.iterdir():
            os.replace(made, out / made.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out / "report.md"
