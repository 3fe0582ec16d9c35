"""File writers: HDF5 files for analysis and rerun recordings (.rrd) for viewing, of any experiment's result
(finrft.experiment) and of optimisations.

Every writer goes through `files.atomic_path` (a temporary file in the target's directory replaced onto it), so an
interrupted or failed write never leaves a truncated file where a complete one is expected.
"""

from __future__ import annotations

import contextlib
import json
import os
import uuid
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from . import geometry, laws
from .errors import SceneError
from .experiment import DISPLAY, Result
from .files import atomic_path, check_target, hdf5_written, provenance, write_bytes
from .scene import to_toml

# Written by write_h5 itself; extra_attrs may not replace them, or a file could contradict its own data.
_ROOT_ATTRS = ("schema", "scene_toml", "scene_json", "drive_json", "cycles", "summary_json", "finrft_version",
               "mujoco_version", "numpy_version", "created_utc", "sign_convention", "law_feeds_energy")


def _provenance(scene: Any, summary: dict[str, Any]) -> dict[str, Any]:
    """What every result file stores about how it was made, and the run's own error estimate (finrft.convergence),
    one attribute per quantity, the unit in its name: error_estimate_angle_deg, ..._force_N, ..._eta_points."""
    # a figure's estimate per body (a dict) as JSON: an HDF5 attribute holds a number or an array
    estimate = {f"error_estimate_{key}": json.dumps(value) if isinstance(value, dict) or value is None else value
                for key, value in (summary.get("error_estimate") or {}).items()}
    if estimate:
        estimate["error_companion"] = summary["error_companion"]
    return {"scene_toml": to_toml(scene), "scene_json": json.dumps(scene.to_dict()),
            "summary_json": json.dumps(summary), **provenance(), **estimate}


def check_new(path: str | Path, force: bool) -> None:
    """SceneError when ``path`` exists (a dangling link too) and ``force`` is not given: a writer replaces a file
    only when asked to, as the command line does with --force."""
    check_target(path)
    if not force and os.path.lexists(path):
        raise SceneError(f"{path} exists: choose a new file, or pass force=True to replace it")


def _check_result(run: Any) -> None:
    if not isinstance(run, Result):
        raise SceneError(f"a file is written from a finrft.Result (finrft.run, simulate, swim), got "
                         f"{type(run).__name__}")


def write_h5(run: Result, path: str | Path, *, extra_attrs: dict[str, Any] | None = None,
             force: bool = False) -> None:
    """Write any experiment's result to HDF5, atomically: its series at the root with SI ``units`` and a
    ``description`` (the per-sample ones on the dimension scale ``time``), the scene, the experiment's parameters
    and the summary as root attributes, with ``law_feeds_energy``: why the scene's segment law can feed energy in,
    or "" (also for a scene without one). ``extra_attrs`` are added to the root attributes. SceneError when the
    file exists, unless ``force``."""
    _check_result(run)
    if extra_attrs is not None and not isinstance(extra_attrs, Mapping):
        raise SceneError(f"extra_attrs must be a mapping of names to values, got {type(extra_attrs).__name__}")
    extra = dict(extra_attrs or {})
    for key, value in extra.items():
        if not isinstance(key, str) or np.asarray(value).dtype.kind not in "biufUS":
            raise SceneError(f"extra_attrs[{key!r}] must be named by a string and hold a string, a number or an "
                             f"array of them (an HDF5 attribute), got {type(value).__name__}")
    clash = sorted(set(extra) & set(_ROOT_ATTRS))
    if clash:
        raise SceneError(f"extra_attrs may not replace {', '.join(clash)}")
    check_new(path, force)
    experiment = run.experiment
    # Without force, a file that another process wrote since the check is kept: one of two writers refuses.
    with hdf5_written(path, exclusive=None if force else True, track_order=True) as f:
        t = f.create_dataset("time", data=run.time)
        t.attrs.update(units="s", description="simulated time of each sample")
        t.make_scale("time")
        for name, quantity in run.quantities.items():
            data = np.asarray(run.series[name])
            big = data.ndim > 1
            ds = f.create_dataset(name, data=data, chunks=True if big else None,
                                  compression="gzip" if big else None, shuffle=big)
            ds.attrs.update(units=quantity.unit, description=quantity.description, **quantity.attrs)
            if quantity.per == "sample":
                ds.dims[0].label = "time"
                ds.dims[0].attach_scale(t)
        # a series indexed by another (a deforming surface's heights by surface_time) on that one as its scale
        for name, quantity in run.quantities.items():
            if quantity.per in run.quantities and quantity.per != name:
                scale = f[quantity.per]
                if not scale.is_scale:
                    scale.make_scale(quantity.per)
                f[name].dims[0].label = quantity.per
                f[name].dims[0].attach_scale(scale)
        feeds = laws.feeds_energy(geometry.segment_law(run.scene))
        f.attrs.update({"schema": experiment.schema, **_provenance(run.scene, run.summary()), **experiment.attrs(),
                        "sign_convention": experiment.sign_convention, "law_feeds_energy": feeds, **extra})


@contextlib.contextmanager
def _stream(path: Path) -> Iterator[rr.RecordingStream]:
    """A recording written to ``path`` when the block ends. Kept in memory and written by Python, which raises
    OSError on a failed write (a full disk): rerun's file writer only logs it, and leaves a file without its end."""
    rec = rr.RecordingStream("finrft", recording_id=uuid.uuid4())
    if not rec.is_enabled():
        raise RuntimeError(f"rerun logging is disabled (RERUN=off?), so {path} cannot be written")
    memory = rec.memory_recording()
    try:
        yield rec
        rec.flush()
        data = memory.drain_as_bytes()
    finally:
        rec.disconnect()
    write_bytes(path, data)


def _send_scalars(rec: rr.RecordingStream, entity: str, label: str, times: rr.TimeColumn,
                  values: np.ndarray) -> None:
    rec.log(entity, rr.SeriesLines(names=label), static=True)
    rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=values))


def _log(rec: rr.RecordingStream, run: Result, prefix: str = "") -> tuple[list[Any], list[Any]]:
    """Log a result: the experiment's 3D view, and every plotted series as time series in its display unit.
    Returns the blueprint's 3D views and time-series views."""
    times = rr.TimeColumn("sim_time", duration=run.time)
    spatial = run.experiment.draw(rec, run, times, prefix)
    plots = []
    for name, quantity in run.quantities.items():
        plot = quantity.plot
        if plot is None:
            continue
        shown = DISPLAY.get(plot.unit, np.asarray)(run.series[name])
        suffix = f" ({plot.unit or quantity.unit})"
        if shown.ndim == 1:
            _send_scalars(rec, f"{prefix}{plot.entity}", plot.label + suffix, times, shown)
        for i in range(shown.shape[1] if shown.ndim == 2 else 0):
            part = rr.escape_entity_path_part(plot.names[i]) if plot.names else f"{plot.part}{i + 1}"
            name = plot.names[i] if plot.names else i + 1
            _send_scalars(rec, f"{prefix}{plot.entity}/{part}", f"{plot.label} {name}{suffix}", times, shown[:, i])
        plots.append(rrb.TimeSeriesView(name=plot.title, origin=f"{prefix}{plot.entity}"))
    return spatial, plots


def write_rrd(run: Result, path: str | Path, *, force: bool = False) -> None:
    """Write any experiment's result as a rerun recording with a ready-made layout: the experiment's 3D view (the
    plate and its RFT forces, the robot from above) beside the scene, and time series of its plotted series, on
    the timeline ``sim_time``. SceneError when the file exists, unless ``force``."""
    _check_result(run)
    check_new(path, force)
    with atomic_path(path, exclusive=None if force else True) as tmp, _stream(tmp) as rec:
        rec.log("scene", rr.TextDocument(to_toml(run.scene), media_type=rr.MediaType.TEXT), static=True)
        spatial, plots = _log(rec, run)
        # The layout, once logging has made the views it shows.
        rec.send_blueprint(rrb.Blueprint(rrb.Horizontal(
            rrb.Tabs(*spatial, rrb.TextDocumentView(name="Scene", origin="scene"), active_tab=0),
            rrb.Vertical(*plots), column_shares=[3, 2])), make_active=True, make_default=True)


def write_optimization_rrd(path: str | Path, generations: list[tuple[np.ndarray, np.ndarray]],
                           names: list[str], best: Result, *, figure: str = "eta", scale: float = 100.0,
                           unit: str = "%", maximize: bool = True) -> None:
    """An optimisation as a rerun recording: the best ``figure`` so far per generation (times ``scale``, in
    ``unit``; the largest, or the smallest unless ``maximize``), the population in the searched variables (the
    first three, in the CLI's units) per generation, and the best gait's motion."""
    sign = 1.0 if maximize else -1.0
    entity = f"optimization/best_{figure.replace('.', '_')}"
    with atomic_path(path) as tmp, _stream(tmp) as rec:
        best_so_far = -np.inf
        for g, (values, etas) in enumerate(generations):
            rec.set_time("generation", sequence=g)
            finite = sign * etas[np.isfinite(etas)]
            best_so_far = max(best_so_far, float(finite.max()) if len(finite) else -np.inf)
            if np.isfinite(best_so_far):
                rec.log(entity, rr.Scalars(scale * sign * best_so_far))
            cloud = np.zeros((len(values), 3))
            cloud[:, :min(3, values.shape[1])] = values[:, :3]
            rec.log("optimization/population", rr.Points3D(cloud, radii=0.5,
                                                           colors=[[230, 80, 20]] * len(values)))
        spatial, plots = _log(rec, best, prefix="best/")
        views = rrb.Vertical(rrb.TimeSeriesView(name=f"Best {figure} per generation ({unit})", origin=entity),
                             rrb.Spatial3DView(name="Population: " + ", ".join(names[:3]),
                                               origin="optimization/population"))
        rec.send_blueprint(rrb.Blueprint(rrb.Horizontal(views, *spatial, rrb.Vertical(*plots),
                                                        column_shares=[2, 2, 1])),
                           make_active=True, make_default=True)
