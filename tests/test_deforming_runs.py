"""The deforming surface in runs (finrft.surfaces.deforming.DeformingSurface, medium.surface = "deforming"): the
native plugin and the numpy backend step the same surface, the sand's volume is conserved over a run, the surface
is recorded, and a second press at the same place meets the disturbed sand."""

import json
import math

import h5py
import numpy as np
import pytest

from finrft import media
from finrft import experiment
from finrft.experiments import wheel
from finrft.laws import li2013
from finrft.record import write_h5
from finrft.surfaces import deforming

G = np.array([0.0, 0.0, -9.81])
REPOSE = media.medium("wheel_sand_cmu").get("angle_of_repose").value


def _wheel(backend: str, duration: float = 0.4, **settings: object) -> object:
    # a braked wheel held 30 mm deep, on a coarse grid: a few surface steps
    scene = wheel.default_scene(**{"wheel.slip": -0.5, "wheel.slip_angle": math.radians(30), "wheel.sinkage": 0.03,
                                   "medium.name": "wheel_sand_cmu", "medium.surface": "deforming",
                                   "medium.surface_point": (0.05, 0.0, 0.0), "medium.hfield_extent": 0.12,
                                   "medium.hfield_spacing": 0.004, "sim.duration": duration, "sim.settle": 0.1,
                                   "sim.backend": backend, **settings})
    # without the companion run of its error estimate: these tests check the surface, not the step
    return experiment.run(wheel.Wheel.of(scene), scene, max_error=None, estimate_error=False)


@pytest.fixture(scope="module")
def runs():
    return {backend: _wheel(backend) for backend in ("native", "python")}


def test_native_and_numpy_runs_step_the_same_surface(runs):
    native, numpy = runs["native"].series["surface_height"], runs["python"].series["surface_height"]
    assert np.abs(native[-1] - native[0]).max() > 0.01  # a rut and a berm
    assert np.abs(native - numpy).max() < 1e-6
    force = runs["native"].series["medium_force"], runs["python"].series["medium_force"]
    assert np.abs(force[0] - force[1]).max() < 1e-6 * np.abs(force[0]).max()


def test_a_run_conserves_the_sand(runs):
    h = runs["native"].series["surface_height"]
    # from the first step on (the body's imprint of its start is no flow of sand): the volume the surface lost
    # between samples, and the whole volume's change
    displaced = np.clip(h[1:-1] - h[2:], 0.0, None).sum()
    assert displaced > 0 and abs(h[-1].sum() - h[1].sum()) <= 1e-6 * displaced


def test_native_and_numpy_runs_agree_on_compaction_and_facing_berms():
    # the plugin gathers the elements' normals for the facing rule as the numpy backend does (body_elements)
    settings = {"medium.compaction": 0.3, "medium.berm": "facing"}
    native, numpy = (_wheel(backend, **settings).series["surface_height"] for backend in ("native", "python"))
    plain = _wheel("native").series["surface_height"]
    assert np.abs(native[-1] - plain[-1]).max() > 1e-3  # the options change the surface
    assert np.abs(native - numpy).max() < 1e-6


def test_the_surface_is_recorded(runs, tmp_path):
    path = tmp_path / "wheel.h5"
    write_h5(runs["native"], path)
    with h5py.File(path) as f:
        heights, times = f["surface_height"], f["surface_time"]
        assert heights.attrs["units"] == "m" and heights.shape == (len(times), 61, 61)
        assert heights.dims[0].label == "surface_time" and times.attrs["units"] == "s"
        assert np.array_equal(heights[-1], runs["native"].series["surface_height"][-1])


def test_the_surface_is_recorded_where_it_changed(runs):
    run = runs["native"]
    times, heights = run.series["surface_time"], run.series["surface_height"]
    # a copy at the start, then no two within record_dt (but the last, at the end, had it changed since), each one
    # changed from the one before
    assert times[0] == run.time[0] and run.time[0] < times[-1] <= run.time[-1]
    assert np.all(np.diff(times[:-1]) >= run.scene.sim.record_dt * (1 - 1e-9))
    assert all(np.abs(heights[k + 1] - heights[k]).max() > 0 for k in range(len(times) - 1))
    assert len(times) < len(run.time)


def _press(surface: deforming.DeformingSurface, depth: float) -> float:
    """A 20 x 20 mm plate pushed down at 10 mm/s to ``depth`` below the original surface (li2013): its vertical
    force there, then withdrawn."""
    x, y = np.meshgrid(np.linspace(-0.009, 0.009, 10), np.linspace(-0.009, 0.009, 10))
    area = np.full(x.size, 4e-6)
    down = np.tile([0.0, 0.0, -0.01], (x.size, 1))
    normal = np.tile([0.0, 0.0, -1.0], (x.size, 1))
    for z in np.linspace(-0.001, -depth, 20):
        points = np.c_[x.ravel(), y.ravel(), np.full(x.size, z)]
        surface.step(points, area, down, G)
    force = li2013.element_forces(normal, down, surface.depth(points, G), area, zeta=1.0).sum(axis=0)
    surface.step(points + [0.0, 0.0, 1.0], area, -down, G)  # out of the sand: the surface relaxes
    return float(force[2])


def test_a_second_press_meets_its_own_footprint():
    surface = deforming.DeformingSurface(np.zeros((41, 41)), (0.04, 0.04), REPOSE, step_iterations=10_000)
    first, second = _press(surface, 0.02), _press(surface, 0.02)
    # the first press measures 20 mm from the undisturbed surface; the second from the floor of its footprint,
    # which relaxation to 29 deg has partly filled from the walls: less deep, less resistance, but some
    under = surface.level[16:25, 16:25]  # the grid points under the plate
    assert under.mean() < -0.002 and np.abs(surface.heights - surface.level).max() == 0  # a footprint, no body in it
    # a flat plate's force is proportional to its depth: between its shallowest and deepest below the footprint
    ratio = second / first
    assert (under.min() + 0.02) / 0.02 <= ratio <= (under.max() + 0.02) / 0.02 and ratio < 0.8


def test_finrft_wheel_surface_deforming_puts_the_grid_under_the_wheel():
    from finrft.cli import build_parser
    from finrft.experiments import REGISTRY

    argv = ["wheel", "--slip", "-1", "--sinkage", "50", "--surface", "deforming"]
    command = REGISTRY["wheel"]
    scene = command.scene(build_parser().parse_args(argv))
    assert scene.medium.surface == "deforming" and scene.medium.hfield_spacing == 0.0025
    # the grid reaches from behind the wheel at its start to ahead of it after 6 s at 10 mm/s, berms included
    x0, half = scene.medium.surface_point[0], scene.medium.hfield_extent
    assert x0 - half < -scene.wheel.radius - 0.02 and x0 + half > 6 * scene.wheel.speed + scene.wheel.radius + 0.05
    given = command.scene(build_parser().parse_args([*argv, "--set", "medium.hfield_spacing=0.004"]))
    assert given.medium.hfield_spacing == 0.004  # --set wins


def test_finrft_wheel_surface_deforming_runs_as_written(capsys):
    # the command alone: the scene's wheel (slip 0.5, free under its 21 N load) on sand it displaces, its JSON alone
    # on stdout, every figure with its estimate
    from finrft.cli import main

    assert main(["wheel", "--surface", "deforming", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["slip"] == 0.5 and out["mode"] == "load" and out["Fz_N"] == pytest.approx(21.0, rel=0.01)
    assert all(key in out["error_estimate"] for key in ("Fx_N", "Fy_N", "Fz_N", "sinkage_mm", "axle_torque_Nm"))


def test_the_recording_draws_the_surface(runs, tmp_path):
    import rerun as rr

    from finrft.record import write_rrd
    from finrft.views import SURFACE_FRAMES, _draw_deforming

    logged = []

    class Recording:
        def set_time(self, *args, **kwargs):
            pass

        def log(self, entity, item):
            logged.append(item)

    run = runs["native"]
    _draw_deforming(Recording(), run, run.experiment.build(run.scene).attached.free_surface, "surface")
    assert 2 <= len(logged) <= SURFACE_FRAMES and all(isinstance(m, rr.Mesh3D) for m in logged)
    first, last = logged[0], logged[-1]
    colours = [np.asarray(m.vertex_colors.as_arrow_array().to_pylist()) for m in (first, last)]
    assert (colours[0] == colours[0][0]).all()  # unchanged at the start: one colour
    assert len(np.unique(colours[1], axis=0)) > 2  # rut and berm coloured at the end
    write_rrd(run, tmp_path / "wheel.rrd")
    assert (tmp_path / "wheel.rrd").stat().st_size > 0


def test_the_level_is_the_plugins_state():
    import mujoco

    scene = wheel.default_scene(**{"wheel.slip": -1.0, "wheel.sinkage": 0.04, "medium.name": "wheel_sand_cmu",
                                   "medium.surface": "deforming", "medium.hfield_extent": 0.12,
                                   "medium.hfield_spacing": 0.004})
    experiment = wheel.Wheel.of(scene)
    built = experiment.build(scene)
    m = built.model
    d = mujoco.MjData(m)
    trial = experiment.start(scene, built, d, False)
    d.qvel[m.joint("carriage").dofadr[0]] = 0.01
    read = built.attached.wrenches(m)
    mujoco.mj_forward(m, d)
    flat = read(d)[0, 3:].copy()
    trial.surface.level[...] += 0.01  # 10 mm more sand everywhere: deeper, more resistance
    trial.surface.installed(m, d)
    mujoco.mj_forward(m, d)
    raised = read(d)[0, 3:].copy()
    assert raised[0] < flat[0] < 0
    # MuJoCo's state carries the level: another MjData set to it meets the same sand
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, state, spec)
    other = mujoco.MjData(m)
    mujoco.mj_setState(m, other, state, spec)
    mujoco.mj_forward(m, other)
    assert np.array_equal(read(other)[0, 3:], raised)
    mujoco.mj_resetData(m, other)  # and a reset puts the original surface back
    other.qpos[:], other.qvel[:] = d.qpos, d.qvel
    mujoco.mj_forward(m, other)
    assert np.allclose(read(other)[0, 3:], flat, rtol=1e-12)


@pytest.mark.slow  # a bench row: the wheel run on both surfaces, end to end
def test_the_modelling_bench_compares_the_wheel_on_both_surfaces():
    from finrft.studies.bench import _wheel_surfaces

    row = _wheel_surfaces(1)
    # the braked wheel pushes a pile ahead of it on the deforming surface: more resistance than on the flat one
    assert row["fx_diff_N"] < -1.0 and min(row["wall_a_s"], row["wall_b_s"], row["cpu_a_s"], row["cpu_b_s"]) > 0


def test_the_surface_converges_in_its_update_and_tolerance(runs):
    # stepped every half grid spacing and relaxed to within 1e-3 of the angle of repose (medium.surface_update and
    # relax_tolerance, as first run) the held wheel's mean forces move by under 1 % from the defaults'
    finer = _wheel("native", **{"medium.surface_update": 0.5, "medium.relax_tolerance": 0.001}).summary()
    coarse = runs["native"].summary()
    assert deforming.MOVE > 0.5 and deforming.STEP_TOLERANCE > 0.001 and finer["Fx_N"] != coarse["Fx_N"]
    for key in ("Fx_N", "Fy_N", "Fz_N"):
        assert coarse[key] == pytest.approx(finer[key], rel=0.01)
