"""HDF5 logs of CMA-ES searches (`finrft optimize` and `finrft fit`): numbers as numeric datasets and text as
attributes, nothing pickled, so opening a log runs no code and a log outlives the pycma version that wrote it.

A log is small and is rewritten whole through a temporary file after each generation: a process killed at any
moment leaves the previous complete log. Its root attribute ``digest`` (SHA-256 of every other attribute and every
dataset with its attributes) is checked whenever it is read: a log edited or damaged since is refused, not
continued or reported.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..files import check_regular, hdf5_written
from ..errors import SceneError

OPTIMIZE = "finrft.optimize/2"
FIT = "finrft.fit/1"
# a robot scene's search (finrft optimize --scene ROBOT.toml --objective FIGURE)
SCENE = "finrft.optimize-scene/1"
# schema -> (what the log is called, the command that continues it)
_KINDS = {OPTIMIZE: ("optimisation", "optimize"), FIT: ("fit", "fit"), SCENE: ("robot scene optimisation",
                                                                              "optimize")}
# The largest log read, and the most its datasets may hold: far above a search of a million evaluations.
MAX_LOG_BYTES = 2**30


@dataclass
class Dataset:
    data: np.ndarray
    units: str
    description: str
    attrs: dict[str, Any] = field(default_factory=dict)


@dataclass
class Series:
    """A dataset that grows by one block of rows per generation."""

    units: str
    description: str
    row: tuple[int, ...] = ()      # the shape of one row
    dtype: str = "f8"
    blocks: list[np.ndarray] = field(default_factory=list)

    def dataset(self) -> Dataset:
        data = np.concatenate(self.blocks) if self.blocks else np.empty((0, *self.row))
        return Dataset(data.astype(self.dtype), self.units, self.description)


def write(path: str | Path, attrs: dict[str, Any], datasets: dict[str, Dataset]) -> None:
    """Replace ``path`` with a log of root ``attrs`` and ``datasets`` (each with its units and description), and
    their digest. It replaces the log it continues: a run owns its log (`finrft.files.locked`)."""
    with hdf5_written(path, exclusive=False, track_order=True) as f:
        f.attrs.update(attrs)
        for name, d in datasets.items():
            ds = f.create_dataset(name, data=d.data)
            ds.attrs.update(units=d.units, description=d.description, **d.attrs)
        # of what the file holds, read back: the reader computes it from the same values
        f.attrs["digest"] = digest(f)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def _canonical(attrs: Any) -> bytes:
    return json.dumps({k: _plain(v) for k, v in attrs.items() if k != "digest"}, sort_keys=True,
                      default=repr).encode()


def digest(f: Any) -> str:
    """SHA-256 of an open log's root attributes but ``digest`` and of every dataset: name, type, shape, values and
    attributes."""
    import h5py
    h = hashlib.sha256(_canonical(f.attrs))
    names: list[str] = []
    f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    for name in sorted(names):
        data = np.ascontiguousarray(f[name][()])
        h.update(json.dumps([name, data.dtype.str, list(data.shape)]).encode())
        h.update(data.tobytes() if data.dtype.kind != "O" else json.dumps(_plain(data), default=repr).encode())
        h.update(_canonical(f[name].attrs))
    return h.hexdigest()


def read(path: str | Path, schema: str) -> tuple[dict[str, Any], dict[str, Dataset]]:
    """A log's root attributes and datasets; SceneError naming the command to use when it is another kind, and
    when it is no regular file, too large, incomplete, or its contents do not match its digest."""
    import h5py
    noun, _ = _KINDS[schema]
    datasets: dict[str, Dataset] = {}
    found: list[Any] = []

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset):
            found.append(obj)

    try:
        check_regular(os.stat(path), path, f"finrft {noun} log", MAX_LOG_BYTES)
        with h5py.File(path, "r") as f:
            kind = f.attrs.get("schema")
            if kind != schema:
                raise SceneError(_mismatch(path, kind, schema))
            f.visititems(visit)
            if sum(obj.size * obj.dtype.itemsize for obj in found) > MAX_LOG_BYTES:
                raise SceneError(f"{path}: its datasets hold more than {MAX_LOG_BYTES} bytes: not a finrft {noun} "
                                 f"log")
            if "digest" in f.attrs and f.attrs["digest"] != digest(f):
                raise SceneError(f"{path}: its contents do not match the digest written with them: the log was "
                                 f"edited or damaged since, and cannot be trusted")
            attrs = {k: _plain(v) for k, v in f.attrs.items()}
            for obj in found:
                extra = {k: _plain(v) for k, v in obj.attrs.items() if k not in ("units", "description")}
                datasets[obj.name.lstrip("/")] = Dataset(obj[()], obj.attrs["units"], obj.attrs["description"], extra)
    except OSError as exc:
        raise SceneError(f"cannot read {path} as a finrft {noun} log: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, SceneError):
            raise
        raise SceneError(f"{path} is not a complete finrft {noun} log: {exc}") from None
    return attrs, datasets


def schema_of(path: str | Path) -> str | None:
    """The schema a log declares (None: not a readable HDF5 file, which its reader then refuses in its words). A
    path that is not a regular file is not opened: a FIFO's open would wait for a writer."""
    import h5py
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None
        with h5py.File(path, "r") as f:
            kind = f.attrs.get("schema")
    except (OSError, ValueError):
        return None
    return kind if isinstance(kind, str) else None


def _mismatch(path: str | Path, found: Any, schema: str) -> str:
    noun, _ = _KINDS[schema]
    if found in _KINDS:
        other, command = _KINDS[found]
        return f"{path} is a finrft {other} log; continue it with finrft {command} --resume {path}"
    if isinstance(found, str) and found.split("/")[0] == schema.split("/")[0]:
        return f"{path} is a finrft {noun} log of an older format ({found}), which this version cannot continue"
    return f"{path} is not a finrft {noun} log"
