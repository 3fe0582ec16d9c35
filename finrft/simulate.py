"""Run a plate test (drag or rotate) on MuJoCo and collect its results.

The drive joint carries a very large armature, so the RFT load changes its speed by about 1e-9 of itself per
stroke: the force the drive applies to hold the motion is ``-armature * qacc``, and its impulse over a stroke
``-armature`` times the change of its velocity. At a reversal of the triangle wave the drive is put back on the
exact profile and its velocity jumps; the rest of the plate receives the impulse an ideal kinematic constraint
would give it (computed with the plate's own mass matrix). `step_through` and `Prescribed` serve the robot too.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import mujoco
import numpy as np

from .convergence import ErrorLimits, SimulationUnstable, check_resolution, check_size, record_every
from .coupling import SegmentForces
from .drive import Drive
from .experiment import Compared, Plot, Quantity, Result, run
from .integrate import Stepper
from .models import PlateModel, build_plate
from .native import Code, captured_warnings
from .scene import Scene

_BAD_STATE = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL)


SIGN_CONVENTION = (
    "A drag moves the base along +y; a rotation turns the rod about +z through the base. Angles are positive "
    "counter-clockwise about +z. The drive force (torque) is what the drive applies to the plate, along +y "
    "(about +z).")


@dataclass(frozen=True)
class PlateTest:
    """The paper's plate tests as an experiment (finrft.experiment): the base dragged along +y or the rod turned
    about z by a `Drive`. Its result's series, SI units (drag: metres and newtons; rotate: radians and newton-metres):
    ``displacement`` (or ``rotation``), ``segment_angle`` and ``hinge_angle`` (T, N), ``drive_force`` (or
    ``drive_torque``), ``rft_force`` (T, N, 3) and ``stroke_impulse`` per stroke; also offered as
    ``run.displacement`` and ``run.drive_force`` whatever the test, with ``run.peak_drive_force``."""

    drive: Drive
    schema = "finrft.run/1"
    sign_convention = SIGN_CONVENTION

    @property
    def name(self) -> str:
        return self.drive.kind

    @property
    def quantity(self) -> str:
        return "force" if self.drive.kind == "drag" else "torque"

    @property
    def unit(self) -> str:
        return "N" if self.drive.kind == "drag" else "Nm"

    def build(self, scene: Scene) -> PlateModel:
        return build_plate(scene, self.drive.kind, self.drive.attack_deg)

    def drive_for(self, scene: Scene) -> Drive:
        return self.drive

    def quantities(self, scene: Scene) -> dict[str, Quantity]:
        drag = self.drive.kind == "drag"
        motion = "displacement" if drag else "rotation"
        load = "drive_force" if drag else "drive_torque"
        return {
            motion: Quantity("m" if drag else "rad", "base displacement along +y" if drag else "rod rotation about +z",
                             plot=Plot(f"drive/{motion}", motion.capitalize() + (" (mm)" if drag else " (deg)"),
                                       motion, "mm" if drag else "deg")),
            "segment_angle": Quantity("rad", "change of each segment's absolute orientation since t = 0",
                                      plot=Plot("angles/segment", "Segment angles (deg)", "segment", "deg", "seg")),
            "hinge_angle": Quantity("rad", "hinge angles, segment i relative to the body before it",
                                    plot=Plot("angles/hinge", "Hinge angles (deg)", "hinge", "deg", "hinge")),
            load: Quantity("N" if drag else "N m", "force (torque) the drive applies to the plate",
                           plot=Plot("drive/force" if drag else "drive/torque",
                                     "Drive force (N)" if drag else "Drive torque (N m)",
                                     "drive force" if drag else "drive torque")),
            "rft_force": Quantity("N", "resistive force of the medium on each segment, at its midpoint",
                                  attrs={"frame": "world"}),
            "stroke_impulse": Quantity("N s" if drag else "N m s", "integral of the drive load over each stroke",
                                       per="stroke"),
        }

    def compared(self, scene: Scene) -> tuple[Compared, ...]:
        """Segment and hinge angles (deg) and the per-stroke mean drive load (N or N m)."""
        return (Compared("angle_deg", ("segment_angle", "hinge_angle"), float(np.degrees(1.0))),
                Compared(f"{self.quantity}_{self.unit}", ("stroke_impulse",), 1 / self.drive.stroke_time))

    def start(self, scene: Scene, plate: PlateModel, d: mujoco.MjData, companion: bool) -> _PlateTrial:
        return _PlateTrial(self, scene, plate, d, companion)

    def check(self, result: Result) -> None:
        pass

    def attrs(self) -> dict[str, Any]:
        return {"drive_json": json.dumps(dataclasses.asdict(self.drive))}

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        """Per out-and-back cycle: mean drive force/torque in the recovery (out) and power (back) strokes and the
        net impulse the medium gives the plate (minus the drive's), positive along +y / about +z."""
        if self.drive.cycles is None:
            return []
        q, u, ts = self.quantity, self.unit, self.drive.stroke_time
        rows = []
        for c in range(self.drive.cycles):
            out, back = run.stroke_impulse[2 * c], run.stroke_impulse[2 * c + 1]
            rows.append({f"mean_recovery_{q}_{u}": float(out / ts), f"mean_power_{q}_{u}": float(back / ts),
                         f"net_impulse_{u}s": float(-(out + back))})
        return rows

    def summary(self, run: Result) -> dict[str, Any]:
        q, u = self.quantity, self.unit
        out: dict[str, Any] = {
            "test": self.drive.kind,
            "plate": run.scene.plate.kind,
            "final_segment_angle_deg": np.degrees(run.segment_angle[-1]).tolist(),
            "final_hinge_angle_deg": np.degrees(run.hinge_angle[-1]).tolist(),
            f"peak_drive_{q}_{u}": float(run.peak_drive_force),
        }
        cycles = self.cycle_table(run)
        if cycles:
            later = cycles[1:] or cycles
            out["first_cycle"] = cycles[0]
            out["cycles"] = cycles
            for key in (f"mean_recovery_{q}_{u}", f"mean_power_{q}_{u}", f"net_impulse_{u}s"):
                out[key] = float(np.mean([row[key] for row in later]))
            out["cycles_averaged"] = f"{2 if len(cycles) > 1 else 1}..{len(cycles)}"
        return out

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from .views import draw_plate
        return draw_plate(rec, run, times, prefix)


class _PlateTrial:
    """One plate test on one MjData: the base on its prescribed profile, the plate's state and loads read."""

    def __init__(self, test: PlateTest, scene: Scene, plate: PlateModel, d: mujoco.MjData, companion: bool) -> None:
        self.test, self.scene, self.plate = test, scene, plate
        m = plate.model
        self.base = Prescribed([plate.drive_dof], [plate.drive_qpos], plate.armature, test.drive)
        self.forces = SegmentForces(plate.groups[0])
        self.on_stroke = lambda k: self.base.start_stroke(m, d, k)
        self.watch = list(plate.hinge_dof)
        n, hinges = scene.plate.segments, plate.hinge_qpos

        def hinge(d: mujoco.MjData) -> np.ndarray:
            q = np.zeros(n)
            q[:len(hinges)] = d.qpos[hinges]
            return q

        def snapshot(d: mujoco.MjData) -> np.ndarray:
            cvel, offset, frame = np.zeros((n, 6)), np.zeros((n, 3)), np.zeros((n, 3, 3))
            self.forces.snapshot(m, d, cvel, offset, frame)
            return np.concatenate([cvel, offset, frame.reshape(n, 9)], axis=1)

        self.reads = {"x": lambda d: d.qpos[plate.drive_qpos], "hinge": hinge}
        if not companion:
            self.reads.update(load=lambda d: self.base.load(d)[0], snapshot=snapshot)

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        self.base.finish(d)
        x, q = readings["x"], readings["hinge"]
        segment_angle = np.cumsum(q, axis=1)
        if self.test.drive.kind == "rotate":
            segment_angle += x[:, None]
        load = readings.get("load", np.zeros(len(x)))
        snap = readings.get("snapshot")
        rft = (np.zeros((*q.shape, 3)) if snap is None else
               self.forces.recorded(snap[..., :6], snap[..., 6:9], snap[..., 9:].reshape(*q.shape, 3, 3)))
        names = list(self.test.quantities(self.scene))
        # displacement and drive_force name the rotation and the torque too: the names callers use for any test
        series = {names[0]: x, "segment_angle": segment_angle, "hinge_angle": q, names[3]: load, "rft_force": rft,
                  "stroke_impulse": self.base.impulse, "displacement": x, "drive_force": load}
        return series, {"peak_drive_force": float(np.max(np.abs(load)))}


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
             max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Result:
    """Simulate one plate test: `experiment.run` of `PlateTest(drive)`, with an estimate of its discretisation
    error (``run.error_estimate``, from a companion run: see finrft.convergence). Raises SimulationUnstable rather
    than return a diverged run, and InaccurateResult when the estimate exceeds ``max_error`` (None: report it
    only). ``estimate_error=False`` skips the estimate, for studies that measure the error themselves."""
    return run(PlateTest(drive), scene, progress=progress, max_error=max_error, estimate_error=estimate_error)
