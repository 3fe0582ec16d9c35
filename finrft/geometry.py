"""The robot's granular forces from its geometry: one law for every face, scaled by the face's depth moment.

In the frictional regime the stress of a granular medium on a face grows linearly with depth (RFT), so a vertical
face of length l spanning the depths z1..z2, moving in a horizontal plane, takes the medium's stress per unit depth
times its depth moment M = l (z2^2 - z1^2) / 2 (m^3). With ``robot.forces = "geometry"`` the scene's [rft] law
gives those stresses per unit depth (its force coefficients in N/m^3) and every face takes them times its M:

- each fin segment: fin.segment_length x fin.height;
- each arm: arm.length x arm.height;
- the body: its front face (body.width x body.height) moving broadside and its two sides (body.length x
  body.height) sliding along themselves, plus the cart's rolling resistance body.cart; the half robot carries
  half of both.

Every top edge sits at robot.depth. The body slides along its axis only, so its resistance is one number, a
rate-independent force against its velocity. Its top and bottom faces are left out: horizontal faces sliding
horizontally feel only the surface friction times the overburden, mu_surf rho g z W L (with mu_surf = 0.3,
rho = 1500 kg/m^3: 0.18 N on the top face under 10 mm of beads, 1.0 N on the bottom one at 55 mm), which the
law of vertical faces does not describe; the README gives their size beside the front face's.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from . import laws
from .scene import RFT, RobotScene

# The [rft] keys that are forces (N per segment, or N/m^3 per unit depth moment); the others (gamma0, v_reg) are
# not scaled.
FORCE_KEYS = ("f_perp", "f_par", "c_s", "c_f")


def depth_moment(length: float, height: float, top: float) -> float:
    """M = l (z2^2 - z1^2) / 2 (m^3) of a vertical face of length l whose top edge is at depth ``top``."""
    return length * ((top + height) ** 2 - top ** 2) / 2


def scaled(rft: RFT, factor: float) -> RFT:
    """The law with its force coefficients times ``factor``."""
    return dataclasses.replace(rft, **{key: factor * getattr(rft, key) for key in FORCE_KEYS})


def _force(rft: RFT, along_axis: bool) -> float:
    """The force (N) of a law on a face moving fast (1e3 v_reg) broadside, or along its own axis."""
    x, y = np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    v = 1e3 * rft.v_reg * (x if along_axis else y)
    return float(np.linalg.norm(laws.bind(rft)(v, x, y)))


def broadside(rft: RFT) -> float:
    """A law's force (N) on a face moving along its normal."""
    return _force(rft, along_axis=False)


def sliding(rft: RFT) -> float:
    """A law's force (N) on a face sliding along its own axis."""
    return _force(rft, along_axis=True)


def fin_law(scene: RobotScene) -> RFT:
    """The law of one fin segment."""
    f = scene.fin
    return scaled(scene.rft, depth_moment(f.segment_length, f.height, scene.robot.depth))


def arm_law(scene: RobotScene) -> RFT:
    """The law of one arm, a single face."""
    a = scene.arm
    return scaled(scene.rft, depth_moment(a.length, a.height, scene.robot.depth))


def body_resistance(scene: RobotScene) -> dict[str, float]:
    """The whole robot's body resistance (N) and its parts: ``front`` (the front face broadside), ``sides`` (both
    side faces sliding), ``cart`` (rolling) and their ``total``."""
    b, top = scene.body, scene.robot.depth
    front = broadside(scaled(scene.rft, depth_moment(b.width, b.height, top)))
    sides = 2 * sliding(scaled(scene.rft, depth_moment(b.length, b.height, top)))
    return {"front": front, "sides": sides, "cart": b.cart, "total": front + sides + b.cart}


def magnitudes(scene: RobotScene) -> dict[str, Any]:
    """What the geometry gives (N): a fin segment and an arm broadside and sliding, the whole fin broadside, and the
    body's resistance (whole robot)."""
    fin, arm = fin_law(scene), arm_law(scene)
    return {"fin_segment_broadside_N": broadside(fin), "fin_segment_sliding_N": sliding(fin),
            "fin_broadside_N": scene.fin.segments * broadside(fin), "arm_broadside_N": broadside(arm),
            "arm_sliding_N": sliding(arm), "stress_per_depth_broadside_N_m3": broadside(scene.rft),
            "body_N": body_resistance(scene)}
