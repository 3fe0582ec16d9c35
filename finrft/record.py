"""File writers: HDF5 files for analysis and rerun recordings (.rrd) for viewing, of plate runs, swims and
optimisations.

Every writer goes through `files.atomic_path` (a temporary file in the target's directory replaced onto it), so an
interrupted or failed write never leaves a truncated file where a complete one is expected.
"""

from __future__ import annotations

import dataclasses
import json
import uuid
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .files import atomic_path, provenance
from .models import initial_heading
from .scene import to_toml
from .simulate import Run
from .swim import SwimRun

SCHEMA = "finrft.run/1"
SIGN_CONVENTION = (
    "A drag moves the base along +y; a rotation turns the rod about +z through the base. Angles are positive "
    "counter-clockwise about +z. The drive force (torque) is what the drive applies to the plate, along +y "
    "(about +z).")
# Written by write_h5 itself; extra_attrs may not replace them, or a file could contradict its own data.
_ROOT_ATTRS = ("schema", "scene_toml", "scene_json", "drive_json", "summary_json", "finrft_version",
               "mujoco_version", "numpy_version", "created_utc", "sign_convention")


def _motion(run: Run) -> tuple[str, str, str, str]:
    """Names and units of the drive's position and load: (position, its unit, load, its unit)."""
    if run.drive.kind == "drag":
        return "displacement", "m", "drive_force", "N"
    return "rotation", "rad", "drive_torque", "N m"


def _provenance(scene: Any, summary: dict[str, Any]) -> dict[str, Any]:
    """What every result file stores about how it was made, and the run's own error estimate (finrft.convergence),
    one attribute per quantity, the unit in its name: error_estimate_angle_deg, ..._force_N, ..._eta_points."""
    estimate = {f"error_estimate_{key}": value for key, value in (summary.get("error_estimate") or {}).items()}
    if estimate:
        estimate["error_companion"] = summary["error_companion"]
    return {"scene_toml": to_toml(scene), "scene_json": json.dumps(scene.to_dict()),
            "summary_json": json.dumps(summary), **provenance(), **estimate}


def _write_series(path: str | Path, time: np.ndarray, series: list[tuple[str, np.ndarray, str, str]],
                  attrs: dict[str, Any], dataset_attrs: dict[str, dict[str, str]] | None = None) -> None:
    """An HDF5 file of time series (name, data, SI unit, description) on the dimension scale ``time``, written
    atomically, with root attributes and any further attributes per dataset."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=True) as f:
        t = f.create_dataset("time", data=time)
        t.attrs.update(units="s", description="simulated time of each sample")
        t.make_scale("time")
        for name, data, unit, description in series:
            big = data.ndim > 1
            ds = f.create_dataset(name, data=data, chunks=True if big else None,
                                  compression="gzip" if big else None, shuffle=big)
            ds.attrs.update(units=unit, description=description, **(dataset_attrs or {}).get(name, {}))
            if len(data) == len(time):
                ds.dims[0].label = "time"
                ds.dims[0].attach_scale(t)
        f.attrs.update(attrs)


def write_h5(run: Run, path: str | Path, *, extra_attrs: dict[str, Any] | None = None) -> None:
    """Write a run to HDF5: time series at the root with SI ``units`` attributes, the scene, drive and summary as
    root attributes. ``extra_attrs`` are added to the root attributes."""
    extra = dict(extra_attrs or {})
    clash = sorted(set(extra) & set(_ROOT_ATTRS))
    if clash:
        raise ValueError(f"extra_attrs may not replace {', '.join(clash)}")
    position, position_unit, load, load_unit = _motion(run)
    series = [
        (position, run.displacement, position_unit,
         "base displacement along +y" if run.drive.kind == "drag" else "rod rotation about +z"),
        ("segment_angle", run.segment_angle, "rad", "change of each segment's absolute orientation since t = 0"),
        ("hinge_angle", run.hinge_angle, "rad", "hinge angles, segment i relative to the body before it"),
        (load, run.drive_force, load_unit, "force (torque) the drive applies to the plate"),
        ("rft_force", run.rft_force, "N", "resistive force of the medium on each segment, at its midpoint"),
        ("stroke_impulse", run.stroke_impulse, "N s" if run.drive.kind == "drag" else "N m s",
         "integral of the drive load over each stroke"),
    ]
    attrs = {"schema": SCHEMA, **_provenance(run.scene, run.summary()),
             "drive_json": json.dumps(dataclasses.asdict(run.drive)), "sign_convention": SIGN_CONVENTION, **extra}
    _write_series(path, run.time, series, attrs, {"rft_force": {"frame": "world"}})


def plate_points(run: Run) -> np.ndarray:
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
    return _centre_line(base, np.column_stack([rod_angle, heading + run.segment_angle]), p.rod_length, p)


def _centre_line(start: np.ndarray, angles: np.ndarray, first: float, chain) -> np.ndarray:
    """Points (T, N + 2, 3) of a rod of length ``first`` then a chain's segments, from ``start`` (T, 3), each at
    its absolute angle about z (T, N + 1)."""
    lengths = np.r_[first, np.full(chain.segments, chain.segment_length)]
    steps = np.zeros((*angles.shape, 3))
    steps[..., 0] = lengths * np.cos(angles)
    steps[..., 1] = lengths * np.sin(angles)
    return np.concatenate([start[:, None], start[:, None] + np.cumsum(steps, axis=1)], axis=1)


def _blueprint(run: Run, points: np.ndarray, load: tuple[str, str], motion: tuple[str, str]) -> rrb.Blueprint:
    low, high = points.min(axis=(0, 1)), points.max(axis=(0, 1))
    centre = (low + high) / 2
    span = float(np.max(high - low)) or run.scene.plate.segment_length
    # Straight down the -z axis, with +y (the drag direction) up on screen.
    eye = rrb.EyeControls3D(position=centre + [0.0, 0.0, 2.0 * span], look_target=centre, eye_up=[0.0, 1.0, 0.0])
    # The default 1 m grid is coarser than the whole plate.
    grid = rrb.LineGrid3D(spacing=0.01)
    plate = rrb.Spatial3DView(name="Plate (top view, 1 cm grid)", origin="plate", eye_controls=eye, line_grid=grid)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Tabs(plate, rrb.TextDocumentView(name="Scene", origin="scene"), active_tab=0),
            rrb.Vertical(
                rrb.TimeSeriesView(name="Segment angles (deg)", origin="angles/segment"),
                rrb.TimeSeriesView(name="Hinge angles (deg)", origin="angles/hinge"),
                # upper-case the first letter only: capitalize() would lower the unit, "(n)"
                *(rrb.TimeSeriesView(name=label[0].upper() + label[1:], origin=entity)
                  for entity, label in (load, motion)),
            ),
            column_shares=[3, 2],
        ),
    )


def _send_scalars(rec: rr.RecordingStream, entity: str, label: str, times: rr.TimeColumn,
                  values: np.ndarray) -> None:
    rec.log(entity, rr.SeriesLines(names=label), static=True)
    rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=values))


def write_rrd(run: Run, path: str | Path) -> None:
    """Write a run as a rerun recording with a ready-made layout: the plate and its RFT forces seen from above,
    and time series of the segment angles, hinge angles and the drive, on the timeline ``sim_time``."""
    p = run.scene.plate
    n = p.segments
    count = len(run.time)
    if run.drive.kind == "drag":
        load = ("drive/force", "drive force (N)")
        motion, motion_values = ("drive/displacement", "displacement (mm)"), 1e3 * run.displacement
    else:
        load = ("drive/torque", "drive torque (N m)")
        motion, motion_values = ("drive/rotation", "rotation (deg)"), np.degrees(run.displacement)
    points = plate_points(run)
    midpoints = (points[:, 1:-1] + points[:, 2:]) / 2
    peak = float(np.max(np.linalg.norm(run.rft_force, axis=-1), initial=0.0))
    arrow_scale = p.segment_length / peak if peak > 0 else 0.0

    rec = rr.RecordingStream("finrft", recording_id=uuid.uuid4())
    if not rec.is_enabled():
        raise RuntimeError(f"rerun logging is disabled (RERUN=off?), so {path} cannot be written")
    with atomic_path(path) as tmp:
        rec.save(tmp, default_blueprint=_blueprint(run, points, load, motion))
        try:
            times = rr.TimeColumn("sim_time", duration=run.time)
            rec.log("scene", rr.TextDocument(to_toml(run.scene), media_type=rr.MediaType.TEXT), static=True)
            rec.log("plate", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            rec.log("plate/centerline", rr.LineStrips3D.from_fields(colors=[[60, 60, 70]], radii=[0.0005]),
                    static=True)
            rec.send_columns("plate/centerline", indexes=[times], columns=rr.LineStrips3D.columns(strips=points))
            rec.log("plate/rft", rr.Arrows3D.from_fields(colors=[[230, 80, 20]], radii=[0.0006]), static=True)
            rec.log("plate/rft", rr.AnyValues(arrow_scale_m_per_N=arrow_scale,
                                              note=f"arrow length = RFT force x {arrow_scale:.4g} m/N"),
                    static=True)
            rec.send_columns("plate/rft", indexes=[times], columns=rr.Arrows3D.columns(
                origins=midpoints.reshape(-1, 3), vectors=arrow_scale * run.rft_force.reshape(-1, 3),
            ).partition([n] * count))
            for i in range(n):
                _send_scalars(rec, f"angles/segment/seg{i + 1}", f"segment {i + 1} (deg)", times,
                              np.degrees(run.segment_angle[:, i]))
                _send_scalars(rec, f"angles/hinge/hinge{i + 1}", f"hinge {i + 1} (deg)", times,
                              np.degrees(run.hinge_angle[:, i]))
            _send_scalars(rec, *load, times, run.drive_force)
            _send_scalars(rec, *motion, times, motion_values)
        finally:
            # Closes the file sink, so the footer is written (or the file released before it is removed).
            rec.disconnect()


SWIM_SCHEMA = "finrft.swim/1"
SWIM_SIGN_CONVENTION = (
    "Forward is +y, along the body's slide. The right arm's angle is 0 pointing sideways (+x) and +90 deg pointing "
    "forward; fin hinge angles are negative when the fin folds. The servo torque is what the servo applies to its "
    "arm about +z.")


def write_swim_h5(run: SwimRun, path: str | Path) -> None:
    """Write a swim to HDF5: time series of the body, the right arm and fin and the servo, SI units."""
    series = [
        ("body_y", run.body_y, "m", "body position along the travel axis (+y forward)"),
        ("arm_angle", run.arm_angle, "rad", "right arm angle (0 sideways, +pi/2 forward)"),
        ("hinge_angle", run.hinge_angle, "rad", "right fin hinge angles"),
        ("servo_torque", run.servo_torque, "N m", "torque the right servo applies to its arm"),
        ("stroke_y", run.stroke_y, "m", "body position at the start of each stroke, and at the end"),
    ]
    attrs = {"schema": SWIM_SCHEMA, **_provenance(run.scene, run.summary()), "cycles": run.cycles,
             "sign_convention": SWIM_SIGN_CONVENTION}
    _write_series(path, run.time, series, attrs)


def robot_points(run: SwimRun) -> np.ndarray:
    """The right arm and fin's centre line, (T, N + 2, 3) m: pivot, arm tip (first hinge), hinges, fin tip."""
    a, f = run.scene.arm, run.scene.fin
    count = len(run.time)
    pivot = np.zeros((count, 3))
    pivot[:, 0], pivot[:, 1] = a.pivot, run.body_y
    angles = np.column_stack([run.arm_angle, run.arm_angle[:, None] + np.cumsum(run.hinge_angle, axis=1)])
    return _centre_line(pivot, angles, a.length, f)


def _stream(path: Path, blueprint: rrb.Blueprint) -> rr.RecordingStream:
    rec = rr.RecordingStream("finrft", recording_id=uuid.uuid4())
    if not rec.is_enabled():
        raise RuntimeError(f"rerun logging is disabled (RERUN=off?), so {path} cannot be written")
    rec.save(path, default_blueprint=blueprint)
    return rec


def _log_swim(rec: rr.RecordingStream, run: SwimRun, prefix: str = "") -> None:
    """The robot's right half over time (body as a box outline, arm and fin as a line) and its time series."""
    times = rr.TimeColumn("sim_time", duration=run.time)
    points = robot_points(run)
    half_width, half_length = run.scene.arm.pivot, 0.0375
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]) * [half_width, half_length]
    outline = np.zeros((len(run.time), 5, 3))
    outline[..., :2] = corners
    outline[..., 1] += run.body_y[:, None]
    rec.log(f"{prefix}robot", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{prefix}robot/body", rr.LineStrips3D.from_fields(colors=[[90, 110, 160]], radii=[0.0008]),
            static=True)
    rec.send_columns(f"{prefix}robot/body", indexes=[times], columns=rr.LineStrips3D.columns(strips=outline))
    rec.log(f"{prefix}robot/fin", rr.LineStrips3D.from_fields(colors=[[60, 60, 70]], radii=[0.0008]), static=True)
    rec.send_columns(f"{prefix}robot/fin", indexes=[times], columns=rr.LineStrips3D.columns(strips=points))
    _send_scalars(rec, f"{prefix}motion/body_y", "body y (mm)", times, 1e3 * run.body_y)
    _send_scalars(rec, f"{prefix}motion/arm", "arm angle (deg)", times, np.degrees(run.arm_angle))
    for i in range(run.hinge_angle.shape[1]):
        _send_scalars(rec, f"{prefix}hinges/hinge{i + 1}", f"hinge {i + 1} (deg)", times,
                      np.degrees(run.hinge_angle[:, i]))
    _send_scalars(rec, f"{prefix}servo/torque", "servo torque (N m)", times, run.servo_torque)


def _swim_views(prefix: str = "") -> list:
    top = rrb.Spatial3DView(name="Robot (top view)", origin=f"{prefix}robot",
                            eye_controls=rrb.EyeControls3D(position=[0.0, 0.0, 0.6], look_target=[0.0, 0.0, 0.0],
                                                           eye_up=[0.0, 1.0, 0.0]),
                            line_grid=rrb.LineGrid3D(spacing=0.01))
    return [top, rrb.Vertical(rrb.TimeSeriesView(name="Body position (mm)", origin=f"{prefix}motion/body_y"),
                              rrb.TimeSeriesView(name="Arm angle (deg)", origin=f"{prefix}motion/arm"),
                              rrb.TimeSeriesView(name="Fin hinges (deg)", origin=f"{prefix}hinges"),
                              rrb.TimeSeriesView(name="Servo torque (N m)", origin=f"{prefix}servo"))]


def write_swim_rrd(run: SwimRun, path: str | Path) -> None:
    """Write a swim as a rerun recording: the robot from above and time series, on the timeline ``sim_time``."""
    with atomic_path(path) as tmp:
        rec = _stream(tmp, rrb.Blueprint(rrb.Horizontal(*_swim_views(), column_shares=[3, 2])))
        try:
            rec.log("scene", rr.TextDocument(to_toml(run.scene), media_type=rr.MediaType.TEXT), static=True)
            _log_swim(rec, run)
        finally:
            rec.disconnect()


def write_optimization_rrd(path: str | Path, generations: list[tuple[np.ndarray, np.ndarray]],
                           names: list[str], best: SwimRun) -> None:
    """An optimisation as a rerun recording: best eta per generation, the population in the searched variables
    (the first three, in the CLI's units) per generation, and the best gait's motion."""
    with atomic_path(path) as tmp:
        views = rrb.Vertical(rrb.TimeSeriesView(name="Best eta per generation (%)", origin="optimization/best_eta"),
                             rrb.Spatial3DView(name="Population: " + ", ".join(names[:3]),
                                               origin="optimization/population"))
        rec = _stream(tmp, rrb.Blueprint(rrb.Horizontal(views, *_swim_views("best/"), column_shares=[2, 2, 1])))
        try:
            best_so_far = -np.inf
            for g, (values, etas) in enumerate(generations):
                rec.set_time("generation", sequence=g)
                finite = etas[np.isfinite(etas)]
                best_so_far = max(best_so_far, float(finite.max()) if len(finite) else -np.inf)
                if np.isfinite(best_so_far):
                    rec.log("optimization/best_eta", rr.Scalars(100 * best_so_far))
                cloud = np.zeros((len(values), 3))
                cloud[:, :min(3, values.shape[1])] = values[:, :3]
                rec.log("optimization/population", rr.Points3D(cloud, radii=0.5,
                                                               colors=[[230, 80, 20]] * len(values)))
            _log_swim(rec, best, prefix="best/")
        finally:
            rec.disconnect()
