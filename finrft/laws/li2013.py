"""The granular RFT law of Li, Zhang & Goldman, "A terradynamics of legged locomotion on granular media",
Science 339:1408 (2013), in SI units: stresses per unit depth in N/m^3 (1 N/cm^3 = 1e6 N/m^3), extended to three
dimensions by Treers, Cao & Stuart, "Granular resistive force theory implementation for three-dimensional
trajectories", IEEE RA-L 6(2):1887 (2021): the law ``li2013`` (`element_forces`). Its planar form, each element a
plate in the vertical plane of its own velocity, is the law ``li2013-planar`` (`finrft.laws.li2013_planar`).

A plate element of area dA at depth |z| below the free surface, moving in the vertical x-z plane, feels

    dF_x = alpha_x(beta, gamma) |z| dA,    dF_z = alpha_z(beta, gamma) |z| dA,

    alpha_z = zeta (A00 + A10 cos 2b + B11 sin(2b + g) + B01 sin g + B-11 sin(-2b + g))
    alpha_x = zeta (C11 cos(2b + g) + C01 cos g + C-11 cos(-2b + g) + D10 sin 2b)

(the non-zero terms of the paper's discrete Fourier fit), zeta the medium's scale (alpha_z of a horizontal plate
pushed straight down, in N/cm^3 for the generic coefficients, whose values at (0, +pi/2) sum to 1).

Conventions (drawn in the paper's Fig. 2A), fixed here by the fit's own values and the physics: z points up; the plate
moves towards -x when gamma = 0, so alpha_x > 0 resists the horizontal motion (alpha_x(pi/2, 0) = 0.370 N/cm^3 on
a vertical plate); gamma is the angle of the velocity below the horizontal (gamma > 0 moving down:
alpha_z(0, +pi/2) = 1.000, alpha_z(0, -pi/2) = -0.250 on extraction); beta is the plate's angle, positive when
its lower face looks down and forward (towards -x): the lower face's normal is (-sin beta, -cos beta) in (x, z).
With these signs the stress on every element is dissipative: alpha_x cos gamma + alpha_z sin gamma > 0 over the
whole range for the generic coefficients.

Outside beta, gamma in [-pi/2, pi/2]: beta is the same plate after a half turn (period pi); a velocity with a +x
component is the mirror image x -> -x of one in range: beta -> -beta, gamma -> pi - gamma (or -pi - gamma), and
alpha_x changes sign. Public codes differ from the paper's fit in two ways this module avoids: sin on the C terms
(cos on D10), and sin(-2b + g) on C-11.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import SceneError
from ..schema import field

KIND = "surface"
N_PER_CM3 = 1e6  # N/m^3 in one N/cm^3
# The law's parameters of the medium (`finrft.attach` takes them by these names), and the [medium] key of each.
PARAMETERS = ("zeta",)
SECTION_KEYS = {"zeta": "zeta"}
DENSITY = ""  # none of its parameters is the medium's bulk density
FEEDS_ENERGY = ""  # dissipative over the whole range (the module's docstring)
# The law's own keys of a scene's [medium] (`finrft.scene.Medium` is built from every surface law's).
# zeta is in N/cm^3, the literature's unit and the one exception to SI in scene files: every published zeta and
# the catalogue give it so ("0.6 N/cm3" and "6e5 N/m3" read as 0.6 too).
KEYS = (("zeta", float, field(1.0, "N/cm^3", "li2013, li2013-planar: the medium's scale: alpha_z of a horizontal "
                              "plate pushed down, in N/cm^3, the literature's unit (not SI; a suffix converts: "
                              "\"6e5 N/m3\" is 0.6); the generic coefficients are scaled by it; only without "
                              "medium.name", minimum=0.0)),)


@dataclass(frozen=True)
class Coefficients:
    """The fit's nine non-zero Fourier coefficients, N/m^3 (B_11 and C_11 are the paper's B_-11, C_-11)."""

    A00: float
    A10: float
    B11: float
    B01: float
    B_11: float
    C11: float
    C01: float
    C_11: float
    D10: float

    @classmethod
    def per_cm3(cls, *values: float) -> "Coefficients":
        """From values in N/cm^3, in the order of the fields."""
        return cls(*(v * N_PER_CM3 for v in values))

    def values(self) -> tuple[float, ...]:
        # the fields themselves: dataclasses.astuple deep-copies each, half the cost of a law call in numpy
        return tuple(getattr(self, f.name) for f in fields(self))


# Generic coefficients of Li et al. 2013 (their Table S2), as transcribed identically by independent public codes;
# scaled by zeta = alpha_z(0, pi/2) of the medium in N/cm^3.
GENERIC = Coefficients.per_cm3(0.206, 0.169, 0.212, 0.358, 0.055, -0.124, 0.253, 0.007, 0.088)
DEFAULT = GENERIC  # the coefficients of a medium given by its zeta alone
# The coefficient sets of named media (poppy seeds loosely and closely packed, ...) are in the media catalogue
# (finrft/media.toml), with their sources: `medium_parameters`.


def alpha(beta, gamma, zeta: float = 1.0, coefficients: Coefficients = GENERIC) -> tuple[np.ndarray, np.ndarray]:
    """(alpha_x, alpha_z) in N/m^3 for plate angles beta and velocity angles gamma (radians, any values)."""
    beta = np.asarray(beta, dtype=float)
    gamma = np.asarray(gamma, dtype=float)
    gamma = np.where(np.abs(gamma) > np.pi, np.arctan2(np.sin(gamma), np.cos(gamma)), gamma)
    mirrored = np.abs(gamma) > np.pi / 2
    gamma = np.where(mirrored, np.copysign(np.pi, gamma) - gamma, gamma)
    beta = np.where(mirrored, -beta, beta)
    beta = beta - np.pi * np.round(beta / np.pi)
    a00, a10, b11, b01, b_11, c11, c01, c_11, d10 = coefficients.values()
    alpha_z = (a00 + a10 * np.cos(2 * beta) + b11 * np.sin(2 * beta + gamma) + b01 * np.sin(gamma)
               + b_11 * np.sin(-2 * beta + gamma))
    alpha_x = (c11 * np.cos(2 * beta + gamma) + c01 * np.cos(gamma) + c_11 * np.cos(-2 * beta + gamma)
               + d10 * np.sin(2 * beta))
    return zeta * np.where(mirrored, -alpha_x, alpha_x), zeta * alpha_z


# Treers, Cao & Stuart's fitted weights of the two parts of an element's unit velocity (their public code
# granular_rft_3D, rft_3D_body.m, as the wheel experimenters' code qishuny/3D-RFT-wheel uses them): f1 of the part
# across the element's vertical plane, f23 of the part in it. Both are 0 at 0 and 1 at 1 (to 4e-16; to 2.6e-4 with the digits the paper prints).
F1_FIT = (0.440850096954369, 3.62263982880971, 1.60910808139526, 0.832324700111401)
F23_FIT = (1.99392673405210, 1.61146827229181, 0.973746396532650, 5.81083560370960)
# A face tilted less than this from horizontal (|n_h| < sin 2.56 deg, Treers' |n_z| >= 1 - 1e-3) has no reliable
# vertical plane of its own: its force blends towards that of the plane of the velocity (`element_forces`).
HORIZONTAL = float(np.sqrt(1 - (1 - 1e-3) ** 2))
SUMMARY = "Li 2013 in 3D (Treers, Cao & Stuart 2021: lateral and swimming forces)"


def weights(across, within) -> tuple[np.ndarray, np.ndarray]:
    """Treers et al.'s f1(|v1|) and f23(|v23|) of the sizes of the two parts of a unit velocity (each in [0, 1]):
    f1 = a (tanh(b s - c) + tanh(c)) / d and f23 = a (atanh(b s - c) + atanh(c)) / d, each sum in one closed form
    of u = b s, as weight_across and weight_within in finrft_surface.c (one exp, one log per element):
    tanh(u - c) + tanh(c) = E / (cosh c (e^-c E + 2 cosh c)), E = e^(2 u) - 1, and atanh(u - c) + atanh(c) =
    log(1 + 2 u / ((1 + c - u) (1 - c))) / 2."""
    a, b, c, d = F1_FIT
    grow = np.exp(2 * b * np.asarray(across, dtype=float)) - 1
    f1 = a / (d * math.cosh(c)) * grow / (math.exp(-c) * grow + 2 * math.cosh(c))
    a, b, c, d = F23_FIT
    u = b * np.asarray(within, dtype=float)
    f23 = a / (2 * d) * np.log(1 + 2 / (1 - c) * u / (1 + c - u))
    return f1, f23


def _horizontal_unit(vector: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """The unit horizontal direction (..., 2) of vectors (..., 3); fallback's where they are vertical, x where
    both are."""
    size = np.hypot(vector[..., 0], vector[..., 1])
    other = np.hypot(fallback[..., 0], fallback[..., 1])
    pick = np.where((size > 0)[..., None], vector[..., :2], fallback[..., :2])
    length = np.where(size > 0, size, other)
    return np.where((length > 0)[..., None], pick / np.where(length > 0, length, 1.0)[..., None], [1.0, 0.0])


def _stress(normal: np.ndarray, unit: np.ndarray, e2: np.ndarray, zeta: float,
            coefficients: Coefficients) -> np.ndarray:
    """Treers et al.'s stress per unit depth (..., 3, N/m^3) on elements of unit normals ``normal`` moving along
    ``unit`` (unit or zero velocity), the vertical plane being that of the horizontal unit vector e2 (..., 2)."""
    e1 = np.stack([e2[..., 1], -e2[..., 0]], axis=-1)  # e2 x z
    across = np.einsum("...i,...i", unit[..., :2], e1)
    along = np.einsum("...i,...i", unit[..., :2], e2)
    f1, f23 = weights(np.abs(across), np.hypot(along, unit[..., 2]))
    # Li's angles in the (e2, z) plane: the paper's x axis is -e2 (as -r of the planar form)
    beta = np.arctan2(-np.einsum("...i,...i", normal[..., :2], e2), normal[..., 2])
    gamma = np.arctan2(-unit[..., 2], along)
    alpha_x, alpha_z = alpha(beta, gamma, zeta, coefficients)
    alpha_1 = alpha(0.0, 0.0, zeta, coefficients)[0]
    stress = np.empty(normal.shape)
    stress[..., :2] = -(f1 * alpha_1 * np.sign(across))[..., None] * e1 - (f23 * alpha_x)[..., None] * e2
    stress[..., 2] = f23 * alpha_z
    return stress


def element_forces(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   zeta: float = 1.0, coefficients: Coefficients = GENERIC) -> np.ndarray:
    """The force (N, 3), world frame, z up, on surface elements with outward unit normals (N, 3), velocities
    (N, 3, m/s), depths below the free surface (N, m; <= 0 above it) and areas (N, m^2): Li's law extended to 3D
    by Treers, Cao & Stuart 2021 (RA-L 6(2):1887).

    e2 is the horizontal direction of the normal and e1 = e2 x z; the unit velocity v^ splits into v1 = (v^.e1) e1,
    across the element's vertical plane, and v23 = v^ - v1, in it. Li's alpha_x, alpha_z are taken at the angles
    of n and v23 in the (e2, z) plane, and the stress per unit depth is

        -f1(|v1|) alpha_1 sign(v^.e1) e1 - f23(|v23|) alpha_x e2 + f23(|v23|) alpha_z z,   alpha_1 = alpha_x(0, 0),

    times depth and area; only leading elements (n . v > 0) below the surface feel the medium. The law is
    unchanged by e2 -> -e2 (Li's mirror symmetry), so only e2's line matters. A motion in the element's vertical
    plane is the planar form's (`finrft.laws.li2013_planar`): f23(1) = 1.

    Degenerate cases, continuous: a horizontal face has no e2 of its own. Treers' code takes e2 along the
    velocity's horizontal part for faces within 2.56 deg of horizontal (`HORIZONTAL`), a step at that tilt; here
    the force blends from that plane's (w = 0, the planar form at an exactly horizontal face) to the normal's
    plane's (w = 1, at 2.56 deg) with w = smoothstep(|n_h| / HORIZONTAL). When the velocity is vertical its plane
    is the normal's; when both are vertical the force is vertical and any plane gives it. A zero velocity gives
    zero (f1(0) = f23(0) = 0; and the element does not lead). Left: a face tilted less than 2.56 deg moving exactly
    vertically takes the normal's plane for its share 1 - w, whatever its tilt's azimuth; a rate-independent law
    still steps at v = 0, which `finrft.laws.regularised` ramps.
    """
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(velocity, axis=-1)
    unit = velocity / np.where(speed > 0, speed, 1.0)[..., None]
    tilt = np.clip(np.hypot(normal[..., 0], normal[..., 1]) / HORIZONTAL, 0.0, 1.0)
    w = tilt * tilt * (3 - 2 * tilt)
    stress = _stress(normal, unit, _horizontal_unit(normal, velocity), zeta, coefficients)
    flat = w < 1
    if flat.any():
        own = _stress(normal, unit, _horizontal_unit(velocity, normal), zeta, coefficients)
        stress = np.where(flat[..., None], w[..., None] * stress + (1 - w)[..., None] * own, stress)
    leading = (np.einsum("...i,...i", normal, velocity) > 0) & (np.asarray(depth) > 0)
    scale = np.where(leading, np.asarray(area) * np.asarray(depth), 0.0)
    return scale[..., None] * stress


def _alpha_slope(cb, sb, cg, sg, zeta: float, coefficients: Coefficients) -> tuple[np.ndarray, np.ndarray]:
    """(alpha_x, alpha_z) (..., 2) at the angles given by their cosines and sines, and their partial derivatives
    (..., 2, 4) in (cos beta, sin beta, cos gamma, sin gamma), by the angle-sum forms of alpha_unit in
    finrft_surface.c (gamma beyond +-pi/2 folded as `alpha` folds it)."""
    a00, a10, b11, b01, b_11, c11, c01, c_11, d10 = coefficients.values()
    m = np.where(cg < 0, -1.0, 1.0)
    sb, cg = m * sb, m * cg
    c2, s2 = cb * cb - sb * sb, 2 * sb * cb
    alpha_x = (c11 + c_11) * c2 * cg + (c_11 - c11) * s2 * sg + c01 * cg + d10 * s2
    alpha_z = a00 + a10 * c2 + (b11 - b_11) * s2 * cg + (b11 + b_11) * c2 * sg + b01 * sg
    # by c2, s2, cos gamma, sin gamma; then c2 and s2 by cos beta and sin beta
    x_c2, x_s2 = (c11 + c_11) * cg, (c_11 - c11) * sg + d10
    z_c2, z_s2 = a10 + (b11 + b_11) * sg, (b11 - b_11) * cg
    dx = [2 * (x_c2 * cb + x_s2 * sb), 2 * (x_s2 * cb - x_c2 * sb), (c11 + c_11) * c2 + c01, (c_11 - c11) * s2]
    dz = [2 * (z_c2 * cb + z_s2 * sb), 2 * (z_s2 * cb - z_c2 * sb), (b11 - b_11) * s2, (b11 + b_11) * c2 + b01]
    # back to the unfolded angles: alpha_x = m alpha_x', sin beta' = m sin beta, cos gamma' = m cos gamma
    dx = [m * dx[0], dx[1], dx[2], m * dx[3]]
    dz = [dz[0], m * dz[1], m * dz[2], dz[3]]
    return (zeta * np.stack([m * alpha_x, alpha_z], axis=-1),
            zeta * np.stack([np.stack(dx, axis=-1), np.stack(dz, axis=-1)], axis=-2))


def _weight_slopes(across, within) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of `weights`' f1 and f23 in the sizes of the two parts."""
    a, b, c, d = F1_FIT
    grow = np.exp(2 * b * np.asarray(across, dtype=float))
    df1 = (a / (d * math.cosh(c)) * 2 * math.cosh(c) * 2 * b * grow
           / (math.exp(-c) * (grow - 1) + 2 * math.cosh(c)) ** 2)
    a, b, c, d = F23_FIT
    u = b * np.asarray(within, dtype=float)
    q = 2 / (1 - c) * u / (1 + c - u)
    df23 = a / (2 * d) * b * 2 / (1 - c) * (1 + c) / (1 + c - u) ** 2 / (1 + q)
    return df1, df23


def _stress_slope(normal: np.ndarray, unit: np.ndarray, e2: np.ndarray, de2: np.ndarray, zeta: float,
                  coefficients: Coefficients) -> tuple[np.ndarray, np.ndarray]:
    """`_stress` (..., 3) and its derivative (..., 3, 3) in the unit velocity, e2's derivative in it being de2
    (..., 2, 3): 0 for the normal's plane, the velocity's own plane turning with it."""
    e1 = np.stack([e2[..., 1], -e2[..., 0]], axis=-1)
    de1 = np.stack([de2[..., 1, :], -de2[..., 0, :]], axis=-2)
    horizontal = unit[..., :2]
    across = np.einsum("...i,...i", horizontal, e1)
    along = np.einsum("...i,...i", horizontal, e2)
    d_across = np.einsum("...i,...ik->...k", horizontal, de1)
    d_along = np.einsum("...i,...ik->...k", horizontal, de2)
    d_across[..., :2] += e1
    d_along[..., :2] += e2
    within = np.hypot(along, unit[..., 2])
    moving = within > 0
    safe = np.where(moving, within, 1.0)
    z = np.array([0.0, 0.0, 1.0])
    d_within = np.where(moving[..., None], (along[..., None] * d_along + unit[..., 2, None] * z) / safe[..., None],
                        0.0)
    f1, f23 = weights(np.abs(across), within)
    df1, df23 = _weight_slopes(np.abs(across), within)
    # beta = atan2(y, x), y = -n.e2, x = n_z; gamma = atan2(-u_z, along), of size `within`
    y, x = -np.einsum("...i,...i", normal[..., :2], e2), normal[..., 2]
    dy = -np.einsum("...i,...ik->...k", normal[..., :2], de2)
    size = np.hypot(x, y)
    has = size > 0
    r = np.where(has, size, 1.0)
    cb, sb = np.where(has, x / r, 1.0), y / r
    d_cb = np.where(has, -cb * sb / r, 0.0)[..., None] * dy
    d_sb = np.where(has, cb * cb / r, 0.0)[..., None] * dy
    cg, sg = np.where(moving, along / safe, 1.0), -unit[..., 2] / safe
    d_cg = np.where(moving[..., None], (d_along - cg[..., None] * d_within) / safe[..., None], 0.0)
    d_sg = np.where(moving[..., None], (-z - sg[..., None] * d_within) / safe[..., None], 0.0)
    alpha, partial = _alpha_slope(cb, sb, cg, sg, zeta, coefficients)
    d_alpha = np.einsum("...aj,...jk->...ak", partial, np.stack([d_cb, d_sb, d_cg, d_sg], axis=-2))
    alpha_1 = zeta * (coefficients.C11 + coefficients.C01 + coefficients.C_11)
    side = f1 * alpha_1 * np.sign(across)
    d_side = (df1 * alpha_1)[..., None] * d_across  # f1(|a|) sign(a) is odd: its slope is f1'(|a|)
    d_f23 = df23[..., None] * d_within
    stress = np.empty(normal.shape)
    slope = np.empty(normal.shape + (3,))
    stress[..., :2] = -side[..., None] * e1 - (f23 * alpha[..., 0])[..., None] * e2
    stress[..., 2] = f23 * alpha[..., 1]
    d_within_plane = d_f23 * alpha[..., 0, None] + f23[..., None] * d_alpha[..., 0, :]  # of f23 alpha_x
    slope[..., :2, :] = (-e1[..., :, None] * d_side[..., None, :] - side[..., None, None] * de1
                         - e2[..., :, None] * d_within_plane[..., None, :]
                         - (f23 * alpha[..., 0])[..., None, None] * de2)
    slope[..., 2, :] = d_f23 * alpha[..., 1, None] + f23[..., None] * d_alpha[..., 1, :]
    return stress, slope


def element_slopes(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   zeta: float = 1.0, coefficients: Coefficients = GENERIC) -> tuple[np.ndarray, np.ndarray]:
    """`element_forces` (N, 3) and each force's derivative in the velocity, dF/dv (N, 3, 3; row: the force's
    component), analytic: the twin of finrft_li2013_element_slope. The law depends on the direction u = v / |v|
    alone, so dF/dv = dF/du (I - u u^T) / |v|; in the blend of nearly horizontal faces the velocity's own plane
    turns with it, e2 = u_h / |u_h|, de2/du_h = (I - e2 e2^T) / |u_h|."""
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(velocity, axis=-1)
    safe = np.where(speed > 0, speed, 1.0)
    unit = velocity / safe[..., None]
    tilt = np.clip(np.hypot(normal[..., 0], normal[..., 1]) / HORIZONTAL, 0.0, 1.0)
    w = tilt * tilt * (3 - 2 * tilt)
    fixed = np.zeros(normal.shape[:-1] + (2, 3))
    stress, slope = _stress_slope(normal, unit, _horizontal_unit(normal, velocity), fixed, zeta, coefficients)
    flat = w < 1
    if flat.any():
        e2 = _horizontal_unit(velocity, normal)
        size = np.hypot(unit[..., 0], unit[..., 1])
        turning = np.zeros_like(fixed)
        turning[..., :2] = ((np.eye(2) - e2[..., :, None] * e2[..., None, :])
                            / np.where(size > 0, size, 1.0)[..., None, None])
        turning[size == 0] = 0.0
        own, own_slope = _stress_slope(normal, unit, e2, turning, zeta, coefficients)
        stress = np.where(flat[..., None], w[..., None] * stress + (1 - w)[..., None] * own, stress)
        slope = np.where(flat[..., None, None], w[..., None, None] * slope + (1 - w)[..., None, None] * own_slope,
                         slope)
    leading = (np.einsum("...i,...i", normal, velocity) > 0) & (np.asarray(depth) > 0)
    scale = np.where(leading, np.asarray(area) * np.asarray(depth), 0.0)
    across = (np.eye(3) - unit[..., :, None] * unit[..., None, :]) / safe[..., None, None]
    return scale[..., None] * stress, scale[..., None, None] * (slope @ across)


def medium_parameters(medium) -> tuple[float, Coefficients]:
    """zeta and the coefficients of a catalogued medium (`finrft.media.Material`): its own coefficient set if it
    has one (else the generic set), scaled by its zeta if it has one (else 1)."""
    zeta, own = medium.get("zeta"), medium.get("li2013_coefficients")
    if zeta is None and own is None:
        raise SceneError(f"medium {medium.name!r} has neither zeta nor li2013_coefficients (not found in the "
                         f"literature searched), so the li2013 law cannot use it")
    if own is not None and len(own.value) != len(GENERIC.values()):
        raise SceneError(f"medium {medium.name!r}: li2013_coefficients must be {len(GENERIC.values())} numbers "
                         f"(A00 A10 B11 B01 B-11 C11 C01 C-11 D10), got {len(own.value)}")
    if zeta is not None and not zeta.value > 0:
        raise SceneError(f"medium {medium.name!r}: zeta must be > 0, got {zeta.value!r}")
    return (1.0 if zeta is None else zeta.value), (GENERIC if own is None else Coefficients.per_cm3(*own.value))


def given(section: Any) -> dict[str, float | None]:
    """The law's parameters a scene's ``[medium]`` gives (None: not given, the named medium's): zeta, unless it is
    left at its default beside a medium.name."""
    return {"zeta": None if section.name and section.zeta == KEYS[0][2].default else section.zeta}


def catalogued(medium) -> tuple[dict[str, float], Coefficients]:
    """The parameters and coefficients a catalogued medium (`finrft.media.Material`) gives: `medium_parameters`."""
    zeta, coefficients = medium_parameters(medium)
    return {"zeta": zeta}, coefficients


# zeta above it is a value in N/m^3 (1e6 times larger) rather than a medium: the catalogue's lie within 0.3..3.1.
MAX_ZETA = 100.0


def checked(parameters: dict[str, float | None], where: str, shown: dict[str, str]) -> dict[str, float]:
    """The law's parameters, zeta 1 when not given; SceneError beginning with ``where`` for a bad one, named as in
    ``shown``."""
    zeta = 1.0 if parameters.get("zeta") is None else parameters["zeta"]
    if not (math.isfinite(zeta) and zeta > 0):
        raise SceneError(f"{where}: {shown.get('zeta', 'zeta')} must be > 0, got {zeta!r}")
    if zeta > MAX_ZETA:
        raise SceneError(f"{where}: {shown.get('zeta', 'zeta')} = {zeta:g} N/cm^3 is more than {MAX_ZETA:g} N/cm^3, "
                         f"{MAX_ZETA / 3:.0f} times the hardest catalogued medium's: a value in N/m^3 is 1e6 times "
                         f"larger; give zeta in N/cm^3 (\"6e5 N/m3\" reads as 0.6)")
    return {"zeta": float(zeta)}


def config(parameters: dict[str, float]) -> dict[str, str]:
    """The native plugin's scale: zeta."""
    return {"zeta": repr(parameters["zeta"])}


# The stress map's grid: Li 2013 Fig. 2's range, both angles in [-90, 90] deg, at 5 deg.
MAP_DEG = np.arange(-90, 91, 5)
MAP_UNITS = {"alpha_x": "N/cm^3", "alpha_z": "N/cm^3"}


def stress_map(medium) -> dict[str, np.ndarray]:
    """alpha_x and alpha_z (N/cm^3) of a catalogued medium over its grid (beta_deg, gamma_deg), flat arrays,
    beta the outer index: the law's picture, as in Li 2013 Fig. 2."""
    zeta, coefficients = medium_parameters(medium)
    beta, gamma = (a.ravel().astype(float) for a in np.meshgrid(MAP_DEG, MAP_DEG, indexing="ij"))
    alpha_x, alpha_z = alpha(np.radians(beta), np.radians(gamma), zeta, coefficients)
    return {"beta_deg": beta, "gamma_deg": gamma, "alpha_x": alpha_x / N_PER_CM3, "alpha_z": alpha_z / N_PER_CM3}
