"""What every file finrft writes shares: it replaces its target in one step (a failed or interrupted write never
leaves a truncated file where a complete one is expected), and it names the versions that made it."""

from __future__ import annotations

import contextlib
import os
import uuid
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Iterator

import mujoco
import numpy as np


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
