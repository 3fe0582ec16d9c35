"""A heightfield whose heights are state (`finrft.surfaces.hfield`'s grid): sand the body sweeps is pushed into a
berm in front of it and to its sides, and the surface then relaxes to the medium's angle of repose.

`update` does one step: `sweep` then `relax`. Each grid point stands for a cell of the grid's spacing dx x dy, so
the sand's volume is dx dy times the sum of the heights; both conserve it (to rounding).

- `sweep`: every grid point within an element's footprint (a disc of the element's area, and always the point
  nearest to it), where the element is below the surface, is lowered to the element; what it loses goes to the
  first grid point not under the body along the element's horizontal velocity (``front_share`` of it) and across it
  on either side (half the rest each), or equally to the four directions of the grid for an element moving
  straight down. An element coarser than the grid leaves points between footprints untouched. With
  ``compaction`` c (the option "compaction"; 0, the wheel group's model, puts all of it in the berm), only (1 - c)
  of what a point loses goes to the berm: the share c stays under the point, compacted into denser sand below the
  floor the element leaves (``compacted``, a height of sand at its bulk density), so that the sand's mass, not its
  volume, is conserved: the heights' volume plus the compacted volume (`DeformingSurface.sand`). With the berm
  rule "facing" (`BERMS`; "velocity", the default, is the one above), an element leading into the sand (outward
  normal . velocity > 0) pushes its sand along its normal's horizontal part, the side it faces, instead of along its
  motion: a yawed wheel's rim pushes its sand ahead of the rim, and only its side wall pushes sand sideways.
- `relax`: between neighbouring grid points (along x and along y) whose slope exceeds tan(repose) + ``tolerance``,
  sand flows from the higher to the lower, a quarter of the height above the angle of repose per iteration (the
  explicit diffusion limit), until no slope does. Points under the body (``blocked``) neither give nor take.

`depth` measures from the deformed surface; with ``pile_factor`` it follows the wheel group's rule instead
(qishuny/3D-RFT-wheel, RFT3D/SandDeformation.m): an element in raised sand (below the deformed surface, above the
original) takes its depth below the deformed surface times the factor, and one below the original surface the
lesser of its depths below the two. `WHEEL_GROUP_PILE_FACTOR` is their fitted factor.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any, NamedTuple

import numpy as np

from ..errors import SceneError
from . import points3
from .hfield import Grid, grid

SUMMARY = "a heightfield that the body displaces and that relaxes to the angle of repose"

# The wheel group's factor on the depth of elements in raised sand, fitted to their smooth wheel's forces
# (qishuny/3D-RFT-wheel @cdd8f8f, RFT3D/SandDeformation.m: depthList(pile) = ... * 0.2843).
WHEEL_GROUP_PILE_FACTOR = 0.2843
FRONT_SHARE = 0.5  # of the sand an element sweeps, the share pushed ahead of it; half the rest to each side
RELAX_RATE = 0.25  # of an edge's excess height moved per iteration: the explicit diffusion limit on a square grid
TOLERANCE = 1e-3   # slope (tan) above tan(repose) that relaxation leaves
MAX_ITERATIONS = 100_000
# An element moving horizontally slower than this share of its speed pushes its sand to all four sides.
STRAIGHT_DOWN = 1e-9
# Where an element's swept sand goes: along its horizontal motion, or (a leading element's) along its normal.
BERMS = ("velocity", "facing")
# An element this close above the surface (m) is on it, under the body: an element resting in its own rut would
# otherwise be on or off it by rounding, and sand pushed onto it or not.
TOUCH = 1e-9


def depth(points: Any, gravity: Any, heights: Any, size: Any, centre: Any = (0.0, 0.0, 0.0), frame: Any = None,
          original: Any = None, pile_factor: float | None = None) -> np.ndarray:
    """Each point's depth (m) along gravity below the deformed surface ``heights``; with ``pile_factor`` (and the
    ``original`` heights), the wheel group's pile rule (see the module's docstring)."""
    g = grid(heights, size, gravity, centre, frame)
    local = g.local(points3(points))
    deformed = g.height(local[:, 0], local[:, 1]) - local[:, 2]
    if pile_factor is None:
        return deformed
    if not (np.isfinite(pile_factor) and pile_factor > 0):
        raise SceneError(f"pile_factor {pile_factor!r} must be a positive number (the wheel group's: "
                         f"{WHEEL_GROUP_PILE_FACTOR})")
    if original is None:
        raise SceneError("the pile rule needs the original heights (original=) to tell raised sand")
    below_original = g.height(local[:, 0], local[:, 1], np.asarray(original, dtype=float)) - local[:, 2]
    pile = (deformed > 0) & (below_original <= 0)
    return np.where(pile, pile_factor * deformed, np.minimum(deformed, below_original))


def _local_motion(g: Grid, points: Any, velocities: Any) -> tuple[np.ndarray, np.ndarray]:
    p = g.local(points3(points))
    v = points3(velocities) @ g.frame
    return p, v


def sweep(heights: Any, points: Any, areas: Any, velocities: Any, gravity: Any, size: Any,
          centre: Any = (0.0, 0.0, 0.0), frame: Any = None, front_share: float = FRONT_SHARE,
          compaction: float = 0.0, compacted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The heights after the elements at ``points`` (N, 3, m), of ``areas`` (N, m^2), moving at ``velocities``
    (N, 3, m/s) have pushed the sand they are under into a berm, and the grid points under the body (bool grid).
    With ``compaction`` > 0, that share of the sand each point loses is added to ``compacted`` (the heights' shape,
    written in place) instead of the berm."""
    g = grid(heights, size, gravity, centre, frame)
    if not 0.0 <= front_share <= 1.0:
        raise SceneError(f"front_share {front_share!r} must be between 0 and 1")
    _check_compaction(compaction)
    if compaction > 0 and (compacted is None or compacted.shape != g.heights.shape):
        raise SceneError(f"compaction {compaction} needs an array compacted= of the heights' shape {g.heights.shape}")
    p, v = _local_motion(g, points, velocities)
    a = np.asarray(areas, dtype=float)
    if a.shape != (len(p),) or v.shape != p.shape:
        raise SceneError(f"sweep needs one area and one velocity per point: {len(p)} points, areas of shape "
                         f"{a.shape}, velocities of shape {v.shape}")
    h = g.heights.copy()
    nrow, ncol = h.shape
    dx, dy = g.spacing
    target = np.full(h.shape, np.inf)
    direction = np.zeros(h.shape + (2,))
    for e in range(len(p)):
        radius = np.sqrt(max(a[e], 0.0) / np.pi)
        u, w = (p[e, 0] + g.size[0]) / dx, (p[e, 1] + g.size[1]) / dy
        cn, rn = int(np.clip(np.floor(u + 0.5), 0, ncol - 1)), int(np.clip(np.floor(w + 0.5), 0, nrow - 1))
        c0, c1 = max(int(np.ceil(u - radius / dx)), 0), min(int(np.floor(u + radius / dx)), ncol - 1)
        r0, r1 = max(int(np.ceil(w - radius / dy)), 0), min(int(np.floor(w + radius / dy)), nrow - 1)
        rows, cols = np.meshgrid(np.arange(r0, r1 + 1), np.arange(c0, c1 + 1), indexing="ij")
        inside = ((cols * dx - g.size[0] - p[e, 0]) ** 2 + (rows * dy - g.size[1] - p[e, 1]) ** 2 <= radius ** 2)
        inside |= (rows == rn) & (cols == cn)
        rows, cols = rows[inside], cols[inside]
        if not ((rows == rn) & (cols == cn)).any():
            rows, cols = np.append(rows, rn), np.append(cols, cn)
        speed, horizontal = np.linalg.norm(v[e]), np.hypot(v[e, 0], v[e, 1])
        d = v[e, :2] / horizontal if horizontal > STRAIGHT_DOWN * speed and horizontal > 0 else np.zeros(2)
        lower = p[e, 2] < target[rows, cols]
        target[rows[lower], cols[lower]] = p[e, 2]
        direction[rows[lower], cols[lower]] = d
    occupied = target <= h + TOUCH
    removed = np.where(target < h, h - target, 0.0)
    h = np.where(target < h, target, h)
    if compaction > 0:
        compacted += compaction * removed
        removed = (1.0 - compaction) * removed
    for r, c in zip(*np.nonzero(removed)):
        for share, (sx, sy) in _berm(direction[r, c], front_share):
            rr, cc = _march(occupied, r, c, sx, sy, dx, dy)
            h[rr, cc] += share * removed[r, c]
    return h, occupied


def _check_compaction(compaction: float) -> None:
    if not (np.isfinite(compaction) and 0.0 <= compaction <= 1.0):
        raise SceneError(f"compaction {compaction!r} must be a share between 0 and 1 (0: all the swept sand to the "
                         f"berm)")


def _berm(d: np.ndarray, front_share: float) -> list[tuple[float, tuple[float, float]]]:
    """Where an element moving horizontally along ``d`` (unit, or 0 for straight down) puts its sand: shares and
    directions."""
    if not d.any():
        return [(0.25, (1.0, 0.0)), (0.25, (-1.0, 0.0)), (0.25, (0.0, 1.0)), (0.25, (0.0, -1.0))]
    side = 0.5 * (1.0 - front_share)
    return [(front_share, (d[0], d[1])), (side, (-d[1], d[0])), (side, (d[1], -d[0]))]


def _march(occupied: np.ndarray, r: int, c: int, sx: float, sy: float, dx: float, dy: float) -> tuple[int, int]:
    """The first grid point not under the body from (r, c) along (sx, sy), in steps of the finer spacing; the last
    one on the grid should the march leave it first."""
    nrow, ncol = occupied.shape
    step = min(dx, dy)
    last = (r, c)
    for s in range(1, nrow + ncol + 1):
        cf, rf = c + s * step * sx / dx, r + s * step * sy / dy
        cc, rr = int(np.floor(cf + 0.5)), int(np.floor(rf + 0.5))
        if not (0 <= cc < ncol and 0 <= rr < nrow):
            return last
        if (rr, cc) != (r, c):
            last = (rr, cc)
            if not occupied[rr, cc]:
                return last
    return last


class Relaxed(NamedTuple):
    """Heights after relaxation, the iterations it took and whether it got within its tolerance."""

    heights: np.ndarray
    iterations: int
    converged: bool


def relax(heights: Any, size: Any, repose: float, blocked: Any = None, tolerance: float = TOLERANCE,
          max_iterations: int = MAX_ITERATIONS) -> Relaxed:
    """The heights (nrow, ncol) on a grid of half-extents ``size`` relaxed until no slope between neighbours (of
    points not ``blocked``) exceeds tan(``repose``, rad) + ``tolerance``."""
    h = np.array(heights, dtype=float)
    if h.ndim != 2 or min(h.shape) < 2:
        raise SceneError(f"heights must be a grid of at least 2 x 2, got shape {h.shape}")
    if not 0.0 < repose < np.pi / 2:
        raise SceneError(f"angle of repose {repose!r} rad must be between 0 and pi/2")
    if not tolerance > 0:
        raise SceneError(f"relaxation tolerance {tolerance!r} must be a positive slope")
    if not (np.isfinite(size).all() and (np.asarray(size, dtype=float) > 0).all()):
        raise SceneError(f"grid size {list(size)} must be two positive half-extents, m")
    nrow, ncol = h.shape
    dx, dy = 2 * float(size[0]) / (ncol - 1), 2 * float(size[1]) / (nrow - 1)
    free = np.ones(h.shape, bool) if blocked is None else ~np.asarray(blocked, dtype=bool)
    free_x, free_y = free[:, 1:] & free[:, :-1], free[1:, :] & free[:-1, :]
    slope = np.tan(repose)
    for iteration in range(max_iterations + 1):
        step_x, step_y = h[:, 1:] - h[:, :-1], h[1:, :] - h[:-1, :]
        excess_x = np.where(free_x, np.abs(step_x) - slope * dx, 0.0)
        excess_y = np.where(free_y, np.abs(step_y) - slope * dy, 0.0)
        # only an edge steeper than the tolerance flows: a relaxed region stays still while another flows
        flowing_x, flowing_y = excess_x > tolerance * dx, excess_y > tolerance * dy
        if not (flowing_x.any() or flowing_y.any()):
            return Relaxed(h, iteration, True)
        if iteration == max_iterations:
            break
        # moved from the higher point to the lower, along + (up the index) where the step is negative
        flow_x = -np.sign(step_x) * RELAX_RATE * np.where(flowing_x, excess_x, 0.0)
        flow_y = -np.sign(step_y) * RELAX_RATE * np.where(flowing_y, excess_y, 0.0)
        h[:, :-1] -= flow_x
        h[:, 1:] += flow_x
        h[:-1, :] -= flow_y
        h[1:, :] += flow_y
    return Relaxed(h, max_iterations, False)


def update(heights: Any, points: Any, areas: Any, velocities: Any, gravity: Any, size: Any, repose: float,
           centre: Any = (0.0, 0.0, 0.0), frame: Any = None, front_share: float = FRONT_SHARE,
           tolerance: float = TOLERANCE, max_iterations: int = MAX_ITERATIONS) -> Relaxed:
    """One step of the deforming surface: `sweep`, then `relax` with the points under the body blocked."""
    swept, occupied = sweep(heights, points, areas, velocities, gravity, size, centre, frame, front_share)
    return relax(swept, size, repose, occupied, tolerance, max_iterations)


# In a run, relaxation takes at most this many iterations a step and leaves the rest of the excess to the next steps:
# the body moves a small part of a grid spacing a step, so the surface relaxes as it goes, at a bounded cost (run to
# convergence after every step, a rolling wheel's surface took a median of 334 iterations a step).
STEP_ITERATIONS = 16
# In a run, the surface is stepped once an element may have moved this share of the finer grid spacing
# (medium.surface_update): the sweep lowers the grid to the elements, which a move of less than a spacing changes
# little. Both this and the next were made coarser to bring the surface's cost within half a flat run's; what that
# moved is on docs/results/wheel.md, "Cost".
MOVE = 1.0
# In a run, relaxation leaves slopes this much (tan) above tan(repose) (medium.relax_tolerance): 1.3 degrees above the
# wheel sand's 29, within what a catalogued angle of repose is known to.
STEP_TOLERANCE = 0.03


class DeformingSurface:
    """A deforming surface as a run's state: its heights (nrow, ncol, m) on a grid of half-extents ``size`` (m) at
    ``centre`` with ``frame`` (`finrft.surfaces.hfield`'s layout), displaced by the body's elements at every step
    (`step`) and relaxed towards the angle of ``repose`` (rad), to within ``tolerance`` (tan), by at most
    ``step_iterations`` iterations a step; in a run (`step_model`) it steps once an element may have moved ``move``
    of the finer grid spacing.
    ``native`` steps it with the C twins (plugins/surfaces/deforming.c), else with this module's numpy functions:
    the same heights to rounding. ``compaction``: the share of the swept sand compacted under the body (`sweep`),
    accumulated in ``compacted``; ``berm``: where the rest goes (`BERMS`). ``displaced`` is the volume (m^3) the
    sweeps have removed so far; ``level`` (an array of the heights' shape, written in place: a `field`'s heights)
    the surface the elements' depths are measured from. ``instances``: the native plugin's finrft.surface
    instances that measure from it (`installed`)."""

    def __init__(self, heights: Any, size: Any, repose: float, centre: Any = (0.0, 0.0, 0.0), frame: Any = None,
                 pile_factor: float | None = None, front_share: float = FRONT_SHARE,
                 tolerance: float = STEP_TOLERANCE, step_iterations: int = STEP_ITERATIONS, native: bool = True,
                 level: Any = None, instances: tuple[int, ...] | list[int] = (), compaction: float = 0.0,
                 berm: str = "velocity", move: float = MOVE) -> None:
        g = grid(heights, size, (0.0, 0.0, -1.0) if frame is None else -np.asarray(frame, float)[:, 2], centre, frame)
        if not 0.0 < repose < np.pi / 2:
            raise SceneError(f"angle of repose {repose!r} rad must be between 0 and pi/2")
        if not (isinstance(step_iterations, (int, np.integer)) and step_iterations >= 1):
            raise SceneError(f"step_iterations {step_iterations!r} must be a whole number of at least 1")
        if pile_factor is not None and not (np.isfinite(pile_factor) and pile_factor > 0):
            raise SceneError(f"pile_factor {pile_factor!r} must be a positive number (the wheel group's: "
                             f"{WHEEL_GROUP_PILE_FACTOR})")
        if not (np.isfinite(move) and move > 0):
            raise SceneError(f"surface update {move!r} must be a positive share of the grid spacing")
        if not (np.isfinite(tolerance) and tolerance > 0):
            raise SceneError(f"relaxation tolerance {tolerance!r} must be a positive slope")
        _check_compaction(compaction)
        if berm not in BERMS:
            raise SceneError(f"berm {berm!r} is not a berm rule: one of {', '.join(BERMS)}")
        self.heights = np.ascontiguousarray(g.heights, dtype=float).copy()
        self.original = self.heights.copy()
        self.compaction, self.compacted = float(compaction), np.zeros(self.heights.shape)
        self.berm = berm
        self.size, self.centre, self.frame = g.size.copy(), g.centre.copy(), np.ascontiguousarray(g.frame)
        self._spacing = g.spacing
        self.repose, self.pile_factor, self.front_share = float(repose), pile_factor, float(front_share)
        self.tolerance, self.step_iterations, self.native = float(tolerance), int(step_iterations), bool(native)
        self.move = float(move)
        self.displaced = 0.0
        # how many times the level was set in the native instances' state: a copy of that state is current while
        # this has not changed (`finrft.experiments.attached_model.applied_state`)
        self.level_sets = 0
        self.updates = 0  # how many times the surface has stepped (`step`, `step_model`)
        self.instances = tuple(instances)
        self._model: Any = None
        self._pose: np.ndarray | None = None  # the bodies' positions and orientations at the last step_model
        self._bodies: list[int] = []
        self._reach: np.ndarray | None = None  # each body's elements' largest distance from its origin
        self._data: Any = None
        self._occupied = np.zeros(self.heights.shape, np.ubyte)
        # the grid points under the body at the last step (bytes 0 or 1: the C step's, which uses the other bits)
        self._under = np.zeros(self.heights.shape, np.ubyte)
        # The surface the elements measure their depth from: the sand's own (heights) where no body is, and under a
        # body (`_covered`) the height the sand had as the body entered that point (the level of the sand around the
        # hole it digs, not the hole's floor); a point the body has left is its floor again, a rut.
        self.level = self.heights.copy() if level is None else level
        if self.level.shape != self.heights.shape or self.level.dtype != float:
            raise SceneError(f"level must be an array of floats of the heights' shape {self.heights.shape}")
        self.level[...] = self.heights
        self._state = _state(self) if self.native else None

    def installed(self, m: Any, d: Any) -> "DeformingSurface":
        """Set the level in the native plugin's ``instances`` of the MjData ``d`` of model ``m``, now and after
        every `step_model`; the surface itself."""
        self._model, self._data = m, d
        self._set_level()
        return self

    def _set_level(self) -> None:
        if not self.instances:
            return
        set_level = _native_functions()[1]
        nrow, ncol = self.level.shape
        self.level_sets += 1
        for instance in self.instances:
            if set_level(self._model._address, self._data._address, instance, nrow, ncol, self.level.ctypes.data):
                raise SceneError("the model's finrft.surface instances do not measure from this deforming surface "
                                 "(attach it with its field: finrft.surfaces.deforming.field)")

    def step_model(self, attached: Any, m: Any, d: Any) -> float:
        """`step` with every element of an `finrft.attach.Attached` at the state of ``d`` (`body_elements`), then
        the level set in the native instances (`installed`), once an element may have moved ``move`` of the finer
        grid spacing since the last (a bound from the bodies' motion: their origins' travel and their turn times
        their elements' reach); the volume (m^3) displaced."""
        if self.native and self.instances:
            return self._native_step_model(m, d)
        if self._reach is None:
            self._bodies = [m.body(s.body).id for s in attached.surfaces]
            self._reach = np.array([np.sqrt((s.centre ** 2).sum(axis=1)).max() for s in attached.surfaces])
        pose = np.concatenate([d.xpos[self._bodies], d.xquat[self._bodies]], axis=1)
        if self._pose is not None:
            turn = 2 * np.arccos(np.clip(np.abs((pose[:, 3:] * self._pose[:, 3:]).sum(axis=1)), 0.0, 1.0))
            moved = np.linalg.norm(pose[:, :3] - self._pose[:, :3], axis=1) + turn * self._reach
            if moved.max() < self.move * min(self._spacing):
                return 0.0
        first = self._pose is None
        self._pose = pose
        points, velocities, areas, normals = body_elements(attached, m, d)
        removed = self.step(points, areas, velocities, m.opt.gravity, imprint=first, normals=normals)
        self._set_level()
        return removed

    def _native_step_model(self, m: Any, d: Any) -> float:
        if self._pose is None:
            self._pose = np.full(7 * len(self.instances), np.nan)
            self._instance_array = np.array(self.instances, dtype=np.intc)
            self._removed = ctypes.c_double(0.0)
            # the call's arguments but the model and data, made once: it is made at every step of a run
            self._native_arguments = (ctypes.byref(self._state), len(self.instances),
                                      self._instance_array.ctypes.data, self._pose.ctypes.data,
                                      self.move * min(self._spacing), ctypes.byref(self._removed))
        stepped = _native_functions()[2](m._address, d._address, *self._native_arguments)  # (sets the volume)
        removed = self._removed.value
        if stepped < 0:
            raise SceneError("the model's finrft.surface instances do not measure from this deforming surface "
                             "(attach it with its field: finrft.surfaces.deforming.field)")
        self.level_sets += stepped
        self.updates += stepped
        self.displaced += removed
        return removed

    @property
    def cell(self) -> float:
        """The area (m^2) each grid point stands for."""
        return self._spacing[0] * self._spacing[1]

    def volume(self) -> float:
        """The sand's volume above the grid's z = 0 (m^3): what every step conserves without compaction."""
        return self.cell * float(self.heights.sum())

    def sand(self) -> float:
        """The sand's volume at its bulk density (m^3), the heights' and the compacted (`volume` plus the
        ``compacted`` heights'): its mass over its bulk density, what every step conserves."""
        return self.cell * float(self.heights.sum() + self.compacted.sum())

    def _covered(self, points: np.ndarray) -> np.ndarray:
        """The grid points under the body: those with an element below the sand's level at the point nearest to it
        or at a neighbour (elements coarser than the grid leave no gaps). A body above its own hole keeps that hole
        at the level of the sand around it (a wheel's rear over the floor it has just cut); one that has left it
        leaves a rut."""
        local = (points - self.centre) @ self.frame
        nrow, ncol = self.heights.shape
        c = np.floor((local[:, 0] + self.size[0]) / self._spacing[0] + 0.5).astype(int)
        r = np.floor((local[:, 1] + self.size[1]) / self._spacing[1] + 0.5).astype(int)
        on = np.flatnonzero((c >= 0) & (c < ncol) & (r >= 0) & (r < nrow))
        on = on[local[on, 2] < self.level[r[on], c[on]] + TOUCH]
        near = np.zeros(self.heights.shape, bool)
        near[r[on], c[on]] = True
        covered = near.copy()
        covered[1:] |= near[:-1]
        covered[:-1] |= near[1:]
        covered[:, 1:] |= near[:, :-1]
        covered[:, :-1] |= near[:, 1:]
        return covered

    def depth(self, points: Any, gravity: Any) -> np.ndarray:
        """Each point's depth (m) below the sand's level (`level`; `depth`, with the pile rule when set)."""
        return depth(points, gravity, self.level, self.size, self.centre, self.frame,
                     self.original if self.pile_factor else None, self.pile_factor)

    def step(self, points: Any, areas: Any, velocities: Any, gravity: Any, imprint: bool = False,
             normals: Any = None) -> float:
        """Sweep the sand under the elements at ``points`` (N, 3, m) of ``areas`` (N, m^2) moving at ``velocities``
        (N, 3, m/s), of outward unit ``normals`` (N, 3; needed by the berm rule "facing"), then relax at most
        ``step_iterations`` times; the volume (m^3) this step displaced. With
        ``imprint`` (a run's first step), the body's imprint instead: the sand under it lowered to it and no berm,
        a body that starts in the sand sitting in its own hole (its volume is not conserved: 0 displaced)."""
        if self.berm == "facing" and normals is None:
            raise SceneError("the berm rule 'facing' needs the elements' normals (normals=)")
        if self.native:
            removed = _native_step(self, points3(points), np.asarray(areas, float), points3(velocities),
                                   np.asarray(gravity, float), imprint, None if normals is None else points3(normals))
            self.displaced += removed
            self.updates += 1
            return removed
        before, entered = self.heights.copy(), self._under == 0
        under = self._covered(points3(points))
        if self.berm == "facing":  # a leading element pushes its sand along its normal (its sweep's direction)
            n, v = points3(normals), points3(velocities)
            velocities = np.where(((n * v).sum(axis=1) > 0)[:, None], n, v)
        # the imprint is no flow of sand: nothing of it is compacted
        swept, occupied = sweep(self.heights, points, areas, velocities, gravity, self.size, self.centre,
                                self.frame, self.front_share, 0.0 if imprint else self.compaction, self.compacted)
        self._occupied[...] = occupied
        self.heights[...] = relax(swept, self.size, self.repose, occupied, self.tolerance,
                                  self.step_iterations).heights
        if imprint:
            np.minimum(before, self.heights, out=self.heights)
            self.original[...] = np.minimum(self.original, self.heights)
        under |= self._occupied != 0
        entered &= under
        self._under[...] = under
        self.level[...] = np.where(entered, before, np.where(under, self.level, self.heights))
        removed = 0.0 if imprint else self.cell * float(np.clip(before - self.heights, 0.0, None).sum())
        self.displaced += removed
        self.updates += 1
        return removed


class _Deforming(ctypes.Structure):
    """FinrftDeforming (plugins/surfaces/surfaces.h): a DeformingSurface's grid, parameters and arrays for the C
    step."""

    _fields_ = [("nrow", ctypes.c_int), ("ncol", ctypes.c_int), ("size", ctypes.c_double * 2),
                ("centre", ctypes.c_double * 3), ("frame", ctypes.c_double * 9), ("repose", ctypes.c_double),
                ("front_share", ctypes.c_double), ("tolerance", ctypes.c_double), ("step_iterations", ctypes.c_int),
                ("heights", ctypes.c_void_p), ("level", ctypes.c_void_p), ("original", ctypes.c_void_p),
                ("under", ctypes.c_void_p), ("occupied", ctypes.c_void_p), ("dirty", ctypes.c_int * 4),
                ("compaction", ctypes.c_double), ("compacted", ctypes.c_void_p), ("facing", ctypes.c_int),
                ("held", ctypes.c_int * 4)]


def _state(s: DeformingSurface) -> _Deforming:
    """The C step's view of ``s``: its arrays, written in place (they must stay the same arrays)."""
    nrow, ncol = s.heights.shape
    for a in (s.heights, s.level, s.original, s._under, s._occupied, s.compacted):
        if not a.flags.c_contiguous:
            raise SceneError("the deforming surface's arrays must be contiguous")
    return _Deforming(nrow, ncol, (ctypes.c_double * 2)(*s.size), (ctypes.c_double * 3)(*s.centre),
                      (ctypes.c_double * 9)(*np.ravel(s.frame)), s.repose, s.front_share, s.tolerance,
                      s.step_iterations, s.heights.ctypes.data, s.level.ctypes.data, s.original.ctypes.data,
                      s._under.ctypes.data, s._occupied.ctypes.data, (ctypes.c_int * 4)(0, nrow - 1, 0, ncol - 1),
                      s.compaction, s.compacted.ctypes.data, int(s.berm == "facing"),
                      (ctypes.c_int * 4)(0, nrow - 1, 0, ncol - 1))


@functools.cache
def _native_functions() -> tuple[Any, Any, Any]:
    from .. import native

    if not native.available():
        raise SceneError("the native library is not available (reinstall finrft: pip install -e .), so the deforming "
                         "surface cannot step natively: use native=False")
    p, i, f = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
    return (native.function("finrft_deforming_step", i, p, p, i, p, p, p, p, i, p),
            native.function("finrft_surface_set_level", i, p, p, i, i, i, p),
            native.function("finrft_surface_deforming_step", i, p, p, p, i, p, p, f, p))


def _native_step(s: DeformingSurface, points: np.ndarray, areas: np.ndarray, velocities: np.ndarray,
                 gravity: np.ndarray, imprint: bool, normals: np.ndarray | None = None) -> float:
    if areas.shape != (len(points),) or velocities.shape != points.shape or (
            normals is not None and normals.shape != points.shape):
        raise SceneError(f"sweep needs one area and one velocity per point: {len(points)} points, areas of shape "
                         f"{areas.shape}, velocities of shape {velocities.shape}")
    arrays = [np.ascontiguousarray(a, float) for a in (gravity, points, areas, velocities)]
    normals = None if normals is None else np.ascontiguousarray(normals, float)
    removed = ctypes.c_double(0.0)
    if _native_functions()[0](ctypes.byref(s._state), arrays[0].ctypes.data, len(points),
                              *(a.ctypes.data for a in arrays[1:]), None if normals is None else normals.ctypes.data,
                              int(imprint), ctypes.byref(removed)):
        raise SceneError("the deforming surface's sweep refused its input (a grid whose z axis is not against "
                         "gravity, or front_share or compaction outside 0..1)")
    return removed.value


def field(grid: Any, pile_factor: float | None = None) -> Any:
    """The `finrft.surfaces.Field` of a deforming surface that starts as the heightfield ``grid`` (a Field of kind
    hfield, as `finrft.surfaces.hfield.generated` makes): its ``heights`` are the level a run's `DeformingSurface`
    steps in place, ``original`` the heights it started from."""
    from . import Field

    p = grid.parameters
    heights = np.array(p["heights"], dtype=float)
    return Field("deforming", {"heights": heights, "size": tuple(p["size"]), "centre": tuple(p["centre"]),
                               "frame": np.asarray(p["frame"], float), "original": heights.copy(),
                               "pile_factor": pile_factor})


def body_elements(attached: Any, m: Any, d: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The world centres (N, 3, m), velocities (N, 3, m/s), areas (N, m^2) and outward unit normals (N, 3) of every
    element of an `finrft.attach.Attached` at the positions and velocities of ``d`` (its kinematics and velocities
    made here: after a step MuJoCo's data holds the previous state's)."""
    import mujoco

    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_comVel(m, d)
    points, velocities, areas, facing = [], [], [], []
    twist = np.zeros(6)
    for s in attached.surfaces:
        body = m.body(s.body).id
        arm = s.centre @ d.xmat[body].reshape(3, 3).T
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, body, twist, 0)
        points.append(arm + d.xpos[body])
        w = twist[:3]  # w x arm, written out: np.cross costs more than the rest of the update's Python
        velocities.append(twist[3:] + np.c_[w[1] * arm[:, 2] - w[2] * arm[:, 1], w[2] * arm[:, 0] - w[0] * arm[:, 2],
                                            w[0] * arm[:, 1] - w[1] * arm[:, 0]])
        areas.append(s.area)
        facing.append(s.normal @ d.xmat[body].reshape(3, 3).T)
    return np.concatenate(points), np.concatenate(velocities), np.concatenate(areas), np.concatenate(facing)
