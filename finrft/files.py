"""Writing files so that a failed or interrupted write never leaves a truncated file where a complete one is
expected."""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path
from typing import Iterator


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
