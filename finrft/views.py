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


def _geom(rr: Any, m: Any, g: int, color: list[int]) -> Any | None:
    """A MuJoCo geom as a rerun archetype in its own frame (None for a plane or height field)."""
    size, kind = m.geom_size[g], int(m.geom_type[g])
    gt = _GEOM_TYPES
    if kind == gt["box"]:
        return rr.Boxes3D(half_sizes=[size], colors=[color], fill_mode="solid")
    if kind == gt["sphere"]:
        return rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=[color], fill_mode="solid")
    if kind == gt["ellipsoid"]:
        return rr.Ellipsoids3D(half_sizes=[size], colors=[color], fill_mode="solid")
    if kind == gt["capsule"]:  # rerun's capsule runs from its origin along +z; MuJoCo's is centred
        return rr.Capsules3D(lengths=[2 * size[1]], radii=[size[0]], translations=[[0, 0, -size[1]]],
                             colors=[color], fill_mode="solid")
    if kind == gt["cylinder"]:
        return rr.Cylinders3D(lengths=[2 * size[1]], radii=[size[0]], colors=[color], fill_mode="solid")
    if kind == gt["mesh"]:
        mesh = int(m.geom_dataid[g])
        v0, nv = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
        f0, nf = m.mesh_faceadr[mesh], m.mesh_facenum[mesh]
        return rr.Mesh3D(vertex_positions=m.mesh_vert[v0:v0 + nv], triangle_indices=m.mesh_face[f0:f0 + nf],
                         albedo_factor=color)
    return None


_GEOM_TYPES: dict[str, int] = {}


def draw_model(rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
    """A user's model in 3D: each body's geoms (boxes, spheres, ellipsoids, capsules, cylinders, meshes) and the
    surface elements of the attached ones logged once in the body's frame, the bodies' poses over time, the free
    surface as a translucent plane, and the medium's force on each attached body as an arrow from its origin."""
    import mujoco
    import rerun as rr  # loads only when a recording is written
    import rerun.blueprint as rrb
    if not _GEOM_TYPES:
        _GEOM_TYPES.update({name.removeprefix("mjGEOM_").lower(): int(t)
                            for name, t in mujoco.mjtGeom.__members__.items()})
    scene = run.scene
    built = run.experiment.build(scene)
    m = built.model
    root = f"{prefix}robot"
    rec.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    attached = set(run.experiment.bodies)
    count = len(run.time)
    for i, name in enumerate(run.experiment.links):
        body = f"{root}/{name}"
        quat = run.link_quat[:, i]
        rec.send_columns(body, indexes=[times], columns=rr.Transform3D.columns(
            translation=run.link_position[:, i], quaternion=np.c_[quat[:, 1:], quat[:, :1]]))
        color = [200, 120, 60, 255] if name in attached else [150, 150, 165, 255]
        for g in np.flatnonzero(m.geom_bodyid == i + 1):
            shape = _geom(rr, m, int(g), color)
            if shape is None:
                continue
            q = m.geom_quat[g]
            # by the model's name where it gives one
            entity = f"{body}/{rr.escape_entity_path_part(m.geom(int(g)).name) if m.geom(int(g)).name else f'geom{g}'}"
            rec.log(entity, rr.Transform3D(translation=m.geom_pos[g], quaternion=[*q[1:], q[0]]), static=True)
            rec.log(entity, shape, static=True)
    # The surface elements the medium acts on (culled faces left out), in their body's frame: they move with it.
    for surface in built.attached.surfaces:
        rec.log(f"{root}/{surface.body}/elements", rr.Points3D(surface.centre, colors=[[40, 90, 200]],
                                                                radii=[0.25 * built.attached.element_size]),
                static=True)
    # The medium's force: arrows from the attached bodies' origins, scaled to half the motion's span.
    position, force = run.body_position, run.medium_force
    n = position.shape[1]
    low = np.minimum(run.link_position.min(axis=(0, 1)), position.min(axis=(0, 1)))
    high = np.maximum(run.link_position.max(axis=(0, 1)), position.max(axis=(0, 1)))
    span = max(float(np.max(high - low)), run.model_size, 0.05)
    peak = float(np.max(np.linalg.norm(force, axis=-1), initial=0.0))
    arrow_scale = span / 2 / peak if peak > 0 else 0.0
    rec.log(f"{root}/medium_force", rr.Arrows3D.from_fields(colors=[[230, 80, 20]], radii=[span / 300]),
            static=True)
    rec.log(f"{root}/medium_force", rr.AnyValues(arrow_scale_m_per_N=arrow_scale,
                                                 note=f"arrow length = the medium's force x {arrow_scale:.4g} m/N"),
            static=True)
    rec.send_columns(f"{root}/medium_force", indexes=[times], columns=rr.Arrows3D.columns(
        origins=position.reshape(-1, 3), vectors=arrow_scale * force.reshape(-1, 3)).partition([n] * count))
    if "surface_height" in run.series:
        _draw_deforming(rec, run, built.attached.free_surface, f"{root}/surface")
        return [rrb.Spatial3DView(name="The model, the deforming sand and the medium's force", origin=root)]
    z = scene.medium.surface_z
    corners = np.array([[low[0] - span, low[1] - span, z], [high[0] + span, low[1] - span, z],
                        [high[0] + span, high[1] + span, z], [low[0] - span, high[1] + span, z]])
    rec.log(f"{root}/surface", rr.Mesh3D(vertex_positions=corners, triangle_indices=[[0, 1, 2], [0, 2, 3]],
                                         albedo_factor=[200, 170, 110, 90]), static=True)
    return [rrb.Spatial3DView(name="The model, the sand's surface and the medium's force", origin=root)]


# A deforming surface is drawn at this many instants of a run at most: each is a mesh of its whole grid.
SURFACE_FRAMES = 60


def _draw_deforming(rec: Any, run: Result, field: Any, entity: str) -> None:
    """The deforming surface as a mesh of its grid at up to SURFACE_FRAMES of its records, each vertex coloured
    by its change since the start: blue where the sand went down (a rut), red where it rose (a berm), sand-coloured
    where it is unchanged; full colour at the largest change of the run."""
    import rerun as rr

    heights = run.series["surface_height"]
    p = field.parameters
    nrow, ncol = heights.shape[1:]
    x, y = np.meshgrid(np.linspace(-p["size"][0], p["size"][0], ncol), np.linspace(-p["size"][1], p["size"][1], nrow))
    frame, centre = np.asarray(p["frame"], dtype=float), np.asarray(p["centre"], dtype=float)
    r, c = np.meshgrid(np.arange(nrow - 1), np.arange(ncol - 1), indexing="ij")
    corner = (r * ncol + c).ravel()
    triangles = np.r_[np.c_[corner, corner + 1, corner + ncol + 1], np.c_[corner, corner + ncol + 1, corner + ncol]]
    change = heights - heights[0]
    largest = max(float(np.abs(change).max()), 1e-12)
    sand, down, up = np.array([200, 170, 110]), np.array([40, 90, 220]), np.array([220, 50, 30])
    times = run.series["surface_time"]
    for k in np.unique(np.linspace(0, len(times) - 1, SURFACE_FRAMES).round().astype(int)):
        rec.set_time("sim_time", duration=float(times[k]))
        local = np.c_[x.ravel(), y.ravel(), heights[k].ravel()]
        share = (change[k] / largest).ravel()[:, None]
        colour = np.where(share < 0, sand + (down - sand) * -share, sand + (up - sand) * share)
        rec.log(entity, rr.Mesh3D(vertex_positions=local @ frame.T + centre, triangle_indices=triangles,
                                  vertex_colors=colour.astype(np.uint8)))
