"""The three-dimensional granular RFT of Agarwal, Goldman & Kamrin, "Mechanistic framework for reduced-order models
in soft materials: Application to three-dimensional granular intrusion", PNAS 120:e2214017120 (2023), in SI units.

A surface element of area dA at depth |z| below the free surface, leading the motion (outward normal n, n . v > 0),
feels the stress alpha |z| per unit area, alpha = xi_n alpha_gen, capped by the intruder's surface friction:

    xi_n = rho_c g (894 mu_int^3 - 386 mu_int^2 + 89 mu_int)                     N/m^3
    p1 = sin gamma,  p2 = cos beta,  p3 = cos psi cos gamma sin beta + sin gamma cos beta
    f_k = sum_i c_k,i T_i(p1, p2, p3)    (k = 1, 2, 3; T_i the 20 monomials of `terms`)
    alpha_gen = (f1 sin beta cos psi + f2 cos gamma,  f1 sin beta sin psi,  -f1 cos beta - f2 sin gamma - f3)

in the local frame (r, theta, z): z up, r the horizontal direction of the velocity, theta = z x r. gamma is the
velocity's angle below the horizontal (> 0 moving down), beta the tilt of the plate from horizontal and psi the
azimuth of its normal's horizontal projection from r, both of the plate's lower face: n_low = (sin beta cos psi,
sin beta sin psi, -cos beta), beta in [-pi/2, pi/2], psi in (-pi/2, pi/2]. The lower face is the outward normal
when that points down and the opposite face otherwise (a vertical face included), as both public implementations
define beta (KKKobefeng/3D-RFT `RFT3Dfunc.m`, jnskkmhr/IsaacLab `RFT_3D`, citing the paper's SI S7 eqs. 5-7).

In these angles p1 = -v_z, p2 = -n_low_z, p3 = n_low . v (unit v) and alpha_gen = f1 n_low + f2 v - f3 z: the law
needs no frame, which is how `element_forces` evaluates it. The surface-friction cap keeps the normal part
alpha_n = (alpha . n) n and scales the tangential part alpha_t = alpha - alpha_n by min(1, mu_surf |alpha_n| /
|alpha_t|).

Coefficients: the two public transcriptions of the paper's table disagree in two entries, c2 of T_17 = p3 p2^2 and
c3 of T_16 = p2 p3^2. AGARWAL_2023 takes both from KKKobefeng/3D-RFT `src/RFT3Dfunc.m` (c2,17 = 0.18589, c3,16 =
-0.02730); jnskkmhr/IsaacLab `soft_contact_model.py` (`Material3DRFTCfg`) has 0.18519 and -0.20770. With psi = 0 the
law is a 2D RFT in the plane of motion, which should be that of Li et al. 2013: over beta, gamma in [-90, 90] deg
its alpha_z departs from Li's generic fit by 0.123 (rms, in units of a horizontal plate pushed down) with -0.02730
and by 0.155 with -0.20770, and the latter has the wrong sign of alpha_z on half of the extraction quadrant where
Li's |alpha_z| > 0.1 (14 % with -0.02730); -0.20770 also pushes a horizontal plate pulled straight up upwards
(alpha_z = +0.101), feeding energy in. Both sets leave alpha_r 0.077 (rms) from Li's; neither is Li's fit to
better than about 0.1. The c2 entries differ by 7e-4, below what either test resolves. A horizontal plate pushed
straight down has every T_i = 1 and alpha_gen = (0, 0, -sum(c1 + c2 + c3)): 0.87504 with AGARWAL_2023, 1.05614 with
the IsaacLab set. tests/test_rft3d.py measures all of these.

Not dissipative everywhere: the fit's normal stress pulls outward (alpha . n > 0) on about 5 % of leading (normal,
velocity) pairs drawn uniformly, all grazing (n . v below 0.2 of the speed). With mu_surf = 0 the force is that
normal stress alone and feeds energy in there; with mu_surf >= 0.2 the tangential part outweighs it but on about
0.06 % of pairs (upward-facing faces rising at n . v below 0.33 of the speed). The power fed in is at most 0.8 % of
that of a horizontal plate pushed down at the same speed (tests/test_rft3d.py).

`stress_map` (``finrft law rft3d``) draws alpha_x = -alpha_r and alpha_z in the vertical plane (psi = 0, Li 2013's
axes), before the friction cap, for a catalogued medium's xi_n; the generic medium, which has no bulk density nor
internal friction, is drawn at xi_n = 1 N/cm^3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import SceneError
from ..schema import field

KIND = "surface"
STANDARD_GRAVITY = 9.81  # m/s^2, g of xi_n
# The law's parameters of the medium and the intruder (`finrft.attach` takes them by these names), and the [medium]
# key of each.
PARAMETERS = ("rho_c", "mu_int", "mu_surf")
SECTION_KEYS = {"rho_c": "bulk_density", "mu_int": "internal_friction", "mu_surf": "surface_friction"}
DENSITY = "rho_c"  # the parameter that is the medium's bulk density (DRFT's too)
# The law's own keys of a scene's [medium] (`finrft.scene.Medium` is built from every surface law's); rho_c is its
# medium.bulk_density.
KEYS = (("internal_friction", float, field(0.0, "", "rft3d: the medium's internal friction coefficient mu_int (tan "
                                           "of its internal friction angle); 0: the named medium's", minimum=0.0,
                                           exclusive=False)),
        ("surface_friction", float, field(0.0, "", "rft3d: friction coefficient mu_surf between the bodies and the "
                                          "grains; 0: the named medium's, if it catalogues one, else frictionless",
                                          minimum=0.0, exclusive=False)))
# The parameters that are the intruder's rather than the medium's: a value given overrides the catalogue's (which
# holds the one of the intruder its source measured), where for the medium's own the two may not both be given.
INTRUDER = ("mu_surf",)

# Why the published fit can feed energy in (tests/test_rft3d.py measures it): `attach` says so once.
FEEDS_ENERGY = ("its fitted normal stress pulls outward on about 5 % of grazing leading faces (n.v < 0.2 |v|), "
                "0.06 % with mu_surf >= 0.2, at most 0.8 % of the power of a plate pushed down")


@dataclass(frozen=True)
class Coefficients:
    """The fit's coefficients c1, c2, c3 (20 each, dimensionless), in the order of `terms`."""

    c1: tuple[float, ...]
    c2: tuple[float, ...]
    c3: tuple[float, ...]

    def __post_init__(self) -> None:
        if not all(len(c) == 20 for c in (self.c1, self.c2, self.c3)):
            raise ValueError("rft3d coefficients: c1, c2 and c3 take 20 values each")

    def values(self) -> tuple[float, ...]:
        """c1, c2, c3 in one flat tuple of 60."""
        return (*self.c1, *self.c2, *self.c3)

    def matrix(self) -> np.ndarray:
        """(20, 3): column k holds c_k."""
        return np.array([self.c1, self.c2, self.c3]).T


AGARWAL_2023 = Coefficients(
    c1=(0.00212, -0.02320, -0.20890, -0.43083, -0.00259, 0.48872, -0.00415, 0.07204, -0.02750, -0.08772,
        0.01992, -0.45961, 0.40799, -0.10107, -0.06576, 0.05664, -0.09269, 0.01892, 0.01033, 0.15120),
    c2=(-0.06796, -0.10941, 0.04725, -0.06914, -0.05835, -0.65880, -0.11985, -0.25739, -0.26834, 0.02692,
        -0.00736, 0.63758, 0.08997, 0.21069, 0.04748, 0.20406, 0.18589, 0.04934, 0.13527, -0.33207),
    c3=(-0.02634, -0.03436, 0.45256, 0.00835, 0.02553, -1.31290, -0.05532, 0.06790, -0.16404, 0.02287,
        0.02927, 0.95406, -0.00131, -0.11028, 0.01487, -0.02730, 0.10911, -0.04097, 0.07881, -0.27519),
)
DEFAULT = AGARWAL_2023  # the coefficients unless others are given


def terms(p1, p2, p3) -> np.ndarray:
    """The 20 monomials T_i (..., 20): 1, p1, p2, p3, p1^2, p2^2, p3^2, p1p2, p2p3, p3p1, p1^3, p2^3, p3^3,
    p1p2^2, p2p1^2, p2p3^2, p3p2^2, p3p1^2, p1p3^2, p1p2p3."""
    p1, p2, p3 = np.broadcast_arrays(*(np.asarray(p, dtype=float) for p in (p1, p2, p3)))
    return np.stack([np.ones_like(p1), p1, p2, p3, p1 * p1, p2 * p2, p3 * p3, p1 * p2, p2 * p3, p3 * p1,
                     p1 ** 3, p2 ** 3, p3 ** 3, p1 * p2 * p2, p2 * p1 * p1, p2 * p3 * p3, p3 * p2 * p2,
                     p3 * p1 * p1, p1 * p3 * p3, p1 * p2 * p3], axis=-1)


def xi(rho_c: float, mu_int: float, gravity: float = STANDARD_GRAVITY) -> float:
    """The medium's scale xi_n, N/m^3, from its critical (bulk) density rho_c (kg/m^3) and internal friction."""
    return rho_c * gravity * (894 * mu_int ** 3 - 386 * mu_int ** 2 + 89 * mu_int)


def alpha_gen(beta, gamma, psi, coefficients: Coefficients = AGARWAL_2023) -> np.ndarray:
    """The generic stress (..., 3) in the local frame (r, theta, z), before the friction cap, for the plate angles
    beta, psi and the velocity angle gamma (radians, see the module's conventions)."""
    beta, gamma, psi = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (beta, gamma, psi)))
    sb, cb, sg, cg = np.sin(beta), np.cos(beta), np.sin(gamma), np.cos(gamma)
    f1, f2, f3 = np.moveaxis(terms(sg, cb, np.cos(psi) * cg * sb + sg * cb) @ coefficients.matrix(), -1, 0)
    return np.stack([f1 * sb * np.cos(psi) + f2 * cg, f1 * sb * np.sin(psi), -f1 * cb - f2 * sg - f3], axis=-1)


def angles(normal: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(beta, gamma, psi) of elements with outward unit normals (..., 3) and velocities (..., 3), world frame, z
    up. r is the horizontal direction of the velocity; of the normal if the velocity is vertical; x if both are."""
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    lower = np.where((normal[..., 2] < 0)[..., None], normal, -normal)
    horizontal = np.hypot(velocity[..., 0], velocity[..., 1])
    sideways = np.hypot(normal[..., 0], normal[..., 1])
    reference = np.where((horizontal > 0)[..., None], velocity, normal)[..., :2]
    length = np.where(horizontal > 0, horizontal, sideways)
    r = np.where((length > 0)[..., None], reference / np.where(length > 0, length, 1.0)[..., None], [1.0, 0.0])
    theta = np.stack([-r[..., 1], r[..., 0]], axis=-1)
    n_r = np.einsum("...i,...i", lower[..., :2], r)
    n_t = np.einsum("...i,...i", lower[..., :2], theta)
    # beta takes the sign that keeps psi in (-pi/2, pi/2]
    sign = np.where((n_r < 0) | ((n_r == 0) & (n_t < 0)), -1.0, 1.0)
    beta = sign * np.arctan2(np.hypot(n_r, n_t), -lower[..., 2])
    psi = np.arctan2(sign * n_t, sign * n_r)
    gamma = np.arctan2(-velocity[..., 2], np.einsum("...i,...i", velocity[..., :2], r))
    return beta, gamma, psi


def element_forces(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray, rho_c: float,
                   mu_int: float, mu_surf: float, coefficients: Coefficients = AGARWAL_2023) -> np.ndarray:
    """The force (N, 3), world frame, z up, on surface elements with outward unit normals (N, 3), velocities
    (N, 3, m/s), depths below the free surface (N, m; <= 0 above it) and areas (N, m^2), in a medium of critical
    density rho_c (kg/m^3) and internal friction mu_int, the intruder's surface friction being mu_surf. Only
    leading elements (n . v > 0) below the surface feel the medium."""
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(velocity, axis=-1)
    unit = velocity / np.where(speed > 0, speed, 1.0)[..., None]
    lower = np.where((normal[..., 2] < 0)[..., None], normal, -normal)
    p3 = np.einsum("...i,...i", lower, unit)
    f = terms(-unit[..., 2], -lower[..., 2], p3) @ coefficients.matrix()
    stress = f[..., :1] * lower + f[..., 1:2] * unit
    stress[..., 2] -= f[..., 2]
    normal_part = np.einsum("...i,...i", stress, normal)[..., None] * normal
    tangential = stress - normal_part
    cap = mu_surf * np.linalg.norm(normal_part, axis=-1)
    size = np.linalg.norm(tangential, axis=-1)
    stress = normal_part + np.where(size > cap, cap / np.where(size > 0, size, 1.0), 1.0)[..., None] * tangential
    leading = (np.einsum("...i,...i", normal, velocity) > 0) & (np.asarray(depth) > 0)
    scale = np.where(leading, xi(rho_c, mu_int) * np.asarray(area) * np.asarray(depth), 0.0)
    return scale[..., None] * stress


def term_slopes(p1, p2, p3) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of `terms` (..., 20) in p1 and in p3 (p2, the face's, does not move with the velocity)."""
    p1, p2, p3 = np.broadcast_arrays(*(np.asarray(p, dtype=float) for p in (p1, p2, p3)))
    zero, one = np.zeros_like(p1), np.ones_like(p1)
    d1 = np.stack([zero, one, zero, zero, 2 * p1, zero, zero, p2, zero, p3, 3 * p1 * p1, zero, zero, p2 * p2,
                   2 * p1 * p2, zero, zero, 2 * p1 * p3, p3 * p3, p2 * p3], axis=-1)
    d3 = np.stack([zero, zero, zero, one, zero, zero, 2 * p3, zero, p2, p1, zero, zero, 3 * p3 * p3, zero, zero,
                   2 * p2 * p3, p2 * p2, p1 * p1, 2 * p1 * p3, p1 * p2], axis=-1)
    return d1, d3


def element_slopes(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray, rho_c: float,
                   mu_int: float, mu_surf: float, coefficients: Coefficients = AGARWAL_2023
                   ) -> tuple[np.ndarray, np.ndarray]:
    """`element_forces` (N, 3) and each force's derivative in the velocity, dF/dv (N, 3, 3; row: the force's
    component), analytic: the twin of finrft_rft3d_element_slope. With u = v / |v|, p1 = -u_z and p3 = n_low . u
    move with it, so d f_k / du = -(dT/dp1 . c_k) z + (dT/dp3 . c_k) n_low; the friction cap's factor
    kept = mu_surf |s_n| / |s_t| moves with the stress; dF/dv = dF/du (I - u u^T) / |v|."""
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(velocity, axis=-1)
    safe = np.where(speed > 0, speed, 1.0)
    unit = velocity / safe[..., None]
    lower = np.where((normal[..., 2] < 0)[..., None], normal, -normal)
    p1, p2, p3 = -unit[..., 2], -lower[..., 2], np.einsum("...i,...i", lower, unit)
    matrix = coefficients.matrix()
    f = terms(p1, p2, p3) @ matrix
    d1, d3 = term_slopes(p1, p2, p3)
    z = np.array([0.0, 0.0, 1.0])
    df = -(d1 @ matrix)[..., :, None] * z + (d3 @ matrix)[..., :, None] * lower[..., None, :]  # (..., k, 3)
    stress = f[..., :1] * lower + f[..., 1:2] * unit
    stress[..., 2] -= f[..., 2]
    d_stress = (lower[..., :, None] * df[..., 0, None, :] + unit[..., :, None] * df[..., 1, None, :]
                + f[..., 1, None, None] * np.eye(3) - z[:, None] * df[..., 2, None, :])
    along = np.einsum("...i,...i", stress, normal)
    d_along = np.einsum("...i,...ik->...k", normal, d_stress)
    normal_part = along[..., None] * normal
    tangential = stress - normal_part
    d_normal = normal[..., :, None] * d_along[..., None, :]
    cap = mu_surf * np.abs(along)
    size = np.linalg.norm(tangential, axis=-1)
    capped = size > cap
    kept = np.where(capped, cap / np.where(size > 0, size, 1.0), 1.0)
    # d kept = (mu_surf sign(s_n) d s_n - kept t . d s / |t|) / |t|, t being across n
    d_kept = np.where(capped[..., None], (mu_surf * np.sign(along)[..., None] * d_along
                                          - (kept / np.where(size > 0, size, 1.0))[..., None]
                                          * np.einsum("...i,...ik->...k", tangential, d_stress))
                      / np.where(size > 0, size, 1.0)[..., None], 0.0)
    out = normal_part + kept[..., None] * tangential
    d_out = d_normal + kept[..., None, None] * (d_stress - d_normal) + tangential[..., :, None] * d_kept[..., None, :]
    leading = (np.einsum("...i,...i", normal, velocity) > 0) & (np.asarray(depth) > 0)
    scale = np.where(leading, xi(rho_c, mu_int) * np.asarray(area) * np.asarray(depth), 0.0)
    across = (np.eye(3) - unit[..., :, None] * unit[..., None, :]) / safe[..., None, None]
    return scale[..., None] * out, scale[..., None, None] * (d_out @ across)


def given(section: Any) -> dict[str, float | None]:
    """The law's parameters a scene's ``[medium]`` gives (None: not given, the named medium's): surface_friction =
    0 beside a medium.name is the medium's, without one frictionless (one meaning, as a chain's [medium])."""
    return {"rho_c": section.bulk_density or None, "mu_int": section.internal_friction or None,
            "mu_surf": None if section.name and not section.surface_friction else section.surface_friction}


def catalogued(medium) -> tuple[dict[str, float], None]:
    """The parameters a catalogued medium (`finrft.media.Material`) gives: rho_c, its bulk density, mu_int, the
    tangent of its internal friction angle, and mu_surf, the friction of the intruder its source measured (a value
    given overrides it: `INTRUDER`), those it has; no coefficients."""
    rho, angle, mu = medium.get("bulk_density"), medium.get("internal_friction_angle"), medium.get("surface_friction")
    found = {} if mu is None else {"mu_surf": mu.value}
    if rho is not None:
        found["rho_c"] = rho.value
    if angle is not None:
        found["mu_int"] = math.tan(angle.value)
    return found, None


def checked(parameters: dict[str, float | None], where: str, shown: dict[str, str]) -> dict[str, float]:
    """The law's parameters, all three required; SceneError beginning with ``where`` for a missing or bad one,
    named as in ``shown``."""
    for key in PARAMETERS:
        value, name = parameters.get(key), shown.get(key, key)
        if value is None:
            raise SceneError(f"{where}: law rft3d needs {name}")
        if not math.isfinite(value) or value < 0 or (value == 0 and key != "mu_surf"):
            raise SceneError(f"{where}: {name} must be {'>= 0' if key == 'mu_surf' else '> 0'}, got {value!r}")
    return {key: float(parameters[key]) for key in PARAMETERS}  # xi_n > 0 for every mu_int > 0


def config(parameters: dict[str, float]) -> dict[str, str]:
    """The native plugin's scale xi_n and the surface friction."""
    return {"xi": repr(xi(parameters["rho_c"], parameters["mu_int"])), "mu_surf": repr(parameters["mu_surf"])}


# The stress map's grid: the vertical plane (psi = 0), as Li 2013 Fig. 2, both angles in [-90, 90] deg at 5 deg.
MAP_DEG = np.arange(-90, 91, 5)
MAP_UNITS = {"alpha_x": "N/cm^3", "alpha_z": "N/cm^3"}
N_PER_CM3 = 1e6  # N/m^3 in one N/cm^3
GENERIC = "generic"  # the catalogue's generic medium, mapped at xi_n = 1 N/cm^3


def medium_xi(medium) -> float:
    """xi_n (N/m^3) of a catalogued medium (`finrft.media.Material`), from its bulk density and internal friction
    angle; the generic medium, which has neither, takes 1 N/cm^3 (its map is alpha_gen in units of xi_n)."""
    rho, angle = medium.get("bulk_density"), medium.get("internal_friction_angle")
    if rho is not None and angle is not None:
        return xi(rho.value, math.tan(angle.value))
    if medium.name == GENERIC:
        return N_PER_CM3
    missing = [key for key, value in (("bulk_density", rho), ("internal_friction_angle", angle)) if value is None]
    raise SceneError(f"medium {medium.name!r} has no {' nor '.join(missing)} (not found in the literature searched), "
                     f"so the rft3d law cannot scale its stress (xi_n)")


def map_note(medium) -> str:
    """What the map's scale is, in one line."""
    if medium.get("bulk_density") is None or medium.get("internal_friction_angle") is None:
        return "xi_n = 1 N/cm^3 (no bulk density nor internal friction catalogued): alpha_gen in units of xi_n"
    return f"xi_n = {medium_xi(medium) / N_PER_CM3:.4g} N/cm^3 from the bulk density and internal friction"


def stress_map(medium) -> dict[str, np.ndarray]:
    """alpha_x and alpha_z (N/cm^3) of a catalogued medium in the vertical plane (psi = 0) over the grid
    (beta_deg, gamma_deg), flat arrays, beta the outer index, in Li 2013's axes (x = -r: alpha_x > 0 resists a
    horizontal motion) and before the surface-friction cap (the intruder's, not the medium's)."""
    scale = medium_xi(medium) / N_PER_CM3
    beta, gamma = (a.ravel().astype(float) for a in np.meshgrid(MAP_DEG, MAP_DEG, indexing="ij"))
    alpha = alpha_gen(np.radians(beta), np.radians(gamma), 0.0)
    return {"beta_deg": beta, "gamma_deg": gamma, "alpha_x": -scale * alpha[:, 0], "alpha_z": scale * alpha[:, 2]}
