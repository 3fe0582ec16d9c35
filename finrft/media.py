"""The catalogue of named granular media (finrft/media.toml): each medium's values with their units and sources.

`media()` gives every medium, `medium(name)` one (a `SceneError` names the known media for an unknown name). The
values are what the literature gives, nothing estimated: a value not found is absent (`Material.missing`), and a
law that needs it says so (`finrft.laws.li2013.medium_parameters`).

`sandswim_coefficients` derives the sand-swimming law of a segment from 3D-RFT and the medium's bulk density,
internal and surface friction; `immersion_properties` reads those from a chain scene's ``[medium]``.
"""

from __future__ import annotations

import functools
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import numpy as np

from .laws import rft3d, sandswim
from .errors import SceneError

UNVERIFIED = "unverified"  # the one status: from a secondary source, not checked against the primary one
# How the command line shows SI units (it speaks mm and degrees).
DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", 180 / math.pi)}


@dataclass(frozen=True)
class Value:
    """One catalogued value: a number or a list of numbers, in ``unit``, from ``source``."""

    value: float | tuple[float, ...]
    unit: str
    source: str
    status: str = ""

    def shown(self) -> tuple[float | tuple[float, ...], str]:
        """The value in the command line's units (mm, degrees) and that unit."""
        unit, scale = DISPLAY.get(self.unit, (self.unit, 1.0))
        if isinstance(self.value, tuple):
            return tuple(scale * v for v in self.value), unit
        return scale * self.value, unit


@dataclass(frozen=True)
class Material:
    """A named medium: its catalogued values by quantity, the quantities not found, and a note."""

    name: str
    description: str
    values: dict[str, Value] = field(hash=False)
    missing: tuple[str, ...] = ()
    note: str = ""

    def get(self, quantity: str) -> Value | None:
        return self.values.get(quantity)

    def to_dict(self) -> dict[str, Any]:
        """The medium as JSON-ready data, in the command line's units."""
        values = {}
        for key, v in self.values.items():
            number, unit = v.shown()
            values[key] = {"value": list(number) if isinstance(number, tuple) else number, "unit": unit,
                           "source": v.source, "status": v.status}
        return {"name": self.name, "description": self.description, "values": values,
                "missing": list(self.missing), "note": self.note}


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _value(raw: Any, unit: str, where: str) -> Value:
    if not isinstance(raw, dict) or set(raw) - {"value", "source", "status"} or "value" not in raw:
        raise SceneError(f"{where}: expected {{ value = ..., source = \"...\" }} (status optional)")
    source, status = raw.get("source"), raw.get("status", "")
    if not isinstance(source, str) or not source.strip():
        raise SceneError(f"{where}: every value names its source")
    if status not in ("", UNVERIFIED):
        raise SceneError(f"{where}: status must be {UNVERIFIED!r}, got {status!r}")
    value = raw["value"]
    number = (tuple(_number(v, where) for v in value) if isinstance(value, list) else _number(value, where))
    return Value(number, unit, source, status)


def parse(data: dict[str, Any]) -> dict[str, Material]:
    """Check a catalogue (as read from TOML) and give its media by name."""
    units = data.get("units")
    if not isinstance(units, dict) or not all(isinstance(u, str) for u in units.values()):
        raise SceneError("media catalogue: [units] must give each quantity's unit")
    table = data.get("media")
    if not isinstance(table, dict) or not table:
        raise SceneError("media catalogue: no [media.NAME] sections")
    catalogue = {}
    for name, entry in table.items():
        where = f"media catalogue: [media.{name}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("description"), str):
            raise SceneError(f"{where} needs a description")
        missing = entry.get("missing", [])
        note = entry.get("note", "")
        if not isinstance(missing, list) or not all(isinstance(m, str) for m in missing):
            raise SceneError(f"{where}: missing must be a list of quantity names")
        quantities = {k: v for k, v in entry.items() if k not in ("description", "missing", "note")}
        for key in [*quantities, *missing]:
            if key not in units:
                raise SceneError(f"{where}: unknown quantity {key!r}: [units] has {', '.join(units)}")
        if set(missing) & set(quantities):
            raise SceneError(f"{where}: {', '.join(sorted(set(missing) & set(quantities)))} both given and missing")
        if not isinstance(note, str):
            raise SceneError(f"{where}: note must be text")
        values = {k: _value(v, units[k], f"{where} {k}") for k, v in quantities.items()}
        catalogue[name] = Material(name, entry["description"], values, tuple(missing), note)
    return catalogue


@functools.cache
def _catalogue() -> dict[str, Material]:
    text = (resources.files("finrft") / "media.toml").read_text(encoding="utf-8")
    return parse(tomllib.loads(text))


def media() -> tuple[Material, ...]:
    """Every catalogued medium, in the catalogue's order."""
    return tuple(_catalogue().values())


def names() -> tuple[str, ...]:
    return tuple(_catalogue())


def medium(name: str) -> Material:
    """A catalogued medium by name; SceneError naming the known media otherwise."""
    try:
        return _catalogue()[name]
    except KeyError:
        raise SceneError(f"unknown medium {name!r}: use one of {', '.join(names())}") from None


def describe(material: Material) -> str:
    """The medium as text, in the command line's units, each value with its source."""
    lines = [f"{material.name}: {material.description}"]
    for key, v in material.values.items():
        number, unit = v.shown()
        text = " ".join(f"{x:g}" for x in number) if isinstance(number, tuple) else f"{number:g}"
        flag = f" ({v.status})" if v.status else ""
        lines.append(f"  {key} = {text}{' ' + unit if unit else ''}{flag}  [{v.source}]")
    if material.missing:
        lines.append(f"  not found: {', '.join(material.missing)}")
    if material.note:
        lines.append(f"  note: {material.note}")
    return "\n".join(lines)


# The angles between a segment's velocity and its axis at which the sand-swimming law is fitted to 3D-RFT.
PSI = np.radians(np.arange(0.0, 90.5, 1.0))


@dataclass(frozen=True)
class SandswimFit:
    """The sand-swimming law's C_S, C_F (N per segment) and gamma0 (rad) fitted to 3D-RFT, and how well it fits:
    the RMS and the largest difference in F_perp and F_par over the fitted angles (N), against ``scale``, the
    largest force 3D-RFT gives there (N)."""

    c_s: float
    c_f: float
    gamma0: float
    rms: float
    max_error: float
    scale: float


def plate_forces(psi: np.ndarray, length: float, depth: float, height: float, bulk_density: float,
                 internal_friction: float, surface_friction: float,
                 thickness: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """3D-RFT's F_perp and F_par (N, resisting the motion) on a vertical rigid plate, ``length`` along its axis x
    and ``height`` down from ``depth`` below the free surface (m), moving horizontally at the angles ``psi`` (rad)
    to its axis; a ``thickness`` (m) gives it edge faces too. Each face moves flat, so its stress is uniform and
    depth-weighting it is exact: stress x area x the face's mean depth."""
    psi = np.asarray(psi, dtype=float)
    velocity = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=-1)
    mean_depth = depth + height / 2
    total = np.zeros_like(velocity)
    # the side faces (normals +-y) and the edges (normals +-x); only leading faces feel the medium
    for normal, area in (((0.0, 1.0, 0.0), length * height), ((0.0, -1.0, 0.0), length * height),
                         ((1.0, 0.0, 0.0), thickness * height), ((-1.0, 0.0, 0.0), thickness * height)):
        normals = np.broadcast_to(np.array(normal), velocity.shape)
        total += rft3d.element_forces(normals, velocity, np.full(psi.shape, mean_depth), np.full(psi.shape, area),
                                      bulk_density, internal_friction, surface_friction)
    return -total[..., 1], -total[..., 0]


@functools.lru_cache(maxsize=256)
def sandswim_coefficients(length: float, depth: float, height: float, bulk_density: float, internal_friction: float,
                          surface_friction: float, thickness: float = 0.0) -> SandswimFit:
    """The sand-swimming law (`finrft.laws.sandswim`) of one segment: C_S, C_F and gamma0 fitted by least squares
    to 3D-RFT's force (`plate_forces`: Agarwal, Goldman & Kamrin 2023) on a vertical plate of the segment's
    ``length`` and ``height``, its top edge ``depth`` below the free surface (m), moving horizontally at every
    angle psi = 0, 1, ..., 90 deg to its axis, in a medium of critical density ``bulk_density`` (kg/m^3) and
    internal friction coefficient ``internal_friction``, the plate's friction against the grains being
    ``surface_friction``. 3D-RFT's vertical force, which the in-plane law has no place for, is left out."""
    if not (length > 0 and height > 0 and depth >= 0 and thickness >= 0):
        raise SceneError(f"sandswim coefficients need length > 0, height > 0, depth >= 0 and thickness >= 0 (m), "
                         f"got {length:g}, {height:g}, {depth:g}, {thickness:g}")
    if not (bulk_density > 0 and internal_friction > 0 and surface_friction >= 0):
        raise SceneError(f"sandswim coefficients need bulk_density > 0, internal_friction > 0 and surface_friction "
                         f">= 0, got {bulk_density:g}, {internal_friction:g}, {surface_friction:g}")
    perp, par = plate_forces(PSI, length, depth, height, bulk_density, internal_friction, surface_friction,
                             thickness)
    scale = float(max(np.abs(perp).max(), np.abs(par).max()))
    if not scale > 0:
        raise SceneError("3D-RFT gives no horizontal force on this plate: nothing to fit the sandswim law to")

    # in units of the largest force, so that the fit is the same problem at every size and depth
    perp, par = perp / scale, par / scale

    def residual(x: np.ndarray) -> np.ndarray:
        law_perp, law_par = sandswim.magnitudes(PSI, *x)
        return np.concatenate([law_perp - perp, law_par - par])

    from scipy.optimize import least_squares  # here: scipy.optimize took half the command line's start

    c_f = max(float(par.max()), 1e-6)
    start = np.array([max(float(perp[-1]) - c_f, 1e-3), c_f, math.pi / 4])
    found = least_squares(residual, start, bounds=([0.0, 0.0, 1e-6], [np.inf, np.inf, math.pi / 2]),
                          xtol=1e-12, ftol=1e-12, gtol=1e-12)
    error = scale * found.fun
    return SandswimFit(scale * float(found.x[0]), scale * float(found.x[1]), float(found.x[2]),
                       rms=float(np.sqrt(np.mean(error ** 2))), max_error=float(np.abs(error).max()), scale=scale)


def immersion_properties(section: Any) -> tuple[float, float, float] | None:
    """What a chain scene's ``[medium]`` (`finrft.scene.Immersion`) gives `sandswim_coefficients`: its bulk
    density (kg/m^3), internal and surface friction coefficients, each given there or by its named medium (the
    catalogue's internal friction angle as its tangent); None when the bulk density, internal friction or the height
    is missing. The surface friction is the chain's: given, it overrides the catalogue's; 0 is the named medium's,
    else frictionless (as medium.surface_friction of every scene). SceneError for an unknown medium or a value of
    the medium's given by both."""
    material = medium(section.name) if section.name else None
    catalogued = {"bulk_density": "bulk_density", "internal_friction": "internal_friction_angle",
                  "surface_friction": "surface_friction"}
    values = []
    for key, quantity in catalogued.items():
        given = getattr(section, key)
        known = material.get(quantity) if material else None
        if given and key == "surface_friction":
            known = None
        if given and known:
            raise SceneError(f"medium.name = {section.name!r} gives {quantity}: leave medium.{key} out "
                             f"(got {given:g})")
        if known:
            given = math.tan(known.value) if quantity == "internal_friction_angle" else known.value
        values.append(given)
    if not (section.height > 0 and all(values[:2])):
        return None
    return tuple(values)
