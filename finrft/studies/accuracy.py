"""The speed-against-accuracy study (`finrft bench accuracy`): error against wall time for every time-stepping
method, step (or tolerance), backend and v_reg, on the plate and the robot, against a converged reference."""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Protocol

import numpy as np

from .. import batch, methods
from ..convergence import ErrorLimits
from ..drive import Drive
from ..errors import Chatter, NotConverged, SimulationFailed, StepUnderflow, UndefinedResult
from ..experiment import Experiment, run as run_experiment
from ..experiments.plate import PlateTest
from ..experiments.swim import Swim
from ..experiments.swim import RobotScene
from ..scene import Scene, preset
from ..schema import field_of

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


def study(out: str | Path = "accuracy", *, quick: bool = False, workers: int | None = None,
          log: Callable[[str], None] = print,
          progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Error against wall time for every time-stepping method, step (or tolerance), backend and v_reg, on the origami
    drag (one 45 mm recovery and one power stroke) and on one flap cycle of the robot, each with the paper's and
    with physical inertias. The reference is the newton method at 2 µs (10 µs with ``quick``), checked against
    itself at twice the step and (without ``quick``) against the independent solution. A run fails when it goes unstable, non-finite, its adaptive step underflows, its
    Newton solve finds no root, or it chatters (``stepping.CHATTER_DV``: a velocity that swings back and forth
    every step, which stops the run)."""
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
            if progress is not None:
                progress(done, cases)
    if not quick:
        log("independent solutions of the references (Radau)")
        jobs = [(experiment, base, ref["time"]) for experiment, base, ref in references.values()]
        for (name, (*_, ref)), angles in zip(references.items(), batch.map_jobs(_independent, jobs, workers=workers)):
            summary[name]["independent"] = float(np.abs(angles - ref["angles"]).max())
        if progress is not None:
            progress(cases, cases)
    with (out / "accuracy.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _chart(rows, out / "accuracy.png")
    text = _summary(rows, summary)
    (out / "accuracy.md").write_text(text)
    log(text)
    return {"rows": rows, "summary": summary}


def _setting(row: dict[str, Any]) -> str:
    return (f"{row['method']}, tolerance {row['tolerance']:g}" if row["method"] in ADAPTIVE
            else f"{row['method']}, dt {row['dt']:g} s")


def _summary(rows: list[dict[str, Any]], summary: dict[str, Any]) -> str:
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


def _chart(rows: list[dict[str, Any]], path: Path) -> None:
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
