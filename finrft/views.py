"""The built-in experiments' own 3D views in a rerun recording (`Experiment.draw`): the plate's centre line and
RFT forces, the robot's body outline, arm and fin. The time series are `record.write_rrd`'s, for any experiment."""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .experiment import Result
from .models import initial_heading


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


def robot_points(run: Result) -> np.ndarray:
    """The right arm and fin's centre line, (T, N + 2, 3) m: pivot, arm tip (first hinge), hinges, fin tip."""
    a, f = run.scene.arm, run.scene.fin
    count = len(run.time)
    pivot = np.zeros((count, 3))
    pivot[:, 0], pivot[:, 1] = a.pivot, run.body_y
    angles = np.column_stack([run.arm_angle, run.arm_angle[:, None] + np.cumsum(run.hinge_angle, axis=1)])
    return centre_line(pivot, angles, a.length, f)


def centre_line(start: np.ndarray, angles: np.ndarray, first: float, chain: Any) -> np.ndarray:
    """Points (T, N + 2, 3) of a rod of length ``first`` then a chain's segments, from ``start`` (T, 3), each at
    its absolute angle about z (T, N + 1)."""
    lengths = np.r_[first, np.full(chain.segments, chain.segment_length)]
    steps = np.zeros((*angles.shape, 3))
    steps[..., 0] = lengths * np.cos(angles)
    steps[..., 1] = lengths * np.sin(angles)
    return np.concatenate([start[:, None], start[:, None] + np.cumsum(steps, axis=1)], axis=1)


def draw_plate(rec: rr.RecordingStream, run: Result, times: rr.TimeColumn, prefix: str) -> list[Any]:
    """The plate and its RFT forces seen from above."""
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


def draw_robot(rec: rr.RecordingStream, run: Result, times: rr.TimeColumn, prefix: str) -> list[Any]:
    """The robot's right half from above: the body as a box outline, arm and fin as a line."""
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
    eye = rrb.EyeControls3D(position=[0.0, 0.0, 0.6], look_target=[0.0, 0.0, 0.0], eye_up=[0.0, 1.0, 0.0])
    return [rrb.Spatial3DView(name="Robot (top view)", origin=f"{prefix}robot", eye_controls=eye,
                              line_grid=rrb.LineGrid3D(spacing=0.01))]


def draw_bodies(rec: rr.RecordingStream, run: Result, times: rr.TimeColumn, prefix: str, position: np.ndarray,
                force: np.ndarray, title: str) -> list[Any]:
    """Bodies as points (T, B, 3) with the medium's force on each as an arrow, and the free surface's level."""
    count, n = position.shape[:2]
    low, high = position.min(axis=(0, 1)), position.max(axis=(0, 1))
    span = float(np.max(high - low)) or 0.05
    peak = float(np.max(np.linalg.norm(force, axis=-1), initial=0.0))
    arrow_scale = span / 2 / peak if peak > 0 else 0.0
    rec.log(f"{prefix}bodies", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{prefix}bodies/origin", rr.Points3D.from_fields(colors=[[60, 60, 70]], radii=[span / 100]),
            static=True)
    rec.send_columns(f"{prefix}bodies/origin", indexes=[times], columns=rr.Points3D.columns(
        positions=position.reshape(-1, 3)).partition([n] * count))
    rec.log(f"{prefix}bodies/rft", rr.Arrows3D.from_fields(colors=[[230, 80, 20]], radii=[span / 200]), static=True)
    rec.log(f"{prefix}bodies/rft", rr.AnyValues(arrow_scale_m_per_N=arrow_scale,
                                                note=f"arrow length = RFT force x {arrow_scale:.4g} m/N"), static=True)
    rec.send_columns(f"{prefix}bodies/rft", indexes=[times], columns=rr.Arrows3D.columns(
        origins=position.reshape(-1, 3), vectors=arrow_scale * force.reshape(-1, 3)).partition([n] * count))
    z = run.scene.medium.surface_z
    corners = np.array([[low[0] - span, low[1] - span, z], [high[0] + span, low[1] - span, z],
                        [high[0] + span, high[1] + span, z], [low[0] - span, high[1] + span, z],
                        [low[0] - span, low[1] - span, z]])
    rec.log(f"{prefix}bodies/surface", rr.LineStrips3D([corners], colors=[[200, 170, 110]]), static=True)
    return [rrb.Spatial3DView(name=f"{title} and the medium's force", origin=f"{prefix}bodies")]
