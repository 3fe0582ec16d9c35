"""The Python coupling of RFT to MuJoCo: a passive-force callback that adds the RFT force on every segment and the
penalty stop torque to ``qfrc_passive`` each time MuJoCo evaluates passive forces (once per step, 4x under RK4).

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


class PythonCoupling:
    """RFT on each segment's midpoint site and the origami penalty stop, evaluated with numpy."""

    def __init__(self, plate: PlateModel, scene: Scene) -> None:
        m = plate.model
        self.law = rft.force_law(scene.rft)
        self.sites = plate.seg_site
        self.bodies = plate.seg_body
        self.force = np.zeros((len(self.sites), 3))  # the last RFT force per segment (N, world frame)
        penalty = scene.plate.kind == "origami" and scene.plate.stop == "penalty"
        self.stop_qpos = plate.hinge_qpos if penalty else np.zeros(0, dtype=int)
        self.stop_dof = plate.hinge_dof if penalty else np.zeros(0, dtype=int)
        self.springref = scene.plate.springref
        self.stop_stiffness = scene.plate.stop_stiffness
        self._torque = np.zeros(3)
        self._twist = np.zeros(6)
        self._velocity = np.zeros((len(self.sites), 3))

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        for i, site in enumerate(self.sites):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, site, self._twist, 0)
            self._velocity[i] = self._twist[3:]
        frames = d.site_xmat[self.sites].reshape(-1, 3, 3)
        self.force[:] = self.law(self._velocity, frames[:, :, 0], frames[:, :, 1])
        for i, site in enumerate(self.sites):
            mujoco.mj_applyFT(m, d, self.force[i], self._torque, d.site_xpos[site], int(self.bodies[i]),
                              d.qfrc_passive)
        if len(self.stop_dof):
            deflection = d.qpos[self.stop_qpos] - self.springref
            d.qfrc_passive[self.stop_dof] -= self.stop_stiffness * (deflection + np.abs(deflection)) * deflection


@contextlib.contextmanager
def installed(callback: Callable[[mujoco.MjModel, mujoco.MjData], None]) -> Iterator[None]:
    """Install a passive-force callback for the duration of a block, then restore whatever was there."""
    previous = mujoco.get_mjcb_passive()
    mujoco.set_mjcb_passive(callback)
    try:
        yield
    finally:
        mujoco.set_mjcb_passive(previous)
