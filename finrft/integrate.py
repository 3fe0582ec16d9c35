"""Time stepping, ``sim.method`` (what each method is and can do: `finrft.methods`):

- ``explicit``: MuJoCo's own step. The RFT force enters as it is, so light segments (and light attached bodies)
  under a rate-independent law need dt < 2 m v_reg / F or they chatter (MuJoCo's implicit integrators cannot see
  a plugin's derivative).
- ``implicit``: a linearly implicit step, MuJoCo's implicitfast with the RFT force's velocity Jacobian added:
  (M - dt D) qacc' = M qacc, D = joint damping + affine actuator bias + sum_i J_i^T dF_i/dv J_i, then
  activations, qvel += dt qacc', positions and time as MuJoCo advances them. dF/dv comes from central
  differences of the same law. Native (plugins/steppers.c, finrft_implicit_step) or numpy, the same formulas.
- ``newton``: backward Euler in the RFT force: the velocity change dv solves
  (M - dt D') dv = dt (f(v) - F(v) + F(v + dv)), D' without the RFT term, f every force MuJoCo computed at v.
  A rate-independent law is nearly a step function of the velocity's direction, so on light segments the
  linearisation at v (the implicit step, Newton's first iterate) overshoots and chatters; Newton's method with a
  backtracking line search on the residual converges to the root (|change| <= 1e-10 (1 + |qvel|), and the
  residual at most NEWTON_RESIDUAL of dt times the step's largest force). The
  penalty stops are taken at the step's end too, at the deflection d + dt (v + dv). With attached surfaces alone
  (no segments) it keeps its slope while each full step cuts the residual by SURFACE_DECREASE (fresh again when
  that stops, or when a search stalls on a kept one) and takes a step below the tolerance without a residual to
  confirm it: the same root for fewer law calls. There a step that follows the stepper's last one (its time where
  that one ended) starts Newton's method from that step's velocity change, scaled to the step, the force and slope
  taken there, and stops once its change is below PREDICTOR_SHARE (1e-5) of how far it lies from that
  prediction: the prediction misses by about twice backward Euler's local error in the velocity, so the stop is
  1e-5 of the step's own error (at 1e-3 the solver's error spoilt a companion run's estimate), where the fixed
  one (1e-10) took four to six more passes of the law. A step whose Newton's method fails starts its halves
  afresh.
- ``newton-midpoint``: the newton step with the RFT force taken at the positions half a step ahead at the
  starting velocity, q + (dt / 2) v (the segments' and bodies' Jacobians and the elements below the surface; the
  stops stay where they are), and taken out of MuJoCo's forces where MuJoCo applied it, at q. The positions then
  advance with the new velocity, as in every method, so the force acts at the midpoint of the step's path: where
  the motion is quasi-static (a robot's in sand: the velocity follows from the shape and the drives), the first
  order error of taking it at the start cancels (the sand-swimmer's speed at 1 ms: 0.08 % from converged against
  2.5 % with ``newton``). Where the motion is inertial against a force that grows with depth it adds a damping
  of about k dt / 2 (k the force's stiffness in position): a box dropped onto the sand at 1 ms stops 5 % short of
  its converged depth (``newton``: 0.1 %). Stable as ``newton`` is: the velocity is still backward Euler's.
- ``adaptive``: implicit steps whose size follows a step-doubling error estimate: one step of h and two of h/2
  must agree to ``sim.tolerance`` (max over qpos and qvel of |difference| / (1e-3 + |value|)), never above
  ``sim.max_step``; the accepted state is extrapolated, 2 (two halves) - (one step), which cancels the implicit
  step's first-order error. ``sim.dt`` is then only the time grid of reversals and recorded samples.
  A step cut short to land on a sample or a reversal (short by more than TIME_ROUNDING, which the time's own
  rounding is not) leaves the next step's size as it was; after a reversal
  (`Adaptive.restart`) the steps start again from at most ``sim.max_step * sqrt(sim.tolerance)``: the drive's
  velocity jumps there, and the size the sweep before allowed says nothing of the transient after it.
- ``adaptive-newton``: the same control on newton steps, the error measured on qpos only: the stiff RFT force
  slaves a light segment's velocity to its position, so the velocity jumps within microseconds (at the start, at
  each reversal) and the newton step lands on the jumped value whatever its size; the halves and the whole step
  differ there in velocity by O(1) at any step, in position by h times that, which the position test sees. A stop
  engaging or a segment reversing is where the positions disagree, so the steps shrink there and grow through the
  quasi-static sweep between; a step whose Newton solve finds no root is rejected and retried at a quarter of its
  size.

Attached surfaces (`finrft.attach`, the plugin finrft.surface: one instance per body) are taken implicitly as the
segments are: F(u) sums, besides J_i^T F_i(J_i u) over the segments, J_b^T W_b(J_b u) over the bodies, J_b the
6 x nv Jacobian of body b's origin (angular rows, then linear: its twist t) and W_b its wrench (torque about the
origin, force) at the positions of the step's start, summed over the elements below the surface there (taken once
per step). Element e at arm a_e moves at v_e = A_e t, A_e = [-[a_e]x | I], and W_b = sum_e A_e^T F_e(v_e), so
dW/dtwist = sum_e A_e^T (dF_e/dv_e) A_e, each element's 3 x 3 its law's own analytic one where the law has one
(li2013 and rft3d: `Attached.element_slopes`, finrft_surface_element_slope; the ramp and DRFT's term included), none
for an element that trails (n . v <= 0, where every surface law is 0). A law without one (li2013-planar) is
differenced in steps 1e-6 (|v_e| + SURFACE_SPEED): three law calls per element (forward differences), none for an
element that trails at v_e and at every probe; two for one that leads, whose law depends on the direction of v_e
alone, so that only the directions across v_e need probing (`_leading_slope`; not with DRFT's term, which grows
with the speed). Both backends apply the surfaces' forces among MuJoCo's passive forces at v;
the step takes them out there (``other``; the native stepper leaves them out of its forward pass) and back at
v + dv, as the segments'.

What is stable, and why: a rate-independent force regularised over v_reg is, on a light body of mass m, a damper
F / v_reg, which an explicit step resolves only for dt < 2 m v_reg / F (a 0.5 kg box resting on li2013 with
v_reg = 1e-5 m/s: about 1 µs; at 1 ms its vertical velocity flips by 19 mm/s every step). Backward Euler in that
force (``newton``) is unconditionally stable for it, a damper being dissipative at any step: the box dropped at
1 ms settles at the closed-form depth and creeps at the regularised law's own rate, v_reg atanh(load / capacity),
its velocity never reversing (tests/test_implicit_surfaces.py). The linearised step (``implicit``) has no such
guarantee: it extrapolates the damper's slope at v across the switch and overshoots once dt F / (m v_reg) is large.
Unweighted (``v_reg`` 0 in `attach`) a leading face switches its full stress on at n . v = 0, and the step may
have no root: Newton's method then stops at the switch where it can (a box pressed onto the medium rests there,
within 1e-9 m/s: the exact sticking solution), but a box thrown spinning into the medium finds no step at 1 ms
(NOT_CONVERGED). Weighted over v_reg the force is continuous, and the step has a root near v.

A stepper advances ``n`` steps of ``sim.dt`` and returns 0 or a `finrft.native.Code`: UNSTABLE when the state
stopped being finite, STEP_TOO_SMALL when the adaptive step fell below 1e-9 s, NOT_CONVERGED when Newton's method
did not converge, ARENA_FULL when the native step's workspace does not fit on the mjData stack. It counts
the steps it has taken and rejected: a fixed step takes exactly the steps asked for, unless Newton's method halves
one (one rejected, two taken); the adaptive method takes its accepted steps and rejects those over the tolerance.
An adaptive stepper also steps ``until(d, t)``, to an instant off the grid (a reversal of the drive).
"""

from __future__ import annotations

import ctypes
import functools
import math
from typing import Callable, Protocol, Sequence

import mujoco
import numpy as np

from . import laws, methods, native
from .attach import Attached
from .coupling import penalty_stop
from .models import ForceGroup
from .native import Code
from .scene import Sim

NEWTON_ITERATIONS = 50
NEWTON_TOLERANCE = 1e-10
NEWTON_HALVINGS = 10
NEWTON_SHARE = 1e-2  # the adaptive newton method stops Newton's method at this share of the step's tolerance
# Newton's method takes an iterate as the root only where its residual is at most this share of dt times the step's
# largest force, besides its change being small (NEWTON_RESIDUAL in steppers.c).
NEWTON_RESIDUAL = 1e-3
# Spans of time (s) shorter than this are the rounding of d.time (TIME_ROUNDING in steppers.c): the adaptive steps
# stop this short of their end, and a step this close to the step size was not cut short to land there.
TIME_ROUNDING = 1e-12
# The speed (m/s) on whose scale an element's force is differenced besides its own (SURFACE_SPEED in steppers.c):
# the surface laws are rate-independent, so any step small against the element's speed would do but for one at rest.
SURFACE_SPEED = 1e-3
# Newton's method on attached surfaces alone keeps its slope while each full step cuts the residual at least this
# much (SURFACE_DECREASE in steppers.c).
SURFACE_DECREASE = 0.1
# A newton step on attached surfaces alone that follows the stepper's last one starts from that step's velocity
# change, scaled to the step, and stops once Newton's change is below this share of how far it lies from that
# prediction (PREDICTOR_SHARE in steppers.c).
PREDICTOR_SHARE = 1e-5


def _native(name: str, *argtypes) -> Callable[..., int]:
    """A native stepper: (mjModel*, mjData*, *argtypes) -> a return code."""
    return native.function(name, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, *argtypes)


class Stepper(Protocol):
    """``advance(d, n)``: ``n`` steps of ``sim.dt``, 0 or a failure code (above); ``taken`` and ``rejected``: the
    steps taken and rejected since the stepper was made."""

    taken: int
    rejected: int

    def __call__(self, d: mujoco.MjData, n: int) -> int: ...


Counts = ctypes.c_int64 * 2  # steps taken, steps rejected: the native functions add to it
# What the native steppers that keep a `LoadPeak` take after their own arguments: its `native_args`; the fixed-step
# ones then a `Trace`'s (none: _NO_TRACE).
_PEAK_ARGS = (ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.c_double, ctypes.POINTER(ctypes.c_double))
_TRACE_ARGS = (ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double))
_NO_TRACE = (ctypes.c_int(0), None, None)


class Trace:
    """The velocities of the dofs ``watch`` after each step of a native stepper's call, which the stepper writes
    (plugins/peaks.c) for the chatter probe: ``rows[i]`` after the call's step i + 1, so that a call may step past
    the probe's steps. A call takes at most ``len(rows)`` steps."""

    def __init__(self, watch: Sequence[int], steps: int) -> None:
        self.rows = np.zeros((steps, len(watch)))
        self.native_args = (ctypes.c_int(len(watch)), (ctypes.c_int * len(watch))(*watch),
                            self.rows.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))


def stepper(m: mujoco.MjModel, sim: Sim, backend: str, groups: Sequence[ForceGroup],
            attached: Attached | None = None, peak: LoadPeak | None = None) -> Stepper:
    """The step function for a model: MuJoCo's step, or the implicit or adaptive method (native or numpy), as the
    method's entry in `finrft.methods` says. The implicit methods take implicitly the forces of the segment force
    ``groups`` and of the ``attached`` surfaces (`finrft.attach`; the native steppers find both in the model's
    plugin instances). Given a ``peak``, the stepper takes the drive's load at every step's state into it (an
    adaptive method's: at every instant of a grid of its largest step, `Adaptive.until`)."""
    method = methods.get(sim.method)
    iterations = NEWTON_ITERATIONS if method.newton else 1
    if method.adaptive:
        return Adaptive(m, sim, method.stepper, iterations, backend, groups, attached, peak)
    if method.implicit:
        return Implicit(m, method.stepper, iterations, backend, groups, attached, method.midpoint, peak)
    return Explicit(m, backend, peak)


class LoadPeak:
    """A prescribed drive's largest load in a stroke, taken at every step's state (the twin of plugins/peaks.c):
    armature times the largest |qacc| of its dofs, from a forward pass. Besides the peak it keeps how much the load
    changes between the peak's step and its neighbours (`change`): the load's largest value between steps is within
    about that of the steps', where a companion run's comparison can miss it (the paper plate's peak at its stop
    converges unevenly in dt). The native steppers keep it in C (``state``, peaks.c's slots: the peak, its change,
    the last load, NaN before the stroke's first, 1 when that one set the peak, and 1 when the present state's load
    is still to be taken, which the native explicit steps take from the next step's own forward pass); the numpy
    twin in `take` after every step."""

    PEAK, CHANGE, LAST, AFTER_PEAK, PENDING = range(5)

    def __init__(self, dofs: Sequence[int], armature: float) -> None:
        self.dofs, self.armature = list(dofs), float(armature)
        self.state = np.zeros(5)
        self.restart()
        self.native_args = (ctypes.c_int(len(self.dofs)), (ctypes.c_int * len(self.dofs))(*self.dofs),
                            ctypes.c_double(self.armature), self.state.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))

    def restart(self) -> None:
        """A new stroke: no load taken yet."""
        self.state[:] = (0.0, 0.0, np.nan, 0.0, 0.0)

    def take(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """Take the load at the state of ``d`` (after a forward pass, which this runs)."""
        mujoco.mj_forward(m, d)
        qacc = d.qacc
        load = self.armature * max(abs(qacc[i]) for i in self.dofs)
        state = self.state
        peak, last = float(state[self.PEAK]), float(state[self.LAST])
        if state[self.AFTER_PEAK]:
            state[self.CHANGE] = max(state[self.CHANGE], abs(peak - load))
        higher = load > peak
        if higher:
            state[self.PEAK] = load
            state[self.CHANGE] = 0.0 if math.isnan(last) else abs(load - last)
        # a peak at the stroke's first state is at its instant exactly: nothing earlier in the stroke to miss, and
        # the load falling after it (a light plate relaxing to the new velocity in microseconds) is no error
        state[self.AFTER_PEAK] = higher and not math.isnan(last)
        state[self.LAST], state[self.PENDING] = load, 0.0

    def flush(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """Take the present state's load if the steps left it pending: before the state jumps, and at the end."""
        if self.state[self.PENDING]:
            self.take(m, d)

    @property
    def peak(self) -> float:
        return float(self.state[self.PEAK])

    @property
    def change(self) -> float:
        return float(self.state[self.CHANGE])


class _Counted:
    def __init__(self) -> None:
        self.counts = Counts()
        self._trace, self._traces = _NO_TRACE, False  # _traces: a native stepper that writes a `Trace`

    def traced(self, watch: Sequence[int], steps: int) -> Trace | None:
        """A `Trace` of ``watch`` that every later call (of at most ``steps`` steps) writes; None where this
        stepper keeps none (the native fixed-step ones with a `LoadPeak` do)."""
        if not self._traces:
            return None
        trace = Trace(watch, steps)
        self._trace = trace.native_args
        return trace

    @property
    def taken(self) -> int:
        return self.counts[0]

    @property
    def rejected(self) -> int:
        return self.counts[1]


class Explicit(_Counted):
    """MuJoCo's own step; with a `LoadPeak`, the native backend's in C (finrft_explicit_peak)."""

    def __init__(self, m: mujoco.MjModel, backend: str = "native", peak: LoadPeak | None = None) -> None:
        super().__init__()
        self.m, self.peak = m, peak
        self._native = None
        if peak is not None and backend == "native":
            # Called for every few steps (a plate's samples and chatter probes: 830 calls in a drag of 6667 steps),
            # so with its arguments made once, as ctypes objects, and no argtypes to convert them: a third of the
            # call's cost, about 3 % of the drag's.
            self._native = native.function("finrft_explicit_peak", ctypes.c_int)
            self._native.argtypes = None
            self._model = ctypes.c_void_p(m._address)
            self._data: tuple[mujoco.MjData | None, ctypes.c_void_p] = (None, ctypes.c_void_p())
            self._traces = True

    def __call__(self, d: mujoco.MjData, n: int) -> int:
        self.counts[0] += n
        if self.peak is None:
            mujoco.mj_step(self.m, d, n)
        elif self._native is not None:
            if self._data[0] is not d:
                self._data = (d, ctypes.c_void_p(d._address))
            return self._native(self._model, self._data[1], ctypes.c_int(n), *self.peak.native_args, *self._trace)
        else:
            for _ in range(n):
                mujoco.mj_step(self.m, d)
                self.peak.take(self.m, d)
        return 0


class Implicit(_Counted):
    """The implicit (one Newton iteration) or newton method, native or numpy."""

    def __init__(self, m: mujoco.MjModel, native_stepper: str, iterations: int, backend: str,
                 groups: Sequence[ForceGroup], attached: Attached | None = None, midpoint: float = 0.0,
                 peak: LoadPeak | None = None) -> None:
        super().__init__()
        self.m, self.iterations, self.midpoint, self.peak = m, iterations, midpoint, peak
        self._traces = backend == "native" and peak is not None
        # the last step's time after it, size and velocity change: the next step's prediction (PREDICTOR_SHARE)
        self.history = np.full(m.nv + 2, np.nan)
        if backend == "native":
            # finrft_implicit_peak calls the method's own stepper, finrft_implicit_step, one step at a time
            self._native = _native(native_stepper if peak is None else "finrft_implicit_peak", ctypes.c_int,
                                   ctypes.c_int, ctypes.c_double, ctypes.POINTER(ctypes.c_int64),
                                   ctypes.POINTER(ctypes.c_double),
                                   *(() if peak is None else (*_PEAK_ARGS, *_TRACE_ARGS)))
        else:
            self._native, self._python = None, PythonImplicit(m, groups, attached)

    def __call__(self, d: mujoco.MjData, n: int) -> int:
        if self._native is not None:
            return self._native(self.m._address, d._address, n, self.iterations, self.midpoint, self.counts,
                                self.history.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                                *(() if self.peak is None else (*self.peak.native_args, *self._trace)))
        if self.peak is None:
            return self._python.steps(d, n, self.m.opt.timestep, self.iterations, self.counts, self.midpoint,
                                      self.history)
        for _ in range(n):
            failed = self._python.steps(d, 1, self.m.opt.timestep, self.iterations, self.counts, self.midpoint,
                                        self.history)
            if failed:
                return failed
            self.peak.take(self.m, d)
        return 0


class Adaptive(_Counted):
    """The adaptive methods on implicit (``iterations`` 1) or newton steps; the step size carries over from one
    call to the next."""

    def __init__(self, m: mujoco.MjModel, sim: Sim, native_stepper: str, iterations: int, backend: str,
                 groups: Sequence[ForceGroup], attached: Attached | None = None, peak: LoadPeak | None = None) -> None:
        super().__init__()
        self.m, self.max_step, self.tolerance, self.h = m, sim.max_step, sim.tolerance, sim.dt
        self.iterations, self.dt, self.peak = iterations, sim.dt, peak
        self._native = self._native_peak = None
        if backend == "native" and peak is None:
            self._native = _native(native_stepper, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                                   ctypes.c_int, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int64))
        elif backend == "native":  # it calls the method's stepper, finrft_adaptive_advance, to each instant
            self._native_peak = _native("finrft_adaptive_peak", ctypes.c_int, ctypes.POINTER(ctypes.c_double),
                                        ctypes.c_double, ctypes.c_double, ctypes.c_int,
                                        ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int64),
                                        *_PEAK_ARGS)
        else:
            self._implicit = PythonImplicit(m, groups, attached)
            # Newton's error, a velocity, moves a position by h times it: far below what the step's test allows
            self._implicit.tolerance = max(NEWTON_TOLERANCE, NEWTON_SHARE * sim.tolerance)
            self._spec = mujoco.mjtState.mjSTATE_INTEGRATION
            size = mujoco.mj_stateSize(m, self._spec)
            self._start, self._full, self._halves = np.zeros(size), np.zeros(size), np.zeros(size)

    def __call__(self, d: mujoco.MjData, n: int) -> int:
        return self.until(d, d.time + n * self.m.opt.timestep)

    def restart(self) -> None:
        """Take the next step small again, as after a discontinuity (a reversal of the drive): at most max_step x
        sqrt(tolerance), the step the control would choose after a largest step whose error were of order one.
        Carried over, a step grown through the sweep before a reversal took the transient after it in one piece,
        its halves fooled alike: eta 0.1 points off on the physical robot's symmetric gaits at every tolerance
        from 2.5e-2 to 2.5e-4. Not sim.dt, which is only the grid of the reversals."""
        self.h = min(self.h, self.max_step * np.sqrt(self.tolerance))

    def until(self, d: mujoco.MjData, end: float) -> int:
        """Steps to time ``end`` exactly, off the grid of ``sim.dt`` if need be (a reversal of the drive). With a
        `LoadPeak`, the load is taken at every instant of a grid of the largest step (sim.max_step rounded to whole
        steps of sim.dt, at least one) before ``end`` and at ``end``: the steps are cut there but keep their size."""
        if self.peak is not None:
            return self._through(d, self._grid(d.time, end))
        duration = end - d.time
        if self._native is not None:
            h = ctypes.c_double(self.h)
            failed = self._native(self.m._address, d._address, duration, self.max_step, self.tolerance,
                                  self.iterations, ctypes.byref(h), self.counts)
            self.h = h.value
            return failed
        return self._python(d, duration)

    def _grid(self, start: float, end: float) -> np.ndarray:
        """The instants `until` takes the load at from ``start`` to ``end``, both on or rounded to the scheduled
        steps of sim.dt (a reversal's instant is rounded to the step its stroke starts at)."""
        stride = max(1, round(self.max_step / self.dt))
        first, last = (round(start / self.dt) // stride + 1) * stride, round(end / self.dt)
        return np.r_[np.arange(first, last, stride) * self.dt, end]

    def _through(self, d: mujoco.MjData, instants: np.ndarray) -> int:
        """Steps to each of ``instants`` in turn, the load taken into the peak at each."""
        if self._native_peak is not None:
            h = ctypes.c_double(self.h)
            failed = self._native_peak(self.m._address, d._address, len(instants),
                                       instants.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), self.max_step,
                                       self.tolerance, self.iterations, ctypes.byref(h), self.counts,
                                       *self.peak.native_args)
            self.h = h.value
            return failed
        for instant in instants:
            failed = self._python(d, instant - d.time)
            if failed:
                return failed
            self.peak.take(self.m, d)
        return 0

    def _python(self, d: mujoco.MjData, duration: float) -> int:
        m, spec, end = self.m, self._spec, d.time + duration
        span = slice(1, 1 + m.nq + m.nv)  # qpos and qvel in the integration state, after time
        measured = slice(1, 1 + m.nq) if self.iterations > 1 else span
        while d.time < end - TIME_ROUNDING:
            step = min(self.h, self.max_step, end - d.time)
            mujoco.mj_getState(m, d, self._start, spec)
            failed = self._implicit.step(d, step, self.iterations, NEWTON_HALVINGS)
            mujoco.mj_getState(m, d, self._full, spec)
            mujoco.mj_setState(m, d, self._start, spec)
            for _ in range(2):
                failed = failed or self._implicit.step(d, step / 2, self.iterations, NEWTON_HALVINGS)
            mujoco.mj_getState(m, d, self._halves, spec)
            if failed == Code.NOT_CONVERGED and self.iterations > 1:
                mujoco.mj_setState(m, d, self._start, spec)
                self.h = step / 4
                self.counts[1] += 1
                if self.h < 1e-9:
                    return Code.STEP_TOO_SMALL
                continue
            error = np.max(np.abs(self._full[measured] - self._halves[measured])
                           / (1e-3 + np.abs(self._halves[measured])))
            if failed or not np.isfinite(error):
                return failed or Code.UNSTABLE
            if error <= self.tolerance:
                self._halves[span] += self._halves[span] - self._full[span]
                mujoco.mj_setState(m, d, self._halves, spec)
                proposal = min(self.max_step, step * min(2.0, 0.9 * np.sqrt(self.tolerance / max(error, 1e-300))))
                self.h = max(self.h, proposal) if step < self.h - TIME_ROUNDING else proposal
                self.counts[0] += 1
            else:
                mujoco.mj_setState(m, d, self._start, spec)
                self.h = step * max(0.2, 0.9 * np.sqrt(self.tolerance / error))
                self.counts[1] += 1
                if self.h < 1e-9:
                    return Code.STEP_TOO_SMALL
        return 0


def _cross_matrices(a: np.ndarray) -> np.ndarray:
    """[a]x for each row of ``a`` (N, 3): (N, 3, 3), [a]x b = a x b."""
    out = np.zeros((len(a), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -a[:, 2], a[:, 1], -a[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = a[:, 2], -a[:, 1], a[:, 0]
    return out


def _across(v: np.ndarray) -> np.ndarray:
    """Two unit vectors across each nonzero row of ``v`` (E, 3): (E, 2, 3), p1 = v x e / |v x e| (e the axis
    along v's smallest component, the first of equals) and p2 = v^ x p1, as `across` in steppers.c."""
    e = np.eye(3)[np.argmin(np.abs(v), axis=1)]
    p1 = np.cross(v, e)
    p1 /= np.linalg.norm(p1, axis=1, keepdims=True)
    return np.stack([p1, np.cross(v / np.linalg.norm(v, axis=1, keepdims=True), p1)], axis=1)


def _leading_slope(attached: Attached, normal: np.ndarray, v: np.ndarray, f0: np.ndarray, depth: np.ndarray,
                   area: np.ndarray, h: np.ndarray, frame: np.ndarray | None = None) -> np.ndarray:
    """dF/dv (E, 3, 3) of elements leading at ``v`` with forces ``f0`` = r L, by forward differences (as
    leading_slope in steppers.c): the law L is rate-independent (dL/dv v = 0), so dF/dv = r'(n . v) L n^T
    + r (dL/dv p1 p1^T + dL/dv p2 p2^T), p1, p2 `_across` v: two probes of the law rather than three."""
    if attached.v_reg > 0:
        ratio = np.einsum("ei,ei->e", normal, v) / attached.v_reg
        ramp = np.where(ratio < 20, np.tanh(np.minimum(ratio, 20.0)), 1.0)
        rate = np.where(ratio < 20, (1 - ramp ** 2) / attached.v_reg, 0.0)
    else:
        ramp, rate = np.ones(len(v)), np.zeros(len(v))
    law = f0 / ramp[:, None]
    across = _across(v)
    dl = np.stack([(attached.law_forces(normal, v + h[:, None] * across[:, c], depth, area, frame) - law)
                   / h[:, None]
                   for c in range(2)], axis=1)
    return (rate[:, None, None] * law[:, :, None] * normal[:, None, :]
            + ramp[:, None, None] * np.einsum("ecr,ecj->erj", dl, across))


class PythonImplicit:
    """The implicit method in numpy: the twin of finrft_implicit_step, used with the python backend."""

    def __init__(self, m: mujoco.MjModel, groups: Sequence[ForceGroup], attached: Attached | None = None) -> None:
        self.m = m
        self.laws = [(laws.bind(g.law), g) for g in groups if len(g.sites)]
        # per attached body: its id and surface; the callback's submerged elements, the law's forces on them
        self._surfaces = attached.callback(m) if attached is not None else None
        self.bodies = [] if self._surfaces is None else self._surfaces.bodies
        self.damping = np.diag(m.dof_damping)
        servo = [a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
                 and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE]
        for a in servo:
            dof = m.jnt_dofadr[m.actuator_trnid[a, 0]]
            self.damping[dof, dof] -= m.actuator_gear[a, 0] ** 2 * m.actuator_biasprm[a, 2]
        self._mass = np.zeros((m.nv, m.nv))
        self._rhs = np.zeros(m.nv)
        self.tolerance = NEWTON_TOLERANCE  # Newton's method stops when the change is below this times (1 + |qvel|)

    def _segments(self, d: mujoco.MjData) -> tuple[list, list, list]:
        """Per force group: its law, v_reg, the site Jacobians (k, 3, nv) and the segments' axes and normals; per
        penalty stop: its stiffness, hinge dofs and their deflections from the rest angle now; per attached body:
        its `Attached` (the law), the Jacobian of its origin (6, nv: angular rows, then linear, the twist's order),
        its elements below the surface now (arms, normals, depths, areas) and the laws' frame (None: level)."""
        segments, stops, bodies = [], [], []
        for body, surface in self.bodies:
            jac = np.zeros((6, self.m.nv))
            mujoco.mj_jacBody(self.m, d, jac[3:], jac[:3], body)
            bodies.append((self._surfaces.attached, jac, self._surfaces.submerged(d, body, surface),
                           self._surfaces.frame()))
        for law, group in self.laws:
            jacp = np.zeros((len(group.sites), 3, self.m.nv))
            for row, site in zip(jacp, group.sites):
                mujoco.mj_jacSite(self.m, d, row, None, site)
            frames = d.site_xmat[group.sites].reshape(-1, 3, 3)
            segments.append((law, group.law.v_reg, jacp, frames[:, :, 0], frames[:, :, 1]))
            if group.stop_stiffness > 0:
                deflection = d.qpos[group.hinge_qpos] - self.m.qpos_spring[group.hinge_qpos]
                stops.append((group.stop_stiffness, group.hinge_dof, deflection))
        return segments, stops, bodies

    @staticmethod
    def _forces(forces: tuple[list, list, list], u: np.ndarray, ahead: float, slope: bool,
                forward: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """At generalised velocity ``u``: the RFT force (segments' and attached surfaces') plus the penalty stops'
        torque at the deflection they reach ``ahead`` seconds on at ``u``, and, with ``slope``, its derivative in
        ``u`` (the laws' by central differences, or with ``forward`` forward ones: half the laws' calls, for
        Newton's method, whose root does not depend on the derivative)."""
        segments, stops, bodies = forces
        nv = len(u)
        force, jacobian = np.zeros(nv), np.zeros((nv, nv)) if slope else None
        for law, v_reg, jacp, x, y in segments:
            v = jacp @ u
            f = law(v, x, y)
            force += np.einsum("kin,ki->n", jacp, f)
            if slope:
                h = 1e-6 * (np.linalg.norm(v, axis=1) + v_reg)[:, None, None] * np.eye(3)  # (k, probe, 3)
                up = law(v[:, None] + h, x[:, None], y[:, None])
                down = f[:, None] if forward else law(v[:, None] - h, x[:, None], y[:, None])
                step = h.sum(axis=2, keepdims=True) * (1 if forward else 2)
                dfdv = np.swapaxes((up - down) / step, 1, 2)  # (k, force, v)
                jacobian += np.einsum("kin,kij,kjm->nm", jacp, dfdv, jacp)
        for attached, jac, (arm, normal, depth, area), frame in bodies:
            law = functools.partial(attached.element_forces, frame=frame)
            twist = jac @ u
            v = twist[3:] + np.cross(twist[:3], arm)
            f = law(normal, v, depth, area)
            force += jac.T @ np.concatenate([np.cross(arm, f).sum(axis=0), f.sum(axis=0)])
            analytic = attached.element_slopes(normal, v, depth, area, frame) if slope and len(area) else None
            if analytic is not None:
                dfdv = analytic[1]  # each element's own, as body_slope takes it from finrft_surface_element_slope
                if not forward:  # the linearly implicit step: across the ramp's kink, a secant
                    dfdv = dfdv + attached.trailing_slopes(normal, v, depth, area)
            elif slope and len(area):
                # each element's dF/dv (as body_slope): forward, those leading with no DRFT term by
                # `_leading_slope`; the others by probes (element, probe, 3), the law on all of them at once
                h = 1e-6 * (np.linalg.norm(v, axis=1) + SURFACE_SPEED)
                rated = np.any(f != 0, axis=1) & (forward and attached.drft_lambda == 0)
                dfdv = np.zeros((len(area), 3, 3))
                dfdv[rated] = _leading_slope(attached, normal[rated], v[rated], f[rated], depth[rated],
                                             area[rated], h[rated], frame)
                rest = ~rated
                probe = h[rest, None, None] * np.eye(3)
                each = [np.repeat(x[rest], 3, axis=0) for x in (normal, depth, area)]
                up = law(each[0], (v[rest, None] + probe).reshape(-1, 3), *each[1:]).reshape(-1, 3, 3)
                down = f[rest, None] if forward else law(each[0], (v[rest, None] - probe).reshape(-1, 3),
                                                         *each[1:]).reshape(-1, 3, 3)
                dfdv[rest] = np.swapaxes((up - down) / (h[rest] * (1 if forward else 2))[:, None, None], 1, 2)
            if slope and len(area):
                # A_e = [-[arm]x | I]: v_e = A_e twist, and the wrench is sum_e A_e^T F_e
                a = np.zeros((len(area), 3, 6))
                a[:, :, :3] = -_cross_matrices(arm)
                a[:, :, 3:] = np.eye(3)
                jacobian += jac.T @ np.einsum("eri,erk,ekj->ij", a, dfdv, a) @ jac
        for stiffness, dofs, deflection in stops:
            torque, stiffening = penalty_stop(deflection + ahead * u[dofs], stiffness)
            force[dofs] += torque
            if slope:
                jacobian[dofs, dofs] += stiffening * ahead
        return force, jacobian

    def _segments_ahead(self, d: mujoco.MjData, seconds: float, stops: list) -> tuple[list, list, list]:
        """`_segments` at the positions ``seconds`` ahead at the present velocity, the penalty stops as given (the
        present ones); ``d``'s derived quantities are the present ones again afterwards."""
        m, qpos = self.m, d.qpos.copy()
        mujoco.mj_integratePos(m, d.qpos, d.qvel, seconds)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        segments, _, bodies = self._segments(d)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        return segments, stops, bodies

    def velocity_change(self, d: mujoco.MjData, dt: float, iterations: int, midpoint: float = 0.0,
                        guess: np.ndarray | None = None) -> np.ndarray | None:
        """The step's velocity change (after mj_forward): the linearly implicit step in the RFT force when
        ``iterations`` is 1; else the root of G with the penalty stops taken at the new positions too, by Newton's
        method, or None if it does not converge. With ``midpoint`` > 0 the RFT force is taken at the positions that
        far ahead at the present velocity (as step_prepare in steppers.c). Given ``guess`` (a predicted velocity
        change; attached surfaces alone), Newton's method starts there and stops once its change is below
        PREDICTOR_SHARE of how far it lies from the guess (or below the tolerance)."""
        m = self.m
        mujoco.mj_mulM(m, d, self._rhs, d.qacc)
        mujoco.mj_fullM(m, d, self._mass)
        matrix = self._mass + dt * self.damping
        forces = self._segments(d)
        qvel = d.qvel.copy()
        ahead = dt if iterations > 1 else 0.0
        # every force but F, taken out as MuJoCo applied it: at the present positions, the stops undeflected further
        taken = self._forces(forces, qvel, 0.0, False)[0] if ahead or midpoint > 0 else None
        if midpoint > 0:
            forces = self._segments_ahead(d, midpoint, forces[1])
        start = qvel if guess is None else qvel + guess
        force, slope = self._forces(forces, start, ahead, True, forward=iterations > 1)
        other = self._rhs - (force if taken is None else taken)

        at = [force]  # the RFT and stop forces at the last iterate whose residual was taken

        def residual(dv: np.ndarray) -> np.ndarray:
            at[0] = self._forces(forces, qvel + dv, dt, False)[0]
            return matrix @ dv - dt * (other + at[0])

        def small(g: np.ndarray) -> bool:  # residual_small in steppers.c
            return np.abs(g).max(initial=0.0) <= NEWTON_RESIDUAL * dt * max(np.abs(other).max(initial=0.0),
                                                                              np.abs(at[0]).max(initial=0.0))
        def converged(change: float, next_dv: np.ndarray) -> bool:  # change_small in steppers.c
            miss = 0.0 if guess is None else PREDICTOR_SHARE * np.abs(next_dv - guess).max(initial=0.0)
            return change <= max(self.tolerance * (1 + np.abs(qvel + next_dv).max(initial=0.0)), miss)
        dv = np.zeros(m.nv) if guess is None else guess.copy()
        g = matrix @ dv - dt * (other + force)
        # attached surfaces alone: the leaner Newton's method of newton_solve in steppers.c (the same root)
        lean, fresh = not self.laws, True
        for _ in range(iterations):
            step = np.linalg.solve(matrix - dt * slope, -g)
            if iterations == 1:
                return step
            if lean and converged(np.abs(step).max(initial=0.0), dv + step) and small(g):
                return dv + step
            norm, alpha = np.linalg.norm(g), 1.0
            while True:
                trial = residual(dv + alpha * step)
                if np.linalg.norm(trial) <= (1 - 1e-4 * alpha) * norm or alpha < 1e-6:
                    break
                alpha /= 2
            dv, g = dv + alpha * step, trial
            if converged(np.abs(alpha * step).max(initial=0.0), dv) and (fresh or alpha >= 1e-6) and small(g):
                return dv
            if lean and fresh and np.linalg.norm(trial) > (1 - 1e-4 * alpha) * norm:  # a kink: halve (steppers.c)
                return None
            fresh = not (lean and alpha == 1 and np.linalg.norm(trial) <= SURFACE_DECREASE * norm)
            if fresh:
                _, slope = self._forces(forces, qvel + dv, dt, True, forward=True)
        return None

    def steps(self, d: mujoco.MjData, n: int, dt: float, iterations: int, counts: Counts | None = None,
              midpoint: float = 0.0, history: np.ndarray | None = None) -> int:
        """``n`` steps of ``dt``, the RFT force at the positions a fraction ``midpoint`` of a step ahead; the steps
        taken and rejected are added to ``counts`` when given; ``history`` as finrft_implicit_step's."""
        for _ in range(n):
            failed = self.step(d, dt, iterations, 0, counts, midpoint, history)
            if failed:
                return failed
        return 0

    def step(self, d: mujoco.MjData, dt: float, iterations: int, halvings: int, counts: Counts | None = None,
             midpoint: float = 0.0, history: np.ndarray | None = None) -> int:
        """One step of ``dt``; where Newton's method finds no root (forces that feed energy in, such as
        f_par < 0, can leave the implicit equation without one near v) it halves the step, at most
        NEWTON_HALVINGS times (the step is rejected, its halves taken). ``history`` (or None): the last step's
        time after it, size and velocity change, the prediction a newton step on attached surfaces alone that
        starts at that time starts from (as implicit_step in steppers.c), which the step leaves for the next."""
        m = self.m
        mujoco.mj_forward(m, d)
        predicted = history is not None and iterations > 1 and not self.laws and history[0] == d.time
        guess = history[2:] * (dt / history[1]) if predicted else None
        dv = self.velocity_change(d, dt, iterations, midpoint * dt, guess)
        if history is not None:
            history[0] = np.nan  # the halves start afresh: a prediction may be what led Newton's method astray
        if dv is None:
            if iterations == 1 or halvings == NEWTON_HALVINGS:
                return Code.NOT_CONVERGED
            if counts is not None:
                counts[1] += 1
            return (self.step(d, dt / 2, iterations, halvings + 1, counts, midpoint, history)
                    or self.step(d, dt / 2, iterations, halvings + 1, counts, midpoint, history))
        for a in range(m.nu):
            adr = m.actuator_actadr[a]
            if adr < 0:
                continue
            span = slice(adr, adr + m.actuator_actnum[a])
            d.act[span] += dt * d.act_dot[span]
            if m.actuator_actlimited[a]:
                d.act[span] = np.clip(d.act[span], *m.actuator_actrange[a])
        d.qvel[:] += dv
        if counts is not None:
            counts[0] += 1
        if not np.all(np.isfinite(d.qvel)):
            return Code.UNSTABLE
        d.qacc_warmstart[:] = d.qacc
        mujoco.mj_integratePos(m, d.qpos, d.qvel, dt)
        d.time += dt
        if history is not None:
            history[0], history[1], history[2:] = d.time, dt, dv
        return 0
