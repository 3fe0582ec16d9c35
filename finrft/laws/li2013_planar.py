"""The planar form of the Li, Zhang & Goldman 2013 law (`finrft.laws.li2013` for the fit, its coefficients and its
conventions): each element is a plate in the vertical plane of its own velocity, as in the paper's 2D experiments.

Its horizontal force is always anti-parallel to the element's horizontal velocity: it has no force across an
element's plane of motion, so an undulating body (a sand-swimmer) gets no thrust from it (wave efficiency about
0.0005 against 0.3 with the 3D form). `li2013`, the 3D form of Treers, Cao & Stuart 2021, gives those lateral
forces; this form is kept, by the name ``li2013-planar``, to reproduce runs made with it, and `finrft.attach`
warns once per process that it cannot swim (`CAVEAT`). A body moving in one vertical plane (a plate pushed down
or dragged normal to its face, a wheel without slip angle) feels the same from both forms but for the 3D form's
weight f23(1) = 1 (to 4e-16).
"""

from __future__ import annotations

import numpy as np

from .li2013 import (DEFAULT, DENSITY, FEEDS_ENERGY, GENERIC, PARAMETERS, SECTION_KEYS, Coefficients, alpha,
                     catalogued, checked, config, given)

KIND = "surface"
NAME = "li2013-planar"  # the law's name (a module name cannot hold a hyphen)
SUMMARY = "Li 2013 in the vertical plane of each element's velocity (no force across it: cannot swim)"
# The [medium] keys are li2013's (zeta): declared there once.
KEYS = ()
# What `finrft.attach` warns of, once per process, when the law is chosen.
CAVEAT = ("li2013-planar has no force across an element's plane of motion, so an undulating body gets no thrust "
          "(use li2013, its 3D form, or rft3d to swim)")
__all__ = ["DEFAULT", "DENSITY", "FEEDS_ENERGY", "GENERIC", "PARAMETERS", "SECTION_KEYS", "Coefficients",
           "catalogued", "checked", "config", "given", "element_forces"]

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
