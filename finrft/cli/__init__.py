"""The ``finrft`` command line: a dispatcher over the Python API that speaks the paper's units (mm, mm/s, degrees).

Every registered experiment (`finrft.experiments.REGISTRY`) is a subcommand run on one generic path (`run`); the
other commands describe (`info`), search (`search`) or regenerate the paper's results and benchmarks (`studies`).

Exit status: 0 success, 1 the simulation went unstable or its estimated discretisation error exceeds --max-error,
2 bad input or a file that cannot be read or written (one line on stderr, nothing written), 128 + the signal's
number when interrupted (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP; within a second, also inside a long native call),
141 stdout closed early (as Unix tools on SIGPIPE). Output paths are checked before anything runs; every command
takes --quiet, every writer --force.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import sys
import warnings
from typing import Sequence

from .. import interrupts
from ..errors import SceneError, SimulationFailed
from ..files import keep_existing, remove_temporaries
from . import helps
from .common import Interrupted, Parser, one_line_warning

__all__ = ["build_parser", "main"]

DESCRIPTION = ("Compliant fins in granular media: resistive force theory (RFT) on MuJoCo. Command-line flags use the "
               "paper's units (mm, mm/s, degrees); scene and HDF5 files use SI units, JSON keys name theirs. Every "
               "run estimates its own discretisation error. Every command runs the physical presets unless given "
               "--preset paper (the authors' model) or --scene. Exit status: 0 done, 1 the simulation went unstable "
               "or its estimated error exceeds --max-error, 2 bad input or a file that cannot be written, 130 "
               "interrupted (143 on SIGTERM).")


def build_parser() -> argparse.ArgumentParser:
    """The full parser: a subcommand per registered experiment, then the other commands."""
    # The commands' modules import the experiments (MuJoCo, numpy): here, not for `finrft --version` (`main`).
    from ..experiments import REGISTRY
    from . import info, search, studies
    from .run import add_experiment

    parser = Parser(prog="finrft", description=DESCRIPTION)
    _add_version(parser)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for command in REGISTRY.values():
        add_experiment(sub, command)
    for add in (*info.SUBCOMMANDS, *search.SUBCOMMANDS, *studies.SUBCOMMANDS):
        add(sub)
    return parser


def _add_version(parser: argparse.ArgumentParser) -> None:
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"finrft {__version__}")


def _print_version_if_asked(argv: Sequence[str]) -> None:
    """Print the version and exit (SystemExit 0), as the full parser would, if the options before the command ask
    for it and not for the help, without building the full parser: its commands' imports were most of `finrft
    --version`'s time. Anything else, an error included, is left to the full parser."""
    front = Parser(prog="finrft", add_help=False)
    front.add_argument("-h", "--help", action="store_true")
    front.add_argument("--version", action="store_true")
    with contextlib.suppress(SceneError):
        asked, _ = front.parse_known_args(list(itertools.takewhile(lambda word: word.startswith("-"), argv)))
        if asked.version and not asked.help:
            from .. import __version__
            print(f"finrft {__version__}")
            raise SystemExit(0)


def main(argv: Sequence[str] | None = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C before the handlers were in place
        _report("finrft: interrupted")
        return 128 + interrupts.received()


def _main(argv: Sequence[str] | None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    _print_version_if_asked(words)
    # The command line renders nothing with MuJoCo: without this, importing it imports GLFW, which starts a Python
    # process to read the library's version (a tenth of a second, and tracebacks of its own on Ctrl-C). A user's
    # choice of MUJOCO_GL is kept.
    os.environ.setdefault("MUJOCO_GL", "disable")
    if sys.stderr is None:  # started with stderr closed: its one-line reports go nowhere rather than to stdout
        sys.stderr = open(os.devnull, "w")
    if sys.stdout is None:
        # Started with stdout closed (finrft drag --json >&-): a file opened later would take its descriptor and
        # receive what is meant for stdout, so refuse before anything opens one.
        os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
        _report("finrft: error: standard output is closed: redirect it to a file or to /dev/null")
        return 2
    # SIGTERM (a scheduler's pre-emption) and SIGHUP (a lost terminal) stop as Ctrl-C does, so that a search leaves
    # a valid log, says how to continue it and shuts its workers down.
    try:
        help_of = helps.asked(words)
        text = None if help_of is None else helps.cached(help_of)
        if text is not None:  # a help the full parser printed before, for the package as it is; ends as argparse's
            sys.stdout.write(text)
            sys.stdout.flush()
            raise SystemExit(0)
        with warnings.catch_warnings(), interrupts.watched(_killed_in_native_code):
            warnings.showwarning = one_line_warning
            # The commands' imports take a signal when they are done: raised inside a C extension's initialisation
            # (MuJoCo's) it became an ImportError. Past GRACE the watcher ends the process as interrupted.
            with interrupts.deferred():
                parser = build_parser()
                if help_of is not None:
                    helps.keep(parser)
            status = _dispatch(parser, argv)
            sys.stdout.flush()  # a reader that went away shows here, not as a traceback at exit
            return status
    except BrokenPipeError:
        # stdout was closed early (finrft swim --json | head): stop quietly, as Unix tools do on SIGPIPE.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except KeyboardInterrupt:
        _report("finrft: interrupted")
        return 128 + interrupts.received()


def _killed_in_native_code(signum: int) -> None:
    """A signal Python could not raise in time (the main thread is in a long C call): the files being written are
    removed, and the process ends (`interrupts.watched`)."""
    remove_temporaries()
    _report("finrft: interrupted")


def _report(text: str) -> None:
    """One line on stderr, which may be gone (a hung-up terminal): the exit status still tells."""
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _dispatch(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    """Parse and run the command; each failure one line on stderr and its exit status."""
    try:
        args = parser.parse_args(argv)
        # An output checked absent before the run may have been written by another run since: kept, unless --force.
        with keep_existing(not getattr(args, "force", False)):
            return args.handler(args)
    except SceneError as exc:  # a UsageError too
        _report(f"finrft: error: {exc}")
        return 2
    except SimulationFailed as exc:
        _report(f"finrft: error: {exc}")
        return 1
    except Interrupted as exc:
        _report(f"finrft: {exc}")
        return 128 + interrupts.received()
    except BrokenPipeError:
        raise
    except OSError as exc:  # a file that could not be read or written after the checks (disk full, removed)
        where = f"{exc.filename}: " if exc.filename else ""
        _report(f"finrft: error: {where}{exc.strerror or exc}")
        return 2


if __name__ == "__main__":
    sys.exit(main())
