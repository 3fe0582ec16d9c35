"""The coupling of RFT to MuJoCo.

`SegmentForces` evaluates the RFT force on every segment from MuJoCo's kinematics (the velocity of each segment's
midpoint site and the site's frame), with the pure laws of `finrft.rft`. `PythonCoupling` is the ``python``
backend: a passive-force callback that adds those forces and the penalty stop torque to ``qfrc_passive`` each time
MuJoCo evaluates passive forces (once per step, four times under RK4). The ``native`` backend does the same in the
C plugin (plugins/finrft_rft.c), bound to the model in `finrft.models`.

MuJoCo's callback is process-global; `installed` sets it for the duration of a run and restores the previous one.
"""

from __future__ import annotations

import contextlib
from typing import Callable, Iterator

import mujoco
import numpy as np

from . import rft
from .models import PlateModel
from .scene import Scene

Callback = Callable[[mujoco.MjModel, mujoco.MjData], None]


class SegmentForces:
    """The RFT force on each segment (N, 3), world frame, for MuJoCo's current kinematics."""

    def __init__(self, plate: PlateModel, scene: Scene) -> None:
        self.law = rft.force_law(scene.rft)
        self.sites = plate.seg_site
        self.bodies = plate.seg_body
        n = len(self.sites)
        self.force = np.zeros((n, 3))
        self._twist = np.zeros(6)
        self._velocity = np.zeros((n, 3))
        self._frames = np.zeros((n, 3, 3))

    def kinematics(self, m: mujoco.MjModel, d: mujoco.MjData, velocity: np.ndarray, frames: np.ndarray) -> None:
        """Fill each midpoint's world velocity (N, 3) and its site frame (N, 3, 3), the law's inputs."""
        for i, site in enumerate(self.sites):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, site, self._twist, 0)
            velocity[i] = self._twist[3:]
        frames[:] = d.site_xmat[self.sites].reshape(-1, 3, 3)

    def evaluate(self, velocity: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """The law on recorded inputs of any leading shape (..., 3) and (..., 3, 3)."""
        return self.law(velocity, frames[..., :, 0], frames[..., :, 1])

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        self.kinematics(m, d, self._velocity, self._frames)
        self.force[:] = self.evaluate(self._velocity, self._frames)
        return self.force


class PythonCoupling:
    """The ``python`` backend: RFT on each segment's midpoint site and the origami penalty stop."""

    def __init__(self, plate: PlateModel, scene: Scene) -> None:
        self.forces = SegmentForces(plate, scene)
        penalty = scene.plate.kind == "origami" and scene.plate.stop == "penalty"
        self.stop_qpos = plate.hinge_qpos if penalty else np.zeros(0, dtype=int)
        self.stop_dof = plate.hinge_dof if penalty else np.zeros(0, dtype=int)
        self.springref = scene.plate.springref
        self.stop_stiffness = scene.plate.stop_stiffness
        self._torque = np.zeros(3)

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        force = self.forces(m, d)
        for i, site in enumerate(self.forces.sites):
            mujoco.mj_applyFT(m, d, force[i], self._torque, d.site_xpos[site], int(self.forces.bodies[i]),
                              d.qfrc_passive)
        if len(self.stop_dof):
            deflection = d.qpos[self.stop_qpos] - self.springref
            d.qfrc_passive[self.stop_dof] -= self.stop_stiffness * (deflection + np.abs(deflection)) * deflection


@contextlib.contextmanager
def installed(callback: Callback | None) -> Iterator[None]:
    """Install a passive-force callback (None: none at all) for a block, then restore whatever was there."""
    previous = mujoco.get_mjcb_passive()
    mujoco.set_mjcb_passive(callback)
    try:
        yield
    finally:
        mujoco.set_mjcb_passive(previous)
