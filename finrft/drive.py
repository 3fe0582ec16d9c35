"""Prescribed motions of the plate's base: the paper's drag and rotate tests.

SI units: a drag moves the base along +y (m, m/s); a rotation turns the rod about z (rad, rad/s). The first stroke
always goes in the positive direction, which bends the plate's hinges to negative angles: the soft, recovery
direction of an origami plate. With ``cycles`` the motion is a triangle wave: out by ``stroke`` and back, repeated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

KINDS = ("drag", "rotate")


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
            raise ValueError(f"drive kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        for name in ("speed", "stroke"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"drive {name} must be > 0, got {value!r}")
        if self.cycles is not None and self.cycles < 1:
            raise ValueError(f"cycles must be >= 1, got {self.cycles}")
        if not 0.0 <= self.attack_deg <= 180.0:
            raise ValueError(f"angle of attack must be within 0..180 degrees, got {self.attack_deg}")

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

    def position(self, t: float) -> float:
        k = self.stroke_index(t)
        return self.stroke_start(k) + self.stroke_velocity(k) * (t - k * self.stroke_time)
