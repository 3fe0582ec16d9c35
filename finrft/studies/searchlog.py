"""HDF5 logs of CMA-ES searches (`finrft optimize` and `finrft fit`): numbers as numeric datasets and text as
attributes, nothing pickled, so opening a log runs no code and a log outlives the pycma version that wrote it.

A log is small and is rewritten whole through a temporary file after each generation: a process killed at any
moment leaves the previous complete log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..files import atomic_path
from ..errors import SceneError

OPTIMIZE = "finrft.optimize/2"
FIT = "finrft.fit/1"
# schema -> (what the log is called, the command that continues it)
_KINDS = {OPTIMIZE: ("optimisation", "optimize"), FIT: ("fit", "fit")}


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
    """Replace ``path`` with a log of root ``attrs`` and ``datasets`` (each with its units and description)."""
    import h5py  # here, not at the top: `import finrft` stays light
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=True) as f:
        f.attrs.update(attrs)
        for name, d in datasets.items():
            ds = f.create_dataset(name, data=d.data)
            ds.attrs.update(units=d.units, description=d.description, **d.attrs)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def read(path: str | Path, schema: str) -> tuple[dict[str, Any], dict[str, Dataset]]:
    """A log's root attributes and datasets; SceneError naming the command to use when it is another kind."""
    import h5py
    noun, _ = _KINDS[schema]
    datasets: dict[str, Dataset] = {}

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset):
            extra = {k: _plain(v) for k, v in obj.attrs.items() if k not in ("units", "description")}
            datasets[name] = Dataset(obj[()], obj.attrs["units"], obj.attrs["description"], extra)

    try:
        with h5py.File(path, "r") as f:
            found = f.attrs.get("schema")
            if found != schema:
                raise SceneError(_mismatch(path, found, schema))
            attrs = {k: _plain(v) for k, v in f.attrs.items()}
            f.visititems(visit)
    except OSError as exc:
        raise SceneError(f"cannot read {path} as a finrft {noun} log: {exc}") from None
    except KeyError as exc:
        raise SceneError(f"{path} is not a complete finrft {noun} log: {exc}") from None
    return attrs, datasets


def _mismatch(path: str | Path, found: Any, schema: str) -> str:
    noun, _ = _KINDS[schema]
    if found in _KINDS:
        other, command = _KINDS[found]
        return f"{path} is a finrft {other} log; continue it with finrft {command} --resume {path}"
    if isinstance(found, str) and found.split("/")[0] == schema.split("/")[0]:
        return f"{path} is a finrft {noun} log of an older format ({found}), which this version cannot continue"
    return f"{path} is not a finrft {noun} log"
