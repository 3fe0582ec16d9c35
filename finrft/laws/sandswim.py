"""Law ``sandswim``: the sand-swimming RFT of Maladen et al. (Science 325:314, 2009, supplement) and Ding et al.
(PLoS Comput Biol 8:e1002810, 2012) for slender segments moving in a horizontal plane at a fixed depth. With psi the
angle between a segment's velocity and its axis, the granular medium resists with the speed-independent
("frictional fluid") magnitudes::

    F_par(psi)  = C_F cos psi
    F_perp(psi) = C_S sin beta0 + C_F sin psi,      tan beta0 = cot(gamma0) sin psi

each opposing its component of the motion, regularised below v_reg as every law here. Written with the direction
cosines v^.x^ = cos psi and v^.y^ = sin psi (signed), k = cot gamma0::

    F = -tanh(|v| / v_reg) * ( (C_S k (v^.y^) / sqrt(1 + k^2 (v^.y^)^2) + C_F (v^.y^)) y^ + C_F (v^.x^) x^ )

which is odd in v and smooth in its direction. Its power is F.v = -tanh(|v|/v_reg) |v| (C_S k s / sqrt(1 + k^2 s)
+ C_F (s + t)), s = (v^.y^)^2, t = (v^.x^)^2: it dissipates for C_S, C_F >= 0 and 0 < gamma0 <= 90 deg
(`feeds_energy`).

Coefficients. C_S and C_F are forces (N) on the whole drag rod of the papers, at their depth; the forces scale in
proportion to the area of the body and, in the frictional regime, to its depth, so a scene gives them per unit area
and depth: ``rft.c_s`` and ``rft.c_f`` (N/m^3) = the published value / (rod area x rod mean depth), and a segment's
C_S and C_F (N) are those times its face's area and mean depth (`finrft.laws.segment_scale`). ``rft.gamma0`` (rad)
is the same for any size or depth.

The published fits (0.3 mm and 3 mm glass beads, loose and close packing: Maladen 2009, supplement; the 3 mm
particles in Ding 2012, Table 2, from a DEM drag of a 40 mm rod of 16 mm x 16 mm section at 7.6 cm depth) could
not be recovered from the text available to this project, so no values are built in: a scene must give all three.
The C twin is plugins/laws/sandswim.c.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import SceneError
from ..schema import field
from . import LEAST_COEFFICIENT, WHY_LEAST, components

KIND = "segment"
SUMMARY = "the sand-swimming law of Maladen et al. 2009"  # what the scene's rft.law documents
# The law's keys of [rft], with their units (`finrft.scene.RFT` is built from every law's). A chain's scene may
# leave all three at 0 to take them from its [medium].
KEYS = (("c_s", float, field(0.0, "N/m^3", "sandswim law: C_S per unit area and depth (the medium's normal-force "
                             "scale); all of c_s, c_f, gamma0 at 0: from [medium]", minimum=0.0, exclusive=False,
                             least=LEAST_COEFFICIENT, why_least=WHY_LEAST)),
        ("c_f", float, field(0.0, "N/m^3", "sandswim law: C_F per unit area and depth (the medium's friction-like "
                             "drag)", minimum=0.0, exclusive=False)),
        ("gamma0", float, field(0.0, "rad", "sandswim law: gamma0, how fast F_perp saturates with the angle of "
                                "motion", minimum=0.0, exclusive=False, maximum=math.pi / 2,
                                why_maximum="beyond it the normal force would push a segment along its motion")))
INTENSIVE = ("c_s", "c_f")


def from_medium(rft: Any) -> bool:
    """Whether a scene's [rft] leaves c_s, c_f and gamma0 all at 0, to take them from its chain's [medium]
    (`finrft.geometry.resolve`, at model build)."""
    return not any(getattr(rft, key) for key, _, _ in KEYS)


def check(rft: Any, medium: tuple[float, float, float] | None) -> None:
    """SceneError unless the section gives c_s, c_f and gamma0 > 0, or leaves all three at 0 in a ``medium`` that
    gives what they are derived from."""
    if from_medium(rft) and medium is not None:
        return
    if not (rft.c_s > 0 and rft.c_f > 0 and rft.gamma0 > 0):
        raise SceneError("rft.law = 'sandswim' needs rft.c_s > 0, rft.c_f > 0 (N/m^3) and 0 < rft.gamma0 <= pi/2 "
                         "(rad), the medium's fitted values: none are built in (or leave all three at 0 and give "
                         "[medium] bulk_density, internal_friction and surface_friction to derive them)")


def parameters(rft: Any) -> dict[str, float]:
    return {"c_s": rft.c_s, "c_f": rft.c_f, "gamma0": rft.gamma0}


def force(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray, v_reg: float, c_s: float, c_f: float,
          gamma0: float) -> np.ndarray:
    """(N, 3) newtons."""
    ramp, vx, vy = components(v, x_axis, y_axis, v_reg)
    ky = math.cos(gamma0) / math.sin(gamma0) * vy
    perp = c_s * ky / np.sqrt(1.0 + ky * ky) + c_f * vy
    return -ramp[..., None] * (perp[..., None] * y_axis + (c_f * vx)[..., None] * x_axis)


def magnitudes(psi: np.ndarray, c_s: float, c_f: float, gamma0: float) -> tuple[np.ndarray, np.ndarray]:
    """The papers' F_perp(psi) and F_par(psi) (N), psi in [0, pi/2] rad, as they are written there."""
    beta0 = np.arctan(np.sin(psi) / np.tan(gamma0))
    return c_s * np.sin(beta0) + c_f * np.sin(psi), c_f * np.cos(psi)


def feeds_energy(params: dict[str, float]) -> str:
    """Why the law can push a segment along its own motion (F.v > 0), or "" when it dissipates at every velocity.

    Per unit speed the power is -(C_S k s / sqrt(1 + k^2 s) + C_F (s + t)), s = (v^.y^)^2, t = (v^.x^)^2, s + t <= 1
    (a velocity out of the segment's plane has s + t < 1); its worst case is C_F alone (s = 0) or, for C_S k < 0,
    C_S k + C_F as s -> 0 with t = 0."""
    c_s, c_f, gamma0 = params["c_s"], params["c_f"], params["gamma0"]
    k = math.cos(gamma0) / math.sin(gamma0)
    if c_f < 0:
        return f"c_f = {c_f:g} N < 0 pushes a segment along its motion"
    if c_s * k + c_f < 0:
        return f"c_s cot(gamma0) + c_f = {c_s * k + c_f:g} N < 0 pushes a segment along a slight sideways motion"
    return ""


# The stress map's grid: psi over 0..90 deg at 1 deg, gamma0 over 5..90 deg at 5 deg.
MAP_PSI_DEG = np.arange(0, 91, 1)
MAP_GAMMA0_DEG = np.arange(5, 91, 5)
MAP_UNITS = {"f_perp_c_s": "C_S", "f_perp_c_f": "C_F", "f_par_c_f": "C_F"}
MAP_QUANTITY = "force per segment, per unit coefficient"


def map_note(medium) -> str:
    """What the map shows, in one line."""
    return ("per unit coefficient, for any medium (no medium's C_S, C_F, gamma0 are catalogued): F_perp = C_S "
            "f_perp_c_s + C_F f_perp_c_f, F_par = C_F f_par_c_f")


def stress_map(medium) -> dict[str, np.ndarray]:
    """The law's magnitudes over the grid (psi_deg, gamma0_deg), flat arrays, psi the outer index, split into the
    parts each coefficient multiplies: F_perp's C_S part sin(beta0) per unit C_S, its C_F part sin(psi) and F_par's
    cos(psi) per unit C_F. The catalogue gives no medium's coefficients (a scene does: rft.c_s, rft.c_f,
    rft.gamma0), so the map is the same for every medium."""
    psi, gamma0 = (a.ravel().astype(float) for a in np.meshgrid(MAP_PSI_DEG, MAP_GAMMA0_DEG, indexing="ij"))
    per_c_s, _ = magnitudes(np.radians(psi), 1.0, 0.0, np.radians(gamma0))
    per_c_f, par = magnitudes(np.radians(psi), 0.0, 1.0, np.radians(gamma0))
    return {"psi_deg": psi, "gamma0_deg": gamma0, "f_perp_c_s": per_c_s, "f_perp_c_f": per_c_f, "f_par_c_f": par}
