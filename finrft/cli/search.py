"""The searches: optimize (the robot's gait), fit (plate parameters to measured drags), fit-rft (RFT coefficients
from rigid-plate forces), and their logs (--out, --resume, Ctrl-C)."""

from __future__ import annotations

import argparse
import os
import shlex
from pathlib import Path
from typing import Any

import numpy as np

from .. import geometry
from .. import scene as scenes
from ..experiments.swim import RobotScene
from ..errors import SceneError, UsageError
from ..experiments.flags import (add_force, add_json, add_max_error, add_quiet, add_scene_flags, add_workers, limits,
                                 number)
from ..experiments.plate import add_plate_scene, resolve_plate
from ..experiments.swim import add_robot, resolve_robot
from ..experiments.user_model import EXAMPLES
from ..files import atomic_path
from .common import (Interrupted, check_output, print_json, progress, said_written, say, text_stream,
                     write_text)


def _add_search(p: argparse.ArgumentParser, command: str) -> None:
    p.add_argument("--budget", type=number("evaluations", minimum=1, inclusive=True, integer=True),
                   metavar="EVALS", help="evaluations in all (default: 300, or the log's with --resume; CMA-ES "
                   "finishes the generation it is in)")
    p.add_argument("--seed", type=_seed, metavar="S",
                   help="random seed, 1 to 4294967295 (2**32 - 1); the same seed gives the same result (default: 1, "
                   "or the log's with --resume)")
    p.add_argument("--out", metavar="LOG.h5", help="new HDF5 log of every evaluation and of the optimiser's state, "
                   "rewritten after each generation (an existing file only with --force)")
    p.add_argument("--resume", metavar="LOG.h5", help=f"continue the run logged in LOG.h5 (a finrft {command} log) "
                   "exactly as if it had not stopped, and go on logging to it")


def _seed(text: str) -> int:
    from ..studies.optimize import MAX_SEED
    seed = number("", minimum=1, inclusive=True, integer=True)(text)
    if seed > MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be <= {MAX_SEED} (2**32 - 1), got {text}")
    return seed


def search_log(args: argparse.Namespace, fixed: dict[str, str]) -> str | None:
    """The log of an optimise or fit command, after checking --out and --resume; ``fixed``: the options (attribute
    -> flag) that a resumed run takes from its log, so that they may not be given with --resume."""
    if args.out and args.resume:
        raise UsageError("give either --out (a new log) or --resume (an existing one), not both")
    check_output(args.out, ".h5", "--out", True)
    if args.out and os.path.lexists(args.out) and not args.force:
        raise UsageError(f"--out {args.out} exists: continue it with --resume {args.out}, choose a new file, or "
                         f"pass --force to replace it")
    if args.resume:
        if not os.path.exists(args.resume):  # anything else there, the log's reader refuses in its words
            raise UsageError(f"--resume {args.resume}: no such file")
        for name, flag in fixed.items():
            if getattr(args, name, None):
                raise UsageError(f"{flag} cannot be given with --resume: the log fixes it")
    return args.resume or args.out


def interrupted(command: str, log: str | None, schema: str) -> Interrupted:
    """Ctrl-C during a search: how far the log got and how to continue it."""
    from ..studies.optimize import read_log
    if log is None:
        return Interrupted("interrupted; nothing was logged (--out LOG.h5 makes a run resumable)")
    try:
        done = len(read_log(log, schema)["state/sigma"])
    except SceneError:  # stopped before the log was first written (or a --force run, while it was replaced)
        return Interrupted("interrupted before anything was logged")
    return Interrupted(f"interrupted after {done} generation{'s' * (done != 1)}; continue with: finrft {command} "
                       f"--resume {shlex.quote(log)}")


def _allow_warp(p: argparse.ArgumentParser, what: str) -> None:
    """--backend also takes warp: the population in one batched rollout on MuJoCo Warp (`finrft.warp.population`)."""
    action = p._option_string_actions["--backend"]
    action.choices = (*action.choices, "warp")
    action.help = (f"{action.help}; warp: {what} as the worlds of one batched rollout on MuJoCo Warp (needs "
                   f"finrft[warp]; medium and open-loop control keys only; the centre of mass's and the medium "
                   f"force's figures)")


def _batched(args: argparse.Namespace) -> str:
    """The population's backend (warp, else native); --backend warp sets no scene key."""
    if args.backend != "warp":
        return "native"
    args.backend = None
    return "warp"


def add_optimize(sub: Any) -> None:
    p = sub.add_parser("optimize", help="optimise the gait with CMA-ES",
                       description="Maximise the swimming efficiency eta over one flap cycle with CMA-ES (pycma): by "
                       "default over theta1 in [0, 90] deg, theta2 in [-90, 0] deg and the arm length in [60, 85] "
                       "mm. Every evaluation is logged to HDF5 after each generation.")
    _add_search(p, "optimize")
    p.add_argument("--bounds", action="append", default=[], metavar="KEY=LOW:HIGH",
                   help="search a scene key between bounds, in SI or with a unit suffix deg or mm, e.g. "
                        "gait.theta1=10:80deg, gait.omega=0.5:2, fin.stiffness=0.1:2 (repeatable; replaces the "
                        "default bounds of that key)")
    add_workers(p)
    p.add_argument("--executor", choices=("local", "dask"), default="local",
                   help="where evaluations run: local processes, or a Dask cluster (needs finrft[cluster])")
    p.add_argument("--address", metavar="tcp://HOST:PORT", help="Dask scheduler address (--executor dask)")
    p.add_argument("--rrd", metavar="FILE.rrd", help="rerun recording: best eta per generation, the population, "
                   "and the best gait's motion")
    add_force(p)
    add_json(p, "the result")
    add_quiet(p)
    add_robot(p)
    g = p.add_argument_group("any robot scene (finrft run's; docs/guide/optimize.md)")
    g.add_argument("--objective", metavar="FIGURE[:max|min]", help="optimise this figure of a robot scene's run "
                   "(--scene ROBOT.toml or --example NAME, as finrft run) instead of the two-fin robot's eta: any "
                   "number of its JSON by path, e.g. com_velocity_m_s.0, com_speed_m_s, cost_of_transport:min, "
                   "medium_force_N.2 (max when left out); --bounds then takes any of its keys, e.g. "
                   "control.0.amplitude=0.5,1.2, control.*.frequency=0.5,2 (every entry's), medium.zeta=0.3,0.8, "
                   "model.geom.NAME.size.0=10,30mm")
    g.add_argument("--constraint", action="append", default=[], metavar="FIGURE<=VALUE",
                   help="with --objective: keep a figure below (<=) or above (>=) a value in its SI unit, e.g. "
                   "cost_of_transport<=5 (repeatable)")
    g.add_argument("--example", choices=EXAMPLES, help="with --objective: an example robot instead of --scene")
    g.add_argument("--write-scene", metavar="OUT.toml", help="with --objective: write the best scene")
    g.add_argument("--plot", metavar="OUT.png", help="with --objective: chart of the search (each evaluation's "
                   "objective and estimate by generation, the best so far); needs --out or --resume")
    add_max_error(p)
    _allow_warp(p, "with --objective, each generation")
    p.set_defaults(handler=optimize)


def _variables(args: argparse.Namespace) -> tuple[RobotScene, dict[str, Any], list]:
    """The scene, the searched variables (key -> Variable) and the generations logged so far (for --rrd)."""
    from ..studies.bounds import display_units, parse_bounds
    from ..studies.optimize import DEFAULT_VARIABLES, Variable, logged_problem, read_log
    scene, variables, generations = resolve_robot(args), {v.key: v for v in DEFAULT_VARIABLES}, []
    if args.resume:
        scene, logged = logged_problem(args.resume)
        variables = {v.key: v for v in logged}
        past = read_log(args.resume)
        generations = [(display_units(RobotScene, list(variables), past["x"][past["generation"] == g]),
                        past["eta"][past["generation"] == g]) for g in range(len(past["state/sigma"]))]
    for key, (low, high) in parse_bounds(args.bounds, RobotScene).items():
        variables[key] = Variable(key, low, high)
    return scene, variables, generations


def optimize(args: argparse.Namespace) -> int:
    from ..studies import searchlog
    from ..studies.bounds import display_units
    from ..studies.optimize import best_gait, best_gait_text, optimize
    if args.objective or args.example or (args.resume and searchlog.schema_of(args.resume) == searchlog.SCENE):
        return optimize_scene(args)
    for flag in ("constraint", "write_scene", "plot"):
        if getattr(args, flag):
            raise UsageError(f"--{flag.replace('_', '-')} goes with --objective (a robot scene's search)")
    if args.backend == "warp":
        raise UsageError("--backend warp goes with --objective (a robot scene's search); the gait's takes native "
                         "or python")
    check_output(args.rrd, ".rrd", "--rrd", args.force)
    log = search_log(args, {"bounds": "--bounds", "scene": "--scene", "preset": "--preset", "set": "--set",
                            "fin": "--fin", "model": "--model", "backend": "--backend"})
    scene, variables, generations = _variables(args)
    executor = _executor(args)
    with progress(args, args.budget, "optimize", "evaluations") as bar:
        def on_generation(g: int, values: np.ndarray, extras: dict[str, np.ndarray], es: Any) -> None:
            generations.append((display_units(RobotScene, list(variables), values), extras["eta"]))
            if bar:
                best = np.nanmax([1 - c for c in es.fit.fit]) if len(es.fit.fit) else float("nan")
                bar(es.countevals, f"generation {g + 1}, best eta {100 * best:.2f} %")

        try:
            result = optimize(scene, variables=list(variables.values()), budget=args.budget, seed=args.seed,
                              log=log, resume=bool(args.resume), replace=args.force, executor=executor,
                              workers=args.workers, max_error=limits(args), on_generation=on_generation)
        except KeyboardInterrupt:
            raise interrupted("optimize", log, searchlog.OPTIMIZE) from None
    best, summary = best_gait(scene, result, limits(args))
    if args.rrd:
        from .. import record
        record.write_optimization_rrd(args.rrd, generations, list(variables), best)
    say(args, best_gait_text(summary))
    said_written(args, (("search log", log), ("rerun recording", args.rrd)))
    print_json(args, summary)
    return 0


def optimize_scene(args: argparse.Namespace) -> int:
    """finrft optimize --objective: any figure of a robot scene over any of its keys."""
    from ..experiments.user_model import robot_scene
    from ..studies import searchlog
    from ..studies.bounds import display_units, parse_bounds, shown
    from ..studies.optimize import Constraint, Objective, Variable, logged_scene_problem, optimize_scene
    from ..scene import UserScene
    for flag in ("preset", "fin", "model"):
        if getattr(args, flag):
            raise UsageError(f"--{flag} is the two-fin robot's: a robot scene's search takes --scene or --example")
    check_output(args.rrd, ".rrd", "--rrd", args.force)
    check_output(args.write_scene, ".toml", "--write-scene", args.force)
    check_output(args.plot, ".png", "--plot", args.force)
    if args.plot and not (args.out or args.resume):
        raise UsageError("--plot charts the search's log: give --out LOG.h5 (or --resume LOG.h5)")
    log = search_log(args, {"bounds": "--bounds", "scene": "--scene", "example": "--example", "set": "--set",
                            "backend": "--backend", "objective": "--objective", "constraint": "--constraint",
                            "max_error": "--max-error"})
    backend = _batched(args)
    if args.resume:
        scene, variables, objective, constraints, max_error = logged_scene_problem(args.resume)
        past = read_scene_log(args.resume)
    else:
        if not args.objective:
            raise UsageError("--objective FIGURE is required with --example (e.g. --objective com_speed_m_s)")
        scene = robot_scene(args)
        objective = Objective.parse(args.objective)
        constraints = [Constraint.parse(c) for c in args.constraint]
        max_error = limits(args) if args.max_error else None
        variables = [Variable(k, lo, hi) for k, (lo, hi) in parse_bounds(args.bounds, UserScene).items()]
        if not variables:
            raise UsageError("give the keys to search: --bounds KEY=LOW,HIGH (repeatable), e.g. "
                             "--bounds control.*.frequency=0.5,2")
        past = []
    keys = [v.key for v in variables]
    generations = [(display_units(UserScene, keys, x), f) for x, f in past]
    sign = 1 if objective.maximize else -1
    executor = _executor(args)
    with progress(args, args.budget, "optimize", "evaluations") as bar:
        def on_generation(g: int, values: np.ndarray, extras: dict[str, np.ndarray], es: Any) -> None:
            usable = np.where(extras["usable"] > 0, extras["objective"], np.nan)
            generations.append((display_units(UserScene, keys, values), usable))
            if bar:
                best = np.nanmax(sign * usable) * sign if np.any(np.isfinite(usable)) else float("nan")
                bar(es.countevals, f"generation {g + 1}, best {objective.figure} {best:.4g}")

        try:
            result = optimize_scene(scene, variables, objective, constraints, budget=args.budget, seed=args.seed,
                                    log=log, resume=bool(args.resume), replace=args.force, executor=executor,
                                    workers=args.workers, max_error=max_error, on_generation=on_generation,
                                    backend=backend)
        except KeyboardInterrupt:
            raise interrupted("optimize", log, searchlog.SCENE) from None
    if args.write_scene:
        write_text(args.write_scene, scenes.to_toml(result.best_scene))
    if args.plot:
        from ..studies.optimize import plot_scene_search, read_log
        plot_scene_search(args.plot, read_log(log, searchlog.SCENE), objective)
    if args.rrd:
        from .. import record
        from ..experiments.user_model import run_robot
        record.write_optimization_rrd(args.rrd, generations, keys, run_robot(result.best_scene, max_error=None),
                                      figure=objective.figure, scale=1.0, unit="SI", maximize=objective.maximize)
    search = result.search
    say(args, f"best {objective.figure} {result.best_objective:.6g} +- {result.best_objective_estimate:.2g} (refined "
        f"at half the step{'; the refined candidates overlap within their estimates' * result.best_ambiguous}) at "
        + ", ".join(shown(UserScene, k, v) for k, v in result.best.items())
        + f" after {search.evaluations} evaluations in {search.wall_s:.1f} s ({result.flagged} flagged, "
          f"{result.infeasible} infeasible, {result.failed} failed)")
    said_written(args, (("search log", log), ("scene", args.write_scene), ("chart", args.plot),
                        ("rerun recording", args.rrd)))
    print_json(args, _reported({"objective": str(objective), "best": result.best, "best_objective": result.best_objective,
                      "best_objective_estimate": result.best_objective_estimate,
                      "best_ambiguous": result.best_ambiguous, "refined": result.refined,
                      "constraints": [str(c) for c in constraints], "evaluations": search.evaluations,
                      "generations": search.generations, "flagged": result.flagged,
                      "infeasible": result.infeasible, "failed": result.failed, "wall_s": search.wall_s,
                      "seed": search.seed, "budget": search.budget,
                      "stop": {k: str(v) for k, v in search.stop.items()}}))
    return 0


def _reported(value: Any) -> Any:
    """A result as JSON reports it: a figure a run does not report (NaN in the tables) as null."""
    if isinstance(value, dict):
        return {k: _reported(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_reported(v) for v in value]
    return None if isinstance(value, float) and value != value else value


def read_scene_log(path: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """A robot scene's search log as its generations: (values SI, the objective, NaN where unusable) each."""
    from ..studies import searchlog
    from ..studies.optimize import INFEASIBLE, read_log
    log = read_log(path, searchlog.SCENE)
    out = []
    for g in range(len(log["state/sigma"])):
        at = log["generation"] == g
        out.append((log["x"][at], np.where(log["cost"][at] < INFEASIBLE, log["objective"][at], np.nan)))
    return out


def _executor(args: argparse.Namespace):
    """The Dask cluster's executor with --executor dask; None for local processes."""
    if args.executor != "dask":
        if args.address:
            raise UsageError("--address goes with --executor dask")
        return None
    if not args.address:
        raise UsageError("--executor dask needs --address tcp://HOST:PORT")
    try:
        from dask.distributed import Client
    except ImportError:
        raise UsageError("--executor dask needs Dask: pip install 'finrft[cluster]'") from None
    try:
        return Client(args.address, timeout="3s").get_executor()
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"cannot reach the Dask scheduler at {args.address}: {exc}") from None


def add_fit(sub: Any) -> None:
    p = sub.add_parser("fit", help="fit plate-scene parameters to measured segment angles (CMA-ES)",
                       description="Fit plate-scene parameters so that simulated segment angles match measured ones: "
                       "each data file is a drag from flat at constant speed, 1 to 1000 mm/s (columns time_s, "
                       "displacement_mm, segment1_deg ...); the objective is the mean over files of the mean squared "
                       "error (deg^2), as the paper's E(b). The measurements shipped with finrft are in the folder "
                       "python -c 'import finrft.data as d; print(d.plate_drag_dir())' prints.")
    p.add_argument("--data", nargs="+", metavar="FILE.csv", help="drag data to fit (required unless --resume)")
    p.add_argument("--validate", nargs="+", default=[], metavar="FILE.csv",
                   help="drag data to check the fit on, not fitted")
    p.add_argument("--params", metavar="NAMES",
                   help="comma-separated parameters: b (plate.damping), k (plate.stiffness), f_perp (rft.f_perp), "
                        "f_par (rft.f_par), or any numeric plate-scene key (default: b, the paper's procedure)")
    p.add_argument("--bounds", action="append", default=[], metavar="KEY=LOW:HIGH",
                   help="bounds of a fitted parameter, by name or key, in SI or with a unit suffix deg or mm, e.g. "
                        "b=0.0001:100, plate.segment_length=20:50mm (defaults: b 0.01:100, k 0.01:100, f_perp and "
                        "f_par 0.1:100 N and -2:2 N per segment of the paper plate, in N/m^3); positive bounds over "
                        "more than a decade are searched in log space")
    _add_search(p, "fit")
    add_workers(p)
    add_max_error(p)
    p.add_argument("--write-scene", metavar="OUT.toml", help="write the fitted scene (finrft drag --scene OUT.toml)")
    p.add_argument("--plot", metavar="OUT.png", help="simulated against measured angles for every file")
    p.add_argument("--rrd", metavar="FILE.rrd", help="rerun recording of the fitted drag of the first file")
    add_force(p)
    add_json(p, "the result")
    add_quiet(p)
    add_plate_scene(p)
    p.set_defaults(handler=fit)


def _fit_problem(args: argparse.Namespace) -> tuple[scenes.Scene, list, list]:
    """The plate scene, the data and the fitted variables: from the log with --resume, else from the flags."""
    from ..studies.bounds import parse_bounds
    from ..studies.fit import ALIASES, logged_problem, read_drag, resolve_params
    if args.resume:
        return logged_problem(args.resume)
    if not args.data:
        raise UsageError("--data is required (or --resume LOG.h5)")
    names = ["b"] if args.params is None else [n.strip() for n in args.params.split(",")]
    return (resolve_plate(args), [read_drag(p) for p in args.data],
            resolve_params(names, parse_bounds(args.bounds, scenes.Scene, ALIASES)))


def fit(args: argparse.Namespace) -> int:
    from ..studies import searchlog
    from ..studies.fit import fit, fit_summary, read_drag
    for path, suffix, flag in ((args.write_scene, ".toml", "--write-scene"), (args.plot, ".png", "--plot"),
                               (args.rrd, ".rrd", "--rrd")):
        check_output(path, suffix, flag, args.force)
    log = search_log(args, {"data": "--data", "params": "--params", "bounds": "--bounds", "scene": "--scene",
                            "preset": "--preset", "set": "--set", "backend": "--backend"})
    scene, data, variables = _fit_problem(args)
    validate = [read_drag(p) for p in args.validate]
    with progress(args, args.budget, "fit", "evaluations") as bar:
        def on_generation(g: int, values: np.ndarray, extras: dict[str, np.ndarray], es: Any) -> None:
            if bar:
                bar(es.countevals, f"best RMSE {np.sqrt(es.best.f):.2f} deg")

        try:
            result = fit(scene, data, variables, budget=args.budget, seed=args.seed, validate=validate, log=log,
                         resume=bool(args.resume), replace=args.force, workers=args.workers, max_error=limits(args),
                         on_generation=on_generation)
        except KeyboardInterrupt:
            raise interrupted("fit", log, searchlog.FIT) from None
    _fit_files(args, result, data, validate)
    for key, value in result.search.best.items():
        say(args, f"{key} = {value:.6g}")
    for label, table in (("fitted", result.rmse_deg), ("validation", result.validate_rmse_deg)):
        for name, rmse in table.items():
            say(args, f"RMSE {name} ({label}): {rmse:.2f} deg")
    say(args, f"{result.search.evaluations} evaluations in {result.search.wall_s:.1f} s")
    said_written(args, (("search log", log), ("scene", args.write_scene), ("figure", args.plot),
                        ("rerun recording", args.rrd)))
    print_json(args, fit_summary(result))
    return 0


def _fit_files(args: argparse.Namespace, result: Any, data: list, validate: list) -> None:
    """The fitted scene, the figure and the recording the flags ask for."""
    from ..experiments.plate import simulate
    from ..studies.fit import drag_for, plot
    if args.write_scene:
        write_text(args.write_scene, scenes.to_toml(result.scene))
    if args.plot:
        with atomic_path(args.plot) as tmp:
            plot(result.scene, [(d, "fitted") for d in data] + [(d, "validation") for d in validate], tmp)
    if args.rrd:
        from .. import record
        record.write_rrd(simulate(result.scene, drag_for(data[0])), args.rrd, force=True)


def add_fit_rft(sub: Any) -> None:
    p = sub.add_parser("fit-rft", help="identify RFT coefficients from rigid-plate forces",
                       description="Identify the paper law's f_perp and f_par (least squares) and the table law's "
                       "F_perp(theta), F_par(theta) from the steady forces on a rigid plate dragged at several angles "
                       "of attack (columns attack_deg, force_normal_N, force_tangential_N, as written by finrft drag "
                       "--plate rigid --forces-csv; one row per angle, with an angle above 0 and one below 90 deg). "
                       "Writes a scene fragment and the table CSV.")
    p.add_argument("--data", required=True, metavar="FORCES.csv", help="forces per angle of attack")
    p.add_argument("--speed", type=number("mm/s"), default=30.0, metavar="MM_S",
                   help="drag speed of the measurements in mm/s (default: %(default)s)")
    p.add_argument("--out", metavar="FRAGMENT.toml", help="write the [rft] scene fragment here (default: print it)")
    p.add_argument("--table", metavar="TABLE.csv", help="write the table law here (default: beside --out)")
    add_force(p)
    add_json(p, "the coefficients")
    add_quiet(p)
    add_plate_scene(p, backend=False)
    p.set_defaults(handler=fit_rft)


def fit_rft(args: argparse.Namespace) -> int:
    from ..laws.table import write_table
    from ..studies.fit import identify_rft, read_forces, rft_fragment
    scene = resolve_plate(args)
    table_path = args.table or (str(Path(args.out).with_suffix(".csv")) if args.out else None)
    check_output(args.out, ".toml", "--out", args.force)
    check_output(table_path, ".csv", "--table", args.force)
    forces = read_forces(args.data)
    law, table = identify_rft(forces, scene.plate.segments, scene.rft.v_reg, args.speed / 1000,
                              geometry.segment_scale(scene))
    fragment = rft_fragment(law, Path(table_path).name if table_path else "TABLE.csv")
    if table_path:
        with atomic_path(table_path) as tmp:
            write_table(tmp, table)
    if args.out:
        write_text(args.out, fragment)
        said_written(args, (("law", args.out), ("table", table_path)))
    else:
        print(fragment, end="", file=text_stream(args))
    print_json(args, {"f_perp": law.f_perp, "f_par": law.f_par, "v_reg": law.v_reg,
                      "table": {"attack_deg": table.attack_deg, "f_perp": table.f_perp, "f_par": table.f_par}})
    return 0


def add_sweep(sub: Any) -> None:
    p = sub.add_parser("sweep", help="run variants of a robot scene over a grid or at random: a table of figures",
                       description="Run variants of a robot scene (finrft run's: --scene ROBOT.toml or --example "
                       "NAME) over a grid of values of any of its keys (--grid, repeatable: every combination), or "
                       "N variants drawn at random (--random N --seed S, with a distribution per key: --dist), each "
                       "with its error estimate, in parallel processes (or on a Dask cluster). Writes one table of "
                       "every figure of the run's JSON and its estimate per variant (--csv; --out: HDF5 with each "
                       "variant's resolved scene) and draws a figure against a swept key (--plot). Keys are scene "
                       "keys in SI (medium.zeta, control.0.amplitude), every entry's (control.*.frequency) or the "
                       "model's design keys (model.geom.NAME.size.0); values may carry a unit suffix (20mm, 30deg).")
    p.add_argument("--grid", action="append", default=[], metavar="KEY=A,B,C", help="the values of a key (repeatable; "
                   "every combination runs)")
    p.add_argument("--random", type=number("variants", minimum=1, inclusive=True, integer=True), metavar="N",
                   help="N variants drawn at random from the --dist distributions")
    p.add_argument("--seed", type=_seed, default=1, metavar="S", help="the random variants' seed (default: 1)")
    p.add_argument("--dist", action="append", default=[], metavar="KEY=NAME:A,B", help="a key's distribution for "
                   "--random: uniform:LOW,HIGH, loguniform:LOW,HIGH or normal:MEAN,SD, e.g. "
                   "medium.zeta=uniform:0.4,0.8 (repeatable)")
    p.add_argument("--csv", metavar="TABLE.csv", help="the table: a row per variant, its keys, every figure and its "
                   "estimate")
    p.add_argument("--out", metavar="TABLE.h5", help="the table as HDF5, with each variant's resolved scene")
    p.add_argument("--plot", metavar="KEY", help="draw --figure against this swept key (into --png)")
    p.add_argument("--figure", default="com_speed_m_s", metavar="PATH", help="the figure --plot draws (default: "
                   "%(default)s)")
    p.add_argument("--png", metavar="OUT.png", help="where --plot draws")
    add_workers(p)
    p.add_argument("--executor", choices=("local", "dask"), default="local",
                   help="where variants run: local processes, or a Dask cluster (needs finrft[cluster])")
    p.add_argument("--address", metavar="tcp://HOST:PORT", help="Dask scheduler address (--executor dask)")
    g = add_scene_flags(p, "robot", "medium.zeta=0.5", backend="where the RFT force is computed (overrides "
                        "sim.backend)")
    g.add_argument("--example", choices=EXAMPLES, help="an example robot instead of --scene")
    add_max_error(p)
    add_force(p)
    add_json(p, "the table (a list of variants: keys, figures, estimates)")
    add_quiet(p)
    _allow_warp(p, "every variant")
    p.set_defaults(handler=sweep)


def sweep(args: argparse.Namespace) -> int:
    from ..experiments.user_model import UserModel, robot_scene
    from ..studies import sweep as sweeps
    from ..studies.figures import check_path
    for path, suffix, flag in ((args.csv, ".csv", "--csv"), (args.out, ".h5", "--out"), (args.png, ".png", "--png")):
        check_output(path, suffix, flag, args.force)
    if bool(args.plot) != bool(args.png):
        raise UsageError("--plot KEY and --png OUT.png go together")
    if bool(args.grid) == bool(args.random):
        raise UsageError("give the variants: --grid KEY=A,B,C (repeatable), or --random N with --dist")
    if args.random and not args.dist:
        raise UsageError("--random N draws from the --dist distributions: give one per key, e.g. "
                         "--dist medium.zeta=uniform:0.4,0.8")
    if args.dist and not args.random:
        raise UsageError("--dist goes with --random N")
    backend = _batched(args)
    scene = robot_scene(args)
    variants = (sweeps.grid_variants(sweeps.parse_grid(args.grid)) if args.grid
                else sweeps.random_variants(sweeps.parse_dist(args.dist), args.random, args.seed))
    check_path(args.figure, scene, UserModel.of(scene).bodies)
    if args.plot:
        if args.plot not in variants[0]:
            raise UsageError(f"--plot {args.plot}: the sweep's keys are {', '.join(variants[0])}")
        if not all(isinstance(v[args.plot], (int, float)) and not isinstance(v[args.plot], bool) for v in variants):
            raise UsageError(f"--plot {args.plot}: its values are not numbers; plot against a numeric key")
    executor = _executor(args)
    max_error = limits(args) if args.max_error else None
    with progress(args, len(variants), "sweep", "variants") as bar:
        try:
            result = sweeps.sweep(scene, variants, workers=args.workers, executor=executor, max_error=max_error,
                                  progress=None if bar is None else lambda done, total: bar(done), backend=backend)
        except KeyboardInterrupt:
            raise Interrupted("interrupted; nothing was written") from None
    if args.csv:
        write_text(args.csv, sweeps.table_csv(result))
    if args.out:
        sweeps.write_hdf5(args.out, result)
    if args.plot:
        sweeps.plot(args.png, result, args.plot, args.figure)
    failed = sum(1 for r in result.results if r["error"])
    say(args, f"{len(variants)} variants of {', '.join(result.keys)}: {failed} failed; " + "; ".join(
        f"{', '.join(f'{k}={v:g}' if isinstance(v, float) else f'{k}={v}' for k, v in variant.items())}: "
        + (f"{args.figure} {r['figures'].get(args.figure, float('nan')):.4g} +- "
           f"{r['estimates'].get(args.figure, float('nan')):.2g}" if not r["error"] else "failed")
        for variant, r in list(zip(variants, result.results))[:20]) + ("; ..." if len(variants) > 20 else ""))
    said_written(args, (("table", args.csv), ("table", args.out), ("figure", args.png)))
    print_json(args, _reported([{"keys": v, "figures": r["figures"], "estimates": r["estimates"], "error": r["error"]}
                                for v, r in zip(variants, result.results)]))
    return 0


SUBCOMMANDS = (add_optimize, add_fit, add_fit_rft, add_sweep)
