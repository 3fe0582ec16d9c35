"""Benchmarks, measured as ratios within one run on this machine (never as timed tests)."""

from __future__ import annotations

import platform
import time
from datetime import date
from pathlib import Path
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


# ---------------------------------------------------------------------------------------------------------
# Speed against accuracy

METHODS = (("explicit", "euler"), ("explicit", "implicitfast"), ("explicit", "implicit"), ("explicit", "rk4"),
           ("implicit", "implicitfast"), ("adaptive", "implicitfast"))


def _plate_scenes() -> dict[str, Scene]:
    paper = preset("paper")
    physical = paper.replace(**{"plate.segment_inertia": 0.00289 * 0.033 ** 2 / 12,
                                "plate.rod_inertia": 0.010 * 0.007 ** 2 / 12, "plate.stop": "limit"})
    return {"plate, paper inertia": paper, "plate, physical inertia": physical}


def _label(method: str, integrator: str) -> str:
    return f"{method} ({integrator})" if method == "explicit" else method


def _trial(job: tuple[Scene, Drive, float]) -> dict[str, Any]:
    """One setting of the study: its segment angles at 10 ms samples, wall time, or how it failed."""
    from .simulate import SimulationUnstable
    scene, drive, _ = job
    start = time.perf_counter()
    try:
        run = simulate(scene, drive)
    except SimulationUnstable as exc:
        return {"failure": "unstable", "detail": str(exc), "wall_s": time.perf_counter() - start}
    angles = np.degrees(run.segment_angle)
    if not np.all(np.isfinite(angles)):
        return {"failure": "non-finite", "wall_s": run.wall_s}
    return {"failure": "", "time": run.time, "angles": angles, "force": run.drive_force,
            "mean_force": run.stroke_impulse / drive.stroke_time, "wall_s": run.wall_s}


def accuracy(out: str | Path = "accuracy", *, quick: bool = False, workers: int | None = None,
             log: Callable[[str], None] = print) -> dict[str, Any]:
    """Error against wall time for every time-stepping method and step on the origami drag (one 45 mm recovery and
    one power stroke) with the paper's and with physical inertias. The reference is the implicit method at 2 µs (10 µs
    with ``quick``), checked against itself at twice the step. A run fails when it goes unstable or non-finite, or
    chatters: its drive force varies more than twice as much as the reference's (total variation)."""
    import csv
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # 45 mm at 30 mm/s: every step of the grid divides the 1.5 s stroke, so reversals fall on the grid.
    drive = Drive(speed=0.03, stroke=0.045, cycles=1)
    steps = [1e-4, 1e-3] if quick else [1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2]
    rows, summary = [], {}
    for name, base in _plate_scenes().items():
        # Samples every 30 ms: a whole number of every step of the grid, so all runs sample the same instants.
        base = base.replace(**{"sim.record_dt": 0.03})
        ref_dt = 1e-5 if quick else 2e-6
        ref, check = (_trial((base.replace(**{"sim.method": "implicit", "sim.dt": dt}), drive, dt))
                      for dt in (ref_dt, 2 * ref_dt))
        if ref["failure"] or check["failure"]:
            raise RuntimeError(f"the reference of {name} failed: {ref.get('detail', ref['failure'])}")
        self_error = float(np.abs(ref["angles"] - check["angles"]).max())
        steady = np.abs(ref["time"] - drive.stroke_time) > 0.045  # samples away from the reversal
        peak = np.abs(ref["force"]).max()
        jobs = [(base.replace(**{"sim.method": method, "sim.integrator": integrator, "sim.dt": dt}), drive, dt)
                for method, integrator in METHODS for dt in steps]
        for (scene, _, dt), result in zip(jobs, batch.map_jobs(_trial, jobs, workers=workers)):
            row = {"scene": name, "method": _label(scene.sim.method, scene.sim.integrator), "dt": dt,
                   "failure": result["failure"], "angle_error_deg": float("nan"), "force_error_pct": float("nan"),
                   "wall_s": result.get("wall_s", float("nan"))}
            if not result["failure"]:
                n = min(len(result["time"]), len(ref["time"]))
                if not np.allclose(result["time"][:n], ref["time"][:n]):
                    raise RuntimeError(f"{name}, {row['method']}, dt {dt:g}: samples not at the reference's times")
                row["angle_error_deg"] = float(np.abs(result["angles"][:n] - ref["angles"][:n]).max())
                row["force_error_pct"] = float(100 * np.abs((result["mean_force"] - ref["mean_force"])
                                                            / ref["mean_force"]).max())
                if np.abs(result["force"][:n] - ref["force"][:n])[steady[:n]].max() > 0.05 * peak:
                    row["failure"] = "chatter"
            rows.append(row)
        ok = [r for r in rows if r["scene"] == name and not r["failure"]]
        summary[name] = {limit: min((r for r in ok if r["angle_error_deg"] <= limit), key=lambda r: r["wall_s"],
                                    default=None) for limit in (0.1, 1.0)}
        summary[name]["reference"] = (ref_dt, self_error)
    with (out / "accuracy.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _accuracy_chart(rows, out / "accuracy.png")
    lines = ["| scene | reference (implicit) | fastest within 0.1° | fastest within 1° |", "|---|---|---|---|"]
    for name, best in summary.items():
        cells = [f"{b['method']}, dt {b['dt']:g} s: {1e3 * b['wall_s']:.0f} ms, {b['angle_error_deg']:.3g}°"
                 if b else "none" for b in (best[0.1], best[1.0])]
        ref_dt, self_error = best["reference"]
        lines.append(f"| {name} | dt {ref_dt:g} s, {self_error:.2g}° from dt {2 * ref_dt:g} s | {cells[0]} | "
                     f"{cells[1]} |")
    (out / "accuracy.md").write_text("\n".join(lines) + "\n")
    log("\n".join(lines))
    return {"rows": rows, "summary": summary}


def _accuracy_chart(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(7 * len(names), 5), squeeze=False)
    for ax, name in zip(axes[0], names):
        mine = [r for r in rows if r["scene"] == name]
        top = max([r["angle_error_deg"] for r in mine if not r["failure"]] + [1.0]) * 3
        for method in dict.fromkeys(r["method"] for r in mine):
            good = [r for r in mine if r["method"] == method and not r["failure"]]
            bad = [r for r in mine if r["method"] == method and r["failure"]]
            line, = ax.plot([r["wall_s"] for r in good], [max(r["angle_error_deg"], 1e-6) for r in good], "o-",
                            label=method)
            ax.plot([r["wall_s"] for r in bad], [top] * len(bad), "x", color=line.get_color(), ms=9)
        ax.axhline(0.1, color="grey", ls=":", lw=0.8)
        ax.axhline(1.0, color="grey", ls="--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per run (s)")
        ax.set_ylabel("max segment-angle error (deg)")
        ax.set_title(f"{name}: origami drag, 45 mm out and back\n(x at the top: failed, unstable or chattering)",
                     fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)
