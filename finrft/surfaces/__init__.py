"""The free surfaces of the medium: each kind is one module here, found by its name as the laws are
(`finrft.laws`), and its C twin is ``plugins/surfaces/NAME.c`` (declared in plugins/surfaces/surfaces.h).

Not yet used by runs: every scene still measures depth from ``surface_z`` (`flat` is that surface).

A kind's module provides

- ``SUMMARY``: the kind in a few words;
- ``depth(points, gravity, **parameters) -> (N,)``, pure numpy: each point's depth (m) measured along gravity from
  the local surface, positive below it; 0 or less above it, where an element gets no force.

`surface_depth` gives that depth and the direction the laws take their angles against: up, against gravity, the
same for every element (RFT's angles are measured against gravity, not against a tilted surface). A law never
learns about the surface: it gets a depth and this direction.

Gravity is the model's (``option.gravity``), any direction. Bad input raises `finrft.errors.SceneError`.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from types import ModuleType
from typing import Any

import numpy as np

from ..errors import SceneError


@functools.cache
def _registry() -> dict[str, ModuleType]:
    return {info.name: importlib.import_module(f"{__name__}.{info.name}") for info in pkgutil.iter_modules(__path__)
            if not info.name.startswith("_")}


def names() -> tuple[str, ...]:
    """The kinds of surface, by name."""
    return tuple(sorted(_registry()))


def module(name: str) -> ModuleType:
    """The module of a kind of surface; SceneError naming the kinds for an unknown name."""
    try:
        return _registry()[name]
    except KeyError:
        raise SceneError(f"unknown surface {name!r}: use one of {', '.join(names())}") from None


def up(gravity: Any) -> np.ndarray:
    """The unit vector against gravity (3,); SceneError for a gravity that is zero or not finite."""
    g = np.asarray(gravity, dtype=float).reshape(3)
    norm = float(np.linalg.norm(g))
    if not np.isfinite(norm) or norm == 0.0:
        raise SceneError(f"gravity {g.tolist()} gives no direction to measure depth along: give a nonzero gravity")
    return -g / norm


def points3(points: Any) -> np.ndarray:
    """Points as an (N, 3) array of floats; SceneError for another shape."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise SceneError(f"surface points must be an (N, 3) array, got shape {p.shape}")
    return p


def surface_depth(kind: str, points: Any, gravity: Any, **parameters: Any) -> tuple[np.ndarray, np.ndarray]:
    """The depth (N,) of each point along gravity below a surface of the kind, and the direction (N, 3) the laws
    take their angles against (up, against gravity)."""
    p = points3(points)
    depth = module(kind).depth(p, gravity, **parameters)
    return depth, np.broadcast_to(up(gravity), p.shape).copy()
