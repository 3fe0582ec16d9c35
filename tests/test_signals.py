"""Signals: Ctrl-C and SIGTERM stop a run within a second, in one line, with 128 + the signal's number, and leave
no file; in the Python API Ctrl-C is a KeyboardInterrupt, never the end of the interpreter."""

import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from conftest import default_ctrl_c

OUTSIDE = tempfile.gettempdir()  # not the repository's root, whose source tree has no built plugin


def _started(argv: list[str], tmp_path) -> subprocess.Popen:
    code = ("import sys; from finrft.cli import main; print('ready', flush=True); sys.exit(main(sys.argv[1:]))")
    run = subprocess.Popen([sys.executable, "-c", code, *argv, "--quiet", "--out", str(tmp_path / "run.h5")],
                           cwd=OUTSIDE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           preexec_fn=default_ctrl_c)
    assert run.stdout.readline() == "ready\n"
    return run


def _stopped(run: subprocess.Popen, sig: int, errors_only) -> float:
    run.send_signal(sig)
    start = time.monotonic()
    status = run.wait(timeout=60)
    took = time.monotonic() - start
    assert status == 128 + sig
    assert errors_only(run.stderr.read()) == "finrft: interrupted\n"
    return took


# SIGTERM takes the same path as SIGINT (finrft.interrupts); it runs with the slow studies.
@pytest.mark.parametrize("sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_a_robot_run_stops_on_a_signal(tmp_path, sig, errors_only):
    run = _started(["run", "--example", "sand_swimmer"], tmp_path)
    time.sleep(3)  # into its steps
    assert _stopped(run, sig, errors_only) < 2
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_a_signal_inside_a_long_native_call_stops_the_process(tmp_path, tmp_path_factory, sig, errors_only):
    # A mesh of 300,000 points: MuJoCo takes its convex hull for many seconds, in one C call that no Python handler
    # interrupts.
    folder = tmp_path_factory.mktemp("model")
    points = np.random.default_rng(0).normal(size=(300_000, 3))
    np.savetxt(folder / "ball.obj", 0.05 * points / np.linalg.norm(points, axis=1)[:, None], fmt="v %.6f %.6f %.6f")
    (folder / "ball.xml").write_text('<mujoco><asset><mesh name="ball" file="ball.obj"/></asset><worldbody>'
                                     '<body name="ball" pos="0 0 0.02"><freejoint/>'
                                     '<geom type="mesh" mesh="ball" mass="0.5"/></body></worldbody></mujoco>')
    (folder / "ball.toml").write_text('[model]\npath = "ball.xml"\nbodies = ["ball"]\n[sim]\nduration = 0.1\n')
    run = _started(["run", "--scene", str(folder / "ball.toml")], tmp_path)
    time.sleep(2)
    assert _stopped(run, sig, errors_only) < 2
    assert not any(tmp_path.iterdir())


def test_ctrl_c_in_a_controller_is_a_keyboard_interrupt(errors_only):
    # Ctrl-C while MuJoCo's C code runs the controller (a native stepper calls it): a notebook's "interrupt".
    code = """
import dataclasses, os, signal, mujoco, finrft
from finrft.experiments.user_model import example
scene = dataclasses.replace(finrft.load_scene(example("sand_swimmer"), cls=finrft.UserScene), control=())
calls = []
def control(t, d):
    calls.append(t)
    if len(calls) == 50:
        os.kill(os.getpid(), signal.SIGINT)
    return d.ctrl * 0
try:
    finrft.run_robot(scene, control=control)
except KeyboardInterrupt:
    print("interrupted after", len(calls), "calls;", mujoco.get_mjcb_control(), mujoco.get_mjcb_passive())
"""
    done = subprocess.run([sys.executable, "-c", code], cwd=OUTSIDE, capture_output=True, text=True, timeout=300,
                          preexec_fn=default_ctrl_c)
    assert done.returncode == 0 and errors_only(done.stderr) == "", done.stdout + done.stderr
    calls = int(done.stdout.split()[2])
    assert calls >= 50 and done.stdout.endswith("calls; None None\n")


def test_ctrl_c_while_mujoco_converts_an_argument_is_the_search_interrupt(tmp_path, errors_only):
    # Ctrl-C that lands while pybind11 converts an argument of MuJoCo's (the handler runs in the conversion) was a
    # TypeError "incompatible function arguments" and exit 1, in about 1 of 30 interrupted searches.
    code = f"""
import os, signal, sys, mujoco
from finrft import models
from finrft.cli import main

class Interrupting:
    def __float__(self):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(100):  # bytecodes in which Python runs the handler
            pass
        return 0.0

built = []
segment_spec = models._segment_spec
def interrupted_spec(*args):
    built.append(1)
    if len(built) == 8:  # in the second generation, after the log's first write
        mujoco.MjSpec().worldbody.add_body(pos=[Interrupting(), 0.0, 0.0])
    return segment_spec(*args)
models._segment_spec = interrupted_spec
sys.exit(main(["optimize", "--preset", "paper", "--seed", "3", "--workers", "1", "--set", "gait.omega=3",
               "--budget", "55", "--quiet", "--out", {str(tmp_path / "run.h5")!r}]))
"""
    done = subprocess.run([sys.executable, "-c", code], cwd=OUTSIDE, capture_output=True, text=True, timeout=300,
                          preexec_fn=default_ctrl_c)
    assert done.returncode == 130, done.stderr
    assert errors_only(done.stderr) == (f"finrft: interrupted after 1 generation; continue with: finrft optimize "
                                        f"--resume {tmp_path / 'run.h5'}\n")


def test_a_controller_error_inside_a_native_step_is_raised_to_the_caller():
    # A controller that fails while a native stepper (MuJoCo's C code) calls it: was the interpreter's end.
    code = """
import dataclasses, finrft
from finrft.experiments.user_model import example
scene = dataclasses.replace(finrft.load_scene(example("sand_swimmer"), cls=finrft.UserScene), control=())
calls = []
def control(t, d):
    calls.append(t)
    return [1.0] if len(calls) > 30 else d.ctrl * 0
try:
    finrft.run_robot(scene, control=control)
except finrft.SceneError as exc:
    print(exc)
"""
    done = subprocess.run([sys.executable, "-c", code], cwd=OUTSIDE, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "control(t, data) returned 1 values: give one ctrl per actuator (6)\n"
