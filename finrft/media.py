"""The catalogue of named granular media (finrft/media.toml): each medium's values with their units and sources.

`media()` gives every medium, `medium(name)` one (a `SceneError` names the known media for an unknown name). The
values are what the literature gives, nothing estimated: a value not found is absent (`Material.missing`), and a
law that needs it says so (`finrft.laws.li2013.medium_parameters`).
"""

from __future__ import annotations

import functools
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

from .scene import SceneError

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
