"""The ``finrft`` command line: a dispatcher over the Python API that speaks the paper's units (mm, mm/s, degrees).

Every registered experiment (`finrft.experiments.REGISTRY`) is a subcommand run on one generic path (`run`); the
other commands describe (`info`), search (`search`) or regenerate the paper's results and benchmarks (`studies`).

Exit status: 0 success, 1 the simulation went unstable or its estimated discretisation error exceeds --max-error,
2 bad input or a file that cannot be read or written (one line on stderr, nothing written), 130 interrupted
(Ctrl-C), 141 stdout closed early (as Unix tools on SIGPIPE). Output paths are checked before anything runs;
every command takes --quiet, every writer --force.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from typing import Sequence

from .. import __version__
from ..errors import SceneError, SimulationFailed
from ..experiments import REGISTRY
from . import info, search, studies
from .common import Interrupted, Parser, one_line_warning
from .run import add_experiment

__all__ = ["build_parser", "main"]

DESCRIPTION = ("Compliant fins in granular media: resistive force theory (RFT) on MuJoCo. Command-line flags use the "
               "paper's units (mm, mm/s, degrees); scene and HDF5 files use SI units, JSON keys name theirs. Every "
               "run estimates its own discretisation error. Every command runs the physical presets unless given "
               "--preset paper (the authors' model) or --scene. Exit status: 0 done, 1 the simulation went unstable "
               "or its estimated error exceeds --max-error, 2 bad input or a file that cannot be written, 130 "
               "interrupted.")


def build_parser() -> argparse.ArgumentParser:
    """The full parser: a subcommand per registered experiment, then the other commands."""
    parser = Parser(prog="finrft", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"finrft {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for command in REGISTRY.values():
        add_experiment(sub, command)
    for add in (*info.SUBCOMMANDS, *search.SUBCOMMANDS, *studies.SUBCOMMANDS):
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    with warnings.catch_warnings():
        warnings.showwarning = one_line_warning
        try:
            status = _dispatch(parser, argv)
            sys.stdout.flush()  # a reader that went away shows here, not as a traceback at exit
            return status
        except BrokenPipeError:
            # stdout was closed early (finrft swim --json | head): stop quietly, as Unix tools do on SIGPIPE.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        except KeyboardInterrupt:
            print("finrft: interrupted", file=sys.stderr)
            return 130


def _dispatch(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    """Parse and run the command; each failure one line on stderr and its exit status."""
    try:
        args = parser.parse_args(argv)
        return args.handler(args)
    except SceneError as exc:  # a UsageError too
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 2
    except SimulationFailed as exc:
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 1
    except Interrupted as exc:
        print(f"finrft: {exc}", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except OSError as exc:  # a file that could not be read or written after the checks (disk full, removed)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"finrft: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
