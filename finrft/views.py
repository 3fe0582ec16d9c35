"""What the experiments' 3D views in a rerun recording (`Experiment.draw`) share: a chain's centre line, and bodies
with the medium's force on each (a user's model, the intrusion plate). The plate's and the robot's own views are in
their modules; the time series are `record.write_rrd`'s, for any experiment."""

from __future__ import annotations

from typing import Any

import numpy as np

from .experiment import Result


def centre_line(start: np.ndarray, angles: np.ndarray, first: float, chain: Any) -> np.ndarray:
    """Points (T, N + 2, 3) of a rod of length ``first`` then a chain's segments, from ``start`` (T, 3), each at
    its absolute angle about z (T, N + 1)."""
    lengths = np.r_[first, np.full(chain.segments, chain.segment_length)]
    steps = np.zeros((*angles.shape, 3))
    steps[..., 0] = lengths * np.cos(angles)
    steps[..., 1] = lengths * np.sin(angles)
    return np.concatenate([start[:, None], start[:, None] + np.cumsum(steps, axis=1)], axis=1)


def draw_bodies(rec: Any, run: Result, times: Any, prefix: str, position: np.ndarray, force: np.ndarray,
                title: str) -> list[Any]:
    """Bodies as points (T, B, 3) with the medium's force on each as an arrow, and the free surface's level."""
    import rerun as rr  # loads only when a recording is written
    import rerun.blueprint as rrb
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
