"""Law ``paper``: the direction-cosine law of the paper's model, regularised below v_reg::

    F = -tanh(|v| / v_reg) * ( f_perp (v^.y^) y^ + f_par (v^.x^) x^ ),   v^ = v / |v|

A scene gives ``rft.f_perp`` and ``rft.f_par`` per unit area and depth (N/m^3, like RFT's zeta); a segment's
``f_perp`` and ``f_par`` (N) are those times its face's area and mean depth (`finrft.laws.segment_scale`).

The C twin is plugins/laws/paper.c.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..schema import field
from . import LEAST_COEFFICIENT, WHY_LEAST, components

KIND = "segment"
SUMMARY = "direction-cosine law (the paper's model)"  # what the scene's rft.law documents
# The law's keys of [rft], with their units (`finrft.scene.RFT` is built from every law's). The defaults: the
# authors' 1.2 N and -0.2 N per 33 mm segment, over its face 33 x 55 mm at 37.5 mm mean depth.
KEYS = (("f_perp", float, field(17630.85399449036, "N/m^3", "normal force coefficient per unit area and depth "
                                "(paper law): a segment's is this x its face's area x mean depth; < 0 would pull "
                                "the plate along", minimum=0.0, exclusive=False,
                                least=LEAST_COEFFICIENT, why_least=WHY_LEAST)),
        ("f_par", float, field(-2938.475665748393, "N/m^3", "tangential force coefficient per unit area and depth "
                               "(paper law; < 0 feeds energy in)")))
INTENSIVE = ("f_perp", "f_par")


def parameters(rft: Any) -> dict[str, float]:
    return {"f_perp": rft.f_perp, "f_par": rft.f_par}


def force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, v_reg: float, f_perp: float,
          f_par: float) -> np.ndarray:
    """(N, 3) newtons."""
    ramp, vx, vy = components(v, x_axis, y_axis, v_reg)
    return -ramp[..., None] * (f_perp * vy[..., None] * y_axis + f_par * vx[..., None] * x_axis)


def feeds_energy(params: dict[str, float]) -> str:
    """Why the law can push a segment along its own motion (F.v > 0), or "" when it dissipates at every velocity
    (``params``: one segment's, N):
    per unit speed its power is -(f_perp (v^.y^)^2 + f_par (v^.x^)^2), so either coefficient < 0 feeds energy in."""
    if params["f_par"] < 0:
        return f"f_par = {params['f_par']:g} N < 0 (per segment) pushes a segment along its axial motion"
    if params["f_perp"] < 0:
        return f"f_perp = {params['f_perp']:g} N < 0 (per segment) pushes a segment along its sideways motion"
    return ""
