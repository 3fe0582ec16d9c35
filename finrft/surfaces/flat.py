"""The horizontal free surface z = ``surface_z`` (m), unbounded: every scene's surface today."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import plane

SUMMARY = "the horizontal plane z = surface_z"


def depth(points: Any, gravity: Any, surface_z: float = 0.0) -> np.ndarray:
    """Each point's depth (m) along gravity below the plane z = ``surface_z``."""
    return plane.depth(points, gravity, surface_point=(0.0, 0.0, surface_z), surface_normal=(0.0, 0.0, 1.0))
