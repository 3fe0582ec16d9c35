"""A robot's speed-accuracy frontier (`finrft bench robots --scene FILE.toml`): every method over a range of steps,
each run's wall time against the error of each figure it reports, measured against a converged run.

Each run is the whole run as `finrft run` makes it, in this process: the run and its error estimate's companion
(`finrft.convergence`), timed together, with no limit on its error (`max_error=None`). A figure's error is the norm
of its difference from the converged run's, relative to the norm of the converged figure (as `--max-error
NAME=X%` bounds it), never over less than the headline limit's floor (the speed's 0.1 mm/s). The converged run is
`newton` or `newton-midpoint` at half the finest step swept, whichever differs less from itself at the finest step
(`REFERENCE_METHODS`); that difference is stated beside it as its own error (``reference_error``): about its error
for `newton`, first order in the step, and three times it for a second-order method (Richardson).
"""

from __future__ import annotations

import csv
import math
import platform
import time
from datetime import date
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from .. import methods
from ..convergence import ROBOT_HEADLINE, ErrorLimits, figure_difference, magnitude
from ..errors import SceneError, SimulationFailed
from ..experiments.user_model import STILL_SPEED

# The robots of the battery, shipped in finrft.mjcf under battery/ (each NAME.xml and NAME.toml), and what each is.
BATTERY = {
    "sandfish": "six 10 g links undulating in glass beads (li2013 3D), swimming",
    "eel": "eight 40 g links undulating in the 3D-RFT code's sand (rft3d), swimming",
    "screw_probe": "a 300 g spinning screw pushed into glass beads on a stand (li2013 3D), burrowing",
    "whegs": "a 0.96 kg four-wheg walker on the 3D-RFT code's sand (rft3d), legged",
    "spoke_hexapod": "a 0.78 kg hexapod with straight rotating legs in glass beads (li2013 3D), legged",
    "quadruped": "a 1.9 kg trotting quadruped with plate feet in the wheel experiments' sand (li2013 3D), legged",
    "rover": "a 2.6 kg four-wheeled rover with a 2 kg chassis in the wheel experiments' sand (li2013 3D), wheeled",
    "paddle_sled": "a 1.4 kg sled pushed by two paddle wheels on the 3D-RFT code's sand (rft3d), wheeled",
}
# The accuracy a run is held to against the converged run, relative: the default's, and the one the fastest run of
# the sweep must reach (or the default's own, where that is worse).
ACCURACY = 0.02
# The steps swept, as multiples of the scene's step: twice it down to a quarter.
STEP_FACTORS = (2.0, 1.0, 0.5, 0.25)


def battery_scene(name: str) -> str:
    """The TOML scene of a battery robot (`BATTERY`), as a path `load_scene` reads."""
    from ..models import mjcf_path
    if name not in BATTERY:
        raise SceneError(f"no battery robot named {name!r} (the battery: {', '.join(BATTERY)})")
    return str(mjcf_path(f"battery/{name}.toml"))


def headline_keys() -> tuple[str, ...]:
    return tuple(f.key for f in ROBOT_HEADLINE)


def relative_error(value: Any, reference: Any, floor: float = 0.0) -> float | None:
    """|value - reference| over |reference| (norms of all components), the denominator never below ``floor``; None
    where the reference is 0 (or not reported) and the floor 0. A run that does not report a figure the reference
    does (a cost of transport where the run does not move) is off by its whole size."""
    scale = max(magnitude(reference), floor)
    if scale == 0:
        return None
    return (magnitude(reference) if value is None else magnitude(figure_difference(value, reference))) / scale


def relative_estimate(estimate: Any, reference: Any, floor: float = 0.0) -> float | None:
    """An error estimate (in the figure's unit and shape) on the same scale as `relative_error`."""
    scale = max(magnitude(reference), floor)
    if scale == 0 or estimate is None:
        return None
    return magnitude(estimate) / scale


# The converged run's candidates (`frontier`): newton at half the finest step differed from itself at the finest
# by 0.37-0.65 % on the undulators' speed (the sand-swimmer's, the sandfish's), more than their defaults' errors;
# newton-midpoint, second order in their quasi-static motion, by 0.013 % on the sand-swimmer's.
REFERENCE_METHODS = ("newton", "newton-midpoint")

# The scale no figure's error is measured against less than: the headline limits' floors, and the speed's for the
# velocity too (a robot that stays where it is has a mean velocity of ~0, which no run matches relatively).
FLOORS = {f.key: f.floor for f in ROBOT_HEADLINE} | {"com_velocity_m_s": STILL_SPEED}


@dataclass
class Run:
    """One run of the sweep."""

    method: str
    dt: float                    # the step (an adaptive method: its largest step, sim.max_step)
    default: bool = False        # the scene's own setting
    wall_s: float = math.nan     # the whole run, its error estimate's companion included
    companion_wall_s: float = math.nan
    steps: int = 0
    failed: str = ""             # why the run stopped, one line; "" where it finished
    chosen: str = ""             # what `auto` chose, where it ran
    figures: dict[str, Any] = field(default_factory=dict)
    estimates: dict[str, Any] = field(default_factory=dict)
    errors: dict[str, float | None] = field(default_factory=dict)
    estimated: dict[str, float | None] = field(default_factory=dict)

    def compare(self, reference: dict[str, Any]) -> None:
        """Each figure's relative error against the converged run's figures, and its estimate's."""
        for key, ref in reference.items():
            if key in self.figures:
                self.errors[key] = relative_error(self.figures[key], ref, FLOORS.get(key, 0.0))
                self.estimated[key] = relative_estimate(self.estimates.get(key), ref, FLOORS.get(key, 0.0))

    def headline_error(self) -> float | None:
        """The largest error of the headline figures the run reports (`ROBOT_HEADLINE`)."""
        values = [e for k in headline_keys() if (e := self.errors.get(k)) is not None]
        return max(values) if values else None

    def worst(self) -> tuple[str, float] | None:
        """The figure furthest from the converged run, and its error."""
        values = [(k, e) for k, e in self.errors.items() if e is not None]
        return max(values, key=lambda item: item[1]) if values else None


def _scene_for(scene: Any, method: str, dt: float) -> Any:
    if not methods.chooses(method) and methods.get(method).adaptive:
        return scene.replace(**{"sim.method": method, "sim.max_step": dt})
    return scene.replace(**{"sim.method": method, "sim.dt": dt})


def measure(scene: Any, method: str, dt: float, *, estimate: bool = True) -> Run:
    """One whole run of the scene at ``method`` and ``dt`` (its companion too, with ``estimate``), timed in this
    process; a run that fails is returned with ``failed`` saying why. `auto` chooses under the default limits (the
    headline figures', as `finrft run` does), its pilots timed with the run; any other method runs unlimited."""
    from ..experiment import run
    from ..experiments.user_model import UserModel
    s = _scene_for(scene, method, dt)
    row = Run(method, dt)
    start = time.perf_counter()
    try:
        limits = ErrorLimits() if methods.chooses(method) else None
        result = run(UserModel.of(s), s, estimate_error=estimate, max_error=limits)
    except SimulationFailed as exc:
        row.wall_s = time.perf_counter() - start
        row.failed = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        return row
    row.wall_s = time.perf_counter() - start
    row.companion_wall_s = float(result.error_wall_s)
    row.steps = int(result.steps)
    row.figures = result.figure_values()
    row.estimates = {k: v for k, v in (result.error_estimate or {}).items() if k in row.figures}
    choice = result.method_choice
    if choice is not None:
        row.chosen = f"{choice.method}, {1e3 * choice.dt:g} ms"
    return row


def frontier(scene: Any, *, name: str = "robot", method_names: tuple[str, ...] | None = None,
             steps: tuple[float, ...] | None = None, duration: float = 0.0, accuracy: float = ACCURACY,
             log: Callable[[str], None] = print, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Sweep a robot scene (a `UserScene`) over ``method_names`` (default: every method) and ``steps`` (s; default:
    the scene's step times `STEP_FACTORS`), and run its default setting (the scene's own method and step) and `auto`
    from the scene's step, where the scene's method is not `auto` itself; compare every run's figures with the
    converged run's (`REFERENCE_METHODS` at half the finest step). ``duration`` > 0: that long instead of the
    scene's, its settle scaled alike. Returns the rows (`Run`), the reference and the summary (`summarise`)."""
    if duration > 0:
        scene = scene.replace(**{"sim.duration": duration,
                                 "sim.settle": scene.sim.settle * duration / scene.sim.duration})
    names = tuple(method_names or methods.names())
    steps = tuple(sorted(steps or tuple(scene.sim.dt * f for f in STEP_FACTORS), reverse=True))
    default_method = scene.sim.method
    default_swept = default_method in names and any(math.isclose(dt, scene.sim.dt) for dt in steps)
    auto_extra = not methods.chooses(default_method)
    total = (len(names) * len(steps) + (not default_swept) + auto_extra
             + sum(1 + (m not in names) for m in REFERENCE_METHODS))
    done = 0

    def tick(row: Run) -> None:
        nonlocal done
        done += 1
        what = row.failed or f"{row.wall_s:.2f} s"
        chose = f" (chose {row.chosen})" if row.chosen else ""
        log(f"{name}: {row.method} at {row.dt:g} s{' (default)' if row.default else ''}{chose}: {what}")
        if progress is not None:
            progress(done, total)

    rows: list[Run] = []
    for method in names:
        for dt in steps:
            row = measure(scene, method, dt)
            row.default = method == default_method and math.isclose(dt, scene.sim.dt)
            rows.append(row)
            tick(row)
    if not default_swept:
        row = measure(scene, default_method, scene.sim.dt)
        row.default = True
        rows.append(row)
        tick(row)
    if auto_extra:
        row = measure(scene, methods.AUTO, scene.sim.dt)
        rows.append(row)
        tick(row)
    reference_dt = min(steps) / 2
    converged: list[tuple[float, Run, Run]] = []  # each candidate's difference from itself, it, its check
    failures = []
    for method in REFERENCE_METHODS:
        candidate = measure(scene, method, reference_dt, estimate=False)
        tick(candidate)
        check = next((r for r in rows if r.method == method and math.isclose(r.dt, 2 * reference_dt)), None)
        if check is None:
            check = measure(scene, method, 2 * reference_dt, estimate=False)
            tick(check)
        if candidate.failed or check.failed:
            failures.append(f"{method} at {reference_dt:g} s and {2 * reference_dt:g} s: "
                            f"{candidate.failed or check.failed}")
            continue
        check.compare(candidate.figures)
        converged.append((check.headline_error() or 0.0, candidate, check))
    if not converged:
        raise SimulationFailed(f"{name}: no converged run: {'; '.join(failures)}")
    _, reference, check = min(converged, key=lambda c: c[0])
    for row in rows + [check]:
        if not row.failed:
            row.compare(reference.figures)
    summary = summarise(name, rows, reference, check, accuracy)
    summary["step_cost"] = step_cost(scene)
    return {"name": name, "rows": rows, "reference": reference, "check": check, "summary": summary}


def step_cost(scene: Any) -> dict[str, Any]:
    """What a step costs: one step of an implicit method (the scene's own where it is a fixed-step implicit one,
    else newton) and one of MuJoCo's explicit step, both at the scene's step, timed in C from the same state in
    this process (`bench._step_costs`): ns per element per step of each beyond the bare step (the model without
    the medium), and the implicit step's cost in explicit steps."""
    from .bench import _bare_step_s, _elements, _step_costs
    own = None if methods.chooses(scene.sim.method) else methods.get(scene.sim.method)
    method = scene.sim.method if own is not None and own.implicit and not own.adaptive else "newton"
    implicit = scene.replace(**{"sim.method": method})
    elements = _elements(implicit)
    costs = _step_costs(implicit, scene.sim.dt, _bare_step_s(implicit, STEP_COST_BARE_STEPS), elements)
    return {"method": method, "dt": scene.sim.dt, "elements": elements, **costs}


# The bare steps (the model without the medium) timed for `step_cost`, in C.
STEP_COST_BARE_STEPS = 2000


def summarise(name: str, rows: list[Run], reference: Run, check: Run, accuracy: float) -> dict[str, Any]:
    """The default run's and `auto`'s wall time, headline errors and estimate/error ratios (``default``, ``auto``:
    one and the same where the scene's method is `auto`); the fastest run of the sweep whose headline figures are
    within the accuracy asked for (or the default's own, where that is worse), and the default's and `auto`'s wall
    time over that run's; and the fastest whose own estimate keeps its headline figures within the default limits
    (``known``: the fastest run a chooser can know is within them, as `finrft run` would accept it; an honest
    estimate is above the error, so this run is finer than the fastest within the accuracy), and `auto`'s wall
    time over its."""
    default = next(r for r in rows if r.default)
    auto = next((r for r in rows if methods.chooses(r.method)), None)
    out: dict[str, Any] = {
        "robot": name, "reference": {"method": reference.method, "dt": reference.dt, "wall_s": reference.wall_s},
        "reference_error": {k: check.errors.get(k) for k in reference.figures},
        "default": _described(default)}
    if auto is not None:
        out["auto"] = _described(auto)
    if default.failed:
        return out
    target = max(accuracy, default.headline_error() or 0.0)
    swept = [r for r in rows if not methods.chooses(r.method)]
    reaching = [r for r in swept if not r.failed and r.headline_error() is not None and r.headline_error() <= target]
    out["target"] = target
    if reaching:
        fastest = min(reaching, key=lambda r: r.wall_s)
        out["fastest"] = {"method": fastest.method, "dt": fastest.dt, "wall_s": fastest.wall_s,
                          "headline_error": fastest.headline_error()}
        out["default_over_fastest"] = default.wall_s / fastest.wall_s
        if auto is not None and not auto.failed:
            out["auto_over_fastest"] = auto.wall_s / fastest.wall_s
    accepted = [r for r in swept if not r.failed and r.figures and r.estimates
                and not ErrorLimits().exceeded(r.estimates, r.figures, ROBOT_HEADLINE)]
    if accepted:
        known = min(accepted, key=lambda r: r.wall_s)
        out["known"] = {"method": known.method, "dt": known.dt, "wall_s": known.wall_s,
                        "headline_error": known.headline_error()}
        if auto is not None and not auto.failed:
            out["auto_over_known"] = auto.wall_s / known.wall_s
    return out


def _described(row: Run) -> dict[str, Any]:
    """A run's setting, wall time, what `auto` chose, and where it finished its headline errors, their estimates
    over them and its worst figure."""
    out: dict[str, Any] = {"method": row.method, "dt": row.dt, "wall_s": row.wall_s, "failed": row.failed,
                           "chosen": row.chosen}
    if not row.failed:
        out.update(errors={k: row.errors.get(k) for k in headline_keys() if k in row.errors},
                   estimate_over_error={k: (row.estimated.get(k) / e if e and row.estimated.get(k) is not None
                                            else None) for k in headline_keys() if (e := row.errors.get(k)) is not None},
                   worst=row.worst())
    return out


def csv_rows(result: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per run: method, step, whether it is the default, its wall time, each figure's relative error and
    relative estimate, and why it failed."""
    keys = list(result["reference"].figures)
    out = []
    for r in result["rows"]:
        row: dict[str, Any] = {"robot": result["name"], "method": r.method, "dt_s": r.dt, "default": int(r.default),
                               "wall_s": r.wall_s, "companion_wall_s": r.companion_wall_s, "steps": r.steps}
        for k in keys:
            row[f"{k}_error"] = r.errors.get(k)
            row[f"{k}_estimate"] = r.estimated.get(k)
        worst = r.worst()
        row.update(headline_error=r.headline_error(), worst_figure=worst[0] if worst else "",
                   worst_error=worst[1] if worst else None, failed=r.failed, chosen=r.chosen)
        out.append(row)
    return out


def write_csv(path: str | Path, result: dict[str, Any]) -> None:
    rows = csv_rows(result)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: "" if v is None else v for k, v in row.items()} for row in rows)


def chart(path: str | Path, result: dict[str, Any], accuracy: float = ACCURACY) -> None:
    """Wall time against error, one panel per headline figure and one for each run's worst figure, one marker per
    method (a line through its steps; `auto` a star, labelled with its choice), the default's run ringed; failed runs
    are left out."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    panels = [*headline_keys(), "worst figure"]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.8), sharey=True)
    markers = dict(zip(methods.names(), "osD^v<>ph")) | {methods.AUTO: "*"}
    for ax, panel in zip(axes, panels):
        for method in dict.fromkeys(r.method for r in result["rows"]):
            points = [(e, r.wall_s, r.default, r.dt) for r in result["rows"] if r.method == method and not r.failed
                      and (e := (r.worst() or (None, None))[1] if panel == "worst figure" else r.errors.get(panel))
                      is not None]
            if not points:
                continue
            points.sort(key=lambda p: p[3])  # a method's line runs through its steps in order
            ax.plot([max(p[0], 1e-7) for p in points], [p[1] for p in points], marker=markers.get(method, "o"),
                    color=f"C{list(markers).index(method) if method in markers else 9}", alpha=0.85,
                    label=method if not methods.chooses(method) else
                    f"auto: {next(r.chosen for r in result['rows'] if r.method == method)}")
            for e, wall, default, _ in points:
                if default:
                    ax.plot(max(e, 1e-7), wall, "o", ms=16, mfc="none", mec="k", mew=1.5,
                            label="default" if ax is axes[0] else None)
        ax.axvline(accuracy, color="0.5", ls="--", lw=1)
        ax.set(xscale="log", yscale="log", xlabel=f"relative error of {panel}", title=panel)
    axes[0].set_ylabel("wall time of the whole run (s)")
    axes[0].legend(fontsize=7)
    own = result["check"].headline_error()
    reference = result["reference"]
    fig.suptitle(f"{result['name']}: wall time against error (reference: {reference.method} at {reference.dt:g} s"
                 + ("" if own is None else f", its own headline error about {100 * own:.2g} %") + ")", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _pct(v: float | None) -> str:
    return "—" if v is None else f"{100 * v:.2g} %"


def _headline(run: dict[str, Any]) -> str:
    return ", ".join(f"{k.split('_m_s')[0]} {_pct(v)}" for k, v in run["errors"].items())


def markdown_row(summary: dict[str, Any]) -> str:
    """The robot's row of the results page's table."""
    d = summary["default"]
    setting = f"{d['method']}, {1e3 * d['dt']:g} ms"
    if d["failed"]:
        return f"| {summary['robot']} | {setting} | {d['wall_s']:.2f} | failed: {d['failed']} |" + " |" * 9 + \
            f" {_cost(summary)} |"
    errors = _headline(d)
    ratios = ", ".join(f"{'—' if v is None else f'{v:.2g}'}" for v in d["estimate_over_error"].values())
    worst = f"{d['worst'][0]} {_pct(d['worst'][1])}" if d.get("worst") else "—"
    auto = summary.get("auto")
    if auto is None:
        chose = "—"
    elif auto["failed"]:
        chose = f"failed: {auto['failed']}"
    else:
        chose = f"{auto['chosen']} ({auto['wall_s']:.2f} s; {_headline(auto)})"
    fastest = summary.get("fastest")
    fast = f"{fastest['method']}, {1e3 * fastest['dt']:g} ms ({fastest['wall_s']:.2f} s)" if fastest else "none"
    ratio = f"{summary['default_over_fastest']:.2f}" if fastest else "—"
    auto_ratio = f"{summary['auto_over_fastest']:.2f}" if "auto_over_fastest" in summary else "—"
    known = summary.get("known")
    passed = f"{known['method']}, {1e3 * known['dt']:g} ms ({known['wall_s']:.2f} s)" if known else "none"
    auto_known = f"{summary['auto_over_known']:.2f}" if "auto_over_known" in summary else "—"
    ref = max((v for k, v in summary["reference_error"].items() if v is not None and k in headline_keys()),
              default=None)
    return (f"| {summary['robot']} | {setting} | {d['wall_s']:.2f} | {errors} | {ratios} | {worst} | {chose} | "
            f"{fast} | {ratio} | {auto_ratio} | {passed} | {auto_known} | {_pct(ref)} | {_cost(summary)} |")


def _cost(summary: dict[str, Any]) -> str:
    """The step's cost (`step_cost`): ns per element per step of its implicit and of the explicit step, and their
    ratio."""
    c = summary.get("step_cost")
    if c is None:
        return "—"
    return (f"{c['method']} {c['implicit_ns_per_element_step']:.0f} ns, explicit "
            f"{c['explicit_ns_per_element_step']:.0f} ns ({c['elements']} elements); "
            f"{c['implicit_over_explicit_step']:.1f} explicit steps")


MARKDOWN_HEADER = ("| robot | default | wall s | headline error vs converged | estimate / error | worst figure | "
                   "auto's choice (wall s; headline error) | fastest at the same accuracy (wall s) | default / fastest "
                   "| auto / fastest | fastest its own estimate passes (wall s) | auto / it | reference's own headline "
                   "error | per element per step, implicit and explicit; an implicit step in explicit steps |\n"
                   "|---|---|---:|---|---|---|---|---|---:|---:|---|---:|---:|---|")


# The fixed-step implicit methods `steps` times against MuJoCo's explicit step.
STEP_METHODS = ("implicit", "newton", "newton-midpoint")


def steps(names: tuple[str, ...] | None = None, *, log: Callable[[str], None] = print,
          progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """What one step costs, for each robot (an example, `finrft run --example NAME`, or one of the battery,
    `BATTERY`; default: the examples) at its own step: one step of each fixed-step implicit
    method (`STEP_METHODS`) and one of MuJoCo's explicit step at the same step, from the same states of the run (ten
    over a second from 0.5 s in, or its settle: `bench.step_start`), timed in C in one process, each the best of
    several interleaved rounds (`_step_costs`):
    microseconds a step, nanoseconds per element per step beyond the bare step (the model without the medium), and
    the implicit step's cost in explicit steps. A few seconds a robot."""
    from ..experiments.user_model import EXAMPLES, example
    from ..scene import UserScene, load_scene
    import mujoco
    from .. import batch
    from .bench import _bare_step_s, _elements, _step_costs, _tick
    names = names or EXAMPLES
    out: dict[str, Any] = {"date": date.today().isoformat(), "machine": f"{platform.machine()}, "
                           f"{batch.default_workers()} cores", "mujoco": mujoco.__version__, "robots": {}}
    for i, name in enumerate(names):
        scene = load_scene(battery_scene(name) if name in BATTERY else example(name), cls=UserScene)
        elements = _elements(scene)
        bare = _bare_step_s(scene, STEP_COST_BARE_STEPS)
        row: dict[str, Any] = {"dt": scene.sim.dt, "elements": elements, "bare_us_per_step": 1e6 * bare}
        for method in STEP_METHODS:
            implicit = scene.replace(**{"sim.method": method})
            row[method] = _step_costs(implicit, scene.sim.dt, bare, elements)
        out["robots"][name] = row
        log(f"{name} ({elements} elements, {scene.sim.dt:g} s): " + "; ".join(
            f"{m} {row[m]['implicit_ns_per_element_step']:.0f} ns per element, "
            f"{row[m]['implicit_over_explicit_step']:.1f} explicit steps" for m in STEP_METHODS)
            + f"; explicit {row[STEP_METHODS[0]]['explicit_ns_per_element_step']:.0f} ns per element")
        _tick(progress, i + 1, len(names))
    return out
