"""Benchmarks, measured as ratios within one run on this machine (never as timed tests)."""

from __future__ import annotations

import contextlib
import platform
import time
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any, Callable, Protocol

import mujoco
import numpy as np

from .. import batch, methods, models, native
from ..drive import Drive
from ..convergence import ErrorLimits
from ..errors import Chatter, NotConverged, SimulationFailed, StepUnderflow, UndefinedResult
from .fit import fit, read_drag, resolve_params, simulated_drag
from ..experiment import Experiment, run as run_experiment
from .optimize import evaluation_scene, optimize
from ..scene import PRESETS, RobotScene, Scene, preset, resolution
from ..schema import field_of
from ..experiments.plate import PlateTest, simulate
from ..experiments.swim import Swim, steady_cycles, swim


# progress(cases done, cases): called as each measured case of a benchmark finishes.
Progress = Callable[[int, int], None] | None


def _tick(progress: Progress, done: int, total: int) -> None:
    if progress is not None:
        progress(done, total)


def _best(fn: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def backends(scene: Scene | None = None, *, batch_size: int = 64, workers: int | None = None,
             repeat: int = 3, log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """The paper plate drag (200 mm at 30 mm/s) with each backend, against bare MuJoCo stepping of the same
    model without RFT, and the batch throughput of ``batch_size`` drags on ``workers`` cores: a process pool of
    whole runs (`batch.run_many`) and their states stepped on threads (`batch.PlateRollouts`)."""
    scene = scene or preset("paper")
    drive = Drive(speed=0.03, stroke=0.2)
    workers = workers or batch.default_workers()
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores, {platform.python_implementation()} "
                           f"{platform.python_version()}", "mujoco": mujoco.__version__, "dt": scene.sim.dt}
    steps = simulate(scene, drive, estimate_error=False).steps
    out["steps"] = steps
    for i, backend in enumerate(("python", "native")):
        wall = _best(lambda: simulate(scene.replace(**{"sim.backend": backend}), drive, estimate_error=False),
                     repeat)
        out[f"{backend}_wall_s"], out[f"{backend}_steps_per_s"] = wall, steps / wall
        log(f"{backend:>6} backend: {wall * 1e3:8.1f} ms per drag, {steps / wall:10.0f} steps/s")
        _tick(progress, i + 1, 4)

    # The step alone, with and without the plugin: the same model, integrator and motion (the drive at its
    # speed), stepped in C (mj_step's nstep) so that neither pays Python per step, without MuJoCo's profiling
    # timer as finrft steps (native.untimed); interleaved, so that the machine's load weighs on both alike. The
    # bare step with the timer that MuJoCo's Python bindings install gives its cost.
    bare = scene.replace(**{"sim.backend": "python"})
    loops = {"bare": _stepping(bare, drive, steps), "native_step": _stepping(scene, drive, steps),
             "bare_timed": _stepping(bare, drive, steps, timed=True)}
    walls = {name: min(times) for name, times in _interleaved(loops, max(repeat, 7)).items()}
    _tick(progress, 3, 4)
    for name, wall in walls.items():
        out[f"{name}_wall_s"], out[f"{name}_steps_per_s"] = wall, steps / wall
    out["timer_cost"] = walls["bare_timed"] / walls["bare"] - 1
    log(f"  bare mj_step, same model without RFT: {walls['bare'] * 1e3:8.1f} ms, {steps / walls['bare']:10.0f} "
        f"steps/s; with the RFT plugin {walls['native_step'] * 1e3:8.1f} ms; MuJoCo's profiling timer, which finrft "
        f"turns off while it steps, would add {100 * out['timer_cost']:.0f} % to the bare step")
    out["native_over_python"] = out["python_wall_s"] / out["native_wall_s"]
    out["native_over_bare"] = walls["native_step"] / walls["bare"]
    out["drag_over_bare"] = out["native_wall_s"] / walls["bare"]
    log(f"native is {out['native_over_python']:.1f}x faster than the Python callback (target >= 10x); its step "
        f"costs {out['native_over_bare']:.2f}x bare mj_step (target <= 1.3x), the whole drag (model, recording, "
        f"chatter probe) {out['drag_over_bare']:.2f}x")
    for name in PRESETS[Scene]:
        out[f"error_estimate_overhead_{name}"] = _estimate_overhead(
            lambda **options: simulate(preset(name), drive, max_error=None, **options), repeat)
        log(f"error estimate on the {name} preset's drag: {100 * out[f'error_estimate_overhead_{name}']:.0f} % of "
            f"the run (target <= 30 %)")

    jobs = _drags(scene, drive, batch_size)
    serial = _best(lambda: batch.run_many(jobs, workers=1), 1)
    parallel = _pool_rate(jobs, workers)
    first, rolled = _rollout_rate(scene, drive, batch_size, workers)
    _tick(progress, 4, 4)
    total = steps * batch_size
    bare = workers * out["bare_steps_per_s"]
    out.update(batch_size=batch_size, workers=workers, batch_serial_steps_per_s=total / serial,
               batch_parallel_steps_per_s=total / parallel, batch_speedup=serial / parallel,
               batch_parallel_over_bare=total / parallel / bare, batch_rollout_steps_per_s=total / rolled,
               batch_rollout_over_bare=total / rolled / bare, batch_rollout_first_steps_per_s=total / first,
               batch_rollout_first_over_bare=total / first / bare)
    log(f"batch of {batch_size} drags: {total / serial:10.0f} steps/s on 1 core, {total / parallel:10.0f} steps/s "
        f"on {workers} workers ({serial / parallel:.2f}x; {out['batch_parallel_over_bare']:.2f} of workers x bare), "
        f"their states on threads {total / rolled:10.0f} steps/s ({out['batch_rollout_over_bare']:.2f} of workers x "
        f"bare; target >= 0.8; the first batch, which compiles its models, "
        f"{out['batch_rollout_first_over_bare']:.2f})")
    return out


def _stepping(scene: Scene, drive: Drive, steps: int, timed: bool = False) -> Callable[[], None]:
    """``steps`` of mj_step, in C, of the plate's model with the drive at its speed: without MuJoCo's profiling
    timer, as finrft steps, unless ``timed``."""
    plate = models.build_plate(scene)

    def run() -> None:
        d = mujoco.MjData(plate.model)
        d.qvel[plate.drive_dof] = drive.stroke_velocity(0)
        with contextlib.nullcontext() if timed else native.untimed():
            mujoco.mj_step(plate.model, d, steps)
    return run


def _interleaved(runs: dict[str, Callable[[], Any]], rounds: int) -> dict[str, list[float]]:
    """Wall times of each run, taken in turn ``rounds`` times."""
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(rounds):
        for name, fn in runs.items():
            times[name].append(_best(fn, 1))
    return times


def _drags(scene: Scene, drive: Drive, n: int, seed: int = 0) -> list[tuple[Scene, Drive]]:
    """``n`` drags of the scene with the plate's damping drawn from 0.5 to 2.5 N m s/rad."""
    rng = np.random.default_rng(seed)
    return [(scene.replace(**{"plate.damping": float(b)}), drive) for b in rng.uniform(0.5, 2.5, n)]


def _pool_rate(jobs: list[tuple[Scene, Drive]], workers: int) -> float:
    """Wall time of `batch.run_many` of the jobs on a warm pool of ``workers`` processes."""
    if workers == 1:
        return _best(lambda: batch.run_many(jobs, workers=1), 1)
    with batch.local_executor(workers) as pool:
        batch.run_many(jobs[:workers], executor=pool)  # start the workers before timing
        return _best(lambda: batch.run_many(jobs, executor=pool), 1)


def _rollout_rate(scene: Scene, drive: Drive, n: int, workers: int) -> tuple[float, float]:
    """Wall times of batches of ``n`` drags (`_drags`) on one `batch.PlateRollouts` of ``workers`` threads: the
    first, which compiles its models, and the best of the next two, each with other dampings, which reuse them as a
    sweep's batches do."""
    with batch.PlateRollouts(workers) as rollouts:
        first = _best(lambda: rollouts(_drags(scene, drive, n)), 1)
        later = [_drags(scene, drive, n, seed) for seed in (1, 2)]
        return first, min(_best(lambda: rollouts(jobs), 1) for jobs in later)


def scaling(path: str | Path, scene: Scene | None = None, *, batch_size: int = 64,
            counts: list[int] | None = None, measured: dict[str, Any] | None = None,
            log: Callable[[str], None] = print) -> dict[str, Any]:
    """Batch throughput (steps/s) of the paper drag against the number of workers (1, 2 and up to the cores):
    the process pool of whole runs and the threaded batch of their states, with bare mj_step on one core times
    the workers for scale; a chart at ``path``. ``measured``: the figures of `backends` in the same run, whose bare
    rate and batches on its workers the chart takes rather than measure them again (and disagree by the noise)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scene = scene or preset("paper")
    drive = Drive(speed=0.03, stroke=0.2)
    counts = counts or list(range(1, max(2, batch.default_workers()) + 1))
    steps = simulate(scene, drive, estimate_error=False).steps
    measured = measured if measured and measured.get("batch_size") == batch_size else {}
    bare = measured.get("bare_steps_per_s") or steps / _best(_stepping(scene.replace(**{"sim.backend": "python"}),
                                                                       drive, steps), 7)
    jobs = _drags(scene, drive, batch_size)
    total = steps * batch_size
    rows = []
    for n in counts:
        if n == measured.get("workers"):
            pool, rolled = measured["batch_parallel_steps_per_s"], measured["batch_rollout_steps_per_s"]
        else:
            pool, rolled = total / _pool_rate(jobs, n), total / _rollout_rate(scene, drive, batch_size, n)[1]
        rows.append({"workers": n, "pool_steps_per_s": pool, "rollout_steps_per_s": rolled,
                     "bare_steps_per_s": n * bare})
        log(f"{n} workers: pool {rows[-1]['pool_steps_per_s']:10.0f}, threads {rows[-1]['rollout_steps_per_s']:10.0f}"
            f" steps/s (bare x workers {n * bare:10.0f})")
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for key, label, style in (("rollout_steps_per_s", "threaded batch (states)", "o-"),
                              ("pool_steps_per_s", "process pool (whole runs)", "s-"),
                              ("bare_steps_per_s", "bare mj_step x workers", "k--")):
        ax.plot(counts, [r[key] / 1e3 for r in rows], style, label=label)
    ax.set(xlabel="workers", ylabel="thousand steps / s", xticks=counts,
           title=f"{batch_size} paper drags of {steps} steps, {batch.default_workers()} cores")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"date": date.today().isoformat(), "batch_size": batch_size, "steps": steps, "rows": rows}


def robot(scene: RobotScene | None = None, *, budget: int = 300, workers: int | None = None, repeat: int = 3,
          log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """One gait evaluation (as the optimiser runs it: gait.cycles flap cycles, eta over the steady ones, the body
    recorded at the reversals) against a converged reference, and a full CMA-ES optimisation of ``budget``
    evaluations."""
    scene = scene or preset("paper", RobotScene)
    workers = workers or batch.default_workers()
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores", "mujoco": mujoco.__version__, "dt": scene.sim.dt,
                           "method": scene.sim.method}
    cycles, evaluated = scene.gait.cycles, evaluation_scene(scene)
    run = swim(evaluated, cycles, estimate_error=False)
    wall = _best(lambda: swim(evaluated, cycles, estimate_error=False), repeat)
    converged, label = _converged(scene)
    reference = swim(converged, cycles, estimate_error=False)
    eta, eta_reference = run.summary()["eta_steady"], reference.summary()["eta_steady"]
    out.update(gait_cycles=cycles, gait_steps=run.steps, gait_steps_rejected=run.steps_rejected, gait_wall_s=wall,
               gait_us_per_step=1e6 * wall / run.steps, gait_eta=eta, gait_eta_reference=eta_reference,
               gait_eta_error=abs(eta - eta_reference), gait_reference=label,
               error_estimate_overhead=_estimate_overhead(lambda **o: swim(evaluated, cycles, max_error=None, **o),
                                                          repeat))
    log(f"one gait evaluation ({cycles} flap cycle(s), eta over {steady_cycles(cycles)}; {resolution(scene.sim)}, "
        f"{run.steps} steps): {wall * 1e3:.1f} ms (target <= 10 ms; the authors' model ~15 s); its error estimate "
        f"costs {100 * out['error_estimate_overhead']:.0f} % more (target <= 30 %); eta {100 * eta:.3f} %, "
        f"{100 * out['gait_eta_error']:.4f} points from the reference ({label}: {100 * eta_reference:.3f} %; "
        f"target <= 0.05)")
    _tick(progress, 1, 2)
    result = optimize(scene, budget=budget, seed=1, workers=workers)
    _tick(progress, 2, 2)
    out.update(optimize_budget=budget, optimize_evaluations=result.evaluations, optimize_wall_s=result.wall_s,
               optimize_eta=1 - result.cost, best=result.best, workers=workers)
    log(f"optimize, budget {budget} ({result.evaluations} evaluations) on {workers} workers: {result.wall_s:.1f} s "
        f"(target <= 60 s), best eta {100 * (1 - result.cost):.2f} %")
    return out


def _converged(scene: Any) -> tuple[Any, str]:
    """The scene at a resolution whose result stands for the converged one, and its label: an adaptive method at
    1/100 of the tolerance (its reversals fall on the drive's instants, so its grid does not matter), a fixed step
    at 1/10 of the step."""
    sim = scene.sim
    if methods.get(sim.method).adaptive:
        return (scene.replace(**{"sim.tolerance": sim.tolerance / 100}),
                f"{sim.method}, tolerance {sim.tolerance / 100:g}")
    return scene.replace(**{"sim.dt": sim.dt / 10}), f"{sim.method}, dt {sim.dt / 10:g} s"


def _estimate_overhead(run: Callable[..., Any], repeat: int) -> float:
    """What the always-on error estimate adds to a run, as a fraction of the run without it (best of
    ``repeat`` each, interleaved so that machine load affects both alike)."""
    plain, checked = [], []
    for _ in range(max(repeat, 5)):
        plain.append(_best(lambda: run(estimate_error=False), 1))
        checked.append(_best(run, 1))
    return min(checked) / min(plain) - 1


def fit_speed(paths: list[str] | None = None, *, budget: int = 300, workers: int | None = None,
              log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """A 4-parameter fit (k, b, f_perp, f_par) of the paper plate over three drag files with ``budget``
    evaluations: the given files, or the model's own drags at 10, 30 and 50 mm/s over 200 mm. ``progress``
    counts evaluations (at most ``budget``)."""
    scene = preset("paper")
    data = [read_drag(p) for p in paths] if paths else [
        simulated_drag(scene.replace(**{"plate.damping": 0.8}), v, 0.2) for v in (0.01, 0.03, 0.05)]
    workers = workers or batch.default_workers()
    result = fit(scene, data, resolve_params(["k", "b", "f_perp", "f_par"]), budget=budget, seed=1,
                 workers=workers, on_generation=lambda g, values, extras, es:
                 _tick(progress, min(es.countevals, budget), budget))
    out = {"date": date.today().isoformat(), "files": [d.name for d in data], "budget": budget,
           "evaluations": result.search.evaluations, "wall_s": result.search.wall_s, "workers": workers,
           "rmse_deg": result.rmse_deg}
    log(f"4-parameter fit over {len(data)} files, budget {budget} ({result.search.evaluations} evaluations) on "
        f"{workers} workers: {result.search.wall_s:.1f} s (target <= 30 s); RMSE "
        + ", ".join(f"{k} {v:.2f} deg" for k, v in result.rmse_deg.items()))
    return out


# ---------------------------------------------------------------------------------------------------------
# What each modelling choice costs and changes


MODELLING_CASES = 9  # chain x 2 presets, rigid plate x 2, origami stop x 3, robot x 2


def _plate_pair(a: Scene, b: Scene, drive: Drive, repeat: int) -> dict[str, float]:
    """Two plate models of the same test: the largest difference of their segment angles (deg) and drive force
    (% of the peak), and their best wall times."""
    first, second = simulate(a, drive, estimate_error=False), simulate(b, drive, estimate_error=False)
    return {"angle_diff_deg": float(np.degrees(np.abs(first.segment_angle - second.segment_angle)).max()),
            "force_diff_pct": float(100 * np.abs(first.drive_force - second.drive_force).max()
                                    / first.peak_drive_force),
            "wall_a_s": _best(lambda: simulate(a, drive, estimate_error=False), repeat),
            "wall_b_s": _best(lambda: simulate(b, drive, estimate_error=False), repeat)}


def modelling(*, repeat: int = 3, log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """Measure what each modelling choice costs and changes: a planar chain against a 3D chain free to turn
    out of the plane, the half robot against the full one, a MuJoCo limit stop against the penalty stop, and a
    rigid plate as one body against hinged segments held by welds. Returns the rows and a Markdown table."""
    drag = Drive()  # 200 mm at 30 mm/s
    cycle = PLATE_DRIVE  # 45 mm out and back
    rows = []

    def add(choice: str, scene: str, a: str, b: str, pair: dict[str, float], note: str = "") -> None:
        row = {"choice": choice, "scene": scene, "a": a, "b": b, **pair,
               "cost_ratio": pair["wall_b_s"] / pair["wall_a_s"], "note": note}
        rows.append(row)
        _tick(progress, len(rows), MODELLING_CASES)
        log(f"{choice}, {scene}: {a} {1e3 * pair['wall_a_s']:.1f} ms, {b} {1e3 * pair['wall_b_s']:.1f} ms; "
            + ", ".join(f"{k} {v:.3g}" for k, v in pair.items() if not k.startswith("wall")))

    for name in ("paper", "physical"):
        scene = preset(name)
        add("chain", f"plate {name}, 200 mm drag", "planar", "spatial",
            _plate_pair(scene, scene.replace(**{"plate.chain": "spatial"}), drag, repeat))
    for name in ("paper", "physical"):
        scene = preset(name).replace(**{"plate.kind": "rigid"})
        add("rigid plate", f"plate {name}, 200 mm drag", "one body", "welded segments",
            _plate_pair(scene, scene.replace(**{"plate.rigid_as": "welds"}), drag, repeat))
    for name, dt in (("paper", 1e-3), ("physical", 1e-3), ("physical", 1e-4)):
        scene = preset(name).replace(**{"sim.dt": dt})
        pair = _plate_pair(scene.replace(**{"plate.stop": "penalty"}), scene.replace(**{"plate.stop": "limit"}),
                           cycle, repeat)
        fine = [simulate(scene.replace(**{"plate.stop": stop, "sim.dt": 1e-5}), cycle, estimate_error=False)
                for stop in ("penalty", "limit")]
        coarse = [simulate(scene.replace(**{"plate.stop": stop}), cycle, estimate_error=False)
                  for stop in ("penalty", "limit")]
        errors = [float(np.degrees(np.abs(c.segment_angle - f.segment_angle)).max()) for c, f in zip(coarse, fine)]
        add("origami stop", f"plate {name} ({scene.sim.method}, dt {dt:g} s), 45 mm out and back", "penalty",
            "limit", pair, f"error against the same stop at 10 µs: penalty {errors[0]:.2g}°, limit {errors[1]:.2g}°")
    for name in ("paper", "physical"):
        scene = preset(name, RobotScene)
        full_scene = scene.replace(**{"robot.model": "full"})
        half, full = swim(scene, 1, estimate_error=False), swim(full_scene, 1, estimate_error=False)
        pair = {"eta_diff_pts": 100 * abs(half.cycle_table()[0]["eta"] - full.cycle_table()[0]["eta"]),
                "wall_a_s": _best(lambda: swim(scene, 1, estimate_error=False), repeat),
                "wall_b_s": _best(lambda: swim(full_scene, 1, estimate_error=False), repeat)}
        add("robot", f"robot {name}, optimised gait, one cycle", "half", "full", pair)
    lines = ["| choice | scene | A | B | what changes (B against A) | cost of B / A |", "|---|---|---|---|---|---:|"]
    for r in rows:
        change = ", ".join(f"{v:.2g} {unit}" for key, unit in (("angle_diff_deg", "° in angle"),
                                                                ("force_diff_pct", "% in drive force"),
                                                                ("eta_diff_pts", "points in η"))
                           if (v := r.get(key)) is not None)
        change += f"; {r['note']}" if r["note"] else ""
        lines.append(f"| {r['choice']} | {r['scene']} | {r['a']} ({1e3 * r['wall_a_s']:.1f} ms) | {r['b']} "
                     f"({1e3 * r['wall_b_s']:.1f} ms) | {change} | {r['cost_ratio']:.2f} |")
    table = "\n".join(lines) + "\n"
    log(table)
    return {"date": date.today().isoformat(), "rows": rows, "table": table}


# ---------------------------------------------------------------------------------------------------------
# Speed against accuracy

# Every fixed-step method, with each MuJoCo integrator it runs on: all of them for a method that takes no force
# implicitly, implicitfast for one that extends it.
FIXED = tuple((name, integrator) for name, m in methods.METHODS.items() if not m.adaptive
              for integrator in (field_of(Scene, "sim.integrator").metadata["choices"] if not m.implicit
                                 else ("implicitfast",)))
ADAPTIVE = tuple(name for name, m in methods.METHODS.items() if m.adaptive)
# How the study names a failure, by its kind; any other is "unstable".
FAILURES = ((Chatter, "chatter"), (StepUnderflow, "step underflow"), (NotConverged, "no root"),
            (UndefinedResult, "eta undefined"))
STEPS = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2)
TOLERANCES = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5)
V_REGS = (1e-4, 1e-3, 1e-2)
# 45 mm at 30 mm/s: every step of the grid divides the 1.5 s stroke, so the plate's reversals fall on the grid.
PLATE_DRIVE = Drive(speed=0.03, stroke=0.045, cycles=1)
SAMPLE_DT = 0.03  # a whole number of every step of the grid: all runs sample the same instants
LIMIT = ErrorLimits().angle_deg


class Studied(Experiment, Protocol):
    """An experiment the accuracy study measures: ``shape`` names the series of angles that give the compliant
    part's shape, ``load`` the series of the drive's load, and ``independent`` gives the shape angles (rad) of
    the independent solution (finrft.reference) at ``times``. A series ``eta`` (per cycle), where the
    experiment records one, is compared too."""

    shape: str
    load: str

    def independent(self, scene: Any, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray: ...


@dataclass(frozen=True)
class StudyCase:
    """A scene of the study, the experiment run on it, and the grid of its adaptive runs."""

    scene: Scene | RobotScene
    experiment: Studied
    grid: float


def study_cases() -> dict[str, StudyCase]:
    """The study's cases: the origami plate drag and one flap cycle of the robot, paper and physical presets. The
    adaptive method runs on the plate's 1 ms grid and on the 10 µs grid the robot's reversals need."""
    plate, robot = PlateTest(PLATE_DRIVE), Swim(1)
    return {"plate, paper inertia": StudyCase(preset("paper"), plate, 1e-3),
            "plate, physical inertia": StudyCase(preset("physical"), plate, 1e-3),
            "robot, paper": StudyCase(preset("paper", RobotScene), robot, 1e-5),
            "robot, physical": StudyCase(preset("physical", RobotScene), robot, 1e-5)}


def _label(method: str, integrator: str) -> str:
    return method if methods.get(method).implicit else f"{method} ({integrator})"


def _trial(job: tuple[Studied, Scene | RobotScene, bool]) -> dict[str, Any]:
    """One setting of the study: the experiment's shape angles (deg) at SAMPLE_DT samples, the mean of its drive's
    load per stroke, its first cycle's eta (NaN without one), wall time, the run's own error estimate
    (finrft.convergence; skipped when the job's last item is False); or how it failed."""
    experiment, scene, estimate = job
    start = time.perf_counter()
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging run is reported, not warned about
            run = run_experiment(experiment, scene, max_error=None, estimate_error=estimate)
    except SimulationFailed as exc:
        failure = next((name for kind, name in FAILURES if isinstance(exc, kind)), "unstable")
        return {"failure": failure, "detail": str(exc), "wall_s": time.perf_counter() - start}
    angles, load = np.degrees(run.series[experiment.shape]), run.series[experiment.load]
    eta = float(run.series["eta"][0]) if "eta" in run.series else float("nan")
    if not np.all(np.isfinite(angles)):
        return {"failure": "non-finite", "wall_s": run.wall_s}
    # Samples strictly inside each stroke: at a reversal the load is an impulse, its sampled value arbitrary.
    bounds = [0.0, run.stroke_time, run.time[-1]]
    means = [float(np.mean(load[(run.time > a + 1e-9) & (run.time < b - 1e-9)])) for a, b in zip(bounds, bounds[1:])]
    return {"failure": "", "time": run.time, "angles": angles, "load": np.asarray(means), "eta": eta,
            "wall_s": run.wall_s, "estimate": run.error_estimate or {}}


def _independent(job: tuple[Studied, Scene | RobotScene, np.ndarray]) -> np.ndarray:
    """The independent solution (finrft.reference, Radau at rtol 1e-7) of a study case: its shape angles (deg)
    at ``times``."""
    experiment, scene, times = job
    return np.degrees(experiment.independent(scene, times, rtol=1e-7, atol=1e-10))


def _settings(case: StudyCase, base: Scene | RobotScene, quick: bool,
              python: bool) -> list[tuple[dict[str, Any], Any]]:
    """(CSV fields, scene) for every setting of one case's scene ``base`` at one v_reg."""
    out = []
    steps = (1e-4, 1e-3) if quick else STEPS
    for backend in ("native", "python") if python else ("native",):
        for method, integrator in FIXED:
            for dt in steps:
                if backend == "python" and dt < 1e-3:
                    continue  # the twins give the same trajectories; only their wall time differs
                fields = {"backend": backend, "method": _label(method, integrator), "dt": dt, "tolerance": ""}
                out.append((fields, base.replace(**{"sim.backend": backend, "sim.method": method,
                                                    "sim.integrator": integrator, "sim.dt": dt})))
        # The adaptive methods on the case's grid, largest step 10 ms.
        for method in ADAPTIVE:
            for tolerance in ((1e-2,) if quick else TOLERANCES) if backend == "native" else ():
                fields = {"backend": backend, "method": method, "dt": case.grid, "tolerance": tolerance}
                out.append((fields, base.replace(**{"sim.backend": backend, "sim.method": method,
                                                    "sim.dt": case.grid, "sim.max_step": 1e-2,
                                                    "sim.tolerance": tolerance})))
    return out


def accuracy(out: str | Path = "accuracy", *, quick: bool = False, workers: int | None = None,
             log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """Error against wall time for every time-stepping method, step (or tolerance), backend and v_reg, on the origami
    drag (one 45 mm recovery and one power stroke) and on one flap cycle of the robot, each with the paper's and
    with physical inertias. The reference is the newton method at 2 µs (10 µs with ``quick``), checked against
    itself at twice the step and (without ``quick``) against the independent solution. A run fails when it goes unstable, non-finite, its adaptive step underflows, its
    Newton solve finds no root, or it chatters (``stepping.CHATTER_DV``: a velocity that swings back and forth
    every step, which stops the run)."""
    import csv
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows, summary, references = [], {}, {}
    v_regs = (None,) if quick else V_REGS
    ref_dt = 1e-5 if quick else 2e-6
    cases = len(study_cases()) * len(v_regs) + (0 if quick else 1)  # + the independent solutions
    done = 0
    for name, case in study_cases().items():
        preset_scene, experiment = case.scene, case.experiment
        for v_reg in v_regs:
            base = preset_scene.replace(**{"sim.record_dt": SAMPLE_DT})
            if v_reg is not None:
                base = base.replace(**{"rft.v_reg": v_reg})
            reg = base.rft.v_reg
            default = v_reg is None or np.isclose(v_reg, preset_scene.rft.v_reg)
            ref, check = batch.map_jobs(_trial, [(experiment, base.replace(**{"sim.method": "newton",
                                                                              "sim.integrator": "implicitfast",
                                                                              "sim.dt": dt}), False)
                                                 for dt in (ref_dt, 2 * ref_dt)], workers=workers)
            if ref["failure"] or check["failure"]:
                raise RuntimeError(f"the reference of {name} failed: {ref.get('detail', ref['failure'])}")
            self_error = float(np.abs(ref["angles"] - check["angles"]).max())
            settings = _settings(case, base, quick, python=default)
            log(f"{name}, v_reg {reg:g} m/s: {len(settings)} runs")
            results = batch.map_jobs(_trial, [(experiment, scene, True) for _, scene in settings], workers=workers)
            for (fields, _), result in zip(settings, results):
                row = {"scene": name, "v_reg": reg, **fields, "failure": result["failure"],
                       "angle_error_deg": float("nan"), "force_error_pct": float("nan"),
                       "eta_error_pts": float("nan"), "wall_s": result["wall_s"],
                       "estimated_angle_error_deg": result.get("estimate", {}).get("angle_deg", float("nan")),
                       "estimated_eta_error_pts": result.get("estimate", {}).get("eta_points", float("nan"))}
                if not result["failure"]:
                    # Common instants: every run samples each SAMPLE_DT; the last sample is the run's end.
                    _, mine, theirs = np.intersect1d(np.round(result["time"], 9), np.round(ref["time"], 9),
                                                     return_indices=True)
                    error = np.abs(result["angles"][mine] - ref["angles"][theirs])
                    row["angle_error_deg"] = float(error.max())
                    row["force_error_pct"] = float(100 * np.abs((result["load"] - ref["load"]) / ref["load"]).max())
                    row["eta_error_pts"] = float(100 * abs(result["eta"] - ref["eta"]))
                rows.append(row)
            if default:
                ok = [r for r in rows if r["scene"] == name and r["v_reg"] == reg and r["backend"] == "native"
                      and not r["failure"]]
                summary[name] = {limit: min((r for r in ok if r["angle_error_deg"] <= limit),
                                            key=lambda r: r["wall_s"], default=None) for limit in (0.1, 1.0)}
                summary[name]["reference"] = (ref_dt, self_error)
                references[name] = (experiment, base, ref)
            done += 1
            _tick(progress, done, cases)
    if not quick:
        log("independent solutions of the references (Radau)")
        jobs = [(experiment, base, ref["time"]) for experiment, base, ref in references.values()]
        for (name, (*_, ref)), angles in zip(references.items(), batch.map_jobs(_independent, jobs, workers=workers)):
            summary[name]["independent"] = float(np.abs(angles - ref["angles"]).max())
        _tick(progress, cases, cases)
    with (out / "accuracy.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _accuracy_chart(rows, out / "accuracy.png")
    text = _accuracy_summary(rows, summary)
    (out / "accuracy.md").write_text(text)
    log(text)
    return {"rows": rows, "summary": summary}


def _setting(row: dict[str, Any]) -> str:
    return (f"{row['method']}, tolerance {row['tolerance']:g}" if row["method"] in ADAPTIVE
            else f"{row['method']}, dt {row['dt']:g} s")


def _accuracy_summary(rows: list[dict[str, Any]], summary: dict[str, Any]) -> str:
    """The fastest setting within 0.1° and 1° per scene, and the physical plate's newton method at 1 ms against
    plain explicit coupling at its largest step that does not fail."""
    lines = ["| scene | reference (newton) | fastest within 0.1° | fastest within 1° |", "|---|---|---|---|"]
    for name, best in summary.items():
        cells = [f"{_setting(b)}: {1e3 * b['wall_s']:.0f} ms, {b['angle_error_deg']:.3g}°" if b else "none"
                 for b in (best[0.1], best[1.0])]
        ref_dt, self_error = best["reference"]
        checked = f"; {best['independent']:.2g}° from the independent solution" if "independent" in best else ""
        lines.append(f"| {name} | dt {ref_dt:g} s, {self_error:.2g}° from dt {2 * ref_dt:g} s{checked} | {cells[0]} | "
                     f"{cells[1]} |")
    lines.append("")
    for name in summary:
        mine = [r for r in rows if r["scene"] == name and r["backend"] == "native"
                and r["v_reg"] == study_cases()[name].scene.rft.v_reg]
        newton = next((r for r in mine if r["method"] == "newton" and np.isclose(r["dt"], 1e-3)), None)
        explicit = [r for r in mine if r["method"] == "explicit (implicitfast)" and not r["failure"]]
        if newton is None or newton["failure"] or not explicit:
            continue
        largest = max(explicit, key=lambda r: r["dt"])
        lines.append(f"- {name}: newton at 1 ms, {1e3 * newton['wall_s']:.1f} ms and "
                     f"{newton['angle_error_deg']:.2g}°; plain explicit coupling (implicitfast) does not fail up "
                     f"to dt {largest['dt']:g} s, {1e3 * largest['wall_s']:.1f} ms and "
                     f"{largest['angle_error_deg']:.2g}°: {largest['wall_s'] / newton['wall_s']:.1f}x.")
    lines += ["", "Each run's own error estimate (finrft.convergence) against its error from the reference, at the "
              f"default limit of {LIMIT}° (η: {LIMIT} points):", "",
              "| scene | runs | estimate ≥ error | would pass but are wrong | flagged but right | estimate / error "
              "(median) |", "|---|---:|---:|---:|---:|---:|"]
    for name in summary:
        ok = [r for r in rows if r["scene"] == name and not r["failure"]]
        # eta's pairs are NaN for a case without cycles: dropped with the other non-finite ones
        pairs = [(r["estimated_angle_error_deg"], r["angle_error_deg"]) for r in ok]
        pairs += [(r["estimated_eta_error_pts"], r["eta_error_pts"]) for r in ok]
        pairs = np.array([p for p in pairs if np.all(np.isfinite(p))]).reshape(-1, 2)
        estimate, error = pairs.T
        ratio = np.median(estimate[error > 1e-6] / error[error > 1e-6]) if np.any(error > 1e-6) else float("nan")
        lines.append(f"| {name} | {len(ok)} | {np.mean(estimate >= error):.0%} | "
                     f"{np.sum((estimate <= LIMIT) & (error > LIMIT))} | {np.sum((estimate > LIMIT) & (error <= LIMIT))} "
                     f"| {ratio:.2g} |")
    return "\n".join(lines) + "\n"


def _accuracy_chart(rows: list[dict[str, Any]], path: Path) -> None:
    """Error against wall time, log-log: columns are scenes, rows v_reg; one colour per method, python backend
    dashed; failed runs as crosses along the top."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(dict.fromkeys(r["scene"] for r in rows))
    regs = sorted(dict.fromkeys(r["v_reg"] for r in rows))
    labels = list(dict.fromkeys(r["method"] for r in rows))
    colours = {m: f"C{i}" for i, m in enumerate(labels)}
    fig, axes = plt.subplots(len(regs), len(names), figsize=(5.5 * len(names), 4.5 * len(regs)), squeeze=False)
    for i, reg in enumerate(regs):
        for ax, name in zip(axes[i], names):
            mine = [r for r in rows if r["scene"] == name and r["v_reg"] == reg]
            good = [r["angle_error_deg"] for r in mine if not r["failure"]]
            top = max(good + [1.0]) * 3
            for method in labels:
                for backend, style in (("native", "o-"), ("python", "s--")):
                    runs = [r for r in mine if r["method"] == method and r["backend"] == backend]
                    ok = sorted((r for r in runs if not r["failure"]), key=lambda r: r["wall_s"])
                    bad = [r for r in runs if r["failure"]]
                    ax.plot([r["wall_s"] for r in ok], [max(r["angle_error_deg"], 1e-6) for r in ok], style,
                            color=colours[method], ms=4, label=method if backend == "native" else None)
                    ax.plot([r["wall_s"] for r in bad], [top] * len(bad), "x", color=colours[method], ms=8)
            ax.axhline(0.1, color="grey", ls=":", lw=0.8)
            ax.axhline(1.0, color="grey", ls="--", lw=0.8)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("wall time per run (s)")
            ax.set_ylabel("max angle error (deg)")
            ax.set_title(f"{name}, v_reg {1e3 * reg:g} mm/s", fontsize=10)
            ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7, title="x at the top: failed; dashed: python backend", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
