"""Run a plate test (drag or rotate) on MuJoCo and collect its results.

The drive joint carries a very large armature, so the RFT load changes its speed by about 1e-9 of itself per
stroke: the force the drive applies to hold the motion is ``-armature * qacc``, and its impulse over a stroke
``-armature`` times the change of its velocity. At a reversal of the triangle wave the drive is put back on the
exact profile and its velocity jumps; the rest of the plate receives the impulse an ideal kinematic constraint
would give it (computed with the plate's own mass matrix). `step_through` and `Prescribed` serve the robot too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from .convergence import (ErrorLimits, Estimated, SimulationUnstable, check_resolution, check_size, checked,
                          max_difference, paired, record_every, require_finite)
from .coupling import PythonCoupling, SegmentForces, installed
from .drive import Drive
from .integrate import Stepper, stepper
from .models import PlateModel, build_plate
from .native import Code, captured_warnings
from .scene import Scene

_BAD_STATE = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)


@dataclass
class Run(Estimated):
    """Results of one plate test, SI units. Drag: metres and newtons; rotate: radians and newton-metres."""

    scene: Scene
    drive: Drive
    time: np.ndarray               # (T,) s
    displacement: np.ndarray       # (T,) base displacement along +y (m) or rod rotation about z (rad)
    segment_angle: np.ndarray      # (T, N) rad, change of each segment's absolute orientation since t = 0
    hinge_angle: np.ndarray        # (T, N) rad, hinge angles (zero for a rigid plate)
    drive_force: np.ndarray        # (T,) N or N m that the drive applies to the plate along +y / about +z
    rft_force: np.ndarray          # (T, N, 3) N, RFT force on each segment, world frame
    stroke_impulse: np.ndarray     # (strokes,) integral of the drive force over each stroke (N s or N m s)
    peak_drive_force: float        # max |drive force| over the recorded samples
    steps: int                     # steps taken (the adaptive method's accepted steps)
    wall_s: float
    backend: str = "python"
    steps_rejected: int = 0        # the adaptive method's rejected steps, and newton's halved ones

    @property
    def stroke_time(self) -> float:
        return self.drive.stroke_time

    def differences(self, other: Run) -> dict[str, float]:
        """Largest differences from a run of the same test at another resolution, at the same instants: segment
        and hinge angles (deg) and the per-stroke mean drive load (N or N m)."""
        i, j = paired(self.time, other.time)
        angles = max(max_difference(self.segment_angle[i], other.segment_angle[j]),
                     max_difference(self.hinge_angle[i], other.hinge_angle[j]))
        stroke_load = max_difference(self.stroke_impulse, other.stroke_impulse) / self.drive.stroke_time
        return {"angle_deg": float(np.degrees(angles)), f"{self.quantity}_{self.unit}": stroke_load}

    @property
    def quantity(self) -> str:
        return "force" if self.drive.kind == "drag" else "torque"

    @property
    def unit(self) -> str:
        return "N" if self.drive.kind == "drag" else "Nm"

    def cycle_table(self) -> list[dict[str, float]]:
        """Per out-and-back cycle: mean drive force/torque in the recovery (out) and power (back) strokes and the
        net impulse the medium gives the plate (minus the drive's), positive along +y / about +z."""
        if self.drive.cycles is None:
            return []
        q, u, ts = self.quantity, self.unit, self.drive.stroke_time
        rows = []
        for c in range(self.drive.cycles):
            out, back = self.stroke_impulse[2 * c], self.stroke_impulse[2 * c + 1]
            rows.append({f"mean_recovery_{q}_{u}": float(out / ts), f"mean_power_{q}_{u}": float(back / ts),
                         f"net_impulse_{u}s": float(-(out + back))})
        return rows

    def summary(self) -> dict[str, Any]:
        """The figures `finrft ... --json` prints, as plain Python numbers."""
        q, u = self.quantity, self.unit
        out: dict[str, Any] = {
            "test": self.drive.kind,
            "plate": self.scene.plate.kind,
            "final_segment_angle_deg": np.degrees(self.segment_angle[-1]).tolist(),
            "final_hinge_angle_deg": np.degrees(self.hinge_angle[-1]).tolist(),
            f"peak_drive_{q}_{u}": float(self.peak_drive_force),
            "steps": int(self.steps),
            "steps_rejected": int(self.steps_rejected),
            "sim_time_s": float(self.time[-1]),
            "wall_s": float(self.wall_s),
            "backend": self.backend,
            "integrator": self.scene.sim.integrator,
            "dt": float(self.scene.sim.dt),
        }
        if self.error_estimate is not None:
            out["error_estimate"] = dict(self.error_estimate)
            out["error_companion"] = self.error_companion
        cycles = self.cycle_table()
        if cycles:
            later = cycles[1:] or cycles
            out["first_cycle"] = cycles[0]
            out["cycles"] = cycles
            for key in (f"mean_recovery_{q}_{u}", f"mean_power_{q}_{u}", f"net_impulse_{u}s"):
                out[key] = float(np.mean([row[key] for row in later]))
            out["cycles_averaged"] = f"{2 if len(cycles) > 1 else 1}..{len(cycles)}"
        return out


class Prescribed:
    """Joints that follow a `Drive` exactly: a very large armature holds their speed within a stroke, and at
    each reversal the rest of the system takes the impulse an ideal kinematic constraint would give it.

    The drive's impulse over a stroke is exactly -armature times the change of its velocity (summed over the
    joints), and its instantaneous force or torque is -armature * qacc.
    """

    def __init__(self, dofs: Sequence[int], qpos: Sequence[int], armature: float, drive: Drive) -> None:
        self.dofs, self.qpos, self.armature, self.drive = list(dofs), list(qpos), armature, drive
        self.impulse = np.zeros(drive.strokes)
        self._stroke_velocity = np.zeros(len(self.dofs))
        self._stroke = 0

    def start_stroke(self, m: mujoco.MjModel, d: mujoco.MjData, k: int) -> None:
        if k:
            self._close(d)
            d.qpos[self.qpos] = self.drive.stroke_start(k)
            self._reverse(m, d, self.drive.stroke_velocity(k) - d.qvel[self.dofs])
        else:
            d.qvel[self.dofs] = self.drive.stroke_velocity(0)
        self._stroke, self._stroke_velocity = k, d.qvel[self.dofs].copy()

    def finish(self, d: mujoco.MjData) -> None:
        self._close(d)

    def load(self, d: mujoco.MjData) -> np.ndarray:
        """What each joint's drive applies now (after mj_forward): N or N m."""
        return -self.armature * d.qacc[self.dofs]

    def _close(self, d: mujoco.MjData) -> None:
        self.impulse[self._stroke] = -self.armature * np.sum(d.qvel[self.dofs] - self._stroke_velocity)

    def _reverse(self, m: mujoco.MjModel, d: mujoco.MjData, jump: np.ndarray) -> None:
        """Velocity jumps ``jump`` on the driven joints: M0 dq = E mu with E^T dq = jump, where M0 is the mass
        matrix without the artificial armature."""
        mujoco.mj_forward(m, d)
        mass = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, mass)
        mass[self.dofs, self.dofs] -= self.armature
        columns = np.linalg.solve(mass, np.eye(m.nv)[:, self.dofs])
        d.qvel[:] += columns @ np.linalg.solve(columns[self.dofs], jump)


def unstable(scene: Any, t: float, messages: list[str], code: int = 1) -> SimulationUnstable:
    sim = scene.sim
    if code == Code.STEP_TOO_SMALL:
        return SimulationUnstable(
            f"the adaptive step fell below 1e-9 s at t = {t:.4g} s (tolerance {sim.tolerance:g}): raise "
            f"sim.tolerance or rft.v_reg, or use sim.method = 'newton'")
    if code == Code.ARENA_FULL:
        return SimulationUnstable(
            f"the native step's workspace does not fit in MuJoCo's arena at t = {t:.4g} s: use sim.backend = "
            f"'python'")
    if code == Code.NOT_CONVERGED:
        return SimulationUnstable(
            f"Newton's method of the implicit step did not converge at t = {t:.4g} s (dt = {sim.dt:g} s): reduce "
            f"sim.dt or raise rft.v_reg")
    what = messages[0].rstrip(".") if messages else "the velocity became NaN or Inf"
    advice = ("reduce sim.dt, raise the inertias or rft.v_reg, or use sim.method = 'newton'"
              if sim.method == "explicit" else "reduce sim.dt (or sim.max_step), or raise rft.v_reg")
    return SimulationUnstable(f"simulation went unstable at t = {t:.4g} s ({what}) with method {sim.method}, "
                              f"integrator {sim.integrator}, dt = {sim.dt:g} s: {advice}")


def chatter(scene: Any, t: float) -> SimulationUnstable:
    sim = scene.sim
    return SimulationUnstable(
        f"the RFT force chatters at t = {t:.4g} s (it reverses every step: the segments overshoot) with method "
        f"{sim.method}, dt = {sim.dt:g} s: use sim.method = 'newton', or reduce sim.dt")


def schedule(drive: Drive, dt: float, record_dt: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Step count, the steps at which each stroke starts, and the steps recorded (always the first and last);
    SceneError when dt cannot resolve a stroke."""
    check_resolution(drive.stroke_time, dt)
    steps = max(1, round(drive.duration / dt))
    every = record_every(dt, record_dt)
    check_size(steps, steps // every + 1, dt, drive.duration)
    starts = np.array([round(k * drive.stroke_time / dt) for k in range(drive.strokes)])
    samples = np.unique(np.r_[np.arange(0, steps, every), steps])
    return steps, starts, samples


# A recorded sample chatters when some watched dof's velocity, over the three steps before it, moves by more than
# CHATTER_DV (rad/s or m/s) one way, back, and that way again: an overshoot every step (the RFT force reversing
# each step), which no oscillation the steps resolve can do. Every PROBE_EVERY-th sample is checked (each check
# costs three single steps); CHATTER_SAMPLES checked samples in a row stop the run.
# Chatter swings a segment across the law's regularisation speed (v_reg ~ 1 mm/s at levers of centimetres:
# ~0.1 rad/s); a hinge resting on a MuJoCo limit jitters by ~2e-3 rad/s, which is no chatter.
CHATTER_DV = 1e-2
CHATTER_SAMPLES = 3
PROBE_EVERY = 2


def step_through(m: mujoco.MjModel, d: mujoco.MjData, scene: Any, advance: Stepper, steps: int,
                 starts: np.ndarray, samples: np.ndarray, on_stroke: Callable[[int], None],
                 on_sample: Callable[[int], None], progress: Callable[[float], None] | None = None,
                 watch: Sequence[int] = (), forward: bool = True) -> None:
    """Step a model through a run: ``on_stroke(k)`` as stroke k starts, ``on_sample(i)`` (after mj_forward, unless
    ``forward`` is False: then only the state is current) at recorded step ``samples[i]``; ``advance`` steps in
    chunks in between. Stops loudly if the state blows up, or if the ``watch`` dofs chatter (fixed-step methods:
    the three steps before every PROBE_EVERY-th sample are taken one by one and checked when the run ends)."""
    probe = len(watch) > 0 and scene.sim.method != "adaptive"
    # velocity[i, j]: the watched velocities 3 - j steps before sample i (j = 3: at the sample)
    velocity = np.full((len(samples), 4, len(watch)), np.nan)
    slot: dict[int, list[tuple[int, int]]] = {}
    for i, s in enumerate(samples if probe else []):
        for j in range(4 if i % PROBE_EVERY == 0 else 0):
            slot.setdefault(int(s) - 3 + j, []).append((i, j))
    events = np.union1d(np.union1d(samples, starts), np.array([s for s in slot if s >= 0], dtype=int))
    stroke_of = np.searchsorted(starts, events, side="right") - 1
    counts = d.warning.number
    bad = [int(w) for w in _BAD_STATE]
    messages: list[str] = []
    sample = 0
    with captured_warnings(messages):
        for i, step in enumerate(events):
            k = stroke_of[i]
            if step == starts[k]:
                on_stroke(k)
            for at in slot.get(step, ()):
                velocity[at] = d.qvel[watch]
            if sample < len(samples) and step == samples[sample]:
                if forward:
                    mujoco.mj_forward(m, d)
                on_sample(sample)
                sample += 1
                if progress is not None:
                    progress(step / steps)
            if step == steps:
                break
            code = advance(d, int(events[i + 1] - step))
            if code or any(counts[w] for w in bad):
                raise unstable(scene, d.time, messages, code or 1)
    if probe:
        # Samples whose three steps before lie in one stroke (a reversal jumps the velocities on purpose).
        inside = np.searchsorted(starts, samples - 3, side="right") == np.searchsorted(starts, samples, side="right")
        moves = np.diff(velocity, axis=1)
        flips = np.any(np.all(np.abs(moves) > CHATTER_DV, axis=1) & np.all(moves[:, 1:] * moves[:, :-1] < 0, axis=1),
                       axis=1) & inside
        probed = np.arange(0, len(samples), PROBE_EVERY)
        runs = np.convolve(flips[probed], np.ones(CHATTER_SAMPLES, int), mode="valid")
        if np.any(runs == CHATTER_SAMPLES):
            first = probed[int(np.argmax(runs == CHATTER_SAMPLES)) + CHATTER_SAMPLES - 1]
            raise chatter(scene, samples[first] * scene.sim.dt)


def simulate(scene: Scene, drive: Drive, *, progress: Callable[[float], None] | None = None,
             max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Run:
    """Simulate one plate test, with an estimate of its discretisation error (``run.error_estimate``, from a
    companion run: see finrft.convergence). Raises SimulationUnstable rather than return a diverged run, and
    InaccurateResult when the estimate exceeds ``max_error`` (None: report it only). ``estimate_error=False``
    skips the estimate, for studies that measure the error themselves."""
    return checked(lambda s: build_plate(s, drive.kind, drive.attack_deg),
                   lambda s, plate, p, companion: _simulate(s, drive, plate, p, companion), scene, progress,
                   max_error, estimate_error)


def _simulate(scene: Scene, drive: Drive, plate: PlateModel, progress: Callable[[float], None] | None,
              companion: bool) -> Run:
    start = time.perf_counter()
    m = plate.model
    d = mujoco.MjData(m)
    forces = SegmentForces(plate.groups[0])
    callback = PythonCoupling(plate.groups) if plate.backend == "python" else None
    dt = scene.sim.dt
    steps, starts, samples = schedule(drive, dt, scene.sim.record_dt)
    base = Prescribed([plate.drive_dof], [plate.drive_qpos], plate.armature, drive)

    n = scene.plate.segments
    rec_x = np.zeros(len(samples))
    rec_q = np.zeros((len(samples), n))
    rec_f = np.zeros(len(samples))
    rec_cvel = np.zeros((len(samples), n, 6))
    rec_offset = np.zeros((len(samples), n, 3))
    rec_frame = np.zeros((len(samples), n, 3, 3))
    hinges = plate.hinge_qpos

    def record(i: int) -> None:
        rec_x[i] = d.qpos[plate.drive_qpos]
        rec_q[i, :len(hinges)] = d.qpos[hinges]
        if not companion:
            rec_f[i] = base.load(d)[0]
            forces.snapshot(m, d, rec_cvel[i], rec_offset[i], rec_frame[i])

    advance = stepper(m, scene.sim, plate.backend, plate.groups)
    with installed(callback):
        step_through(m, d, scene, advance, steps, starts, samples, lambda k: base.start_stroke(m, d, k), record,
                     progress, () if companion else plate.hinge_dof, forward=not companion)
    base.finish(d)

    segment_angle = np.cumsum(rec_q, axis=1)
    if drive.kind == "rotate":
        segment_angle += rec_x[:, None]
    run = Run(scene=scene, drive=drive, time=samples * dt, displacement=rec_x, segment_angle=segment_angle,
              hinge_angle=rec_q, drive_force=rec_f, rft_force=forces.recorded(rec_cvel, rec_offset, rec_frame),
              stroke_impulse=base.impulse, peak_drive_force=float(np.max(np.abs(rec_f))), steps=advance.taken,
              wall_s=time.perf_counter() - start, backend=plate.backend, steps_rejected=advance.rejected)
    require_finite({"displacement": rec_x, "segment_angle": segment_angle, "drive_force": rec_f,
                    "rft_force": run.rft_force, "stroke_impulse": base.impulse}, f"{drive.kind} at dt {dt:g} s")
    return run
