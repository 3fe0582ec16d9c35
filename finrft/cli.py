"""The ``finrft`` command line: a thin layer over the Python API that speaks the paper's units (mm, mm/s, degrees).

Exit status: 0 success, 1 the simulation went unstable, 2 bad input (one line on stderr, nothing written).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import scene as scenes
from .drive import Drive
from .simulate import Run, SimulationUnstable, simulate


class UsageError(Exception):
    """Bad input from the command line; reported in one line with exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, not argparse's usage block
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _number(unit: str, *, minimum: float = 0.0, inclusive: bool = False, integer: bool = False) -> Callable:
    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {'whole ' if integer else ''}number ({unit}), got "
                                             f"'{text}'") from None
        if not math.isfinite(value) or (value < minimum if inclusive else value <= minimum):
            raise argparse.ArgumentTypeError(f"must be {'>=' if inclusive else '>'} {minimum:g} {unit}, got {text}")
        return value
    return parse


def _add_common(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene")
    g.add_argument("--plate", choices=("origami", "soft", "rigid"),
                   help="plate kind (overrides plate.kind): origami = one-sided stop, soft = compliant both ways, "
                        "rigid = one body")
    g.add_argument("--scene", metavar="FILE.toml", help="scene file in SI units (default: the built-in preset)")
    g.add_argument("--preset", default="paper", choices=scenes.PRESETS[scenes.Scene],
                   help="built-in scene used when no --scene is given (default: %(default)s)")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key in SI units, e.g. --set plate.segment_inertia=0.001 (repeatable)")
    g.add_argument("--backend", choices=("native", "python"),
                   help="where the RFT force is computed (overrides sim.backend; default native, the C plugin, "
                        "falling back to python when it cannot be loaded)")
    g.add_argument("--cycles", type=_number("cycles", minimum=1, inclusive=True, integer=True), metavar="N",
                   help="back-and-forth cycles of the triangle wave (the paper used 5; the first is reported "
                        "separately); without it, a single stroke out")
    o = p.add_argument_group("output")
    o.add_argument("--out", metavar="FILE.h5", help="write the time series and the resolved scene to HDF5 (SI units)")
    o.add_argument("--rrd", metavar="FILE.rrd", help="write a rerun recording; open it with 'rerun FILE.rrd'")
    o.add_argument("--json", action="store_true", help="print a JSON summary as the last line of stdout (SI units)")
    o.add_argument("--quiet", action="store_true", help="no progress or summary text, only files and --json")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="finrft", description="Compliant fins in granular media: resistive force theory (RFT) "
                     "on MuJoCo. Command-line flags use the paper's units (mm, mm/s, degrees); scene files and "
                     "outputs use SI units.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    drag = sub.add_parser("drag", help="drag a plate through the medium along +y (the paper's drag test)",
                          description="Drag the plate's base along +y at constant speed: one stroke out from flat "
                          "(the soft, recovery direction of the origami plate), or --cycles back-and-forth cycles. "
                          "Reports the drive force (N) that holds the motion.")
    drag.add_argument("--speed", type=_number("mm/s"), default=30.0, metavar="MM_S",
                      help="drag speed in mm/s (default: %(default)s)")
    drag.add_argument("--distance", type=_number("mm"), default=200.0, metavar="MM",
                      help="stroke length in mm (default: %(default)s)")
    drag.add_argument("--attack", type=_number("degrees", inclusive=True), default=90.0, metavar="DEG",
                      help="angle of attack between the plate and the motion, degrees in 0..180 "
                           "(default: %(default)s, plate normal to the motion)")
    _add_common(drag)

    rotate = sub.add_parser("rotate", help="turn a plate about its base (the paper's rotate test)",
                            description="Turn the rod about z through its base at constant angular speed: one "
                            "stroke counter-clockwise from flat along +x, or --cycles back-and-forth cycles. "
                            "Reports the drive torque (N m).")
    rotate.add_argument("--amplitude", type=_number("degrees"), default=120.0, metavar="DEG",
                        help="stroke angle in degrees (default: %(default)s)")
    rotate.add_argument("--omega", type=_number("deg/s"), default=60.0, metavar="DEG_S",
                        help="angular speed in degrees/s (default: %(default)s)")
    _add_common(rotate)

    scene = sub.add_parser("scene", help="print a resolved scene as TOML",
                           description="Print the full resolved scene (SI units) as TOML, to copy and edit.")
    scene.add_argument("--dump", metavar="NAME", default="paper", choices=scenes.PRESETS[scenes.Scene],
                       help="preset to print (default: %(default)s)")
    scene.add_argument("--scene", metavar="FILE.toml", help="resolve this file instead of a preset")
    scene.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key (SI)")

    bench = sub.add_parser("bench", help="benchmarks, measured as ratios in one run on this machine")
    kinds = bench.add_subparsers(dest="bench", required=True, parser_class=_Parser)
    backends = kinds.add_parser("backends", help="Python callback vs native plugin vs bare MuJoCo, and batch",
                                description="Time the paper plate drag (200 mm at 30 mm/s) with each backend "
                                "against bare mj_step of the same model, and the throughput of a batch of drags "
                                "on all cores against one core.")
    backends.add_argument("--batch", type=_number("simulations", minimum=1, inclusive=True, integer=True),
                          default=64, help="simulations in the batch (default: %(default)s)")
    backends.add_argument("--workers", type=_number("processes", minimum=1, inclusive=True, integer=True),
                          help="worker processes (default: all cores)")
    backends.add_argument("--json", action="store_true", help="print the figures as JSON on the last line")
    return parser


def _resolve_scene(args: argparse.Namespace) -> scenes.Scene:
    overrides = dict(scenes.parse_override(item) for item in args.set)
    if getattr(args, "plate", None):
        overrides["plate.kind"] = args.plate
    if getattr(args, "backend", None):
        overrides["sim.backend"] = args.backend
    name = getattr(args, "preset", None) or args.dump
    return scenes.load_scene(args.scene, preset_name=name, overrides=overrides)


def _check_output(path: str | None, suffix: str, flag: str) -> None:
    if path is None:
        return
    target = Path(path)
    if target.suffix != suffix:
        raise UsageError(f"{flag} {path}: the file name must end in {suffix}")
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise UsageError(f"{flag} {path}: directory {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise UsageError(f"{flag} {path}: directory {folder} is not writable")


def _drive(args: argparse.Namespace) -> Drive:
    if args.command == "drag":
        if args.attack > 180:
            raise UsageError(f"argument --attack: must be within 0..180 degrees, got {args.attack:g}")
        return Drive("drag", args.speed / 1000, args.distance / 1000, args.cycles, args.attack)
    return Drive("rotate", math.radians(args.omega), math.radians(args.amplitude), args.cycles)


def _progress(enabled: bool) -> Callable[[float], None] | None:
    if not enabled:
        return None
    state = {"last": -1}

    def show(fraction: float) -> None:
        percent = int(100 * fraction)
        if percent != state["last"]:
            state["last"] = percent
            end = "\n" if percent >= 100 else ""
            print(f"\rsimulating {percent:3d} %", end=end, file=sys.stderr, flush=True)
    return show


def _describe(run: Run, summary: dict[str, Any]) -> str:
    """A human-readable summary in the paper's units."""
    q, u = run.quantity, run.unit
    lines = [f"{run.drive.kind} of the {run.scene.plate.kind} plate: {summary['steps']} steps of "
             f"{run.scene.sim.dt * 1e3:g} ms ({run.scene.sim.integrator}, {run.backend}) in {run.wall_s:.2f} s",
             "final segment angles (deg): " + ", ".join(f"{a:.2f}" for a in summary["final_segment_angle_deg"]),
             "final hinge angles (deg):   " + ", ".join(f"{a:.2f}" for a in summary["final_hinge_angle_deg"]),
             f"peak drive {q}: {summary[f'peak_drive_{q}_{u}']:.4g} {u.replace('Nm', 'N m')}"]
    for i, row in enumerate(run.cycle_table(), start=1):
        lines.append(f"cycle {i}: mean {q} recovery {row[f'mean_recovery_{q}_{u}']:+.4g}, "
                     f"power {row[f'mean_power_{q}_{u}']:+.4g}; net impulse {row[f'net_impulse_{u}s']:+.4g} {u}s")
    return "\n".join(lines)


def _run_test(args: argparse.Namespace) -> int:
    scene = _resolve_scene(args)
    _check_output(args.out, ".h5", "--out")
    _check_output(args.rrd, ".rrd", "--rrd")
    drive = _drive(args)
    run = simulate(scene, drive, progress=_progress(not args.quiet and sys.stderr.isatty()))
    summary = run.summary()
    if args.out or args.rrd:
        from . import record  # h5py and rerun load only when a file is asked for
        if args.out:
            record.write_h5(run, args.out)
        if args.rrd:
            record.write_rrd(run, args.rrd)
    if not args.quiet:
        print(_describe(run, summary))
        for flag, path in (("HDF5", args.out), ("rerun recording", args.rrd)):
            if path:
                print(f"wrote {flag}: {path}")
    if args.json:
        print(json.dumps(summary, default=lambda x: x.tolist() if isinstance(x, np.ndarray) else float(x)))
    return 0


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"finrft: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        return _main(parser, argv)


def _main(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    try:
        args = parser.parse_args(argv)
        if args.command == "scene":
            print(scenes.to_toml(_resolve_scene(args)), end="")
            return 0
        if args.command == "bench":
            from . import bench
            figures = bench.backends(batch_size=args.batch, workers=args.workers)
            if args.json:
                print(json.dumps(figures))
            return 0
        return _run_test(args)
    except (UsageError, scenes.SceneError) as exc:
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 2
    except SimulationUnstable as exc:
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
