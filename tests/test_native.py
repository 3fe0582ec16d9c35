"""The native plugin: built and loaded, the same trajectories as the Python coupling, thread-safe, strict about
its config; and the batch API, which must give the single runs' results."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from mujoco import rollout

from conftest import face
from finrft import batch, models, native
from finrft.cli import main
from finrft.drive import Drive
from finrft.laws.table import ForceTable, write_table
from finrft.scene import SceneError, preset
from finrft.experiments.plate import build_plate, simulate


def test_plugin_is_built_and_loaded():
    assert native.available(), native._status["error"]
    assert native.resolve_backend("native") == "native"
    assert native.built_for() == mujoco.mj_version()


def test_library_names_no_build_directory():
    # Debug information, for one, would record where the sources were compiled.
    root = Path(__file__).resolve().parents[1]
    assert str(root).encode() not in native.library_path().read_bytes()


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("readelf") is None,
                    reason="reads the ELF dynamic section")
def test_library_finds_mujoco_relative_to_itself():
    dynamic = subprocess.run(["readelf", "-d", str(native.library_path())], capture_output=True, text=True,
                             check=True).stdout
    paths = [line.split("[", 1)[1].rstrip("]") for line in dynamic.splitlines()
             if "(RPATH)" in line or "(RUNPATH)" in line]
    assert paths == ["$ORIGIN/../mujoco"]
    assert f"[libmujoco.so.{mujoco.mj_versionString()}]" in dynamic


def test_mujoco_version_mismatch_falls_back_with_one_line(monkeypatch, capsys):
    for key, value in {"loaded": None, "error": "", "advice": "", "warned": False}.items():
        monkeypatch.setitem(native._status, key, value)
    monkeypatch.setattr(mujoco, "mj_version", lambda: 4001000)
    monkeypatch.setattr(mujoco, "mj_loadPluginLibrary", lambda path: pytest.fail("loaded a mismatched plugin"))
    assert main(["drag", "--distance", "5", "--json", "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert err == (f"finrft: warning: the native RFT plugin was built for MuJoCo {mujoco.mj_versionString()} but "
                   f"MuJoCo 4.1.0 is installed; using the Python backend (reinstall finrft to rebuild it)\n")
    assert json.loads(out.splitlines()[-1])["backend"] == "python"


@pytest.fixture(scope="module")
def table_csv(tmp_path_factory):
    # A table that is not the paper law (a flattened sine), so the table path is exercised on its own; per unit
    # area and depth, of the paper plate's per-segment 1.2 N and -0.3 N.
    path = tmp_path_factory.mktemp("rft") / "forces.csv"
    attack, size = np.linspace(0.0, 90.0, 7), face(preset("paper"))
    write_table(path, ForceTable(attack, 1.2 / size * np.sin(np.radians(attack)) ** 0.5,
                                 -0.3 / size * np.cos(np.radians(attack))))
    return str(path)


# each law with a plate that bends; the other four pairs with the slow studies
@pytest.mark.parametrize("law, kind", [
    (law, kind) if (law, kind) in (("paper", "origami"), ("table", "soft")) else
    pytest.param(law, kind, marks=pytest.mark.slow) for law in ("paper", "table") for kind in ("origami", "soft", "rigid")])
def test_backends_give_the_same_trajectories(paper, table_csv, kind, law):
    # Full drag out and back (penalty stop engaged on the way back for the origami plate).
    scene = paper.replace(**{"plate.kind": kind, "rft.law": law, "rft.table": table_csv if law == "table" else ""})
    drive = Drive(stroke=0.1, cycles=1)
    runs = {b: simulate(scene.replace(**{"sim.backend": b}), drive, estimate_error=False) for b in ("python", "native")}
    assert runs["native"].backend == "native" and runs["python"].backend == "python"
    np.testing.assert_allclose(runs["native"].segment_angle, runs["python"].segment_angle, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs["native"].drive_force, runs["python"].drive_force, rtol=1e-9, atol=1e-9)
    if kind != "rigid":
        assert np.degrees(np.abs(runs["native"].hinge_angle).max()) > 5.0


def test_plugin_is_thread_safe_in_rollout(paper):
    # Two threads stepping copies of the plate at once must reproduce a plain sequential run exactly.
    plate = build_plate(paper)
    m = plate.model
    d = mujoco.MjData(m)
    d.qvel[plate.drive_dof] = 0.03
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.zeros(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, x0, spec)
    nstep = 2000
    state, _ = rollout.rollout(m, [mujoco.MjData(m) for _ in range(2)], np.tile(x0, (4, 1)), nstep=nstep)
    mujoco.mj_step(m, d, nstep)
    final = np.zeros_like(x0)
    mujoco.mj_getState(m, d, final, spec)
    for row in state[:, -1]:
        np.testing.assert_array_equal(row, final)
    assert np.abs(d.qpos[plate.hinge_qpos]).max() > 1e-3


@pytest.mark.parametrize("key,value,named", [
    ("f_par", "x", "'f_par' must be a number"),
    ("v_reg", "-1", "'v_reg' must be > 0"),
    ("f_perp", "", "'f_perp' is missing"),
    ("law", "li2013", "'law' must be"),
    ("stop_stiffness", "-5", "'stop_stiffness' must be >= 0"),
])
def test_plugin_rejects_bad_config(paper, monkeypatch, capsys, key, value, named):
    good = models.plugin_config
    monkeypatch.setattr(models, "plugin_config", lambda *args: {**good(*args), key: value})
    with pytest.raises(SceneError, match=named):
        build_plate(paper)
    assert main(["drag", "--preset", "paper", "--distance", "5"]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1


def test_batch_equals_single_runs(paper):
    jobs = [(paper.replace(**{"plate.damping": b, "plate.kind": k}), Drive(stroke=0.05, cycles=1))
            for b in (0.5, 1.43) for k in ("origami", "soft")]
    single = [simulate(*job) for job in jobs]
    many = batch.run_many(jobs, workers=2)
    for a, b in zip(single, many):
        for field in ("time", "segment_angle", "hinge_angle", "drive_force", "rft_force", "stroke_impulse"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert not np.allclose(many[0].segment_angle, many[2].segment_angle)  # the jobs did differ


def test_library_that_warns_on_loading_is_not_used_and_leaves_no_log(monkeypatch, tmp_path):
    for key, value in {"loaded": None, "error": "", "advice": "", "warned": False}.items():
        monkeypatch.setitem(native._status, key, value)
    monkeypatch.chdir(tmp_path)

    def warning_loader(path):  # MuJoCo 4.0.1 warns rather than raises when a library will not load
        m = mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><joint/><geom size='.1'/></body></worldbody>"
                                           "</mujoco>")
        d = mujoco.MjData(m)
        d.qvel[0] = 1e20
        mujoco.mj_step(m, d)  # a real MuJoCo warning: an unstable state

    monkeypatch.setattr(mujoco, "mj_loadPluginLibrary", warning_loader)
    assert not native.available()
    assert "Nan, Inf or huge value in QVEL" in native._status["error"]
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_unavailable_plugin_falls_back_once(monkeypatch, paper):
    monkeypatch.setitem(native._status, "loaded", False)
    monkeypatch.setitem(native._status, "error", "library not built")
    monkeypatch.setitem(native._status, "advice", "")
    monkeypatch.setitem(native._status, "warned", False)
    with pytest.warns(RuntimeWarning, match="library not built") as record:
        runs = [simulate(paper, Drive(stroke=0.01)) for _ in range(2)]
    assert len(record) == 1
    assert all(run.backend == "python" for run in runs)


# Counts heap calls between count_start() and count_stop() when preloaded (glibc's own allocator underneath).
ALLOCATION_COUNTER = r"""
#include <stddef.h>
extern void* __libc_malloc(size_t);
extern void* __libc_calloc(size_t, size_t);
extern void* __libc_realloc(void*, size_t);
extern void* __libc_memalign(size_t, size_t);
extern void __libc_free(void*);
static volatile long calls = -1;
static void count(void) { if (calls >= 0) calls++; }
void* malloc(size_t n) { count(); return __libc_malloc(n); }
void* calloc(size_t n, size_t size) { count(); return __libc_calloc(n, size); }
void* realloc(void* p, size_t n) { count(); return __libc_realloc(p, n); }
void* aligned_alloc(size_t align, size_t n) { count(); return __libc_memalign(align, n); }
int posix_memalign(void** out, size_t align, size_t n) { count(); *out = __libc_memalign(align, n); return *out ? 0 : 12; }
void free(void* p) { if (p) count(); __libc_free(p); }
void count_start(void) { calls = 0; }
long count_stop(void) { long c = calls; calls = -1; return c; }
"""

ALLOCATION_RUN = r"""
import ctypes, json, sys
import mujoco
from finrft import integrate, methods, models
from finrft.experiments import swim
from finrft.experiments.swim import RobotScene
from finrft.scene import preset
counter = ctypes.CDLL(sys.argv[1])
counter.count_stop.restype = ctypes.c_long
out = {}
for method in ("implicit", "newton", "newton-midpoint", "adaptive", "adaptive-newton"):
    largest = {"sim.max_step": 1e-3} if methods.get(method).adaptive else {}
    scene = preset("physical", RobotScene).replace(**{"sim.method": method, "sim.dt": 3e-4, **largest})
    robot = swim.build_robot(scene)
    d = mujoco.MjData(robot.model)
    d.qpos[robot.servo_qpos] = scene.gait.theta2
    d.qvel[robot.servo_dof] = scene.gait.omega
    advance = integrate.stepper(robot.model, scene.sim, "native", robot.groups)
    assert advance(d, 10) == 0  # ctypes and MuJoCo set up what they keep
    for n in (1, 300):
        # the library's function itself, its arguments made beforehand: nothing of Python's is counted
        if method.startswith("adaptive"):
            h = ctypes.c_double(advance.h)
            args = (robot.model._address, d._address, n * scene.sim.dt, advance.max_step, advance.tolerance,
                    advance.iterations, ctypes.byref(h), advance.counts)
        else:
            args = (robot.model._address, d._address, n, advance.iterations, advance.midpoint, advance.counts,
                    advance.history.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        counter.count_start()
        code = advance._native(*args)
        out[f"{method}/{n}"] = counter.count_stop()
        assert code == 0
print(json.dumps(out))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("gcc") is None,
                    reason="interposes glibc's allocator")
def test_native_steps_allocate_nothing(tmp_path):
    # Every heap call of the process during a call of the native steppers is counted: none, however many steps.
    (tmp_path / "counter.c").write_text(ALLOCATION_COUNTER)
    subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-o", str(tmp_path / "counter.so"), str(tmp_path / "counter.c")],
                   check=True)
    counter = str(tmp_path / "counter.so")
    # From tmp_path: at the repository root, python -c would import the source tree, not the installed package.
    done = subprocess.run([sys.executable, "-c", ALLOCATION_RUN, counter], capture_output=True, text=True,
                          env={**os.environ, "LD_PRELOAD": counter}, check=True, cwd=tmp_path)
    counts = json.loads(done.stdout.splitlines()[-1])
    for method in ("implicit", "newton", "newton-midpoint", "adaptive", "adaptive-newton"):
        assert counts[f"{method}/300"] == counts[f"{method}/1"] == 0, counts
