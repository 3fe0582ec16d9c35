"""The robot's faces in its medium: the arm's law and the body's resistance from 3D-RFT (`finrft.media`).

When the scene's ``[medium]`` gives the bulk density, internal and surface friction (and the fins' height),
every force on the robot follows from one derivation, 3D-RFT on vertical faces whose top edges are at
``medium.depth`` (`finrft.media.plate_forces`, Agarwal, Goldman & Kamrin 2023):

- each fin segment: the sand-swimming law fitted to it (fin.segment_length x medium.height), which the scene takes
  from its medium unless [rft] gives c_s, c_f and gamma0 (`finrft.scene`);
- each arm: the same law fitted to arm.length x arm.height;
- the body: 3D-RFT's force on the box body.width x body.length x body.height moving along its axis, plus the
  cart's rolling resistance body.cart; the half robot carries half. In 3D-RFT only the leading front face resists:
  the sides slide along themselves and take nothing.

The body's top and bottom faces are left out: horizontal faces sliding horizontally feel only the surface friction
times the overburden, mu_surf rho g z W L (0.18 N on the top face under 10 mm of beads, 1.0 N on the bottom one at
55 mm, with the preset's estimates), which 3D-RFT on vertical faces does not describe.
"""

from __future__ import annotations

import functools

import numpy as np

from . import media
from .scene import RFT, RobotScene


def properties(scene: RobotScene) -> tuple[float, float, float] | None:
    """The medium's bulk density, internal and surface friction when the scene's [medium] gives them (the robot's
    forces then come from it), None otherwise (the paper preset: each group's coefficients as given)."""
    return media.immersion_properties(scene.medium)


def arm_law(scene: RobotScene) -> RFT:
    """The law of one arm: the sand-swimming law fitted to 3D-RFT on the arm's face."""
    a, m = scene.arm, scene.medium
    fit = media.sandswim_coefficients(a.length, m.depth, a.height, *properties(scene))
    return RFT(law="sandswim", c_s=fit.c_s, c_f=fit.c_f, gamma0=fit.gamma0, v_reg=scene.rft.v_reg)


def body_resistance(scene: RobotScene) -> dict[str, float]:
    """The whole robot's body resistance (N): ``faces`` (3D-RFT on the body moving along its axis), ``cart``
    (rolling) and their ``total``."""
    b = scene.body
    faces = _along_axis(b.length, scene.medium.depth, b.height, b.width, properties(scene))
    return {"faces": faces, "cart": b.cart, "total": faces + b.cart}


@functools.lru_cache(maxsize=256)
def _along_axis(length: float, depth: float, height: float, width: float,
                medium: tuple[float, float, float]) -> float:
    """3D-RFT's resistance (N) of a box moving along its axis: every gait evaluation builds the robot with it, and
    it costs a tenth of one."""
    _, along = media.plate_forces(np.zeros(1), length, depth, height, *medium, thickness=width)
    return float(along[0])
