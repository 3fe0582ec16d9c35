import json
import tomllib
import warnings

import h5py
import mujoco
import numpy as np
import pyarrow as pa
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from finrft import record
from finrft.errors import SceneError
from finrft.drive import Drive
from finrft.scene import preset, to_toml
from finrft.experiment import Result
from finrft.experiments.plate import build_plate, simulate

DRIVES = {
    "drag": Drive(stroke=0.02),
    "rotate": Drive(kind="rotate", speed=1.0, stroke=0.3),
    "drag_oblique": Drive(stroke=0.02, attack_deg=60.0),
}


@pytest.fixture(scope="module")
def runs() -> dict[str, Result]:
    scene = preset("paper").replace(**{"sim.dt": 1e-3})
    return {name: simulate(scene, drive) for name, drive in DRIVES.items()}


def _chunks(path, *, blueprint=False):
    # An unfinalised file (no footer) only warns; make that a failure.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reader = RrdReader(path)
        store = reader.blueprints()[0] if blueprint else None
        return list(reader.stream(store=store))


def _temporal(chunks, entity, component):
    """(times in s, values as a list per row) of one component, ordered by sim_time."""
    times, values = [], []
    for chunk in chunks:
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            if component in batch.schema.names:
                times.append(batch.column("sim_time").cast(pa.int64()).to_numpy() * 1e-9)
                values += batch.column(component).to_pylist()
    times = np.concatenate(times)
    order = np.argsort(times, kind="stable")
    return times[order], [values[i] for i in order]


def _static(chunks, entity, component):
    for chunk in chunks:
        batch = chunk.to_record_batch()
        if chunk.entity_path == entity and chunk.is_static and component in batch.schema.names:
            return batch.column(component).to_pylist()[-1]
    raise KeyError(f"{entity}:{component}")


@pytest.mark.parametrize("name", ["drag", "rotate"])
def test_h5_holds_the_run(runs, name, tmp_path):
    run = runs[name]
    path = tmp_path / "run.h5"
    record.write_h5(run, path, extra_attrs={"label": "test"})
    drag = name == "drag"
    expected = {
        "time": (run.time, "s"),
        "displacement" if drag else "rotation": (run.displacement, "m" if drag else "rad"),
        "segment_angle": (run.segment_angle, "rad"),
        "hinge_angle": (run.hinge_angle, "rad"),
        "drive_force" if drag else "drive_torque": (run.drive_force, "N" if drag else "N m"),
        "rft_force": (run.rft_force, "N"),
        "stroke_impulse": (run.stroke_impulse, "N s" if drag else "N m s"),
        "stroke_peak": (run.stroke_peak, "N" if drag else "N m"),
    }
    with h5py.File(path, "r") as f:
        assert set(f) == set(expected)
        for key, (data, unit) in expected.items():
            np.testing.assert_array_equal(f[key][()], data, err_msg=key)
            assert f[key].attrs["units"] == unit
            assert f[key].attrs["description"]
            if key not in ("time", "stroke_impulse", "stroke_peak"):
                assert f[key].dims[0][0] == f["time"]
        assert f["rft_force"].attrs["frame"] == "world"
        attrs = dict(f.attrs)
    assert attrs["schema"] == "finrft.run/1"
    assert tomllib.loads(attrs["scene_toml"]) == run.scene.to_dict()
    assert json.loads(attrs["scene_json"]) == run.scene.to_dict()
    assert json.loads(attrs["drive_json"])["kind"] == run.drive.kind
    assert json.loads(attrs["summary_json"])["steps"] == run.steps
    assert attrs["mujoco_version"] == mujoco.__version__
    assert attrs["numpy_version"] == np.__version__
    assert attrs["finrft_version"] and attrs["created_utc"] and "+y" in attrs["sign_convention"]
    assert attrs["label"] == "test"
    assert [p.name for p in tmp_path.iterdir()] == ["run.h5"]


def test_extra_attrs_cannot_replace_the_schema(runs, tmp_path):
    with pytest.raises(ValueError, match="schema"):
        record.write_h5(runs["drag"], tmp_path / "run.h5", extra_attrs={"schema": "other"})
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("write", [record.write_h5, record.write_rrd])
def test_a_file_that_cannot_be_written_is_refused_before_writing(runs, write, tmp_path):
    # as the command line's check_output: once raw FileNotFoundError, IsADirectoryError or RuntimeError (rerun)
    for target, message in ((tmp_path / "none" / "run.x", "directory .*none does not exist"),
                            (tmp_path, "is a directory: give a file name"), (3, "must be a path, got int 3")):
        with pytest.raises(SceneError, match=message):
            write(runs["drag"], target, force=True)
    assert not any(tmp_path.iterdir())


def test_extra_attrs_are_what_hdf5_holds(runs, tmp_path):
    for extra, message in (([1], "extra_attrs must be a mapping"), ({"x": object()}, r"extra_attrs\['x'\] must be"),
                           ({1: "a"}, "named by a string")):
        with pytest.raises(SceneError, match=message):
            record.write_h5(runs["drag"], tmp_path / "run.h5", extra_attrs=extra)
    assert not any(tmp_path.iterdir())


def test_of_two_writers_without_force_one_refuses(runs, tmp_path, monkeypatch):
    # the check that the file is absent passes for both; the second to finish must not replace the first's file
    path = tmp_path / "run.h5"
    monkeypatch.setattr(record, "check_new", lambda *args: None)
    record.write_h5(runs["drag"], path)
    first = path.read_bytes()
    with pytest.raises(SceneError, match="appeared while this ran"):
        record.write_h5(runs["rotate"], path)
    assert path.read_bytes() == first and [p.name for p in tmp_path.iterdir()] == ["run.h5"]


@pytest.mark.parametrize("name", ["drag", "rotate"])
def test_rrd_matches_the_h5_file(runs, name, tmp_path):
    run = runs[name]
    record.write_h5(run, tmp_path / "run.h5")
    record.write_rrd(run, tmp_path / "run.rrd")
    chunks = _chunks(tmp_path / "run.rrd")
    with h5py.File(tmp_path / "run.h5", "r") as f:
        time, segment, hinge = f["time"][()], f["segment_angle"][()], f["hinge_angle"][()]
        load = f["drive_force" if name == "drag" else "drive_torque"][()]
    for i in range(run.scene.plate.segments):
        for entity, angles in ((f"/angles/segment/seg{i + 1}", segment), (f"/angles/hinge/hinge{i + 1}", hinge)):
            t, values = _temporal(chunks, entity, "Scalars:scalars")
            np.testing.assert_allclose(t, time, rtol=0, atol=1e-9)
            np.testing.assert_array_equal(np.concatenate(values), np.degrees(angles[:, i]), err_msg=entity)
            assert "(deg)" in _static(chunks, entity, "SeriesLines:names")[0]
    load_entity = "/drive/force" if name == "drag" else "/drive/torque"
    np.testing.assert_array_equal(np.concatenate(_temporal(chunks, load_entity, "Scalars:scalars")[1]), load)
    motion = "/drive/displacement" if name == "drag" else "/drive/rotation"
    expected = 1e3 * run.displacement if name == "drag" else np.degrees(run.displacement)
    np.testing.assert_allclose(np.concatenate(_temporal(chunks, motion, "Scalars:scalars")[1]), expected)
    assert _static(chunks, "/scene", "TextDocument:text")[0] == to_toml(run.scene)

    reader = RrdReader(tmp_path / "run.rrd")
    assert [s.application_id for s in reader.recordings()] == ["finrft"]
    assert [s.application_id for s in reader.blueprints()] == ["finrft"]
    views = {}
    for chunk in _chunks(tmp_path / "run.rrd", blueprint=True):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in batch.schema.names:
            views[batch.column("ViewBlueprint:display_name").to_pylist()[-1][0]] = (
                batch.column("ViewBlueprint:class_identifier").to_pylist()[-1][0])
    assert views["Plate (top view, 1 cm grid)"] == "3D"
    assert views["Segment angles (deg)"] == views["Hinge angles (deg)"] == "TimeSeries"
    series = ("Drive force (N)", "Displacement (mm)") if name == "drag" else ("Drive torque (N m)", "Rotation (deg)")
    assert all(views[label] == "TimeSeries" for label in series), sorted(views)
    assert [p.name for p in sorted(tmp_path.iterdir())] == ["run.h5", "run.rrd"]


@pytest.mark.parametrize("name", list(DRIVES))
def test_rrd_plate_follows_the_mujoco_model(runs, name, tmp_path):
    """The drawn plate must coincide with MuJoCo's own kinematics of the recorded joint positions."""
    run = runs[name]
    record.write_rrd(run, tmp_path / "run.rrd")
    chunks = _chunks(tmp_path / "run.rrd")
    _, strips = _temporal(chunks, "/plate/centerline", "LineStrips3D:strips")
    _, origins = _temporal(chunks, "/plate/rft", "Arrows3D:origins")
    _, vectors = _temporal(chunks, "/plate/rft", "Arrows3D:vectors")
    scale = _static(chunks, "/plate/rft", "arrow_scale_m_per_N")[0]
    strips, origins, vectors = np.array(strips)[:, 0], np.array(origins), np.array(vectors)

    plate = build_plate(run.scene, run.drive.kind, run.drive.attack_deg)
    m, d = plate.model, mujoco.MjData(plate.model)
    for k in range(0, len(run.time), 10):
        d.qpos[plate.drive_qpos] = run.displacement[k]
        d.qpos[plate.hinge_qpos] = run.hinge_angle[k]
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(origins[k], d.site_xpos[plate.groups[0].sites], atol=1e-7)
        np.testing.assert_allclose(strips[k, 1:-1], d.xpos[plate.groups[0].bodies], atol=1e-7)
    peak = np.max(np.linalg.norm(run.rft_force, axis=-1))
    assert scale == pytest.approx(run.scene.plate.segment_length / peak)
    np.testing.assert_allclose(vectors, scale * run.rft_force, rtol=1e-6, atol=1e-9)


def test_failed_h5_write_leaves_no_file(runs, tmp_path, monkeypatch):
    def fail(scene):
        raise RuntimeError("disk full")

    # The scene is serialised after the datasets are written: a failure half-way through the file.
    monkeypatch.setattr(record, "to_toml", fail)
    with pytest.raises(RuntimeError, match="disk full"):
        record.write_h5(runs["drag"], tmp_path / "run.h5")
    assert not any(tmp_path.iterdir())


def test_failed_rrd_write_leaves_no_file(runs, tmp_path, monkeypatch):
    send_columns = rr.RecordingStream.send_columns
    calls = []

    def fail_on_second(self, *args, **kwargs):
        calls.append(args)
        if len(calls) == 2:
            raise RuntimeError("disk full")
        send_columns(self, *args, **kwargs)

    monkeypatch.setattr(rr.RecordingStream, "send_columns", fail_on_second)
    with pytest.raises(RuntimeError, match="disk full"):
        record.write_rrd(runs["drag"], tmp_path / "run.rrd")
    assert not any(tmp_path.iterdir())


def test_swim_recording_matches_its_hdf5(tmp_path):
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import swim

    run = swim(preset("physical", RobotScene).replace(**{"sim.dt": 4e-4}), 1)
    h5, rrd = tmp_path / "swim.h5", tmp_path / "swim.rrd"
    record.write_h5(run, h5)
    record.write_rrd(run, rrd)
    chunks = _chunks(rrd)
    with h5py.File(h5) as f:
        time, hinges, body = f["time"][()], f["hinge_angle"][()], f["body_y"][()]
    for i in range(hinges.shape[1]):
        t, values = _temporal(chunks, f"/hinges/hinge{i + 1}", "Scalars:scalars")
        np.testing.assert_allclose(t, time, atol=1e-9)
        np.testing.assert_allclose(np.ravel(values), np.degrees(hinges[:, i]), rtol=1e-12, atol=1e-12)
    t, values = _temporal(chunks, "/motion/body_y", "Scalars:scalars")
    np.testing.assert_allclose(np.ravel(values), 1e3 * body, rtol=1e-12, atol=1e-12)
    assert _chunks(rrd, blueprint=True)


def _small_file_limit() -> None:
    # A file may not grow past 16 kB, as on a nearly full disk: writes past it fail (EFBIG) instead of the
    # process being killed (SIGXFSZ).
    import resource
    import signal
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (16_000, 16_000))


@pytest.mark.parametrize("flag, name", [("--out", "run.h5"), ("--rrd", "run.rrd")])
def test_a_write_that_fails_on_a_full_disk_is_one_line_and_no_file(tmp_path, flag, name, errors_only):
    import subprocess
    import sys
    done = subprocess.run([sys.executable, "-m", "finrft", "drag", "--set", "sim.dt=0.001", "--distance", "30",
                           "--quiet", flag, str(tmp_path / name)], capture_output=True, text=True,
                          cwd=tmp_path.parent, preexec_fn=_small_file_limit, timeout=300)
    err = errors_only(done.stderr)
    assert done.returncode == 2, err
    assert err.count("\n") == 1 and err.startswith(f"finrft: error: {tmp_path / name}: File too large"), err
    assert not any(tmp_path.iterdir())
