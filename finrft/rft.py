"""Granular resistive force theory (RFT): the force the medium exerts on one rigid segment.

These pure functions are the single source of truth for the force laws; the MuJoCo couplings (the Python passive
callback and the native plugin) evaluate exactly these formulas.

Conventions, for N segments at once: ``v`` (N, 3) is the velocity of each segment's midpoint, ``x_axis`` (N, 3)
the unit vector along the segment and ``y_axis`` (N, 3) its in-plane normal, all in the world frame. The angle of
attack theta is the acute angle between the segment and its direction of motion, in [0, 90] degrees.

Law ``paper``::

    F = -tanh(|v| / v_reg) * ( f_perp (v^.y^) y^ + f_par (v^.x^) x^ ),   v^ = v / |v|

Law ``table``: the same with the magnitudes looked up per angle of attack,
``F = -tanh(|v|/v_reg) * ( F_perp(theta) sgn(v^.y^) y^ + F_par(theta) sgn(v^.x^) x^ )``; the paper law is the
table F_perp = f_perp sin(theta), F_par = f_par cos(theta).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .scene import RFT, SceneError

TABLE_COLUMNS = ("attack_deg", "f_perp_N", "f_par_N")


@dataclass(frozen=True)
class ForceTable:
    """F_perp(theta) and F_par(theta) per segment, sampled at increasing angles of attack (degrees, 0 to 90)."""

    attack_deg: np.ndarray
    f_perp: np.ndarray
    f_par: np.ndarray


def _components(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, v_reg: float):
    speed = np.linalg.norm(v, axis=-1)
    safe = np.where(speed > 0.0, speed, 1.0)
    ramp = np.tanh(speed / v_reg)
    vx = np.einsum("...i,...i->...", v, x_axis) / safe
    vy = np.einsum("...i,...i->...", v, y_axis) / safe
    return ramp, vx, vy


def paper_force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray,
                f_perp: float, f_par: float, v_reg: float) -> np.ndarray:
    """The direction-cosine law of the paper's model, regularised by tanh(|v|/v_reg); (N, 3) newtons."""
    ramp, vx, vy = _components(v, x_axis, y_axis, v_reg)
    return -ramp[..., None] * (f_perp * vy[..., None] * y_axis + f_par * vx[..., None] * x_axis)


def table_force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, table: ForceTable,
                v_reg: float) -> np.ndarray:
    """The tabulated law: magnitudes interpolated linearly in the angle of attack; (N, 3) newtons."""
    ramp, vx, vy = _components(v, x_axis, y_axis, v_reg)
    attack = np.arctan2(np.abs(vy), np.abs(vx))
    samples = np.radians(table.attack_deg)
    perp = np.interp(attack, samples, table.f_perp)
    par = np.interp(attack, samples, table.f_par)
    return -ramp[..., None] * ((perp * np.sign(vy))[..., None] * y_axis + (par * np.sign(vx))[..., None] * x_axis)


def read_table(path: str | Path) -> ForceTable:
    """Read a force table CSV (columns attack_deg, f_perp_N, f_par_N; angles increasing over 0..90 degrees)."""
    path = Path(path)
    try:
        with path.open(newline="") as handle:
            rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    except OSError as exc:
        raise SceneError(f"cannot read RFT table {path}: {exc.strerror}") from None
    if not rows or any(c not in rows[0] for c in TABLE_COLUMNS):
        raise SceneError(f"RFT table {path} needs the columns {', '.join(TABLE_COLUMNS)}")
    try:
        data = np.array([[float(row[c]) for c in TABLE_COLUMNS] for row in rows])
    except (TypeError, ValueError):
        raise SceneError(f"RFT table {path}: every value must be a number") from None
    attack = data[:, 0]
    if not np.all(np.isfinite(data)) or np.any(np.diff(attack) <= 0) or attack[0] > 0 or attack[-1] < 90:
        raise SceneError(f"RFT table {path}: attack_deg must increase and cover 0 to 90 degrees, values finite")
    return ForceTable(attack.copy(), data[:, 1].copy(), data[:, 2].copy())


def write_table(path: str | Path, table: ForceTable) -> None:
    """Write a force table CSV that `read_table` reads back."""
    with Path(path).open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(TABLE_COLUMNS)
        for row in zip(table.attack_deg, table.f_perp, table.f_par):
            writer.writerow([repr(float(x)) for x in row])


def paper_table(f_perp: float, f_par: float, samples: int = 91) -> ForceTable:
    """The paper law written as a table (F_perp = f_perp sin theta, F_par = f_par cos theta)."""
    attack_deg = np.linspace(0.0, 90.0, samples)
    attack = np.radians(attack_deg)
    return ForceTable(attack_deg, f_perp * np.sin(attack), f_par * np.cos(attack))


def force_law(params: RFT):
    """The law a scene selects, as ``f(v, x_axis, y_axis) -> (N, 3)``; a table is read once, here."""
    if params.law == "table":
        table = read_table(params.table)
        return lambda v, x, y: table_force(v, x, y, table, params.v_reg)
    return lambda v, x, y: paper_force(v, x, y, params.f_perp, params.f_par, params.v_reg)
