"""What every file finrft reads or writes shares. A file it reads is read whole or not at all: a file that cannot
be read, is not UTF-8 text or (TOML) is malformed raises SceneError naming it, never a traceback of the reader. A
file it writes replaces its target in one step (a failed or interrupted write never leaves a truncated file where a
complete one is expected), and it names the versions that made it."""

from __future__ import annotations

import contextlib
import os
import tomllib
import uuid
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any, Iterator

import mujoco
import numpy as np

from .errors import SceneError


def read_text(path: str | Path, what: str) -> str:
    """A text file's contents; SceneError naming the file (as ``what``) when it cannot be read or is not UTF-8
    text."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise SceneError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{what} {path} is not a text file (UTF-8)") from None


def read_toml(text: str, origin: str) -> dict[str, Any]:
    """TOML text as a nested mapping; SceneError beginning with ``origin`` when it is malformed."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {exc}") from None


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path next to ``path`` that replaces it when the block succeeds and is removed when it fails.
    It keeps the target's suffix, for writers that choose the format by it (matplotlib)."""
    target = Path(path)
    # Not tempfile.mkstemp: its 0600 mode would carry over to the result; the writers create the file themselves.
    tmp = target.with_name(f".{target.stem}.{uuid.uuid4().hex[:12]}.tmp{target.suffix}")
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def package_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "unknown"


def provenance() -> dict[str, str]:
    """The versions of finrft, MuJoCo and numpy, and the time of writing (UTC, ISO 8601)."""
    return {"finrft_version": package_version("finrft"), "mujoco_version": mujoco.__version__,
            "numpy_version": np.__version__,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
