"""Law ``table``: the magnitudes looked up per angle of attack theta (the acute angle between the segment and its
motion, 0..90 degrees), interpolated linearly::

    F = -tanh(|v| / v_reg) * ( F_perp(theta) sgn(v^.y^) y^ + F_par(theta) sgn(v^.x^) x^ )

which is how RFT is identified from rigid-plate drags; the paper law is the table F_perp = f_perp sin(theta),
F_par = f_par cos(theta). The table is a CSV with columns attack_deg, f_perp_N_m3, f_par_N_m3: the forces on a
segment of unit scale, i.e. per unit area and depth (N/m^3, as the other laws' coefficients); a table of forces per
segment (columns f_perp_N, f_par_N) is refused, not read as N/m^3. A segment's forces are the table times its
face's area and mean depth (`finrft.laws.segment_scale`). The CSV is read once per file version (its path, size and
modification time). The C twin is plugins/laws/table.c.
"""

from __future__ import annotations

import csv
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError
from ..files import read_text
from ..schema import field
from . import components

KIND = "segment"
SUMMARY = "F_perp(theta), F_par(theta) from a CSV"  # what the scene's rft.law documents
# The law's keys of [rft], with their units (`finrft.scene.RFT` is built from every law's).
KEYS = (("table", str, field("", "", "table law: CSV with columns attack_deg, f_perp_N_m3, f_par_N_m3, the "
                             "forces per unit area and depth (N/m^3) (relative to the scene file)")),)
INTENSIVE = ("table",)
TABLE_COLUMNS = ("attack_deg", "f_perp_N_m3", "f_par_N_m3")
# The columns of a table of forces per segment, before the coefficients were per unit area and depth.
PER_SEGMENT_COLUMNS = ("f_perp_N", "f_par_N")


@dataclass(frozen=True)
class ForceTable:
    """F_perp(theta) and F_par(theta) per segment, sampled at increasing angles of attack (degrees, 0 to 90)."""

    attack_deg: np.ndarray
    f_perp: np.ndarray
    f_par: np.ndarray

    def __mul__(self, scale: float) -> ForceTable:
        """The table's forces times ``scale``: a segment's, from the table per unit area and depth."""
        return ForceTable(self.attack_deg, self.f_perp * scale, self.f_par * scale)


def check(rft: Any, medium: Any) -> None:
    """SceneError unless the section names its CSV (the medium gives the table nothing)."""
    if not rft.table:
        raise SceneError("rft.law = 'table' needs rft.table, the path of a CSV with attack_deg, f_perp_N_m3, "
                         "f_par_N_m3")


def parameters(rft: Any) -> dict[str, ForceTable]:
    path = Path(rft.table)
    try:
        stat = path.stat()
    except OSError:
        return {"table": read_table(path)}  # which names the problem
    return {"table": _read_cached(str(path.resolve()), stat.st_size, stat.st_mtime_ns)}


@functools.lru_cache(maxsize=32)
def _read_cached(path: str, size: int, mtime_ns: int) -> ForceTable:
    """`read_table`, once per version of a file: every model build and companion run asks for it."""
    return read_table(path)


def config(params: dict[str, ForceTable]) -> dict[str, str]:
    """The plugin's ``table``: attack_deg f_perp f_par triples (N/m^3)."""
    table = params["table"]
    return {"table": " ".join(repr(float(x)) for row in zip(table.attack_deg, table.f_perp, table.f_par)
                              for x in row)}


def force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, v_reg: float, table: ForceTable) -> np.ndarray:
    """(N, 3) newtons."""
    ramp, vx, vy = components(v, x_axis, y_axis, v_reg)
    attack = np.arctan2(np.abs(vy), np.abs(vx))
    samples = np.radians(table.attack_deg)
    perp = np.interp(attack, samples, table.f_perp)
    par = np.interp(attack, samples, table.f_par)
    return -ramp[..., None] * ((perp * np.sign(vy))[..., None] * y_axis + (par * np.sign(vx))[..., None] * x_axis)


def feeds_energy(params: dict[str, ForceTable]) -> str:
    """Why the law can push a segment along its own motion (F.v > 0), or "" when it dissipates at every velocity.

    Per unit speed its power is -(F_perp(theta) sin theta + F_par(theta) cos theta), times the share of the velocity
    in the segment's plane; a negative magnitude may be outweighed by the other, so the sum is checked at every
    sample and on a 0.01 deg grid."""
    table = params["table"]
    attack_deg = np.union1d(np.linspace(0.0, 90.0, 9001), np.clip(table.attack_deg, 0.0, 90.0))
    samples = np.radians(table.attack_deg)
    attack = np.radians(attack_deg)
    resist = (np.interp(attack, samples, table.f_perp) * np.sin(attack)
              + np.interp(attack, samples, table.f_par) * np.sin(np.radians(90.0 - attack_deg)))  # cos, 0 at 90
    worst = int(np.argmin(resist))
    if resist[worst] < 0:
        return (f"the table pushes a segment along its motion at attack {attack_deg[worst]:g} deg "
                f"({-resist[worst]:.3g} N)")
    return ""


def read_table(path: str | Path) -> ForceTable:
    """Read a force table CSV (columns attack_deg, f_perp_N_m3, f_par_N_m3; angles increasing over 0..90 degrees)."""
    path = Path(path)
    lines = read_text(path, "RFT table").splitlines()
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    if rows and all(c in rows[0] for c in PER_SEGMENT_COLUMNS):
        raise SceneError(f"RFT table {path} holds forces per segment (columns f_perp_N, f_par_N): give them per unit "
                         f"area and depth, divided by the segment's length x medium.height x (medium.depth + "
                         f"medium.height / 2), in columns f_perp_N_m3, f_par_N_m3")
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
