"""`finrft --help` and `finrft COMMAND --help` without the commands' imports (MuJoCo, numpy and every experiment:
most of a second), from the help texts the full parser printed before.

The texts are kept in the user's cache folder, with what they depend on: the package's files (their names, sizes and
modification times), Python's version (argparse's layout) and the terminal's width. Any change there, and the full
parser is built again and prints the help, as without the cache: a help printed from it is the one the full parser
would print. A cache folder that cannot be written only costs the speed.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import shutil
import sys
from pathlib import Path
from typing import Sequence

HELP = ("-h", "--help")
PACKAGE = Path(__file__).resolve().parent.parent


def asked(argv: Sequence[str]) -> str | None:
    """The command path whose help ``argv`` asks for, in the forms answered from the cache (``--help``, ``COMMAND
    --help``, ``COMMAND SUBCOMMAND --help``): "" for the top level, "drag" for ``drag --help``; None otherwise (the
    full parser answers)."""
    if not argv or argv[-1] not in HELP or any(word.startswith("-") for word in argv[:-1]):
        return None
    return " ".join(argv[:-1])


def cached(path: str) -> str | None:
    """The help text of ``path`` (`asked`) as the full parser printed it for the package as it is now, if kept."""
    try:
        kept = json.loads(_file().read_text(encoding="utf-8"))
        return kept["helps"][path] if kept["key"] == _key() else None
    except (OSError, ValueError, KeyError, TypeError):
        return None


def keep(parser: argparse.ArgumentParser) -> None:
    """Keep the help text of every command of ``parser`` for `cached`; nothing where the cache cannot be written."""
    helps = dict(_helps(parser, ""))
    target = _file()
    temporary = target.with_name(f"{target.name}.{os.getpid()}.tmp")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary.write_text(json.dumps({"key": _key(), "helps": helps}), encoding="utf-8")
        os.replace(temporary, target)  # a reader sees the former file or this one, whole
    except OSError:
        with contextlib.suppress(OSError):  # the folder may not exist or be enterable either
            temporary.unlink()


def _helps(parser: argparse.ArgumentParser, path: str):
    yield path, parser.format_help()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _helps(sub, f"{path} {name}".strip())


def _file() -> Path:
    home = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(home):  # the XDG specification: a relative path is to be ignored
        home = os.path.join(os.path.expanduser("~"), ".cache")
    return Path(home) / "finrft" / "helps.json"


def _key() -> str:
    """What the help texts depend on: every file of the package (name, size, modification time), Python's version
    and the width argparse lays the text out in (the terminal's, or COLUMNS)."""
    files = []
    for folder, subfolders, names in os.walk(PACKAGE):
        subfolders[:] = sorted(d for d in subfolders if d != "__pycache__")
        for name in sorted(names):
            info = os.stat(os.path.join(folder, name))
            files.append(f"{os.path.relpath(os.path.join(folder, name), PACKAGE)}:{info.st_size}:{info.st_mtime_ns}")
    text = "\n".join([sys.version, str(shutil.get_terminal_size().columns), *files])
    return hashlib.sha256(text.encode()).hexdigest()
