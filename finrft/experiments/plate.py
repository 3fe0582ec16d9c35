"""Run a plate test (drag or rotate) on MuJoCo and collect its results.

The drive joint carries a very large armature, so the RFT load changes its speed by about 1e-9 of itself per
stroke: the force the drive applies to hold the motion is ``-armature * qacc``, and its impulse over a stroke
``-armature`` times the change of its velocity. At a reversal of the triangle wave the drive is put back on the
exact profile and its velocity jumps; the rest of the plate receives the impulse an ideal kinematic constraint
would give it (computed with the plate's own mass matrix): `stepping.Prescribed`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import mujoco
import numpy as np

from .. import geometry, laws, methods, native
from ..convergence import ErrorLimits
from ..coupling import SegmentForces
from ..drive import Drive
from ..errors import UsageError
from ..experiment import Compared, Plot, Quantity, Result, run
from ..files import atomic_path
from ..geometry import Resolved, resolve
from ..models import (ARMATURE_RATIO, AttachedChain, ForceGroup, addresses, attach_chain, bind_plugin,
                      compile_spec, force_group, new_spec, penalty_stiffness)
from ..scene import Chain, Scene, SceneError, load_scene, parse_override, presets, read_text
from ..stepping import Prescribed
from ..views import centre_line
from .command import Command, Output, authors_model_line, error_line, register, steps_line
from .flags import add_max_error, add_result_files, add_scene_flags, number, preset_name


# ---------------------------------------------------------------------------------------------------------
# The model: mjcf/plate.xml, its rod on the drive, the chain of segments attached (finrft.models)

DRIVES = ("drag", "rotate")


@dataclass(frozen=True)
class PlateModel:
    """A compiled plate model and the indices the simulation needs."""

    model: mujoco.MjModel
    backend: str               # "native" (the RFT plugin is bound to the segments) or "python"
    drive: str                 # "drag" or "rotate"
    drive_dof: int
    drive_qpos: int
    armature: float            # the drive's armature (kg or kg m^2)
    hinge_qpos: np.ndarray     # (H,) qpos address of each hinge: H = segments, or 0 for a rigid plate
    hinge_dof: np.ndarray      # (H,)
    groups: tuple[ForceGroup, ...]  # the segments' RFT (one group)
    resolved: Resolved         # the forces the scene's medium and geometry give (finrft.geometry.resolve)


def _quat_z(angle: float) -> list[float]:
    return [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)]


def initial_heading(drive: str, attack_deg: float) -> float:
    """The plate's orientation about z at t = 0: a drag along +y at angle of attack theta starts at 90 deg - theta."""
    return float(np.radians(90.0 - attack_deg)) if drive == "drag" else 0.0


@dataclass(frozen=True)
class _Plate:
    spec: mujoco.MjSpec
    drive: mujoco.MjsJoint
    chain: AttachedChain


# The drive's speed changes by load x dt / armature in a step, which the step's rounding of the speed (half its
# spacing) must resolve: ARMATURE_RATIO x the inertia moved made the authors' rotated plate (segments of 1 kg m^2)
# so heavy that its 0.2 N m load changed the speed by 7e-17 rad/s a step at dt = 1e-5 s, below the rounding of
# 1.05 rad/s, and its per-stroke mean torques came out 0. The armature is at most what keeps that rounding below
# DRIVE_RESOLUTION of the load's scale (the RFT force of every segment moving at the drive's speed); the drive's lag
# then stays below about steps per stroke x 6e-13 of the stroke (3e-7 at 4e5 steps).
DRIVE_RESOLUTION = 1e-4


def load_scale(scene: Scene, resolved: Resolved, drive: str, speed: float) -> float:
    """The drive's load when every segment moves at its speed on the drive, normal to its face: the sum of the
    segments' largest RFT force (times their radius from the base, for a rotation): N or N m."""
    force = laws.bind(resolved.chain)
    p = scene.plate
    radii = p.rod_length + (np.arange(p.segments) + 0.5) * p.segment_length
    angles = np.radians(np.arange(0.0, 181.0, 15.0))
    axes = np.broadcast_to([1.0, 0.0, 0.0], (len(angles), 3))
    normals = np.broadcast_to([0.0, 1.0, 0.0], (len(angles), 3))
    total = 0.0
    for r in radii:
        v = speed * (r if drive == "rotate" else 1.0)
        largest = np.linalg.norm(force(v * np.column_stack([np.cos(angles), np.sin(angles), 0 * angles]), axes,
                                       normals), axis=1).max()
        total += largest * (r if drive == "rotate" else 1.0)
    return float(total)


def drive_armature(moved: float, scene: Scene, resolved: Resolved, drive: str, speed: float | None) -> float:
    """The drive's armature: ARMATURE_RATIO x what it moves, at most what resolves the load (DRIVE_RESOLUTION) at
    ``speed`` (None: not capped)."""
    armature = ARMATURE_RATIO * moved
    if speed is None:
        return armature
    scale = load_scale(scene, resolved, drive, speed)
    # Python floats: a step too long for the stroke (refused when the drive is timed) gives inf, not numpy's warning
    resolving = 2 * DRIVE_RESOLUTION * float(scale) * scene.sim.dt / float(np.spacing(speed))
    return float(min(armature, resolving)) if resolving > 0 else armature


def _plate(scene: Scene, drive: str, attack_deg: float, backend: str, resolved: Resolved,
           speed: float | None = None) -> _Plate:
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {DRIVES}, got {drive!r}")
    p = scene.plate
    spec = new_spec("plate.xml", scene.sim)
    rod = spec.body("rod")
    rod.mass, rod.ipos = p.rod_mass, [p.rod_length / 2, 0, 0]
    rod.inertia = [p.rod_inertia] * 3
    spec.geom("rod").fromto = [0, 0, 0, p.rod_length, 0, 0]
    mount = spec.frame("chain")
    mount.pos = [p.rod_length, 0, 0]

    joint = spec.joint("drive")
    heading = initial_heading(drive, attack_deg)
    rod.quat = _quat_z(heading)
    if drive == "drag":
        joint.axis = [np.sin(heading), np.cos(heading), 0.0]  # world +y in the rotated rod frame
    else:
        joint.type = mujoco.mjtJoint.mjJNT_HINGE
        joint.axis = [0, 0, 1]
    chain = attach_chain(spec, mount, p, scene.sim.dt, "plate_", spatial=p.chain == "spatial",
                         welded=p.rigid_as == "welds")
    if backend == "native":
        bind_plugin(spec, "sand", resolved.chain, penalty_stiffness(p), chain.bodies)

    # Everything the drive moves, seen from the drive: total mass (slide) or inertia about the base (hinge).
    lumps = [(p.rod_mass, p.rod_inertia, p.rod_length / 2)] + [
        (p.segment_mass, p.segment_inertia, p.rod_length + (i + 0.5) * p.segment_length) for i in range(p.segments)]
    moved = sum(m for m, _, _ in lumps) if drive == "drag" else sum(i + m * r * r for m, i, r in lumps)
    joint.armature = drive_armature(moved, scene, resolved, drive, speed)
    spec.modelname = f"finrft {p.kind} plate ({drive})"
    return _Plate(spec, joint, chain)


def plate_spec(scene: Scene, drive: str = "drag", attack_deg: float = 90.0,
               backend: str = "python") -> mujoco.MjSpec:
    """The plate's MjSpec for a scene: drive ``drag`` (base slides along +y, the plate at angle of attack
    ``attack_deg`` to the motion) or ``rotate`` (the rod turns about z through its base); with backend
    ``native`` the RFT plugin is bound to the segments."""
    return _plate(scene, drive, attack_deg, backend, resolve(scene)).spec


def build_plate(scene: Scene, drive: str = "drag", attack_deg: float = 90.0,
                speed: float | None = None) -> PlateModel:
    """Compile the plate model for a scene and collect its indices; given the drive's ``speed``, its armature is
    one whose speed resolves the load (`drive_armature`)."""
    backend = native.resolve_backend(scene.sim.backend)
    resolved = resolve(scene)
    plate = _plate(scene, drive, attack_deg, backend, resolved, speed)
    model = compile_spec(plate.spec)
    group = force_group(model, "sand", resolved.chain, penalty_stiffness(scene.plate), plate.chain.bodies)
    (drive_qpos,), (drive_dof,) = addresses(model, [plate.drive])
    hinge_qpos, hinge_dof = addresses(model, plate.chain.hinges)
    return PlateModel(
        model=model,
        backend=backend,
        drive=drive,
        drive_dof=int(drive_dof),
        drive_qpos=int(drive_qpos),
        armature=float(model.dof_armature[drive_dof]),
        hinge_qpos=hinge_qpos,
        hinge_dof=hinge_dof,
        groups=(group,),
        resolved=resolved,
    )


# The chain's keys that reach a compiled plate as numbers of its hinges and nowhere else (the plugin reads neither):
# a plate that differs from a compiled one only in these is that model with them set (`retune`), which costs
# microseconds where a compile costs a millisecond. Tested field by field against fresh compiles.
RETUNABLE = ("stiffness", "damping")


def retune(plate: PlateModel, chain: Chain) -> None:
    """Give a compiled plate's hinges the chain's RETUNABLE values, in place."""
    m = plate.model
    m.jnt_stiffness[m.dof_jntid[plate.hinge_dof]] = chain.stiffness
    m.dof_damping[plate.hinge_dof] = chain.damping


def retune_key(scene: Scene) -> tuple:
    """What a plate's compiled model depends on besides its RETUNABLE keys: plates of equal keys differ only in
    those."""
    return (dataclasses.replace(scene.plate, **dict.fromkeys(RETUNABLE, 0.0)), scene.rft, scene.medium, scene.sim)


# ---------------------------------------------------------------------------------------------------------
# The experiment

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
    scene_type = Scene
    sign_convention = SIGN_CONVENTION
    shape = "segment_angle"  # the series whose angles give the plate's shape
    load = "drive_force"     # the series of the drive's load, whatever the test

    def __post_init__(self) -> None:
        if not isinstance(self.drive, Drive):
            raise SceneError(f"a plate test's drive must be a finrft.Drive, got {type(self.drive).__name__} "
                             f"{self.drive!r:.60}")

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
        return build_plate(scene, self.drive.kind, self.drive.attack_deg, self.drive.speed)

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
            "stroke_peak": Quantity("N" if drag else "N m", "largest magnitude of the drive load at any step (the "
                                    "adaptive methods: every sim.max_step) in each stroke", per="stroke"),
        }

    def compared(self, scene: Scene) -> tuple[Compared, ...]:
        """Segment and hinge angles (deg), the per-stroke mean drive load and each stroke's peak (N or N m)."""
        return (Compared("angle_deg", ("segment_angle", "hinge_angle"), float(np.degrees(1.0))),
                Compared(f"{self.quantity}_{self.unit}", ("stroke_impulse",), 1 / self.drive.stroke_time),
                Compared(f"peak_{self.quantity}_{self.unit}", ("stroke_peak",)))

    def resolution(self, run: Result) -> dict[str, float]:
        """The peak's own error, whatever a companion says: its change to the neighbouring steps (`Prescribed`)."""
        return {f"peak_{self.quantity}_{self.unit}": run.peak_resolution}

    def start(self, scene: Scene, plate: PlateModel, d: mujoco.MjData, companion: bool) -> _PlateTrial:
        return _PlateTrial(self, scene, plate, d, companion)

    def check(self, result: Result) -> None:
        pass

    def independent(self, scene: Scene, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray:
        """The segment angles (rad) of the independent solution (finrft.reference) at ``times``."""
        from ..reference import solve  # scipy's integrators load only when asked for
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
            # the largest load at every step's state: whatever sim.record_dt, in the error estimate
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
        return draw_plate(rec, run, times, prefix)


def plate_points(run: Result) -> np.ndarray:
    """The plate's centre line, (T, N + 2, 3) m: base point, rod tip (first hinge), the other hinges, plate tip."""
    p = run.scene.plate
    heading = initial_heading(run.drive.kind, run.drive.attack_deg)
    count = len(run.time)
    base = np.zeros((count, 3))
    if run.drive.kind == "drag":
        base[:, 1] = run.displacement
        rod_angle = np.full(count, heading)
    else:
        rod_angle = heading + run.displacement
    return centre_line(base, np.column_stack([rod_angle, heading + run.segment_angle]), p.rod_length, p)


def draw_plate(rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
    """The plate and its RFT forces seen from above."""
    import rerun as rr  # loads only when a recording is written
    import rerun.blueprint as rrb
    p = run.scene.plate
    n, count = p.segments, len(run.time)
    points = plate_points(run)
    midpoints = (points[:, 1:-1] + points[:, 2:]) / 2
    peak = float(np.max(np.linalg.norm(run.rft_force, axis=-1), initial=0.0))
    arrow_scale = p.segment_length / peak if peak > 0 else 0.0
    rec.log(f"{prefix}plate", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{prefix}plate/centerline", rr.LineStrips3D.from_fields(colors=[[60, 60, 70]], radii=[0.0005]),
            static=True)
    rec.send_columns(f"{prefix}plate/centerline", indexes=[times], columns=rr.LineStrips3D.columns(strips=points))
    rec.log(f"{prefix}plate/rft", rr.Arrows3D.from_fields(colors=[[230, 80, 20]], radii=[0.0006]), static=True)
    rec.log(f"{prefix}plate/rft", rr.AnyValues(arrow_scale_m_per_N=arrow_scale,
                                               note=f"arrow length = RFT force x {arrow_scale:.4g} m/N"), static=True)
    rec.send_columns(f"{prefix}plate/rft", indexes=[times], columns=rr.Arrows3D.columns(
        origins=midpoints.reshape(-1, 3), vectors=arrow_scale * run.rft_force.reshape(-1, 3),
    ).partition([n] * count))
    low, high = points.min(axis=(0, 1)), points.max(axis=(0, 1))
    centre = (low + high) / 2
    span = float(np.max(high - low)) or p.segment_length
    # Straight down the -z axis, with +y (the drag direction) up on screen.
    eye = rrb.EyeControls3D(position=centre + [0.0, 0.0, 2.0 * span], look_target=centre, eye_up=[0.0, 1.0, 0.0])
    # The default 1 m grid is coarser than the whole plate.
    return [rrb.Spatial3DView(name="Plate (top view, 1 cm grid)", origin=f"{prefix}plate", eye_controls=eye,
                              line_grid=rrb.LineGrid3D(spacing=0.01))]


class _PlateTrial:
    """One plate test on one MjData: the base on its prescribed profile, the plate's state and loads read."""

    def __init__(self, test: PlateTest, scene: Scene, plate: PlateModel, d: mujoco.MjData, companion: bool) -> None:
        self.test, self.scene, self.plate = test, scene, plate
        m = plate.model
        self.base = Prescribed([plate.drive_dof], [plate.drive_qpos], plate.armature, test.drive)
        self.forces = SegmentForces(plate.groups[0])
        self.on_stroke = lambda k: self.base.start_stroke(m, d, k)
        self.peak = self.base.load_peak
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
        self.base.finish(self.plate.model, d)
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
                  "stroke_impulse": self.base.impulse, "stroke_peak": self.base.peak, "displacement": x,
                  "drive_force": load}
        return series, {"peak_drive_force": float(np.max(self.base.peak)),
                        "peak_resolution": float(np.max(self.base.peak_change))}


def simulate(scene: Scene, drive: Drive, *, progress: Callable[[float], None] | None = None,
             max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Result:
    """Simulate one plate test: `experiment.run` of `PlateTest(drive)`, with an estimate of its discretisation
    error (``run.error_estimate``, from a companion run: see finrft.convergence). Raises SimulationUnstable rather
    than return a diverged run, and InaccurateResult when the estimate exceeds ``max_error`` (None: report it
    only). ``estimate_error=False`` skips the estimate, for studies that measure the error themselves."""
    return run(PlateTest(drive), scene, progress=progress, max_error=max_error, estimate_error=estimate_error)


# The steady force of a rigid-plate drag, written by `finrft drag --forces-csv` for `finrft fit-rft`.

FORCE_COLUMNS = ("attack_deg", "force_normal_N", "force_tangential_N")


def plate_forces(run: Result) -> dict[str, float]:
    """The medium's steady force on a rigid plate, decomposed along the plate's normal (the +y side at 90 deg
    attack) and its axis: the mean over the second half of the run, the first being any start-up."""
    heading = math.radians(90.0 - run.drive.attack_deg)
    axis, normal = np.array([math.cos(heading), math.sin(heading), 0.0]), np.array([-math.sin(heading),
                                                                                    math.cos(heading), 0.0])
    late = run.time >= 0.5 * run.time[-1]
    total = run.rft_force[late].sum(axis=1).mean(axis=0)
    return {"attack_deg": run.drive.attack_deg, "force_normal_N": float(total @ normal),
            "force_tangential_N": float(total @ axis)}


def append_forces(path: str | Path, row: dict[str, float]) -> None:
    """Add a row to a forces CSV, writing its header first when the file is new; SceneError when the file has
    another header. The file is replaced whole, so a failed write leaves it as it was."""
    check_forces_header(path)
    path = Path(path)
    text = read_text(path, "forces file") if path.exists() else ""
    text = (text if text.endswith("\n") else text + "\n") if text.strip() else ",".join(FORCE_COLUMNS) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text + ",".join(repr(float(row[k])) for k in FORCE_COLUMNS) + "\n")


def check_forces_run(scene: Scene, drive: Drive) -> None:
    """UsageError unless a run gives the steady force --forces-csv records: a rigid plate, one stroke out, faster
    than 3 x rft.v_reg, where the rate-independent force is reached."""
    if scene.plate.kind != "rigid":
        raise UsageError("--forces-csv needs a rigid plate (--plate rigid)")
    if drive.cycles is not None:
        raise UsageError("--forces-csv records the steady force of one stroke out: leave out --cycles")
    if drive.speed < 3 * scene.rft.v_reg:
        raise UsageError(f"--forces-csv needs a drag faster than 3 x rft.v_reg ({3e3 * scene.rft.v_reg:g} mm/s), "
                         f"where the rate-independent force is reached: got {1e3 * drive.speed:g} mm/s")


def check_forces_header(path: str | Path) -> None:
    """SceneError unless ``path`` is new, empty, or a forces CSV `append_forces` can add to."""
    path = Path(path)
    lines = [line for line in (read_text(path, "forces file").splitlines() if path.is_file() else [])
             if line.strip() and not line.startswith("#")]
    header = ",".join(FORCE_COLUMNS)
    if lines and lines[0] != header:
        raise SceneError(f"{path} has the header '{lines[0]}', not '{header}': append to a forces file written "
                         f"by finrft drag --forces-csv, or start a new one")


# ---------------------------------------------------------------------------------------------------------
# The commands: finrft drag and finrft rotate

PRESETS_HELP = ("built-in plate scene when no --scene is given (default: physical): physical = real inertias, "
                "fitted to the measurements, penalty stop, newton method; paper = the authors' plate with its "
                "quirks: inertias of 1 kg m^2, a law that feeds energy in, penalty stop, explicit method")


def add_plate_scene(p: argparse.ArgumentParser, *, kinds: bool = False, backend: bool = True):
    """The plate scene's flags (also those of the studies on plates: fit, fit-rft)."""
    g = add_scene_flags(p, "plate", "plate.segment_inertia=0.001", presets=presets(Scene), presets_help=PRESETS_HELP,
                        backend=backend and "where the RFT force is computed (overrides sim.backend; default native, "
                        "the C plugin, falling back to python when it cannot be loaded)")
    if kinds:
        g.add_argument("--plate", choices=("origami", "soft", "rigid"),
                       help="plate kind (overrides plate.kind): origami = one-sided stop, soft = compliant both "
                            "ways, rigid = does not bend")
    return g


def resolve_plate(args: argparse.Namespace) -> Scene:
    """The plate scene of --scene or --preset, --set, --plate and --backend."""
    overrides = dict(parse_override(item) for item in args.set)
    if getattr(args, "plate", None):
        overrides["plate.kind"] = args.plate
    if getattr(args, "backend", None):
        overrides["sim.backend"] = args.backend
    return load_scene(args.scene, preset_name=preset_name(args), overrides=overrides)


class _PlateCommand(Command):
    """drag and rotate: the flags of a plate test, its checks, and its summary text."""

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        add_plate_scene(p, kinds=True).add_argument(
            "--cycles", type=number("cycles", minimum=1, inclusive=True, integer=True), metavar="N",
            help="back-and-forth cycles of the triangle wave (the paper used 5; the first is reported separately); "
                 "without it, a single stroke out")
        o = p.add_argument_group("output")
        add_result_files(o)
        add_max_error(p)

    def scene(self, args: argparse.Namespace) -> Scene:
        return resolve_plate(args)

    def jobs(self, args: argparse.Namespace, scene: Scene) -> list[tuple[PlateTest, Scene]]:
        return [(PlateTest(self.drive(args)), scene)]

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        run, = runs
        summary = run.summary()
        q, u = run.quantity, run.unit
        sim = run.scene.sim
        lines = [*authors_model_line(args, run.scene),
                 f"{run.drive.kind} of the {run.scene.plate.kind} plate, {sim.method} method (dt {sim.dt * 1e3:g} ms, "
                 f"{sim.integrator}, {run.backend}): {steps_line(summary)} in {run.wall_s:.2f} s",
                 "final segment angles (deg): " + ", ".join(f"{a:.2f}" for a in summary["final_segment_angle_deg"]),
                 "final hinge angles (deg):   " + ", ".join(f"{a:.2f}" for a in summary["final_hinge_angle_deg"]),
                 f"peak drive {q}: {summary[f'peak_drive_{q}_{u}']:.4g} {u.replace('Nm', 'N m')} (the largest at "
                 f"{f'every {1e3 * sim.max_step:g} ms' if methods.get(sim.method).adaptive else 'every step'})"]
        for i, row in enumerate(run.cycle_table(), start=1):
            lines.append(f"cycle {i}: mean {q} recovery {row[f'mean_recovery_{q}_{u}']:+.4g}, "
                         f"power {row[f'mean_power_{q}_{u}']:+.4g}; net impulse {row[f'net_impulse_{u}s']:+.4g} {u}s")
        lines.append(error_line(run))
        return "\n".join(lines)


@register
class DragCommand(_PlateCommand):
    name = "drag"
    help = "drag a plate through the medium along +y (the paper's drag test)"
    description = ("Drag the plate's base along +y at constant speed: one stroke out from flat (the soft, recovery "
                   "direction of the origami plate), or --cycles back-and-forth cycles. Reports the drive force (N) "
                   "that holds the motion.")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("--speed", type=number("mm/s"), default=30.0, metavar="MM_S",
                       help="drag speed in mm/s (default: %(default)s)")
        p.add_argument("--distance", type=number("mm"), default=200.0, metavar="MM",
                       help="stroke length in mm (default: %(default)s)")
        p.add_argument("--attack", type=number("degrees", inclusive=True), default=90.0, metavar="DEG",
                       help="angle of attack between the plate and the motion, degrees in 0..180 "
                            "(default: %(default)s, plate normal to the motion)")
        super().add_flags(p)
        p.add_argument("--forces-csv", metavar="FILE.csv", help="append the steady force on the plate (normal and "
                       "tangential, N) at this angle of attack to a CSV, for finrft fit-rft (rigid plate only)")

    def drive(self, args: argparse.Namespace) -> Drive:
        if args.attack > 180:
            raise UsageError(f"argument --attack: must be within 0..180 degrees, got {args.attack:g}")
        return Drive("drag", args.speed / 1000, args.distance / 1000, args.cycles, args.attack)

    def jobs(self, args: argparse.Namespace, scene: Scene) -> list[tuple[PlateTest, Scene]]:
        jobs = super().jobs(args, scene)
        if args.forces_csv:
            check_forces_run(scene, jobs[0][0].drive)
            check_forces_header(args.forces_csv)
        return jobs

    def outputs(self, args: argparse.Namespace) -> list[Output]:
        return [*super().outputs(args), Output("--forces-csv", args.forces_csv, ".csv", "forces",
                                               lambda runs, path: append_forces(path, plate_forces(runs[0])),
                                               append=True)]


@register
class RotateCommand(_PlateCommand):
    name = "rotate"
    help = "turn a plate about its base (the paper's rotate test)"
    description = ("Turn the rod about z through its base at constant angular speed: one stroke counter-clockwise "
                   "from flat along +x, or --cycles back-and-forth cycles. Reports the drive torque (N m).")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("--amplitude", type=number("degrees"), default=120.0, metavar="DEG",
                       help="stroke angle in degrees, at most 360 (default: %(default)s)")
        p.add_argument("--omega", type=number("deg/s"), default=60.0, metavar="DEG_S",
                       help="angular speed in degrees/s (default: %(default)s)")
        super().add_flags(p)

    def drive(self, args: argparse.Namespace) -> Drive:
        if args.amplitude > 360.0:  # the Drive would speak of radians
            raise UsageError(f"--amplitude {args.amplitude:g} deg is more than one turn: give at most 360 degrees")
        return Drive("rotate", math.radians(args.omega), math.radians(args.amplitude), args.cycles)
