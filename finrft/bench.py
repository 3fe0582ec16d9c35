"""Benchmarks, measured as ratios within one run on this machine (never as timed tests)."""

from __future__ import annotations

import platform
import time
from datetime import date
from typing import Any, Callable

import mujoco
import numpy as np

from . import batch, models
from .drive import Drive
from .optimize import optimize
from .scene import RobotScene, Scene, preset
from .simulate import simulate
from .swim import swim


def _best(fn: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def backends(scene: Scene | None = None, *, batch_size: int = 64, workers: int | None = None,
             repeat: int = 3, log: Callable[[str], None] = print) -> dict[str, Any]:
    """The paper plate drag (200 mm at 30 mm/s) with each backend, against bare MuJoCo stepping of the same
    model without RFT, and the batch throughput of ``batch_size`` drags on all cores against one core."""
    scene = scene or preset("paper")
    drive = Drive(speed=0.03, stroke=0.2)
    workers = workers or batch.default_workers()
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores, {platform.python_implementation()} "
                           f"{platform.python_version()}", "mujoco": mujoco.__version__, "dt": scene.sim.dt}
    steps = simulate(scene, drive).steps
    out["steps"] = steps
    for backend in ("python", "native"):
        wall = _best(lambda: simulate(scene.replace(**{"sim.backend": backend}), drive), repeat)
        out[f"{backend}_wall_s"], out[f"{backend}_steps_per_s"] = wall, steps / wall
        log(f"{backend:>6} backend: {wall * 1e3:8.1f} ms per drag, {steps / wall:10.0f} steps/s")

    bare = models.build_plate(scene.replace(**{"sim.backend": "python"})).model

    def bare_loop() -> None:
        d = mujoco.MjData(bare)
        for _ in range(steps):
            mujoco.mj_step(bare, d)
    wall = _best(bare_loop, repeat)
    out["bare_wall_s"], out["bare_steps_per_s"] = wall, steps / wall
    log(f"  bare mj_step, same model without RFT: {wall * 1e3:8.1f} ms, {steps / wall:10.0f} steps/s")
    out["native_over_python"] = out["python_wall_s"] / out["native_wall_s"]
    out["native_over_bare"] = out["native_wall_s"] / out["bare_wall_s"]
    log(f"native is {out['native_over_python']:.1f}x faster than the Python callback (target >= 10x) and costs "
        f"{out['native_over_bare']:.2f}x bare mj_step (target <= 2x)")

    rng = np.random.default_rng(0)
    jobs = [(scene.replace(**{"plate.damping": float(b)}), drive) for b in rng.uniform(0.5, 2.5, batch_size)]
    serial = _best(lambda: batch.run_many(jobs, workers=1), 1)
    with batch.local_executor(workers) as pool:
        batch.run_many(jobs[:workers], executor=pool)  # start the workers before timing
        parallel = _best(lambda: batch.run_many(jobs, executor=pool), 1)
    total = steps * batch_size
    out.update(batch_size=batch_size, workers=workers, batch_serial_steps_per_s=total / serial,
               batch_parallel_steps_per_s=total / parallel, batch_speedup=serial / parallel)
    log(f"batch of {batch_size} drags: {total / serial:10.0f} steps/s on 1 core, {total / parallel:10.0f} steps/s "
        f"on {workers} workers: {serial / parallel:.2f}x (target >= 1.6x on 2 cores)")
    return out


def robot(scene: RobotScene | None = None, *, budget: int = 300, workers: int | None = None, repeat: int = 3,
          log: Callable[[str], None] = print) -> dict[str, Any]:
    """One gait evaluation (one flap cycle) and a full CMA-ES optimisation of ``budget`` evaluations."""
    scene = scene or preset("paper", RobotScene)
    workers = workers or batch.default_workers()
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores", "mujoco": mujoco.__version__, "dt": scene.sim.dt,
                           "method": scene.sim.method}
    run = swim(scene, 1)
    wall = _best(lambda: swim(scene, 1), repeat)
    out.update(gait_steps=run.steps, gait_wall_s=wall, gait_us_per_step=1e6 * wall / run.steps)
    log(f"one gait evaluation ({scene.sim.method}, dt {scene.sim.dt:g} s, {run.steps} steps): {wall * 1e3:.1f} ms "
        f"(target <= 20 ms; the authors' model ~15 s)")
    result = optimize(scene, budget=budget, seed=1, workers=workers)
    out.update(optimize_budget=budget, optimize_evaluations=result.evaluations, optimize_wall_s=result.wall_s,
               optimize_eta=1 - result.cost, best=result.best, workers=workers)
    log(f"optimize, budget {budget} ({result.evaluations} evaluations) on {workers} workers: {result.wall_s:.1f} s "
        f"(target <= 60 s), best eta {100 * (1 - result.cost):.2f} %")
    return out


def fit_speed(paths: list[str] | None = None, *, budget: int = 300, workers: int | None = None,
              log: Callable[[str], None] = print) -> dict[str, Any]:
    """A 4-parameter fit (k, b, f_perp, f_par) of the paper plate over three drag files with ``budget``
    evaluations: the given files, or the model's own drags at 10, 30 and 50 mm/s over 200 mm."""
    from . import fit as fitting
    scene = preset("paper")
    data = [fitting.read_drag(p) for p in paths] if paths else [
        fitting.simulated_drag(scene.replace(**{"plate.damping": 0.8}), v, 0.2) for v in (0.01, 0.03, 0.05)]
    workers = workers or batch.default_workers()
    result = fitting.fit(scene, data, fitting.resolve_params(["k", "b", "f_perp", "f_par"]), budget=budget, seed=1,
                         workers=workers)
    out = {"date": date.today().isoformat(), "files": [d.name for d in data], "budget": budget,
           "evaluations": result.search.evaluations, "wall_s": result.search.wall_s, "workers": workers,
           "rmse_deg": result.rmse_deg}
    log(f"4-parameter fit over {len(data)} files, budget {budget} ({result.search.evaluations} evaluations) on "
        f"{workers} workers: {result.search.wall_s:.1f} s (target <= 30 s); RMSE "
        + ", ".join(f"{k} {v:.2f} deg" for k, v in result.rmse_deg.items()))
    return out
