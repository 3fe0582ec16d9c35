"""Prescribed motions of the plate's base: the paper's drag and rotate tests.

SI units: a drag moves the base along +y (m, m/s); a rotation turns the rod about z (rad, rad/s). The first stroke
always goes in the positive direction, which bends the plate's hinges to negative angles: the soft, recovery
direction of an origami plate. With ``cycles`` the motion is a triangle wave: out by ``stroke`` and back, repeated.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from .errors import SceneError

KINDS = ("drag", "rotate")
# The longest rotate stroke (rad): one turn. The plate's rotate tests turn it by up to 180 deg, and a stroke past
# a full turn is one in degrees (the command line's unit) given where radians belong.
TURN = 2 * math.pi


@dataclass(frozen=True)
class Drive:
    """A prescribed base motion at constant speed: one stroke out, or ``cycles`` out-and-back cycles."""

    kind: str = "drag"            # "drag" (slide along +y) or "rotate" (turn about z)
    speed: float = 0.03           # m/s (drag) or rad/s (rotate)
    stroke: float = 0.2           # m (drag) or rad (rotate): length of one stroke
    cycles: int | None = None     # None: a single stroke out
    attack_deg: float = 90.0      # drag only: angle between the plate and the motion at t = 0
    start: float = 0.0            # position at t = 0 (m or rad)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SceneError(f"drive kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        linear = self.kind == "drag"
        units = {"speed": "m/s" if linear else "rad/s", "stroke": "m" if linear else "rad", "attack_deg": "degrees",
                 "start": "m" if linear else "rad"}
        for name, unit in units.items():
            # numpy's scalars are numbers too; stored as floats, so that the drive is written out as JSON
            object.__setattr__(self, name, real(f"drive {name}", getattr(self, name), unit))
        for name in ("speed", "stroke"):
            value = getattr(self, name)
            if not value > 0:
                raise SceneError(f"drive {name} must be > 0 {units[name]}, got {value!r}")
        if not linear and self.stroke > TURN:
            raise SceneError(f"drive stroke = {self.stroke:g} rad is more than one turn (2 pi rad): a rotate drive's "
                             f"stroke is in radians, and {self.stroke:g} looks like degrees: give "
                             f"math.radians({self.stroke:g}) = {math.radians(self.stroke):.4g} rad")
        if self.cycles is not None:
            if isinstance(self.cycles, bool) or not isinstance(self.cycles, numbers.Integral):
                raise SceneError(f"drive cycles must be a whole number (or None: one stroke), got {self.cycles!r}")
            if self.cycles < 1:
                raise SceneError(f"drive cycles must be >= 1, got {self.cycles}")
            object.__setattr__(self, "cycles", int(self.cycles))
        if not 0.0 <= self.attack_deg <= 180.0:
            raise SceneError(f"angle of attack must be within 0..180 degrees, got {self.attack_deg}")

    @property
    def stroke_time(self) -> float:
        return self.stroke / self.speed

    @property
    def strokes(self) -> int:
        return 1 if self.cycles is None else 2 * self.cycles

    @property
    def duration(self) -> float:
        return self.strokes * self.stroke_time

    def stroke_index(self, t: float) -> int:
        """Which stroke time t belongs to (0, 1, ...); even strokes go out (+), odd ones come back (-)."""
        return min(int(t / self.stroke_time + 1e-9), self.strokes - 1)

    def stroke_velocity(self, k: int) -> float:
        return self.speed if k % 2 == 0 else -self.speed

    def stroke_start(self, k: int) -> float:
        """Position at which stroke k starts: ``start`` for outward strokes, ``start + stroke`` for return ones."""
        return self.start if k % 2 == 0 else self.start + self.stroke

    def velocity(self, t: float) -> float:
        return self.stroke_velocity(self.stroke_index(t))

    def positions(self, times: np.ndarray) -> np.ndarray:
        """`position` at each of ``times``."""
        return np.array([self.position(float(t)) for t in times])

    def position(self, t: float) -> float:
        k = self.stroke_index(t)
        return self.stroke_start(k) + self.stroke_velocity(k) * (t - k * self.stroke_time)


def real(what: str, value: object, unit: str) -> float:
    """``value`` as a float: SceneError unless it is a finite real number (a bool is not one; numpy's are)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SceneError(f"{what} must be a number ({unit}), got {value!r}")
    if not math.isfinite(value):
        raise SceneError(f"{what} must be finite ({unit}), got {value!r}")
    return float(value)
