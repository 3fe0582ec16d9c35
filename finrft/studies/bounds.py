"""The searched keys' units: --bounds KEY=LOW:HIGH read in SI or with the unit suffix a key's schema unit allows,
and searched values shown in the CLI's units. Units come from the scene schema, never from a key's name."""

from __future__ import annotations

import math

import numpy as np

from ..scene import SceneError, key_unit
from ..schema import UNITS, is_number, quantity

# SI units shown in the CLI's: radians (and per second) in degrees, metres in mm.
DISPLAY = {"rad": 180 / math.pi, "rad/s": 180 / math.pi, "m": 1e3}
DISPLAY_UNIT = {"rad": "deg", "rad/s": "deg/s", "m": "mm"}


def unit_of(cls: type, key: str) -> str | None:
    """A scene key's SI unit; None for a key the schema does not know (the search names it)."""
    try:
        return key_unit(cls, key)
    except SceneError:
        return None


def parse_bounds(items: list[str], cls: type,
                 aliases: dict[str, str] | None = None) -> dict[str, tuple[float, float]]:
    """--bounds KEY=LOW:HIGH (or KEY=LOW,HIGH) items of ``cls``'s scene keys (or their ``aliases``) in SI, or with a
    unit suffix the key's schema unit allows (`finrft.schema.quantity`: deg for rad, mm for m, ...), on HIGH for
    both or on each; SceneError for an item that is not so."""
    bounds = {}
    for item in items:
        key, sep, span = item.partition("=")
        low, sep2, high = span.partition(":")
        if not sep2:
            low, sep2, high = span.partition(",")
        if not sep or not sep2:
            raise SceneError(f"--bounds expects KEY=LOW:HIGH or KEY=LOW,HIGH, got '{item}'")
        name = (aliases or {}).get(key.strip(), key.strip())
        low, high = low.strip(), high.strip()
        suffix = next((s for s in sorted(UNITS, key=len, reverse=True) if high.endswith(s)), None)
        if suffix is not None and is_number(low):
            low += suffix
        unit = unit_of(cls, name)
        twice = next((k for k in bounds if (aliases or {}).get(k, k) == name), None)
        if twice is not None:
            raise SceneError(f"--bounds {item}: {key.strip()} has bounds already ({twice}="
                             f"{bounds[twice][0]:g}:{bounds[twice][1]:g}): give each key's once")
        try:
            span = tuple(quantity(text, unit or "", key.strip()) for text in (low, high))
        except (ValueError, SceneError) as exc:
            raise SceneError(f"--bounds {item}: {exc}") from None
        if not all(map(math.isfinite, span)):
            raise SceneError(f"--bounds {item}: bounds must be finite numbers")
        bounds[key.strip()] = span
    return bounds


def display_units(cls: type, keys: list[str], values: np.ndarray) -> np.ndarray:
    """Searched values in the CLI's units: angles in degrees, lengths in mm, the rest in SI."""
    return values * np.array([DISPLAY.get(unit_of(cls, k) or "", 1.0) for k in keys])


def shown(cls: type, key: str, value: float) -> str:
    """A scene key's SI value in the CLI's unit, with the unit: ``fin.segment_length 20 mm``."""
    unit = unit_of(cls, key) or ""
    # a unit the schema names only in words ("actuator's unit") is left out
    shown_unit = "" if "unit" in unit else DISPLAY_UNIT.get(unit, unit)
    return f"{key} {value * DISPLAY.get(unit, 1.0):.4g} {shown_unit}".rstrip()

