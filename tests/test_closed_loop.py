"""Closed loops in a scene ([[control]] kinds pd and sensor) against the closed form of a damped oscillator; the
offset-keeping ramp; the model's sensors in the summary, HDF5 and rerun by name; a controller in the place of a
scene's controls; recordings naming the model's entities."""

import math
import subprocess
import sys

import h5py
import numpy as np
import pytest

import finrft
from finrft.cli import main
from finrft.scene import SceneError, UserScene
from conftest import physics_run

# A rod on a hinge about z, 5 cm above the sand, no gravity, a motor: in air I q'' = ctrl. Sensors: its angle
# (jointpos), its centre of mass (framepos of the body's inertial frame), unnamed its angular velocity.
I_ROD = 1e-3 * 0.05 ** 2 + 1e-6
ARM = """<mujoco><option gravity="0 0 0"/><worldbody><body name="rod" pos="0 0 0.05">
  <joint name="hinge" type="hinge" axis="0 0 1"/>
  <geom name="bar" type="capsule" fromto="0 0 0 0.1 0 0" size="0.002" mass="0.001"/>
  <inertial pos="0.05 0 0" mass="0.001" diaginertia="1e-7 1e-6 1e-6"/></body></worldbody>
  <actuator><motor name="motor" joint="hinge"/></actuator>
  <sensor><jointpos name="angle" joint="hinge"/><framepos name="centre" objtype="body" objname="rod"/>
  <jointvel joint="hinge"/></sensor></mujoco>"""
KP, KD, TARGET = 0.01, 1e-4, 0.3


@pytest.fixture
def arm(tmp_path):
    (tmp_path / "arm.xml").write_text(ARM)
    return UserScene().replace(**{"model.path": str(tmp_path / "arm.xml"), "model.bodies": ["rod"],
                                  "sim.duration": 0.3, "sim.settle": 0.1, "sim.dt": 1e-4, "sim.record_dt": 0.005,
                                  "sim.method": "newton"})


def _loop(scene, kind, **keys):
    keys = {"actuator": "motor", "kind": kind, "offset": TARGET, "kp": KP, "kd": KD, **keys}
    return scene.replace(**{f"control.0.{k}": v for k, v in keys.items()})


def _oscillator(t):
    """I q'' + KD q' + KP q = KP TARGET from rest at 0, underdamped."""
    w0, zeta = math.sqrt(KP / I_ROD), KD / (2 * math.sqrt(KP * I_ROD))
    wd = w0 * math.sqrt(1 - zeta ** 2)
    decay = np.exp(-zeta * w0 * t)
    return TARGET * (1 - decay * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t)))


def test_a_pd_control_follows_the_damped_oscillator_of_its_gains(arm):
    run = physics_run(_loop(arm, "pd", joint="hinge"))
    angle = run.sensor[:, 0]
    assert np.ptp(angle) > 0.25  # it moved to the target, overshooting (zeta 0.47)
    # within the step's own lag, half a step's travel at the peak speed (dt / 2 x 10 rad/s = 5e-4 rad)
    assert angle == pytest.approx(_oscillator(run.time), abs=1e-3)
    # the ctrl recorded is the law's: kp (r - q) - kd q'
    velocity = run.sensor[:, 4]
    assert run.ctrl[5:, 0] == pytest.approx(KP * (TARGET - angle[5:]) - KD * velocity[5:], abs=1e-4 * KP)


def test_a_sensor_loop_is_the_pd_law_on_its_reading(arm):
    # on the joint's angle sensor with kd = 0 it is the pd law exactly; its rate is a difference over a step,
    # so with kd it follows the same oscillator
    pd = physics_run(_loop(arm, "pd", joint="hinge", kd=0.0))
    fed = physics_run(_loop(arm, "sensor", sensor="angle", kd=0.0))
    assert np.array_equal(pd.link_quat, fed.link_quat)
    damped = physics_run(_loop(arm, "sensor", sensor="angle"))
    assert damped.sensor[:, 0] == pytest.approx(_oscillator(damped.time), abs=1e-3)
    # a framepos's y component (index 1), 5 cm from the hinge: y = 0.05 sin q, taken to the reference (the same
    # oscillator near q = 0.2 rad: 1.5 % of its step left at the end) from y = 0
    y = 0.05 * math.sin(0.2)
    held = physics_run(_loop(arm, "sensor", sensor="centre", index=1, offset=y, kp=KP / 0.05, kd=KD / 0.05))
    assert held.sensor[-1, 2] == pytest.approx(y, rel=0.03)
    assert np.max(held.sensor[:, 2]) > 1.1 * y  # it overshot, as the oscillator does


@pytest.mark.parametrize("keys, message", [
    ({"kind": "pd", "joint": "elbow"}, "control.0.joint: the model has no joint named 'elbow' (its joints: hinge)"),
    ({"kind": "sensor", "sensor": "depth"}, "control.0.sensor: the model has no sensor named 'depth'"),
    ({"kind": "sensor", "sensor": "centre", "index": 3}, "control.0.index = 3: sensor 'centre' has 3 value"),
])
def test_a_bad_loop_is_one_line_before_the_run(arm, keys, message, tmp_path, capsys):
    scene = _loop(arm, **keys)
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        finrft.run_robot(scene)
    (tmp_path / "s.toml").write_text(finrft.to_toml(scene))
    assert main(["run", "--scene", str(tmp_path / "s.toml")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_ramp_of_the_oscillation_alone_holds_the_offset(arm):
    sine = {"control.0.actuator": "motor", "control.0.kind": "sine", "control.0.offset": 0.002,
            "control.0.amplitude": 0.001, "control.0.frequency": 20.0, "control.0.ramp": 0.1}
    t = np.linspace(0, 0.3, 61)
    wave = 0.001 * np.sin(2 * math.pi * 20 * t)
    ramp = np.minimum(1, t / 0.1)
    kept = physics_run(arm.replace(**sine, **{"control.0.ramps": "oscillation"}))
    assert kept.ctrl[:, 0] == pytest.approx(0.002 + wave * ramp, abs=1e-12)
    scaled = physics_run(arm.replace(**sine))  # the default, as before: the offset ramps in too
    assert scaled.ctrl[:, 0] == pytest.approx((0.002 + wave) * ramp, abs=1e-12)


@pytest.mark.slow  # a whole command with its files; the sensor loop itself is checked above
def test_sensors_are_reported_recorded_and_estimated_by_their_names(arm, tmp_path, capsys):
    scene = _loop(arm, "pd", joint="hinge")
    (tmp_path / "s.toml").write_text(finrft.to_toml(scene))
    h5, rrd = tmp_path / "run.h5", tmp_path / "run.rrd"
    assert main(["run", "--scene", str(tmp_path / "s.toml"), "--out", str(h5), "--rrd", str(rrd),
                 "--max-error", "com_speed_m_s=100%"]) == 0  # the rod turns in place: its speed is a few um/s
    assert "sensors' means (their units): angle 0." in capsys.readouterr().out
    run = finrft.run_robot(scene, max_error=None)
    s = run.summary()
    assert list(s["sensors"]) == ["angle", "centre", "sensor2"]
    assert [len(v) for v in s["sensors"].values()] == [1, 3, 1]
    # the means over every step, against the recorded samples' trapezoid (fine samples of a smooth motion)
    from finrft.experiments.user_model import window_mean
    assert s["sensors"]["angle"][0] == pytest.approx(window_mean(run.time, run.sensor[:, 0], 0.1), rel=1e-3)
    assert s["sensors"]["centre"][2] == pytest.approx(0.05, abs=1e-12)
    assert set(s["error_estimate"]["sensors"]) == {"angle", "centre", "sensor2"}
    with h5py.File(h5) as f:
        assert f["sensor"].shape == (len(f["time"]), 5)
        assert f["sensor"].attrs["sensors"] == "angle,centre.0,centre.1,centre.2,sensor2"
    printed = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(rrd)], capture_output=True,
                             text=True, timeout=120).stdout
    for entity in ("/sensor/angle", "/sensor/centre.2", "/actuator/force/motor", "/robot/rod/bar"):
        assert any(f"{entity} " in line for line in printed.splitlines()), entity
    assert "/robot/rod/geom0" not in printed and "actuator1" not in printed


def test_a_python_controller_takes_the_place_of_the_scenes_controls(arm):
    scene = _loop(arm, "pd", joint="hinge")
    with pytest.raises(SceneError, match="without_controls"):
        finrft.run_robot(scene, control=lambda t, d: [0.0])
    law = lambda t, d: [KP * (TARGET - d.qpos[0]) - KD * d.qvel[0]]
    by_python = physics_run(scene.without_controls(), control=law)
    assert by_python.link_quat == pytest.approx(physics_run(scene).link_quat, abs=1e-12)
    assert scene.control and not scene.without_controls().control
