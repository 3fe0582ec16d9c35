"""A heightfield free surface, stored as MuJoCo's ``<hfield>``: ``heights`` (nrow x ncol, m) on a regular grid of
half-extents ``size`` = (rx, ry) (m, MuJoCo's size[0] and size[1]), row r at y = -ry + 2 ry r / (nrow - 1) and
column c at x = -rx + 2 rx c / (ncol - 1) of its frame; between grid points the height is bilinear, exact on a
plane; outside the grid it is the nearest edge's. An ``<hfield>``'s heights in metres are its size[2] times its
data, its geom's position and orientation the ``centre`` and ``frame`` here.

The grid's frame (``frame``, 3 x 3, its columns the grid's x, y and z axes in the world) must have its z axis
against gravity: heights are measured along gravity, so a slope is made with the heights, not by tilting the grid.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..errors import SceneError
from . import points3, up

SUMMARY = "a grid of heights (MuJoCo's <hfield>), bilinear between its points"

# How far the grid's z axis may be from against gravity (and the frame from orthonormal): about rounding of a
# rotation built from angles, far below any tilt meant.
FRAME_TOLERANCE = 1e-9


class Grid(NamedTuple):
    """A heightfield's grid, checked: heights (nrow, ncol), size (rx, ry), centre (3,), frame (3, 3)."""

    heights: np.ndarray
    size: np.ndarray
    centre: np.ndarray
    frame: np.ndarray

    @property
    def spacing(self) -> tuple[float, float]:
        """The distance between grid points along x (columns) and y (rows), m."""
        nrow, ncol = self.heights.shape
        return 2 * self.size[0] / (ncol - 1), 2 * self.size[1] / (nrow - 1)

    def local(self, points: np.ndarray) -> np.ndarray:
        """Points (N, 3) in the grid's frame."""
        return (points - self.centre) @ self.frame

    def height(self, x: np.ndarray, y: np.ndarray, heights: np.ndarray | None = None) -> np.ndarray:
        """The bilinear height at (x, y) of the grid's frame (of ``heights`` on the same grid, if given)."""
        h = self.heights if heights is None else heights
        nrow, ncol = h.shape
        dx, dy = self.spacing
        u = np.clip((x + self.size[0]) / dx, 0.0, ncol - 1.0)
        v = np.clip((y + self.size[1]) / dy, 0.0, nrow - 1.0)
        c = np.minimum(np.floor(u).astype(int), ncol - 2)
        r = np.minimum(np.floor(v).astype(int), nrow - 2)
        fu, fv = u - c, v - r
        return ((1 - fu) * (1 - fv) * h[r, c] + fu * (1 - fv) * h[r, c + 1]
                + (1 - fu) * fv * h[r + 1, c] + fu * fv * h[r + 1, c + 1])


def grid(heights: Any, size: Any, gravity: Any, centre: Any = (0.0, 0.0, 0.0), frame: Any = None) -> Grid:
    """A heightfield's grid, checked against gravity; SceneError naming what is wrong."""
    h = np.asarray(heights, dtype=float)
    if h.ndim != 2 or min(h.shape) < 2:
        raise SceneError(f"hfield heights must be a grid of at least 2 x 2, got shape {h.shape}")
    if not np.isfinite(h).all():
        raise SceneError("hfield heights must be finite numbers")
    s = np.asarray(size, dtype=float).reshape(2)
    if not (np.isfinite(s).all() and (s > 0).all()):
        raise SceneError(f"hfield size {s.tolist()} must be two positive half-extents, m")
    R = np.eye(3) if frame is None else np.asarray(frame, dtype=float).reshape(3, 3)
    if not np.allclose(R.T @ R, np.eye(3), rtol=0.0, atol=FRAME_TOLERANCE):
        raise SceneError("hfield frame must be a rotation (orthonormal columns)")
    off = float(np.linalg.norm(R[:, 2] - up(gravity)))
    if off > FRAME_TOLERANCE:
        raise SceneError(f"hfield frame's z axis is {off:.3g} from against gravity: keep the grid level with "
                         "gravity and make a slope with its heights")
    return Grid(h, s, np.asarray(centre, dtype=float).reshape(3), R)


def depth(points: Any, gravity: Any, heights: Any, size: Any, centre: Any = (0.0, 0.0, 0.0),
          frame: Any = None) -> np.ndarray:
    """Each point's depth (m) along gravity below the heightfield."""
    g = grid(heights, size, gravity, centre, frame)
    local = g.local(points3(points))
    return g.height(local[:, 0], local[:, 1]) - local[:, 2]
