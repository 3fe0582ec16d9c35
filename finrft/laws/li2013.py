"""The granular RFT law of Li, Zhang & Goldman, "A terradynamics of legged locomotion on granular media",
Science 339:1408 (2013), in SI units: stresses per unit depth in N/m^3 (1 N/cm^3 = 1e6 N/m^3).

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
from dataclasses import astuple, dataclass
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
KEYS = (("zeta", float, field(1.0, "", "li2013: the medium's scale: alpha_z of a horizontal plate pushed down, in "
                              "N/cm^3 (the generic coefficients are scaled by it; only without medium.name)",
                              minimum=0.0)),)


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
        return astuple(self)


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


# Below this fraction of the speed, a velocity's horizontal part is taken as none (the motion is vertical).
VERTICAL = 1e-12


def element_forces(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   zeta: float = 1.0, coefficients: Coefficients = GENERIC) -> np.ndarray:
    """The force (N, 3), world frame, z up, on surface elements with outward unit normals (N, 3), velocities
    (N, 3, m/s), depths below the free surface (N, m; <= 0 above it) and areas (N, m^2).

    Each element is a plate in the vertical plane of its velocity: r = the horizontal direction of the velocity
    (if the velocity is vertical, that of the normal; if both are vertical, any: the force is then vertical).
    The normal's projection n_p onto that plane gives beta, the velocity gives gamma, and the element takes
    alpha |z| dA |n_p|: |n_p| dA is the element's share of the plane's slices, as when the 2D law is integrated
    over a body's width, so a face parallel to the plane of motion takes nothing. Only leading elements (n . v > 0)
    below the surface feel the medium.
    """
    normal = np.asarray(normal, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    horizontal = np.hypot(velocity[..., 0], velocity[..., 1])
    moving_sideways = horizontal > VERTICAL * np.linalg.norm(velocity, axis=-1)
    normal_sideways = np.hypot(normal[..., 0], normal[..., 1])
    reference = np.where(moving_sideways[..., None], velocity, normal)[..., :2]
    length = np.where(moving_sideways, horizontal, normal_sideways)
    r = np.where((length > 0)[..., None], reference / np.where(length > 0, length, 1.0)[..., None], [1.0, 0.0])
    n_r = np.einsum("...i,...i", normal[..., :2], r)
    n_z = normal[..., 2]
    v_r = np.einsum("...i,...i", velocity[..., :2], r)
    beta = np.arctan2(-n_r, n_z)  # the paper's x axis is -r
    gamma = np.arctan2(-velocity[..., 2], v_r)
    alpha_x, alpha_z = alpha(beta, gamma, zeta, coefficients)
    leading = (np.einsum("...i,...i", normal, velocity) > 0) & (np.asarray(depth) > 0)
    scale = np.where(leading, np.asarray(area) * np.asarray(depth) * np.hypot(n_r, n_z), 0.0)
    force = np.empty(normal.shape)
    force[..., :2] = -(scale * alpha_x)[..., None] * r
    force[..., 2] = scale * alpha_z
    return force


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


def checked(parameters: dict[str, float | None], where: str, shown: dict[str, str]) -> dict[str, float]:
    """The law's parameters, zeta 1 when not given; SceneError beginning with ``where`` for a bad one, named as in
    ``shown``."""
    zeta = 1.0 if parameters.get("zeta") is None else parameters["zeta"]
    if not (math.isfinite(zeta) and zeta > 0):
        raise SceneError(f"{where}: {shown.get('zeta', 'zeta')} must be > 0, got {zeta!r}")
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
