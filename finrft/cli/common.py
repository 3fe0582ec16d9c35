"""What every command shares: the parser that reports in one line, output checks, the progress bar, summary text,
'wrote' lines and JSON."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from ..errors import SimulationFailed, UsageError
from ..files import atomic_path, check_folder, check_target


class Interrupted(Exception):
    """Ctrl-C: reported in one line (how to continue, when there is a log) with exit status 128 + the signal's number."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, not argparse's usage block
        raise UsageError(f"{message} (see '{self.prog} --help')")


def check_output(path: str | None, suffix: str, flag: str, force: bool, *, append: bool = False) -> None:
    """Refuse, before anything runs, an output file that cannot be written: the wrong suffix, a missing or
    read-only folder, a directory, or (unless ``force``, or ``append`` for files added to) an existing file."""
    if path is None:
        return
    target = Path(path)
    if target.suffix != suffix:
        raise UsageError(f"{flag} {path}: the file name must end in {suffix}")
    check_target(target, flag, UsageError)
    if os.path.lexists(target) and not (force or append):  # a symbolic link too, even one to nothing
        raise UsageError(f"{flag} {path} exists: choose a new file, or pass --force to replace it")


def check_output_dir(path: str, flag: str, force: bool) -> None:
    """The same for an output folder: it may exist, empty, or with ``force``."""
    target = Path(path)
    _check_writable(target.parent, flag, path)
    if target.exists() and not target.is_dir():
        raise UsageError(f"{flag} {path} is a file: give a folder")
    if target.is_dir() and any(target.iterdir()) and not force:
        raise UsageError(f"{flag} {path} exists and is not empty: choose a new folder, or pass --force to write "
                         f"into it")
    if target.is_dir():
        _check_writable(target, flag, path)


def _check_writable(folder: Path, flag: str, path: str) -> None:
    check_folder(folder, f"{flag} {path}", UsageError)


def write_text(path: str, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


@contextlib.contextmanager
def progress(args: argparse.Namespace, total: float, what: str,
             unit: str = "") -> Iterator[Callable[..., None] | None]:
    """A progress bar on stderr: yields ``update(done, note="")``, ``done`` counted towards ``total`` and never
    shown past it (``unit`` "%": ``done`` is a fraction of 1); None when stderr is not a terminal or with --quiet,
    so that the work skips its callbacks."""
    if args.quiet or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm
    scale = 100 if unit == "%" else 1
    form = "{desc}: {percentage:3.0f}% |{bar}| {elapsed}<{remaining}{postfix}" if unit == "%" else None
    try:  # a terminal that reports no size (0 x 0) would hide the bar
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError):
        size = os.terminal_size((0, 0))
    with tqdm(total=scale * total, desc=what, unit=unit or "it", file=sys.stderr, leave=False,
              ncols=size.columns or 80, nrows=size.lines or 24, bar_format=form) as bar:
        def update(done: float, note: str = "") -> None:
            if note:
                bar.set_postfix_str(note, refresh=False)
            bar.update(min(round(scale * done), bar.total) - bar.n)
        yield update


def say(args: argparse.Namespace, text: str) -> None:
    """Human text, unless --quiet (or empty), on stdout; on stderr with --json, so that stdout holds the JSON alone
    (finrft drag --json | python -m json.tool). It keeps a progress bar intact."""
    if text and not args.quiet:
        from tqdm import tqdm
        tqdm.write(text, file=text_stream(args))


def text_stream(args: argparse.Namespace):
    """Where human text goes: stderr when stdout is the JSON's."""
    return sys.stderr if getattr(args, "json", False) else sys.stdout


def said_written(args: argparse.Namespace, files: Sequence[tuple[str, str | None]]) -> None:
    """One line for each file written, (what, path) with path None for one not asked for."""
    for what, path in files:
        if path:
            say(args, f"wrote {what}: {path}")


def to_json(value: Any) -> str:
    """One line of strict JSON; a NaN or infinity anywhere is a failed result (exit 1), never invalid JSON."""
    import numpy as np  # here: `finrft --version` imports this module, and needs no numpy

    try:
        return json.dumps(value, allow_nan=False,
                          default=lambda x: x.tolist() if isinstance(x, np.ndarray) else float(x))
    except ValueError:
        raise SimulationFailed("the result holds a NaN or infinite value: nothing is reported") from None


def print_json(args: argparse.Namespace, value: Any) -> None:
    """The --json line, when asked for."""
    if args.json:
        print(to_json(value))


def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"finrft: warning: {message}", file=sys.stderr)
