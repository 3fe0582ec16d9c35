"""The dynamic inertial correction of DRFT, a rate-dependent term added on top of a surface law (`li2013` or
`rft3d`), in SI units.

Agarwal, Karsai, Goldman & Kamrin, "Surprising simplicity in the modeling of dynamic granular intrusion",
Sci. Adv. 7:eabe0631 (2021), write the traction on a surface element (their Eq. 5)

    t = alpha(beta, gamma) H(-z) |z| - n lambda rho v_n^2

with n the element's outward unit normal, v_n = n . v its normal speed, rho the medium's density (they take
rho ~ rho_c, the critical density: 638 kg/m^3 for their poppy seeds, with lambda = 1) and lambda an O(1) fitted
scalar; the term is the reaction to the momentum the intruder hands to the grains, a dynamic pressure going as
rho A v_n^2. This module is that second term: the force

    dF = -lambda rho_c (n . v)^2 n dA

on each element that the quasi-static law counts, leading (n . v > 0) and below the free surface. It opposes the
element's normal motion, so it dissipates: dF . v = -lambda rho_c (n . v)^3 dA <= 0. On a horizontal plate of area
A pushed straight down at speed v it adds lambda rho_c v^2 A upwards, whatever the depth.

Read in a public text transcription of the paper (its Eqs. 4-5 and the text around them), not in the journal's
own copy. Two choices are this module's, not the paper's: the paper's formula carries no H(-z) on the inertial
term, and trailing elements would feel it too (pushing them along their motion, feeding energy in); here only
submerged leading elements take it, the elements the quasi-static law and the paper's leading-edge hypothesis
count. The paper's full DRFT (Eq. 4) also lowers the free surface behind a fast intruder (the "dynamic structural
correction", fitted to wheels); that part is not implemented. The default lambda = 0 leaves the quasi-static law
unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError

KIND = "surface-term"  # added on top of any surface law, not a law of its own


def element_forces(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   drft_lambda: float, rho_c: float) -> np.ndarray:
    """The inertial force (N, 3), world frame, on surface elements with outward unit normals (N, 3), velocities
    (N, 3, m/s), depths below the free surface (N, m; <= 0 above it) and areas (N, m^2), in a medium of density
    rho_c (kg/m^3), scaled by the dimensionless drft_lambda."""
    normal = np.asarray(normal, dtype=float)
    v_n = np.einsum("...i,...i", normal, np.asarray(velocity, dtype=float))
    leading = (v_n > 0) & (np.asarray(depth) > 0)
    pressure = np.where(leading, drft_lambda * rho_c * v_n * v_n * np.asarray(area), 0.0)
    return -pressure[..., None] * normal


def element_slopes(normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   drft_lambda: float, rho_c: float) -> np.ndarray:
    """The derivative of `element_forces` in the velocity (N, 3, 3): -2 drft_lambda rho_c (n . v) area n n^T on a
    leading element below the surface, else 0."""
    normal = np.asarray(normal, dtype=float)
    v_n = np.einsum("...i,...i", normal, np.asarray(velocity, dtype=float))
    leading = (v_n > 0) & (np.asarray(depth) > 0)
    rate = np.where(leading, 2 * drft_lambda * rho_c * v_n * np.asarray(area), 0.0)
    return -rate[..., None, None] * normal[..., :, None] * normal[..., None, :]


def density(drft_lambda: float, given: float | None, catalogued: float | None, key: str, where: str) -> float:
    """The density the term uses (kg/m^3; 0 when none is known and the term is off): ``given`` if set, else
    the catalogued medium's. Bad values, or drft_lambda > 0 without a density: SceneError beginning with
    ``where`` and naming ``key``, what the user sets."""
    if not (math.isfinite(drft_lambda) and drft_lambda >= 0):
        raise SceneError(f"{where}: drft_lambda must be >= 0, got {drft_lambda!r}")
    rho = given if given is not None else catalogued
    if rho is not None and not (math.isfinite(rho) and rho > 0):
        raise SceneError(f"{where}: {key} must be > 0 kg/m^3, got {rho!r}")
    if drft_lambda > 0 and rho is None:
        raise SceneError(f"{where}: drft_lambda > 0 needs the medium's bulk density: set {key} (kg/m^3; the "
                         f"li2013 media have none)")
    return 0.0 if rho is None else float(rho)
