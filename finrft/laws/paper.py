"""Law ``paper``: the direction-cosine law of the paper's model, regularised below v_reg::

    F = -tanh(|v| / v_reg) * ( f_perp (v^.y^) y^ + f_par (v^.x^) x^ ),   v^ = v / |v|

The C twin is plugins/laws/paper.c.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import components

KIND = "segment"


def parameters(rft: Any) -> dict[str, float]:
    return {"f_perp": rft.f_perp, "f_par": rft.f_par}


def force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, v_reg: float, f_perp: float,
          f_par: float) -> np.ndarray:
    """(N, 3) newtons."""
    ramp, vx, vy = components(v, x_axis, y_axis, v_reg)
    return -ramp[..., None] * (f_perp * vy[..., None] * y_axis + f_par * vx[..., None] * x_axis)
