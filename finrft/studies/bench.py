"""Benchmarks, measured as ratios within one run on this machine (never as timed tests)."""

from __future__ import annotations

import contextlib
import ctypes
import math
import platform
import time
from datetime import date
from pathlib import Path
from typing import Any, Callable

import mujoco
import numpy as np

from .. import batch, methods, native
from ..errors import SimulationFailed
from ..drive import Drive
from ..experiments.plate import build_plate, simulate
from ..experiments.swim import steady_cycles, swim
from ..experiments.swim import RobotScene
from ..scene import Scene, preset, presets, resolution
from .accuracy import PLATE_DRIVE
from .fit import fit, read_drag, resolve_params, simulated_drag
from .optimize import evaluation_scene, optimize


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
    for name in presets(Scene):
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
    plate = build_plate(scene)

    def run() -> None:
        d = mujoco.MjData(plate.model)
        d.qvel[plate.drive_dof] = drive.stroke_velocity(0)
        with contextlib.nullcontext() if timed else native.untimed():
            mujoco.mj_step(plate.model, d, steps)
    return run


def _interleaved(runs: dict[str, Callable[[], Any]], rounds: int,
                 cpu: dict[str, list[float]] | None = None) -> dict[str, list[float]]:
    """Wall times of each run, taken in turn ``rounds`` times; with ``cpu``, each run's CPU time (this process's)
    appended there under its name too."""
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(rounds):
        for name, fn in runs.items():
            start = time.process_time()
            times[name].append(_best(fn, 1))
            if cpu is not None:
                cpu.setdefault(name, []).append(time.process_time() - start)
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


# The laws' cost per call (`laws`): this many leading elements below the surface, each law called on all of them
# LAW_PASSES times in one native call, the best of LAW_ROUNDS such calls, the laws taken in turn.
LAW_ELEMENTS = 1024
LAW_PASSES = 16
LAW_ROUNDS = 1000
# Each law with the medium and intruder of a shipped example: the sand-swimmer's glass beads (li2013, li2013-planar),
# the hexapod's sand and surface friction (rft3d).
LAW_MEDIA = {"li2013": "glass_beads_treers2021", "li2013-planar": "glass_beads_treers2021",
             "rft3d": "sand_3d_rft_code"}
RFT3D_MU_SURF = 0.1806


def law_elements(n: int = LAW_ELEMENTS, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` leading elements below the surface, seeded: unit normals and the directions of velocities uniform
    over the sphere (a velocity turned round where it trails), speeds 1 to 100 mm/s, depths 1 to 50 mm, areas 1
    to 100 mm^2."""
    rng = np.random.default_rng(seed)
    normal, direction = rng.normal(size=(2, n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    direction *= np.sign(np.einsum("ij,ij->i", normal, direction))[:, None]
    return {"normal": normal, "velocity": direction * rng.uniform(1e-3, 0.1, (n, 1)),
            "depth": rng.uniform(1e-3, 0.05, n), "area": rng.uniform(1e-6, 1e-4, n)}


def _law_constants(law: str) -> tuple[np.ndarray, float, float]:
    """The coefficients, scale (zeta or xi) and surface friction the plugin takes for ``law`` (`LAW_MEDIA`)."""
    from .. import media
    from ..laws import li2013, rft3d
    medium = media.medium(LAW_MEDIA[law])
    if law == "rft3d":
        return np.array(rft3d.DEFAULT.values()), rft3d.medium_xi(medium), RFT3D_MU_SURF
    zeta, coefficients = li2013.medium_parameters(medium)
    return np.array(coefficients.values()), zeta, 0.0


def law_forces_call(law: str, elements: dict[str, np.ndarray], force: np.ndarray,
                    passes: int) -> Callable[[], int]:
    """One native call (``finrft_law_forces``) of ``law`` (`LAW_MEDIA`'s constants) on ``elements`` (as
    `law_elements` gives them), ``passes`` passes over them, the forces into ``force`` (n x 3, C-contiguous): its
    arguments made once, so that a call from Python costs only ctypes'. The call returns 0, or -1 for an unknown
    law."""
    import ctypes
    doubles = ctypes.POINTER(ctypes.c_double)
    run = native.function("finrft_law_forces", ctypes.c_int, ctypes.c_char_p, doubles, ctypes.c_double,
                          ctypes.c_double, ctypes.c_int, doubles, doubles, doubles, doubles, ctypes.c_int, doubles)
    coef, scale, mu_surf = _law_constants(law if law in LAW_MEDIA else "li2013")
    # (numpy's pointers hold their arrays)
    pointers = [np.ascontiguousarray(a, dtype=float).ctypes.data_as(doubles)
                for a in (coef, elements["normal"], elements["velocity"], elements["depth"], elements["area"])]
    arguments = (law.encode(), pointers[0], scale, mu_surf, len(elements["depth"]), *pointers[1:], passes,
                 force.ctypes.data_as(doubles))
    return lambda: run(*arguments)


def laws(*, log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """The native surface laws' element force, ns per call: each law as the plugin calls it (``finrft_law_forces``)
    on `law_elements`, `LAW_PASSES` passes over them in one call from Python, the best of `LAW_ROUNDS` calls, the
    laws taken in turn so that the machine's load weighs on each alike."""
    elements = law_elements()
    force = np.zeros((LAW_ELEMENTS, 3))
    calls = {law: law_forces_call(law, elements, force, LAW_PASSES) for law in LAW_MEDIA}
    times = {law: [] for law in calls}
    for i in range(LAW_ROUNDS):
        for law, call in calls.items():
            times[law].append(_best(call, 1))
        _tick(progress, i + 1, LAW_ROUNDS)
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores", "elements": LAW_ELEMENTS, "passes": LAW_PASSES,
                           "rounds": LAW_ROUNDS, "media": LAW_MEDIA, "ns_per_call": {}}
    for law, walls in times.items():
        out["ns_per_call"][law] = 1e9 * min(walls) / (LAW_ELEMENTS * LAW_PASSES)
        log(f"{law:>14}: {out['ns_per_call'][law]:6.1f} ns per element force (median round "
            f"{1e9 * float(np.median(walls)) / (LAW_ELEMENTS * LAW_PASSES):.1f} ns)")
    return out


# ---------------------------------------------------------------------------------------------------------
# What each modelling choice costs and changes


MODELLING_CASES = 11  # chain x 2 presets, rigid plate x 2, origami stop x 3, robot x 2, surface x 2
# The wheel on a deforming surface against the flat one: held 30 mm deep at slip -0.5 for 6 s (60 mm) with its error
# estimate, as the wheel study runs it (docs/results/wheel.md), and driven at slip 0.5, 22 mm deep (its rim's turn
# steps the surface twice as often).
WHEEL_SURFACE_RUN = {"wheel.slip": -0.5, "wheel.sinkage": 0.03, "medium.name": "wheel_sand_cmu", "sim.duration": 6.0,
                     "sim.settle": 4.0}
WHEEL_SURFACE_DRIVEN = {**WHEEL_SURFACE_RUN, "wheel.slip": 0.5, "wheel.sinkage": 0.022}


def _plate_pair(a: Scene, b: Scene, drive: Drive, repeat: int) -> dict[str, float]:
    """Two plate models of the same test: the largest difference of their segment angles (deg) and drive force
    (% of the peak), and their best wall times."""
    first, second = simulate(a, drive, estimate_error=False), simulate(b, drive, estimate_error=False)
    return {"angle_diff_deg": float(np.degrees(np.abs(first.segment_angle - second.segment_angle)).max()),
            "force_diff_pct": float(100 * np.abs(first.drive_force - second.drive_force).max()
                                    / first.peak_drive_force),
            "wall_a_s": _best(lambda: simulate(a, drive, estimate_error=False), repeat),
            "wall_b_s": _best(lambda: simulate(b, drive, estimate_error=False), repeat)}


# The wheel's runs on the two surfaces are taken in turn this many times, each keeping its best. On a shared 2-core
# machine their ratio still spread from 1.2 to 1.8 in wall time over a few minutes, and from 1.15 to 1.54 in CPU
# time, which leaves out the waits for a core but not how fast the core runs; instruction counts held still
# (scripts/wheel_surface_cost.py).
WHEEL_SURFACE_ROUNDS = 8


def _wheel_surfaces(rounds: int = WHEEL_SURFACE_ROUNDS, run: dict[str, Any] = WHEEL_SURFACE_RUN) -> dict[str, float]:
    """The wheel ``run`` (`WHEEL_SURFACE_RUN`, `WHEEL_SURFACE_DRIVEN`) on the flat and the deforming surface: the
    change of its drawbar pull Fx (N), and the best wall and CPU times (s) of each, taken in turn ``rounds`` times.
    The runs are single-threaded, so their CPU time is their cost without the waits for a core that wall time counts
    on a shared machine."""
    from ..experiments.wheel import DEFORMING_GRID, default_scene, run_wheel

    scenes = {"a": default_scene(**run),
              "b": default_scene(**run, **{"medium.surface": "deforming", "medium.pile_factor": 0.7},
                                 **DEFORMING_GRID)}
    pull = {name: run_wheel(scene).summary()["Fx_N"] for name, scene in scenes.items()}
    cpu: dict[str, list[float]] = {}
    wall = _interleaved({name: (lambda scene=scene: run_wheel(scene)) for name, scene in scenes.items()}, rounds, cpu)
    return {"fx_diff_N": pull["b"] - pull["a"], **{f"wall_{name}_s": min(t) for name, t in wall.items()},
            **{f"cpu_{name}_s": min(t) for name, t in cpu.items()}}


def modelling(*, repeat: int = 3, log: Callable[[str], None] = print, progress: Progress = None) -> dict[str, Any]:
    """Measure what each modelling choice costs and changes: a planar chain against a 3D chain free to turn
    out of the plane, the half robot against the full one, a MuJoCo limit stop against the penalty stop, a
    rigid plate as one body against hinged segments held by welds, and the wheel on a deforming surface against
    the flat one. Returns the rows and a Markdown table."""
    drag = Drive()  # 200 mm at 30 mm/s
    cycle = PLATE_DRIVE  # 45 mm out and back
    rows = []

    def add(choice: str, scene: str, a: str, b: str, pair: dict[str, float], note: str = "") -> None:
        clock = "cpu" if "cpu_a_s" in pair else "wall"  # the cost: CPU time where a row measures it
        row = {"choice": choice, "scene": scene, "a": a, "b": b, **pair,
               "cost_ratio": pair[f"{clock}_b_s"] / pair[f"{clock}_a_s"], "cost_clock": clock, "note": note}
        rows.append(row)
        _tick(progress, len(rows), MODELLING_CASES)
        log(f"{choice}, {scene}: {a} {1e3 * pair[f'{clock}_a_s']:.1f} ms, {b} {1e3 * pair[f'{clock}_b_s']:.1f} ms"
            f"{' (CPU)' if clock == 'cpu' else ''}; "
            + ", ".join(f"{k} {v:.3g}" for k, v in pair.items() if not k.startswith(("wall", "cpu"))))

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
    add("surface", "wheel rig, held 30 mm deep at slip -0.5, 6 s", "flat", "deforming",
        _wheel_surfaces(run=WHEEL_SURFACE_RUN), "CPU time")
    add("surface", "wheel rig, held 22 mm deep at slip 0.5 (driven), 6 s", "flat", "deforming",
        _wheel_surfaces(run=WHEEL_SURFACE_DRIVEN), "CPU time")
    lines = ["| choice | scene | A | B | what changes (B against A) | cost of B / A |", "|---|---|---|---|---|---:|"]
    for r in rows:
        change = ", ".join(f"{v:.2g} {unit}" for key, unit in (("angle_diff_deg", "° in angle"),
                                                                ("force_diff_pct", "% in drive force"),
                                                                ("eta_diff_pts", "points in η"),
                                                                ("fx_diff_N", "N in Fx"))
                           if (v := r.get(key)) is not None)
        change += f"; {r['note']}" if r["note"] else ""
        clock = r["cost_clock"]
        lines.append(f"| {r['choice']} | {r['scene']} | {r['a']} ({1e3 * r[f'{clock}_a_s']:.1f} ms) | {r['b']} "
                     f"({1e3 * r[f'{clock}_b_s']:.1f} ms) | {change} | {r['cost_ratio']:.2f} |")
    table = "\n".join(lines) + "\n"
    log(table)
    return {"date": date.today().isoformat(), "rows": rows, "table": table}


# What each example robot's benchmark compares: the swimmer's and the hexapod's mean speed over the window, the
# wheel's mean force of the medium (m/s, N).
ROBOT_FIGURE = {"sand_swimmer": "speed", "hexapod": "speed", "wheel_rig": "force"}
# The accuracy a robot's run is held to against its converged run (relative), the default's and the explicit
# step's alike.
ROBOT_ACCURACY = 0.02
# Explicit steps tried for the speed-up, as fractions of the default step, coarsest first: down to 4 µs at a 1 ms
# default, as the light robots' explicit steps still chatter at 16 µs (a 10 g link's force changes with its velocity
# on the scale of v_reg = 0.1 mm/s). A chattering run stops early, so the fine steps cost little unless they hold.
EXPLICIT_FRACTIONS = (1 / 2, 1 / 4, 1 / 8, 1 / 16, 1 / 32, 1 / 64, 1 / 128, 1 / 256)
# Bisections (in the logarithm of the step) between the first explicit step that holds and the one twice as long.
EXPLICIT_REFINE = 2
# The speed-up's two runs, the default and the explicit step found, are timed this many times more, in turn, and
# each keeps its best: on a shared machine one run of the wheel rig's took 0.21 or 0.30 s from one run to the next.
ROBOT_ROUNDS = 2


def _robot_figure(name: str, result: Any) -> np.ndarray:
    s = result.summary()
    if ROBOT_FIGURE[name] == "speed":
        return np.array([float(np.hypot(*s["com_velocity_m_s"][:2]))])
    return np.array(s["medium_force_N"], dtype=float)


def _relative(value: np.ndarray, reference: np.ndarray) -> float:
    """The relative error of a robot's figure: of the speed; of a force, its worst component's (`_per_component`),
    as the wheel's force is mostly its load, which any stable run carries exactly, and its norm hid a drawbar pull
    3 % off."""
    if len(value) == 1:
        return float(abs(value[0] - reference[0]) / max(abs(reference[0]), 1e-12))
    return max(e for e in _per_component(value, reference) if e is not None)


def _per_component(value: np.ndarray, reference: np.ndarray) -> list[float | None]:
    """Each component's relative error, None for one below 1 % of the whole (the wheel's Fy at no slip angle)."""
    whole = max(float(np.linalg.norm(reference)), 1e-12)
    return [None if abs(r) < 0.01 * whole else float(abs(v - r) / abs(r)) for v, r in zip(value, reference)]


def robots(names: tuple[str, ...] | None = None, *, duration: float = 0.0, log: Callable[[str], None] = print,
           progress: Progress = None) -> dict[str, Any]:
    """Each example robot (``finrft run --example NAME``) at its default settings (``duration`` > 0: that long
    instead, with the settle scaled alike): simulated seconds per wall second, its error against a converged run
    (the same method at 1/8 of the step), the cost against bare ``mj_step`` of the same model without the medium at
    the same step, the cost per element per step, and the speed-up over MuJoCo's explicit step at the largest step
    (1/2 ... 1/256 of the default, then bisected twice towards the one twice as long) whose run is within
    `ROBOT_ACCURACY` of the converged one, as the default's must be. Where none is (each chatters or misses), the
    speed-up is at least the cost of the finest explicit run, its steps (duration over that step) times one explicit
    step of the model with the medium (timed in C), over the default's. The default and the explicit step found are
    timed `ROBOT_ROUNDS` more times in turn, each its best. The cost of one step of the default's method and of
    one explicit step (at the step found, else the finest tried), from the same state in one process
    (`_step_costs`): per element per step beyond the bare step, and their ratio. Errors are relative: the mean speed of the
    centre of mass over the window (swimmer, hexapod), the mean force of the medium (wheel), its worst component."""
    from ..experiment import run
    from ..experiments.user_model import EXAMPLES, UserModel, example
    from ..scene import UserScene, load_scene
    names = names or EXAMPLES
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores", "mujoco": mujoco.__version__,
                           "accuracy": ROBOT_ACCURACY, "robots": {}}
    for i, name in enumerate(names):
        scene = load_scene(example(name), cls=UserScene)
        if duration > 0:
            scene = scene.replace(**{"sim.duration": duration,
                                     "sim.settle": scene.sim.settle * duration / scene.sim.duration})
        dt = scene.sim.dt

        def timed(s: UserScene) -> tuple[Any, float]:
            start = time.perf_counter()
            result = run(UserModel.of(s), s, estimate_error=False, max_error=None)
            return result, time.perf_counter() - start

        default, wall = timed(scene)
        figure = _robot_figure(name, default)
        converged, _ = timed(scene.replace(**{"sim.dt": dt / 8}))
        reference = _robot_figure(name, converged)
        error = _relative(figure, reference)
        elements = _elements(scene)
        bare = _bare_step_s(scene, default.steps)
        def timing(wall: float) -> dict[str, float]:
            return {"wall_s": wall, "sim_s_per_wall_s": float(default.time[-1]) / wall,
                    "us_per_step": 1e6 * wall / default.steps, "cost_over_bare": wall / default.steps / bare,
                    "ns_per_element_step": 1e9 * (wall / default.steps - bare) / elements}

        row: dict[str, Any] = {
            "method": scene.sim.method, "dt": dt, "duration_s": float(default.time[-1]), "steps": default.steps,
            "figure": ROBOT_FIGURE[name], "value": figure.tolist(), "converged_value": reference.tolist(),
            "error": error, "error_per_component": _per_component(figure, reference),
            "within_accuracy": error <= ROBOT_ACCURACY, "bare_us_per_step": 1e6 * bare, "elements": elements,
            **timing(wall)}
        def explicit_run(step: float) -> float | None:
            """The explicit run's wall seconds at ``step``; None where it fails or misses `ROBOT_ACCURACY`."""
            try:
                result, explicit_wall = timed(scene.replace(**{"sim.method": "explicit", "sim.dt": step}))
            except SimulationFailed as exc:
                row.setdefault("explicit", []).append({"dt": step, "failed": type(exc).__name__})
                return None
            explicit_error = _relative(_robot_figure(name, result), reference)
            row.setdefault("explicit", []).append({"dt": step, "error": explicit_error, "wall_s": explicit_wall})
            return explicit_wall if explicit_error <= ROBOT_ACCURACY else None

        passing = next(((dt * f, w) for f in EXPLICIT_FRACTIONS if (w := explicit_run(dt * f)) is not None), None)
        if passing is not None:
            # the largest explicit step that holds, to within 2^(1/4): the halving grid alone can leave it almost
            # twice too small (the wheel rig's holds at 0.5 ms, between the grid's 0.3125 and 0.625 ms)
            low, high = passing[0], 2 * passing[0]
            for _ in range(EXPLICIT_REFINE):
                middle = math.sqrt(low * high)
                if (w := explicit_run(middle)) is not None:
                    low, passing = middle, (middle, w)
                else:
                    high = middle
            explicit_scene = scene.replace(**{"sim.method": "explicit", "sim.dt": passing[0]})
            again = _interleaved({"default": lambda: timed(scene), "explicit": lambda: timed(explicit_scene)},
                                 ROBOT_ROUNDS)
            wall = min(wall, *again["default"])
            explicit_wall = min(passing[1], *again["explicit"])
            row.update(**timing(wall), explicit_dt=passing[0], explicit_wall_s=explicit_wall,
                       speedup_over_explicit=explicit_wall / wall)
        else:
            finest = dt * EXPLICIT_FRACTIONS[-1]
            step = _explicit_step_s(scene, finest)
            row.update(explicit_us_per_step=1e6 * step,
                       speedup_over_explicit_at_least=row["duration_s"] / finest * step / wall)
        row.update(_step_costs(scene, row.get("explicit_dt", dt * EXPLICIT_FRACTIONS[-1]), bare, elements))
        out["robots"][name] = row
        speedup = (f"{row['speedup_over_explicit']:.2f}x faster than the explicit step at {row['explicit_dt']:g} s"
                   if row.get("speedup_over_explicit", 0) >= 1 else
                   f"the explicit step at {row['explicit_dt']:g} s is {1 / row['speedup_over_explicit']:.2f}x faster"
                   if "speedup_over_explicit" in row else
                   f"no explicit step down to {dt * EXPLICIT_FRACTIONS[-1]:g} s was within "
                   f"{100 * ROBOT_ACCURACY:g} %: at least {row['speedup_over_explicit_at_least']:.1f}x faster")
        log(f"{name}: {scene.sim.method} at {dt:g} s, {row['sim_s_per_wall_s']:.2f} simulated s per wall s; "
            f"{ROBOT_FIGURE[name]} {100 * error:.2f} % from the converged run (dt {dt / 8:g} s); "
            f"{row['cost_over_bare']:.1f}x bare mj_step, {row['ns_per_element_step']:.0f} ns per element per step "
            f"({elements} elements); {speedup}; a step from the same state, in C: {scene.sim.method} "
            f"{row['implicit_ns_per_element_step']:.0f} ns per element, explicit "
            f"{row['explicit_ns_per_element_step']:.0f} ns, {row['implicit_over_explicit_step']:.1f} explicit steps")
        _tick(progress, i + 1, len(names))
    return out


# The step costs (`_step_costs`): the run is stepped to this time, at most its settle, then on over STEP_COST_SPAN s
# (at most to its end), its state kept at STEP_COST_STATES instants evenly over that; from each, STEP_COST_STEPS
# steps of each kind are timed, the medium's elements below the surface and moving as in the run. The rounds
# interleave the kinds, STEP_ROUNDS of them, the best of each kept. One instant's steps are not a run's: the
# sand-swimmer's Newton steps just after its ramp-in cost four times its run's mean.
STEP_COST_START = 0.5
STEP_COST_SPAN = 1.0
STEP_COST_STATES = 10
STEP_COST_STEPS = 20
STEP_ROUNDS = 5


def _step_costs(scene: Any, explicit_dt: float, bare_s: float, elements: int) -> dict[str, float]:
    """One step of the scene's method at its step and one of MuJoCo's explicit step at ``explicit_dt``, each timed
    in C from the same states of the run (`step_start`), in one process: the wall seconds of each, the cost per
    element per step of each beyond the bare step (``bare_s``, the model without the medium), and the implicit
    step's cost in explicit steps."""
    with native.untimed():
        implicit, explicit = step_start(scene, explicit_dt)
        steps = STEP_COST_STATES * STEP_COST_STEPS
        walls = {k: min(v) / steps
                 for k, v in _interleaved({"implicit": lambda: implicit(steps),
                                           "explicit": lambda: explicit(steps)}, STEP_ROUNDS).items()}
    return {"implicit_step_us": 1e6 * walls["implicit"], "explicit_step_us": 1e6 * walls["explicit"],
            "implicit_ns_per_element_step": 1e9 * (walls["implicit"] - bare_s) / elements,
            "explicit_ns_per_element_step": 1e9 * (walls["explicit"] - bare_s) / elements,
            "implicit_over_explicit_step": walls["implicit"] / walls["explicit"]}


def step_start(scene: Any, explicit_dt: float) -> tuple[Callable[[int], None], Callable[[int], None]]:
    """Steps of the scene's method at its step and of MuJoCo's explicit step at ``explicit_dt`` from the same states
    of its run: `STEP_COST_STATES` instants evenly over `STEP_COST_SPAN` s from `STEP_COST_START` s or its settle,
    the earlier (at most to its end), with the controls of each instant held and the stepper's history from the
    run. Each of the two returned functions takes the steps it is given in C, an equal share from each instant
    (`_step_costs` times them; scripts/step_counts.py counts their instructions): the implicit method's from the
    instant on, as its run takes them (a Newton step starts from its last one's change), each explicit one from the
    instant again (`finrft_explicit_from`), as an explicit step beyond its limit leaves the sand: the wheel rig's at
    its own 62.5 ms within three steps, after which a step cost a seventh of one in the sand."""
    from ..callbacks import controlled
    from ..experiments.user_model import UserModel
    from ..integrate import stepper
    experiment = UserModel.of(scene)
    built = experiment.build(scene)
    m, explicit_m = built.model, UserModel.of(scene).build(scene).model
    explicit_m.opt.timestep = explicit_dt
    d = mujoco.MjData(m)
    trial = experiment.start(scene, built, d, False)
    advance = stepper(m, scene.sim, built.backend, built.groups, getattr(built, "attached", None))
    history = getattr(advance, "history", None)
    # the controls and applied forces too: steps from one instant with a sine servo's ctrl of another were violent
    # (the sandfish's newton-midpoint step, 100 explicit steps' cost with the last instant's ctrl at each)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    dt, start = scene.sim.dt, min(STEP_COST_START, scene.sim.settle)
    span = max(0.0, min(STEP_COST_SPAN, scene.sim.duration - start - STEP_COST_STEPS * dt))
    at = [max(1, round((start + span * i / STEP_COST_STATES) / dt)) for i in range(STEP_COST_STATES)]
    states = np.zeros((STEP_COST_STATES, mujoco.mj_stateSize(m, spec)))
    histories = [None] * STEP_COST_STATES
    trial.on_stroke(0)  # the drives set going, as the run's first stroke does
    with controlled(m, getattr(trial, "control", None)):
        done = 0
        for i, step in enumerate(at):
            if step > done:
                advance(d, step - done)
                done = step
            mujoco.mj_forward(m, d)  # the instant's controls, as the step from it sets them
            mujoco.mj_getState(m, d, states[i], spec)
            histories[i] = None if history is None else history.copy()
    explicit_d = mujoco.MjData(explicit_m)
    from_states = native.function("finrft_explicit_from", None, ctypes.c_void_p, ctypes.c_void_p,
                                  ctypes.POINTER(ctypes.c_double), ctypes.c_int, ctypes.c_int)
    explicit_args = (explicit_m._address, explicit_d._address,
                     states.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), STEP_COST_STATES)

    def implicit(steps: int) -> None:
        for i in range(STEP_COST_STATES):
            mujoco.mj_setState(m, d, states[i], spec)
            if history is not None:
                history[:] = histories[i]
            advance(d, steps // STEP_COST_STATES + (i < steps % STEP_COST_STATES))

    def explicit(steps: int) -> None:
        from_states(*explicit_args, steps)
    explicit.held = (explicit_m, explicit_d, states)  # type: ignore[attr-defined]  # what the addresses point to
    return implicit, explicit


def _elements(scene: Any) -> int:
    from ..experiments.user_model import UserModel
    return sum(UserModel.of(scene).build(scene).attached.elements.values())


def _explicit_step_s(scene: Any, dt: float) -> float:
    """Wall seconds of one ``mj_step`` at ``dt`` of the scene's model with the medium (native), from its start, in C
    (mj_step's nstep), the best of three."""
    from ..experiments.user_model import UserModel
    s = scene.replace(**{"sim.method": "explicit", "sim.dt": dt})
    built = UserModel.of(s).build(s)
    data = mujoco.MjData(built.model)
    with native.untimed():
        return _best(lambda: mujoco.mj_step(built.model, data, 2000), 3) / 2000


def _bare_step_s(scene: Any, steps: int) -> float:
    """Wall seconds of one ``mj_step`` of the scene's model without the medium, at its step, in C (mj_step's
    nstep), the best of three."""
    from ..experiments.attached_model import scene_spec
    spec = scene_spec(scene)
    spec.option.timestep = scene.sim.dt
    model = spec.compile()
    data = mujoco.MjData(model)
    n = min(steps, 20000)
    with native.untimed():
        wall = _best(lambda: mujoco.mj_step(model, data, n), 3)
    return wall / n
