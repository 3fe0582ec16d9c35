"""Run a plate test (drag or rotate) on MuJoCo and collect its results.

The drive joint carries a very large armature, so the RFT load changes its speed by about 1e-9 of itself per
stroke: the force the drive applies to hold the motion is ``-armature * qacc``, and its impulse over a stroke
``-armature`` times the change of its velocity. At a reversal of the triangle wave the drive is put back on the
exact profile and its velocity jumps; the rest of the plate receives the impulse an ideal kinematic constraint
would give it (computed with the plate's own mass matrix): `stepping.Prescribed`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any, Callable

import mujoco
import numpy as np

from . import geometry
from .convergence import ErrorLimits
from .coupling import SegmentForces
from .drive import Drive
from .experiment import Compared, Plot, Quantity, Result, run
from .models import PlateModel, build_plate
from .scene import Scene
from .stepping import Prescribed


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
    shape = "segment_angle"  # the series whose angles give the plate's shape
    load = "drive_force"     # the series of the drive's load, whatever the test

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

    def independent(self, scene: Scene, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray:
        """The segment angles (rad) of the independent solution (finrft.reference) at ``times``."""
        from .reference import solve  # scipy's integrators load only when asked for
        # a law the [medium] gives, as numbers: the reference writes out the laws, not their derivation
        given = geometry.chain_law(scene)[0] if geometry.from_medium(scene) else None
        return solve(scene, self.drive, times, rtol=rtol, atol=atol, law=given).segment_angle

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
            **geometry.resolve(run.scene).figures(),
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


def simulate(scene: Scene, drive: Drive, *, progress: Callable[[float], None] | None = None,
             max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Result:
    """Simulate one plate test: `experiment.run` of `PlateTest(drive)`, with an estimate of its discretisation
    error (``run.error_estimate``, from a companion run: see finrft.convergence). Raises SimulationUnstable rather
    than return a diverged run, and InaccurateResult when the estimate exceeds ``max_error`` (None: report it
    only). ``estimate_error=False`` skips the estimate, for studies that measure the error themselves."""
    return run(PlateTest(drive), scene, progress=progress, max_error=max_error, estimate_error=estimate_error)
