"""The paper's results and the benchmarks: table (Table I), report, bench."""

from __future__ import annotations

import argparse
import json
from typing import Any

from .. import scene as scenes
from ..experiments.swim import RobotScene
from ..experiments.flags import (add_force, add_json, add_max_error, add_quiet, add_workers, limits, number,
                                 preset_name)
from ..experiments.swim import add_robot, resolve_robot
from ..experiments.user_model import EXAMPLES
from .. import methods
from ..errors import SceneError, UsageError
from .common import check_output, check_output_dir, print_json, progress, said_written, say, write_text


def add_table(sub: Any) -> None:
    p = sub.add_parser("table", help="the paper's Table I: six gaits, eta next to the paper's",
                       description="Evaluate the six gaits of the paper's Table I (the preset's gait.cycles flap "
                       "cycles each, eta over the steady ones) and print eta, the authors' script measure |net|/D1, "
                       "D1, D2 and the net speed next to the paper's eta_sim and eta_exp, as a Markdown table.")
    add_workers(p)
    add_json(p, "the rows")
    add_quiet(p)
    add_robot(p)
    add_max_error(p)
    p.set_defaults(handler=table)


def table(args: argparse.Namespace) -> int:
    from ..studies.table import PAPER_TABLE, table, table_markdown
    scene = resolve_robot(args)
    with progress(args, len(PAPER_TABLE), "Table I", "gaits") as bar:
        rows = table(scene, preset=None if args.scene else preset_name(args), max_error=limits(args),
                     workers=args.workers, progress=bar and (lambda done, total: bar(done)))
    if args.json:
        say(args, table_markdown(rows))
        print_json(args, rows)
    else:  # the table is what was asked for: --quiet leaves it
        print(table_markdown(rows))
    return 0


def add_report(sub: Any) -> None:
    p = sub.add_parser("report", help="regenerate the paper's figures and table (Markdown, PNG, rerun)",
                       description="Write DIR/report.md with the paper's results regenerated: drag and rotate "
                       "forces, effective flapping, model against the plate-drag measurements, the robot's Table I, "
                       "optimisation and trajectories, and how long each part took; plus rerun recordings. The files "
                       "appear in DIR only when every part has succeeded.")
    p.add_argument("--out", default="report", metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="a smaller version: fewer cycles and evaluations")
    p.add_argument("--preset", default="physical", choices=scenes.presets(scenes.Scene),
                   help="plate preset fitted to the measurements (default: %(default)s)")
    p.add_argument("--data", metavar="DIR", help="folder of plate-drag measurements (default: those shipped "
                   "with finrft)")
    add_workers(p)
    add_force(p)
    add_quiet(p)
    p.set_defaults(handler=report)


def report(args: argparse.Namespace) -> int:
    from ..studies.report import write_report
    check_output_dir(args.out, "--out", args.force)
    with progress(args, 1, "report", "%") as bar:
        path = write_report(args.out, quick=args.quick, workers=args.workers, data_dir=args.data,
                            plate=scenes.preset(args.preset),
                            progress=bar and (lambda done, total, part: bar(done / total, part)))
    said_written(args, (("report", path),))
    return 0


def add_bench(sub: Any) -> None:
    bench = sub.add_parser("bench", help="benchmarks, measured as ratios in one run on this machine")
    kinds = bench.add_subparsers(dest="bench", required=True, parser_class=type(bench))
    for add in (_add_backends, _add_robot, _add_robots, _add_steps, _add_laws, _add_accuracy, _add_modelling,
                _add_fit, _add_warp):
        kind = add(kinds)
        add_quiet(kind)
        if add is not _add_accuracy:
            add_json(kind, "the figures")
    bench.set_defaults(handler=run_bench)


def _budget(p: argparse.ArgumentParser, help: str) -> None:
    p.add_argument("--budget", type=number("evaluations", minimum=1, inclusive=True, integer=True), default=300,
                   metavar="EVALS", help=f"{help} (default: %(default)s)")


def _add_backends(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("backends", help="Python callback vs native plugin vs bare MuJoCo, and batch",
                         description="Time the paper plate drag (200 mm at 30 mm/s) with each backend against bare "
                         "mj_step of the same model, and the throughput of a batch of drags on all cores against "
                         "one core.")
    p.add_argument("--batch", type=number("simulations", minimum=1, inclusive=True, integer=True), default=64,
                   metavar="N", help="simulations in the batch (default: %(default)s)")
    p.add_argument("--scaling", metavar="FILE.png", help="also chart the batch throughput against the number of "
                   "workers (1, 2, ... up to the cores): process pool and threaded batch")
    add_workers(p)
    add_force(p)
    return p


def _add_robot(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("robot", help="one gait evaluation and a full optimisation",
                         description="Time one gait evaluation as the optimiser runs it (the preset's gait.cycles "
                         "flap cycles, eta over the steady ones), measure its eta against a converged run of the "
                         "same gait, and time a CMA-ES optimisation of --budget evaluations on all cores, for a "
                         "robot preset.")
    p.add_argument("--preset", default="physical", choices=scenes.presets(RobotScene),
                   help="robot preset (default: %(default)s)")
    _budget(p, "optimisation budget")
    add_workers(p)
    return p


def _add_robots(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("robots", help="the example robots: speed, accuracy, cost against bare MuJoCo and the "
                         "explicit step", description="For each example robot (finrft run --example NAME) at its "
                         "default settings: simulated seconds per wall second; its error against a converged run "
                         "(the same method at 1/8 of the step): the mean speed of the centre of mass (swimmer, "
                         "hexapod) or the mean force of the medium (wheel), in percent; the cost against bare mj_step "
                         "of the model without the medium at the same step, and per element per step; and the "
                         "speed-up over MuJoCo's explicit step at the largest step (1/2 to 1/256 of the default, "
                         "refined to 2^(1/4)) within 2 % of the converged run, as the default must be (a lower bound "
                         "where none is). The explicit runs of the light robots take most of its 10 to 20 minutes.")
    p.add_argument("--robot", action="append", choices=EXAMPLES, help="only this example (repeatable; default: all)")
    p.add_argument("--duration", type=number("s", minimum=0.0, inclusive=False), default=0.0, metavar="S",
                   help="simulate S seconds instead of each example's duration (its settle scaled alike)")
    frontier = p.add_argument_group(
        "speed-accuracy frontier", "With --scene or --battery: run each robot scene with every method (--method) "
        "over a range of steps (--dt; default: the scene's step times 2, 1, 1/2 and 1/4), at its default setting "
        "(the scene's own method and step) and with the method auto from the scene's step, and measure each whole run's wall time (its error "
        "estimate's companion included) and the error of every figure it reports against a converged run (newton or "
        "newton-midpoint at half the finest step, whichever differs less from itself at the finest step, that "
        "difference stated as its own error). Writes "
        "DIR/NAME.csv (one row per run), DIR/NAME.json (its summary), DIR/NAME.png (wall time against error, one "
        "panel per headline figure and one for each run's worst figure, the default's run ringed, auto's a star) and "
        "DIR/frontier.md (one table row per robot).")
    frontier.add_argument("--scene", action="append", metavar="FILE.toml", help="a robot scene (the format of "
                          "finrft run --scene), or the name of an example or battery robot (repeatable)")
    frontier.add_argument("--battery", action="store_true", help="every robot of the battery shipped with finrft "
                          "(finrft/mjcf/battery), then the three examples")
    frontier.add_argument("--method", action="append", choices=[m for m in methods.names() if m != "auto"],
                          help="only this method (repeatable; default: all)")
    frontier.add_argument("--dt", action="append", type=number("s", minimum=0.0, inclusive=False), metavar="S",
                          help="a step to sweep, s (repeatable); an adaptive method's largest step")
    frontier.add_argument("--out", metavar="DIR", help="output folder (default: frontier)")
    add_force(frontier)
    return p


def _add_steps(kinds: Any) -> argparse.ArgumentParser:
    from ..studies.frontier import BATTERY, STEP_METHODS
    p = kinds.add_parser("steps", help="what one step of each implicit method costs against the explicit step",
                         description="For each robot at its own step: one step of each fixed-step implicit method ("
                         f"{', '.join(STEP_METHODS)}) and one of MuJoCo's explicit step at the same step, from the "
                         "same ten states of the run over a second from 0.5 s in, timed in C in one process: "
                         "microseconds a step, nanoseconds "
                         "per element per step beyond the bare step (the model without the medium), and the implicit "
                         "step's cost in explicit steps. A few seconds a robot.")
    p.add_argument("--robot", action="append", choices=[*EXAMPLES, *BATTERY],
                   help="an example or battery robot (repeatable; default: the examples)")
    return p


def _add_laws(kinds: Any) -> argparse.ArgumentParser:
    return kinds.add_parser("laws", help="what one call of each native surface law costs, ns",
                            description="Each native surface law (li2013, li2013-planar, rft3d) as the plugin calls "
                            "it, on 1024 seeded leading elements below the surface (normals and velocities facing "
                            "every way), 16 passes over them in one call from Python, the best of 1000 calls, the "
                            "laws in turn: nanoseconds per element force. A few seconds.")


def _add_accuracy(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("accuracy", help="speed against accuracy of every time-stepping method and step",
                         description="Run the origami drag (45 mm out and back) and one flap cycle of the robot, "
                         "each with the paper's and with physical inertias, for every method (explicit with each "
                         "MuJoCo integrator, implicit, newton: steps of 10 µs to 10 ms; adaptive and adaptive-newton: "
                         "tolerances 0.1 to 1e-5), v_reg (0.1, 1, 10 mm/s) and backend (python at steps of 1 ms and "
                         "more); write DIR/accuracy.csv, a chart of error against wall time (accuracy.png) and a "
                         "summary of the fastest setting within 0.1° and 1° (accuracy.md). Takes many minutes; "
                         "the CSV gives each run's wall time.")
    p.add_argument("--out", default="accuracy", metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--quick", action="store_true",
                   help="steps of 0.1 and 1 ms, one tolerance and v_reg, and a coarser reference")
    add_workers(p)
    add_force(p)
    return p


def _add_modelling(kinds: Any) -> argparse.ArgumentParser:
    return kinds.add_parser("modelling", help="what each modelling choice costs and changes",
                            description="Measure planar against 3D chains, rigid plates as one body against welded "
                            "segments, MuJoCo limit against penalty stops, the half against the full robot, and the "
                            "wheel on a deforming surface against the flat one: the largest change in segment angle "
                            "(deg), drive force (% of its peak) or efficiency (points), or the wheel's Fx (N), and "
                            "the cost ratio: wall time, CPU time for the wheel's runs. About 50 s.")


def _add_fit(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("fit", help="a 4-parameter plate fit over three drag files",
                         description="Time a fit of k, b, f_perp and f_par of the paper plate over three drag files "
                         "with --budget evaluations on all cores.")
    p.add_argument("--data", nargs="+", metavar="FILE.csv", help="drag data (default: the model's own drags at 10, "
                   "30 and 50 mm/s)")
    _budget(p, "evaluations")
    add_workers(p)
    return p


def _worlds(text: str) -> tuple[int, ...]:
    """--worlds: whole numbers >= 1, comma-separated."""
    try:
        counts = tuple(int(item) for item in text.split(","))
    except ValueError:
        counts = ()
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"give whole numbers of worlds >= 1, comma-separated (1,16,256), got "
                                         f"{text!r}")
    return counts


def _add_warp(kinds: Any) -> argparse.ArgumentParser:
    p = kinds.add_parser("warp", help="many worlds on MuJoCo Warp against the native threaded rollout",
                         description="Robot-steps per second of an example robot against the number of worlds: "
                         "MuJoCo Warp with the surface laws in Warp kernels (finrft.warp, the warp extra), on the "
                         "Warp device there is (a GPU, else the CPU), beside MuJoCo's threaded rollout with the "
                         "native plugin on every core; both MuJoCo's step of the model's integrator at the scene's "
                         "dt under the scene's controls. Also the largest relative difference of the Warp "
                         "backend's per-body forces from the native plugin's at native states of the run.")
    p.add_argument("--worlds", type=_worlds, default=(1, 16, 256, 4096), metavar="N,N,...",
                   help="numbers of worlds (default: 1,16,256,4096)")
    p.add_argument("--robot", choices=EXAMPLES, default="sand_swimmer", help="example robot (default: %(default)s)")
    p.add_argument("--steps", type=number("steps", minimum=1, inclusive=True, integer=True), default=0,
                   metavar="K", help="steps per measurement (default: about 20000 robot-steps, at least 5)")
    p.add_argument("--device", help="Warp device, e.g. cpu or cuda:0 (default: Warp's, the GPU where there is one)")
    return p


def _bench_figures(args: argparse.Namespace, log: Any, tick: Any) -> dict[str, Any]:
    from ..studies import bench
    if args.bench == "warp":
        try:
            from ..warp import bench as warp_bench
        except ImportError:
            raise SceneError("finrft bench warp needs the warp extra: pip install 'finrft[warp]'") from None
        return warp_bench.bench(args.robot, args.worlds, steps=args.steps, device=args.device, log=log)
    if args.bench == "fit":
        return bench.fit_speed(args.data, budget=args.budget, workers=args.workers, log=log, progress=tick)
    if args.bench == "robot":
        return bench.robot(scenes.preset(args.preset, RobotScene), budget=args.budget, workers=args.workers,
                           log=log, progress=tick)
    if args.bench == "backends":
        return bench.backends(batch_size=args.batch, workers=args.workers, log=log, progress=tick)
    if args.bench == "robots" and (args.scene or args.battery):
        if args.robot:
            raise UsageError("--robot names an example for the examples' benchmark: with --scene or --battery, give "
                             "the example as --scene NAME")
        return _frontier(args, log, tick)
    if args.bench == "robots" and (args.method or args.dt or args.out):
        raise UsageError("--method, --dt and --out chart a robot's speed against accuracy: give the robot as "
                         "--scene FILE.toml (or --battery)")
    if args.bench == "robots":
        return bench.robots(tuple(args.robot or ()), duration=args.duration, log=log, progress=tick)
    if args.bench == "laws":
        return bench.laws(log=log, progress=tick)
    if args.bench == "steps":
        from ..studies import frontier
        return frontier.steps(tuple(args.robot or ()), log=log, progress=tick)
    return bench.modelling(log=log, progress=tick)


def _frontier_scenes(args: argparse.Namespace) -> list[tuple[str, Any]]:
    """The robots the frontier runs, (name, scene): --battery's, then each --scene (a file, or a robot's name)."""
    from pathlib import Path
    from ..experiments.user_model import example
    from ..scene import UserScene, load_scene
    from ..studies.frontier import BATTERY, battery_scene
    paths = [(n, battery_scene(n)) for n in BATTERY] + [(n, example(n)) for n in EXAMPLES] if args.battery else []
    for item in args.scene or ():
        if Path(item).is_file():
            paths.append((Path(item).stem, item))
        elif item in BATTERY or item in EXAMPLES:
            paths.append((item, battery_scene(item) if item in BATTERY else example(item)))
        else:
            raise SceneError(f"--scene {item}: no such file, nor a robot of the battery ({', '.join(BATTERY)}) "
                                    f"or an example ({', '.join(EXAMPLES)})")
    return [(name, load_scene(path, cls=UserScene)) for name, path in paths]


def _frontier(args: argparse.Namespace, log: Any, tick: Any) -> dict[str, Any]:
    """`frontier.frontier` of each robot: its CSV and chart in --out, and a table row for each in frontier.md."""
    from pathlib import Path
    from ..studies import frontier
    robots = _frontier_scenes(args)
    args.out = args.out or "frontier"
    check_output_dir(args.out, "--out", args.force)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summaries, rows = {}, []
    for i, (name, scene) in enumerate(robots):
        result = frontier.frontier(scene, name=name, method_names=tuple(args.method or ()) or None,
                                   steps=tuple(args.dt or ()) or None, duration=args.duration, log=log,
                                   progress=tick and (lambda done, total: tick(i + done / total, len(robots))))
        frontier.write_csv(out / f"{name}.csv", result)
        frontier.chart(out / f"{name}.png", result)
        summaries[name] = result["summary"]
        write_text(str(out / f"{name}.json"), json.dumps(result["summary"], indent=1) + "\n")
        rows.append(frontier.markdown_row(result["summary"]))
        log(rows[-1])
    write_text(str(out / "frontier.md"), frontier.MARKDOWN_HEADER + "\n" + "\n".join(rows) + "\n")
    said_written(args, [("table", str(out / "frontier.md"))]
                 + [(f"{n} runs", str(out / f"{n}.csv")) for n in summaries])
    return {"robots": summaries}


def run_bench(args: argparse.Namespace) -> int:
    from ..studies import accuracy, bench
    log = lambda text: say(args, text)  # noqa: E731
    if args.bench == "accuracy":
        check_output_dir(args.out, "--out", args.force)
        with progress(args, 1, "bench accuracy", "%") as bar:
            accuracy.study(args.out, quick=args.quick, workers=args.workers, log=log,
                           progress=bar and (lambda done, total: bar(done / total)))
        return 0
    if args.bench == "backends":
        check_output(args.scaling, ".png", "--scaling", args.force)
    unit, total = ("evaluations", args.budget) if args.bench == "fit" else ("%", 1)
    with progress(args, total, f"bench {args.bench}", unit) as bar:
        tick = bar and ((lambda done, total: bar(done)) if unit == "evaluations" else
                        (lambda done, total: bar(done / total)))
        figures = _bench_figures(args, log, tick)
    if args.bench == "backends" and args.scaling:
        figures["scaling"] = bench.scaling(args.scaling, batch_size=args.batch, measured=figures, log=log)["rows"]
        said_written(args, (("figure", args.scaling),))
    print_json(args, figures)
    return 0


SUBCOMMANDS = (add_table, add_report, add_bench)
