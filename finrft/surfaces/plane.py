"""A plane free surface at any tilt: through ``surface_point`` (m), ``surface_normal`` pointing out of the sand."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import SceneError
from . import points3, up

SUMMARY = "a plane through surface_point, surface_normal out of the sand"


def depth(points: Any, gravity: Any, surface_point: Any = (0.0, 0.0, 0.0),
          surface_normal: Any = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Each point's depth (m) along gravity below the plane: the distance from the point, against gravity, to
    where it meets the plane, n . (m - p) / (n . up)."""
    p = points3(points)
    n = np.asarray(surface_normal, dtype=float).reshape(3)
    length = float(np.linalg.norm(n))
    if not np.isfinite(length) or length == 0.0:
        raise SceneError(f"surface_normal {n.tolist()} is no direction: give the normal out of the sand")
    n = n / length
    facing = float(n @ up(gravity))
    if facing <= 0.0:
        raise SceneError(f"surface_normal {n.tolist()} does not point against gravity (n . up = {facing:.3g}): "
                         "a free surface must face up, out of the sand")
    return ((np.asarray(surface_point, dtype=float).reshape(3) - p) @ n) / facing
