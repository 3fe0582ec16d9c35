"""The free surfaces of the medium: each kind is one module here, found by its name as the laws are
(`finrft.laws`), and its C twin is ``plugins/surfaces/NAME.c`` (declared in plugins/surfaces/surfaces.h).

A run holds its surface as a `Field` (``finrft.attach``'s ``surface``; a scene's ``[medium] surface``); the native
plugin holds the same as a FinrftField (plugins/surfaces/surfaces.h). `flat` is ``surface_z``, every scene's default.

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
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from types import ModuleType
from typing import Any, Mapping

import numpy as np

from ..errors import SceneError

# How far from vertical (the sine of the angle) gravity may be over the horizontal `flat` surface: rounding of a
# gravity built from angles, far below a slope meant.
TILT_TOLERANCE = 1e-9


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


def law_frame(up_: Any) -> np.ndarray:
    """The frame the laws measure their angles in (3, 3), its rows the frame's x, y and z axes in the world: z
    against gravity (``up_``, unit), x the world's x (else y, where up is near x) made square to it. The identity
    for up = +z. A law sees normals and velocities as ``vector @ frame.T`` and gives forces back as ``force @
    frame``; every surface law is the same about the vertical, so which x it takes changes no force. The twin of
    finrft_surface_frame (plugins/surfaces/plane.c)."""
    u = np.asarray(up_, dtype=float).reshape(3)
    a = np.array([0.0, 1.0, 0.0]) if abs(u[0]) > 0.9 else np.array([1.0, 0.0, 0.0])
    x = a - (a @ u) * u
    x = x / np.sqrt(x @ x)
    return np.array([x, np.cross(u, x), u])


@dataclass(frozen=True)
class Field:
    """A free surface as a run holds it: its kind and the parameters of the kind's ``depth``."""

    kind: str = "flat"
    parameters: Mapping[str, Any] = dataclass_field(default_factory=lambda: {"surface_z": 0.0})

    def depth(self, points: Any, gravity: Any) -> np.ndarray:
        """Each point's depth (m) along ``gravity`` below the surface, positive below it."""
        return module(self.kind).depth(points3(points), gravity, **self.parameters)

    def check(self, gravity: Any) -> None:
        """SceneError when the surface cannot be measured under ``gravity``, or is flat under a tilted one: a
        horizontal surface under a tilted gravity is no slope (give the plane of the slope instead)."""
        g = np.asarray(gravity, dtype=float).reshape(3)
        if self.kind != "flat":
            self.depth(np.zeros((1, 3)), g)
        elif not (np.hypot(g[0], g[1]) <= TILT_TOLERANCE * np.linalg.norm(g) and g[2] <= 0):
            raise SceneError(f"gravity {g.tolist()} is not along -z over the flat surface (medium.surface = "
                             f"\"flat\" is horizontal, not a slope): for a slope give medium.surface = \"plane\" "
                             f"with its surface_normal, and gravity along -z")
