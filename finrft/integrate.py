"""Time stepping, ``sim.method``:

- ``explicit``: MuJoCo's own step. The RFT force enters as it is, so light segments under a rate-independent
  law need dt < 2 m v_reg / F or they chatter (MuJoCo's implicit integrators cannot see a plugin's derivative).
- ``implicit``: a linearly implicit step, MuJoCo's implicitfast with the RFT force's velocity Jacobian added:
  (M - dt D) qacc' = M qacc, D = joint damping + affine actuator bias + sum_i J_i^T dF_i/dv J_i, then
  activations, qvel += dt qacc', positions and time as MuJoCo advances them. dF/dv comes from central
  differences of the same law. Native (plugins/finrft_rft.c, finrft_implicit_step) or numpy, the same formulas.

- ``adaptive``: implicit steps whose size follows a step-doubling error estimate: one step of h and two of h/2
  must agree to ``sim.tolerance`` (max over qpos and qvel of |difference| / (1e-3 + |value|)), never above
  ``sim.max_step``; the accepted state is extrapolated, 2 (two halves) - (one step), which cancels the implicit
  step's first-order error. ``sim.dt`` is then only the time grid of reversals and recorded samples.

A stepper advances ``n`` steps of ``sim.dt`` and returns 0, nonzero when the state stopped being finite, or
STEP_TOO_SMALL when the adaptive step fell below 1e-9 s.
"""

from __future__ import annotations

import ctypes
from typing import Callable, Sequence

import mujoco
import numpy as np

from . import native, rft
from .models import ForceGroup
from .scene import Sim

Stepper = Callable[[mujoco.MjData, int], int]
STEP_TOO_SMALL = 2  # the native library's code too


def _native(name: str, *argtypes) -> Callable[..., int]:
    function = getattr(ctypes.CDLL(str(native.library_path())), name)
    function.argtypes = [ctypes.c_void_p, ctypes.c_void_p, *argtypes]
    function.restype = ctypes.c_int
    return function


def stepper(m: mujoco.MjModel, sim: Sim, backend: str, groups: Sequence[ForceGroup]) -> Stepper:
    """The step function for a model: MuJoCo's step, or the implicit or adaptive method (native or numpy)."""
    if sim.method == "explicit":
        def explicit(d: mujoco.MjData, n: int) -> int:
            mujoco.mj_step(m, d, n)
            return 0
        return explicit
    if sim.method == "implicit":
        if backend == "native":
            step = _native("finrft_implicit_step", ctypes.c_int)
            return lambda d, n: step(m._address, d._address, n)
        implicit = PythonImplicit(m, groups)
        return lambda d, n: implicit.steps(d, n, m.opt.timestep)
    return Adaptive(m, sim, backend, groups)


class Adaptive:
    """The adaptive method; the step size carries over from one call to the next."""

    def __init__(self, m: mujoco.MjModel, sim: Sim, backend: str, groups: Sequence[ForceGroup]) -> None:
        self.m, self.max_step, self.tolerance, self.h = m, sim.max_step, sim.tolerance, sim.dt
        self._native = None
        if backend == "native":
            self._native = _native("finrft_adaptive_advance", ctypes.c_double, ctypes.c_double, ctypes.c_double,
                                   ctypes.POINTER(ctypes.c_double))
        else:
            self._implicit = PythonImplicit(m, groups)
            self._spec = mujoco.mjtState.mjSTATE_INTEGRATION
            size = mujoco.mj_stateSize(m, self._spec)
            self._start, self._full, self._halves = np.zeros(size), np.zeros(size), np.zeros(size)

    def __call__(self, d: mujoco.MjData, n: int) -> int:
        duration = n * self.m.opt.timestep
        if self._native is not None:
            h = ctypes.c_double(self.h)
            failed = self._native(self.m._address, d._address, duration, self.max_step, self.tolerance,
                                  ctypes.byref(h))
            self.h = h.value
            return failed
        return self._python(d, duration)

    def _python(self, d: mujoco.MjData, duration: float) -> int:
        m, spec, end = self.m, self._spec, d.time + duration
        span = slice(1, 1 + m.nq + m.nv)  # qpos and qvel in the integration state, after time
        while d.time < end - 1e-12:
            step = min(self.h, self.max_step, end - d.time)
            mujoco.mj_getState(m, d, self._start, spec)
            failed = self._implicit.steps(d, 1, step)
            mujoco.mj_getState(m, d, self._full, spec)
            mujoco.mj_setState(m, d, self._start, spec)
            failed = failed or self._implicit.steps(d, 2, step / 2)
            mujoco.mj_getState(m, d, self._halves, spec)
            error = np.max(np.abs(self._full[span] - self._halves[span]) / (1e-3 + np.abs(self._halves[span])))
            if failed or not np.isfinite(error):
                return 1
            if error <= self.tolerance:
                self._halves[span] += self._halves[span] - self._full[span]
                mujoco.mj_setState(m, d, self._halves, spec)
                self.h = min(self.max_step, step * min(2.0, 0.9 * np.sqrt(self.tolerance / max(error, 1e-300))))
            else:
                mujoco.mj_setState(m, d, self._start, spec)
                self.h = step * max(0.2, 0.9 * np.sqrt(self.tolerance / error))
                if self.h < 1e-9:
                    return STEP_TOO_SMALL
        return 0


class PythonImplicit:
    """The implicit method in numpy: the twin of finrft_implicit_step, used with the python backend."""

    def __init__(self, m: mujoco.MjModel, groups: Sequence[ForceGroup]) -> None:
        self.m = m
        self.laws = [(rft.force_law(g.rft), g) for g in groups]
        self.damping = np.diag(m.dof_damping)
        servo = [a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
                 and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE]
        for a in servo:
            dof = m.jnt_dofadr[m.actuator_trnid[a, 0]]
            self.damping[dof, dof] -= m.actuator_gear[a, 0] ** 2 * m.actuator_biasprm[a, 2]
        self._mass = np.zeros((m.nv, m.nv))
        self._rhs = np.zeros(m.nv)
        self._jacp = np.zeros((3, m.nv))
        self._twist = np.zeros(6)

    def jacobian(self, d: mujoco.MjData) -> np.ndarray:
        """sum_i J_i^T dF_i/dv J_i over every segment (nv x nv)."""
        m, total = self.m, np.zeros((self.m.nv, self.m.nv))
        for law, group in self.laws:
            for site in group.sites:
                mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, site, self._twist, 0)
                v = self._twist[3:]
                frame = d.site_xmat[site].reshape(3, 3)
                h = 1e-6 * (np.sqrt(v @ v) + group.rft.v_reg)
                probes = np.concatenate([v + h * np.eye(3), v - h * np.eye(3)])
                force = law(probes, np.tile(frame[:, 0], (6, 1)), np.tile(frame[:, 1], (6, 1)))
                slope = ((force[:3] - force[3:]) / (2 * h)).T     # dF/dv, row = force component
                mujoco.mj_jacSite(m, d, self._jacp, None, site)
                total += self._jacp.T @ slope @ self._jacp
        return total

    def steps(self, d: mujoco.MjData, n: int, dt: float) -> int:
        m = self.m
        for step in range(n):
            mujoco.mj_forward(m, d)
            mujoco.mj_mulM(m, d, self._rhs, d.qacc)
            mujoco.mj_fullM(m, d, self._mass)
            qacc = np.linalg.solve(self._mass + dt * self.damping - dt * self.jacobian(d), self._rhs)
            for a in range(m.nu):
                adr = m.actuator_actadr[a]
                if adr < 0:
                    continue
                span = slice(adr, adr + m.actuator_actnum[a])
                d.act[span] += dt * d.act_dot[span]
                if m.actuator_actlimited[a]:
                    d.act[span] = np.clip(d.act[span], *m.actuator_actrange[a])
            d.qvel[:] += dt * qacc
            if not np.all(np.isfinite(d.qvel)):
                return step + 1
            d.qacc_warmstart[:] = d.qacc
            mujoco.mj_integratePos(m, d.qpos, d.qvel, dt)
            d.time += dt
        return 0
