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
from . import Field, law_frame, points3, up

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


def of_model(model: Any, data: Any, name: str, surface_point: Any = (0.0, 0.0, 0.0)) -> Field:
    """The free surface of the ``<hfield>`` ``name`` of a compiled MuJoCo model (after mj_kinematics of ``data``):
    its heights (size[2] times its data), placed where the geom that shows it is (a geom of a static body, that
    collides with nothing: the sand is RFT's, not a rigid surface), else at ``surface_point`` level with gravity."""
    import mujoco  # the model's own kinds of object; not needed by the depths

    index = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_HFIELD, name) if name else -1
    if index < 0:
        there = ", ".join(model.hfield(i).name for i in range(model.nhfield)) or "none"
        raise SceneError(f"medium.hfield = {name!r} names no <hfield> of the model (its hfields: {there}): name one, "
                         f"or leave it empty for a generated one (medium.hfield_shape)")
    nrow, ncol, adr = int(model.hfield_nrow[index]), int(model.hfield_ncol[index]), int(model.hfield_adr[index])
    size = model.hfield_size[index]
    heights = size[2] * np.asarray(model.hfield_data[adr:adr + nrow * ncol], dtype=float).reshape(nrow, ncol)
    shown = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_HFIELD
             and model.geom_dataid[g] == index]
    if not shown:
        return Field("hfield", {"heights": heights, "size": (float(size[0]), float(size[1])),
                                "centre": tuple(map(float, surface_point)),
                                "frame": law_frame(up(model.opt.gravity)).T})
    g = shown[0]
    geom = model.geom(g).name or f"#{g}"
    if model.body_weldid[model.geom_bodyid[g]] != 0:
        raise SceneError(f"geom {geom!r} showing hfield {name!r} moves with a body: put it in the worldbody")
    if model.geom_contype[g] or model.geom_conaffinity[g]:
        raise SceneError(f"geom {geom!r} showing hfield {name!r} collides: give it contype=\"0\" conaffinity=\"0\" "
                         f"(the sand below it is RFT's, not a rigid surface)")
    return Field("hfield", {"heights": heights, "size": (float(size[0]), float(size[1])),
                            "centre": tuple(map(float, data.geom_xpos[g])),
                            "frame": np.array(data.geom_xmat[g]).reshape(3, 3)})


SHAPES = ("slope", "steps", "noise", "pile")


def generated(shape: str, gravity: Any, centre: Any = (0.0, 0.0, 0.0), extent: float = 1.0, spacing: float = 0.01,
              slope: float = 0.0, height: float = 0.01, length: float = 0.05, seed: int = 0,
              heading: float = 0.0) -> Field:
    """A heightfield made from the scene, a square grid of half-extent ``extent`` (m) and ``spacing`` (m) about
    ``centre``, level with ``gravity``, rising along its x axis at ``slope`` (rad), and on that incline:

    - ``slope``: nothing more;
    - ``steps``: stairs ``height`` (m) high, ``length`` (m) deep, rising along x;
    - ``noise``: smooth random ground, ``height`` (m) its standard deviation, ``length`` (m) its correlation
      length (white noise under a Gaussian filter; ``seed``);
    - ``pile``: a cone ``height`` (m) high, ``length`` (m) in radius, at the centre.

    Its x axis is the world's x (made square to gravity) turned by ``heading`` (rad) about up, towards y."""
    if shape not in SHAPES:
        raise SceneError(f"hfield shape {shape!r} is not one of {', '.join(SHAPES)}")
    if not (np.isfinite(extent) and np.isfinite(spacing) and 0 < spacing <= extent):
        raise SceneError(f"hfield extent {extent!r} and spacing {spacing!r} (m) must be positive, the spacing at most "
                         f"the extent")
    if not (np.isfinite(slope) and abs(slope) < np.pi / 2):
        raise SceneError(f"hfield slope {slope!r} must be an angle in rad, between -pi/2 and pi/2")
    if not (np.isfinite(height) and np.isfinite(length) and length > 0):
        raise SceneError(f"hfield height {height!r} and length {length!r} (m) must be finite, the length positive")
    count = int(round(2 * extent / spacing)) + 1
    if count > MAX_POINTS:
        raise SceneError(f"hfield of {count} x {count} points: more than {MAX_POINTS} a side; give a coarser spacing "
                         f"or a smaller extent")
    axis = np.linspace(-extent, extent, count)
    x, y = np.meshgrid(axis, axis)
    h = np.tan(slope) * x
    if shape == "steps":
        h = h + height * np.floor(x / length + 0.5)
    elif shape == "noise":
        white = np.random.default_rng(seed).normal(size=x.shape)
        k = 2 * np.pi * np.fft.fftfreq(count, axis[1] - axis[0])
        kx, ky = np.meshgrid(k, k)
        smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * np.exp(-0.5 * (kx ** 2 + ky ** 2) * length ** 2)))
        h = h + height * smooth / max(float(smooth.std()), 1e-300)
    elif shape == "pile":
        h = h + height * np.clip(1 - np.hypot(x, y) / length, 0.0, None)
    turn = np.array([[np.cos(heading), -np.sin(heading), 0.0], [np.sin(heading), np.cos(heading), 0.0],
                     [0.0, 0.0, 1.0]])
    return Field("hfield", {"heights": h, "size": (float(extent), float(extent)),
                            "centre": tuple(map(float, np.asarray(centre, dtype=float).reshape(3))),
                            "frame": law_frame(up(gravity)).T @ turn})


# A side of a generated grid: 2001 points (4 million heights) is a 2 m bed at 1 mm.
MAX_POINTS = 2001
