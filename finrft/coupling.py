"""The coupling of RFT to MuJoCo.

`SegmentForces` evaluates the RFT force on every segment from MuJoCo's kinematics (the velocity of each segment's
midpoint site and the site's frame), with the pure laws of `finrft.laws`. `PythonCoupling` is the ``python``
backend: a passive-force callback that adds those forces and the penalty stop torque (`penalty_stop`) to
``qfrc_passive`` each time MuJoCo evaluates passive forces (once per step, four times under RK4). The ``native``
backend does the same in the C plugin (plugins/finrft_rft.c), bound to the model in `finrft.models`.

MuJoCo's callbacks are process-global: `finrft.callbacks.installed` gives the callback to one model for a run.
"""

from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np

from . import laws
from .models import ForceGroup

class SegmentForces:
    """The RFT force on each segment of a force group (N, 3), world frame, for MuJoCo's current kinematics."""

    def __init__(self, group: ForceGroup) -> None:
        self.law = laws.bind(group.law)
        self.sites = group.sites
        self.bodies = group.bodies
        self.roots = None  # the bodies' root bodies, known once a model is seen
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

    def snapshot(self, m: mujoco.MjModel, d: mujoco.MjData, cvel: np.ndarray, offset: np.ndarray,
                 frames: np.ndarray) -> None:
        """Store, cheaply, what `recorded` needs: the bodies' com-based velocities (N, 6), each midpoint's
        offset from its tree's centre of mass (N, 3) and the site frames (N, 3, 3)."""
        if self.roots is None:
            self.roots = m.body_rootid[self.bodies]
        cvel[:] = d.cvel[self.bodies]
        offset[:] = d.site_xpos[self.sites] - d.subtree_com[self.roots]
        frames[:] = d.site_xmat[self.sites].reshape(-1, 3, 3)

    def recorded(self, cvel: np.ndarray, offset: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """The forces of stored snapshots, all at once: midpoint velocity v = v_com + w x offset, as
        mj_objectVelocity computes it."""
        velocity = cvel[..., 3:] + np.cross(cvel[..., :3], offset)
        return self.evaluate(velocity, frames)

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        self.kinematics(m, d, self._velocity, self._frames)
        self.force[:] = self.evaluate(self._velocity, self._frames)
        return self.force


def penalty_stop(deflection: np.ndarray, stiffness: float) -> tuple[np.ndarray, np.ndarray]:
    """The penalty stop on hinge deflections d (rad) from the rest angle: the torque -k (d + |d|) d (nothing on the
    soft side, a stiffening spring on the other) and its derivative in d."""
    return -stiffness * (deflection + np.abs(deflection)) * deflection, -4 * stiffness * np.maximum(deflection, 0)


class PythonCoupling:
    """The ``python`` backend: each group's RFT on its midpoint sites, and its hinges' penalty stop (deflection
    from the spring's rest angle, as in the native plugin)."""

    def __init__(self, groups: Sequence[ForceGroup]) -> None:
        self.groups = [(SegmentForces(g), g) for g in groups]
        self._torque = np.zeros(3)

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        for forces, group in self.groups:
            force = forces(m, d)
            for i, site in enumerate(group.sites):
                mujoco.mj_applyFT(m, d, force[i], self._torque, d.site_xpos[site], int(group.bodies[i]),
                                  d.qfrc_passive)
            if group.stop_stiffness > 0 and len(group.hinge_dof):
                deflection = d.qpos[group.hinge_qpos] - m.qpos_spring[group.hinge_qpos]
                d.qfrc_passive[group.hinge_dof] += penalty_stop(deflection, group.stop_stiffness)[0]
