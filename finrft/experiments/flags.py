"""The command-line flags experiments and studies share: number types in the CLI's units, the output flags and the
error limit (a bad flag raises finrft.errors.UsageError). argparse only: no engine here."""

from __future__ import annotations

import argparse
import math
from typing import Callable

from ..convergence import FIGURES, POSITION_PERCENT, ROBOT_HEADLINE, ErrorLimits, FigureLimit
from ..errors import UsageError


def number(unit: str, *, minimum: float = 0.0, inclusive: bool = False, integer: bool = False) -> Callable:
    """An argparse type: a finite number in ``unit``, above ``minimum`` (or at it, ``inclusive``)."""
    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {'whole ' if integer else ''}number ({unit}), got "
                                             f"'{text}'") from None
        if not math.isfinite(value):  # "must be > 0" would not say what is wrong with inf
            raise argparse.ArgumentTypeError(f"must be a finite number ({unit}), got {text}")
        if value < minimum if inclusive else value <= minimum:
            raise argparse.ArgumentTypeError(f"must be {'>=' if inclusive else '>'} {minimum:g}{' ' if unit else ''}"
                                             f"{unit}, got {text}")
        return value
    return parse


def add_quiet(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary text (what was asked "
                   "for, files or JSON, is still written)")


def add_json(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--json", action="store_true", help=f"print {what} as JSON, alone on stdout (the text goes to "
                   "stderr; each key names its unit: SI, or _deg, _mm where the key says so)")


def add_force(p: argparse.ArgumentParser) -> None:
    p.add_argument("--force", action="store_true", help="replace output files that exist (default: refuse)")


def add_result_files(p: argparse.ArgumentParser) -> None:
    """The outputs of a run: HDF5, rerun, --force, --json, --quiet."""
    p.add_argument("--out", metavar="FILE.h5", help="write the time series and the resolved scene to HDF5 (SI units)")
    p.add_argument("--rrd", metavar="FILE.rrd", help="write a rerun recording; open it with 'rerun FILE.rrd'")
    add_force(p)
    add_json(p, "a summary")
    add_quiet(p)


def max_error_item(text: str) -> float | tuple[str, float, bool]:
    """An argparse type: one --max-error item, a bare number (every bounded quantity, as `ErrorLimits.uniform`)
    or NAME=VALUE (a quantity of `ErrorLimits` or a reported figure, `convergence.FIGURES`), VALUE% relative to
    the figure's magnitude, else in its unit."""
    name, equals, value = text.partition("=")
    if not equals:
        return number("degrees or points")(text)
    name, value = name.strip(), value.strip()
    names = ("angle_deg", "eta_points", "position_percent", *FIGURES)
    if name not in names:
        raise argparse.ArgumentTypeError(f"no bounded quantity or reported figure named {name!r}: give one of "
                                         f"{', '.join(names)}, as NAME=VALUE or NAME=VALUE%")
    relative = value.endswith("%")
    if relative and name in ("angle_deg", "eta_points"):
        raise argparse.ArgumentTypeError(f"{name} is bounded in its own unit: give {name}=VALUE, without %")
    return name, number("%" if relative else "the figure's unit")(value.removesuffix("%")), relative


def add_max_error(p: argparse.ArgumentParser) -> None:
    d = ErrorLimits()
    headline = ", ".join(str(f) for f in ROBOT_HEADLINE)
    p.add_argument("--max-error", type=max_error_item, action="append", metavar="X or NAME=X[%]", help="largest "
                   "estimated discretisation error accepted (repeatable). A bare number bounds every bounded "
                   "quantity: degrees for angles, percentage points for eta, percent of a run's scale (its travel "
                   "or the model's size) for the positions of finrft run; NAME=X bounds one of them, or one figure "
                   f"a run reports ({', '.join(FIGURES)}) in its unit, NAME=X%% in percent of its magnitude: the "
                   f"figures named replace the default ones (default: {d.angle_deg:g} deg, {d.eta_points:g} "
                   f"points; a robot's {headline.replace('%', '%%')}, the speed never below 0.1 mm/s; "
                   f"{POSITION_PERCENT:g} %% of the scale where no figure is bounded). Every run estimates its own "
                   "error from a companion run at another step, and a larger one on a figure the run reports stops "
                   "with exit status 1, nothing written")


def limits(args: argparse.Namespace) -> ErrorLimits:
    """The error limits --max-error sets; the defaults for a command without the flag."""
    uniform: dict[str, float] = {}
    named: dict[str, float] = {}
    figures: dict[str, FigureLimit] = {}
    for item in getattr(args, "max_error", None) or ():
        if isinstance(item, tuple):
            name, value, relative = item
            if name in FIGURES:
                figures[name] = FigureLimit(name, value, relative)
            else:
                named[name] = value
        else:
            uniform = dict(angle_deg=item, eta_points=item, position_percent=item)
    return ErrorLimits(**{**uniform, **named}, figures=tuple(figures.values()) if figures else None)


def add_workers(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=number("processes", minimum=1, inclusive=True, integer=True), metavar="N",
                   help="worker processes (default: all cores)")


def add_scene_flags(p: argparse.ArgumentParser, what: str, example: str, *, presets: tuple[str, ...] = (),
                    presets_help: str = "", backend: str = "where the RFT force is computed", scene_help: str = "",
                    required: bool = False, title: str = "scene"):
    """The scene group: --scene, --preset (when the scene has presets), --set and --backend (when ``backend``)."""
    g = p.add_argument_group(title)
    g.add_argument("--scene", metavar="FILE.toml", required=required, help=scene_help or f"{what} scene file in SI "
                   f"units{' (instead of --preset)' if presets else ''}")
    if presets:
        g.add_argument("--preset", choices=presets, help=presets_help)
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override a scene key in SI units, e.g. --set {example} (repeatable)")
    if backend:
        g.add_argument("--backend", choices=("native", "python"), help=backend)
    return g


def preset_name(args: argparse.Namespace) -> str:
    """The preset a command runs: --preset, else the physical one; refused beside --scene."""
    if args.scene and args.preset:
        raise UsageError(f"give --scene {args.scene} or --preset {args.preset}, not both")
    return args.preset or "physical"
