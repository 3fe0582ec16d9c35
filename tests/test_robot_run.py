"""finrft run as a robot runner: prescribed joints ([[drive]]: constant, sine) and actuators ([[control]], a Python
controller) against force balances and closed forms; the reports, the files, the scene's arrays of tables and bad
input."""

import math
import subprocess
import sys

import h5py
import numpy as np
import pytest

import finrft
from finrft.cli import main
from finrft.experiments.user_model import run_robot, window_mean
from finrft.scene import SceneError, UserScene, load_scene, to_toml
from conftest import physics_run

# The 4 cm x 6 cm plate of the guide on a slide along x, 10 kg (its drag: 0.370 N/cm^3 x 4 cm x (6 cm)^2 / 2).
PLATE = """<mujoco><option gravity="0 0 -9.81"/><worldbody><body name="plate">
  <joint name="drag" type="slide" axis="1 0 0"/><geom type="box" size="0.0005 0.02 0.03" pos="0 0 -0.03" mass="10"/>
</body></worldbody></mujoco>"""
DRAG_N = 0.370 * 4 * 6 ** 2 / 2

# A rod on a hinge about z, 5 cm above the sand, no gravity: in air its dynamics are I q'' = torque. A position
# actuator (kp, kv) and a velocity actuator (kv) on it; the joint's damping b loads it.
I_ROD = 1e-3 * (0.1 ** 2 / 12 + 0.05 ** 2)  # 1 g rod, 10 cm, its centre 5 cm from the hinge (about 3.3e-6 kg m^2)
ARM = """<mujoco><option gravity="0 0 0"/><worldbody><body name="rod" pos="0 0 0.05">
  <joint name="hinge" type="hinge" axis="0 0 1" damping="{b}"/>
  <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.002" mass="0.001"/>
  <inertial pos="0.05 0 0" mass="0.001" diaginertia="1e-7 {i_z} {i_z}"/></body></worldbody>
  <actuator><{kind} name="motor" joint="hinge" {gains}/></actuator></mujoco>"""


def _arm(tmp_path, kind="position", gains='kp="0.01" kv="1e-4"', b=0.0):
    path = tmp_path / "arm.xml"
    path.write_text(ARM.format(b=b, i_z=I_ROD - 1e-3 * 0.05 ** 2, kind=kind, gains=gains))
    return path


def _plate(tmp_path, drive: str, sim: str = "dt = 1e-3\nrecord_dt = 0.01") -> UserScene:
    (tmp_path / "plate.xml").write_text(PLATE)
    (tmp_path / "scene.toml").write_text(f'[model]\npath = "plate.xml"\nbodies = ["plate"]\n[medium]\nzeta = 1.0\n'
                                         f'{drive}\n[sim]\n{sim}\n')
    return load_scene(tmp_path / "scene.toml", cls=UserScene)


def test_a_plate_dragged_at_constant_speed_balances_the_medium_and_moves_at_the_speed(tmp_path):
    scene = _plate(tmp_path, '[[drive]]\njoint = "drag"\nspeed = 0.1\nstroke = 0', "dt = 1e-3\nduration = 0.3\n"
                   "settle = 0.1\nrecord_dt = 0.01")
    s = finrft.run_robot(scene).summary()
    # force balance: the drive pushes the plate exactly as hard as the medium holds it back (quasi-static)
    assert s["drive_load"][0] == pytest.approx(-s["medium_force_N"][0], rel=1e-6)
    assert s["drive_load"][0] == pytest.approx(DRAG_N, rel=1e-6)  # and that is the closed form
    assert s["body_medium_force_N"]["plate"] == s["medium_force_N"]
    assert s["com_velocity_m_s"] == pytest.approx([0.1, 0, 0], abs=1e-9)
    assert s["com_position_m"][0] == pytest.approx(0.03, abs=1e-9)  # 0.1 m/s for 0.3 s
    # only the drive works: P+ = F v, and the cost of transport is F v / (m g v) = F / (m g)
    assert s["positive_power_W"] == pytest.approx(DRAG_N * 0.1, rel=1e-6)
    assert s["cost_of_transport"] == pytest.approx(DRAG_N / (10 * 9.81), rel=1e-6)
    # auto chooses the step (`finrft.choice`): 0.3 s of it
    assert s["actuator_power_W"] == 0 and s["steps"] == round(0.3 / s["dt"]) and s["sim_time_s"] == pytest.approx(0.3)
    assert set(s["error_estimate"]) == {"position_mm", "velocity_mm_s", "position_percent", "com_velocity_m_s",
                                        "com_speed_m_s", "com_position_m", "medium_force_N", "body_medium_force_N", "drive_load",
                                        "actuator_power_W", "positive_power_W", "cost_of_transport"}


def test_a_single_drive_table_with_cycles_keeps_its_own_length_and_holds_after_it(tmp_path):
    # [drive] read as one [[drive]]; duration 0: one cycle (0.4 s); with a longer duration the plate stops at its
    # start after its cycle and the medium lets go of it
    scene = _plate(tmp_path, '[drive]\njoint = "drag"\nspeed = 0.1\nstroke = 0.02\ncycles = 1')
    assert len(scene.drive) == 1 and scene.duration == pytest.approx(0.4)
    run = finrft.run_robot(scene.replace(**{"sim.duration": 0.6, "sim.settle": 0.45}))
    assert run.drive_position[-1, 0] == pytest.approx(0, abs=1e-9)
    out = run.time < 0.2 - 1e-9
    assert run.drive_load[out][1:, 0] == pytest.approx(DRAG_N, rel=1e-6)
    assert run.summary()["drive_load"] == pytest.approx([0], abs=1e-9)  # held still: no load
    assert run.summary()["cost_of_transport"] is None


def test_a_sine_drive_follows_its_profile_and_its_load_is_the_inertia_times_its_acceleration(tmp_path):
    # The rod in air, its hinge driven as q = 0.3 sin(2 pi 2 t + 0.5): the drive's torque is I q'' exactly.
    (tmp_path / "arm.xml").write_text(ARM.format(b=0, i_z=I_ROD - 1e-3 * 0.05 ** 2, kind="motor", gains=""))
    scene = UserScene().replace(**{"model.path": str(tmp_path / "arm.xml"), "model.bodies": ["rod"],
                                   "drive.0.joint": "hinge", "drive.0.profile": "sine", "drive.0.amplitude": 0.3,
                                   "drive.0.frequency": 2.0, "drive.0.phase": 0.5, "drive.0.start": 0.1,
                                   "sim.duration": 1.0, "sim.dt": 1e-3, "sim.record_dt": 0.01})
    run = finrft.run_robot(scene)
    w = 2 * math.pi * 2.0
    q = 0.1 + 0.3 * np.sin(w * run.time + 0.5)
    assert run.drive_position[:, 0] == pytest.approx(q, abs=1e-9)  # the feed-forward lands each step on it
    assert run.drive_load[:, 0] == pytest.approx(-I_ROD * w ** 2 * (q - 0.1), rel=1e-3, abs=1e-9)
    assert np.max(np.abs(run.medium_force)) == 0  # 5 cm above the sand


def test_a_position_actuator_on_a_sine_gives_the_second_order_response(tmp_path):
    # I q'' = kp (u - q) - kv q' with u = 0.2 sin(w t): in steady state q has amplitude 0.2 kp / |kp - I w^2 + i kv w|
    kp, kv, f = 0.01, 1e-4, 5.0
    path = _arm(tmp_path, gains=f'kp="{kp}" kv="{kv}"')
    scene = UserScene().replace(**{"model.path": str(path), "model.bodies": ["rod"], "control.0.actuator": "motor",
                                   "control.0.kind": "sine", "control.0.amplitude": 0.2, "control.0.frequency": f,
                                   "control.0.ramp": 0.2, "sim.duration": 1.2, "sim.settle": 0.8,
                                   "sim.dt": 1e-4, "sim.record_dt": 1e-3})
    run = physics_run(scene)
    w = 2 * math.pi * f
    expected = 0.2 * kp / abs(kp - I_ROD * w ** 2 + 1j * kv * w)  # transients decay as exp(-kv t / 2I): e^-12
    late = run.time >= 0.8
    q = run.link_quat[late, 0]
    angle = 2 * np.arctan2(q[:, 3], q[:, 0])
    assert (angle.max() - angle.min()) / 2 == pytest.approx(expected, rel=5e-3)
    assert run.ctrl[run.time <= 0.2, 0] == pytest.approx(  # the ramp-in
        0.2 * np.sin(w * run.time[run.time <= 0.2]) * run.time[run.time <= 0.2] / 0.2, abs=1e-12)


def test_actuator_power_is_torque_times_speed_against_a_damper(tmp_path):
    # A velocity actuator (kv) asks 2 rad/s of a hinge with damping b: it settles at w = kv 2 / (kv + b), where its
    # torque b w times w is the power the damper takes.
    kv, b = 1e-3, 5e-4
    path = _arm(tmp_path, kind="velocity", gains=f'kv="{kv}"', b=b)
    scene = UserScene().replace(**{"model.path": str(path), "model.bodies": ["rod"], "control.0.actuator": "motor",
                                   "control.0.value": 2.0, "sim.duration": 1.0, "sim.settle": 0.5,
                                   "sim.dt": 1e-4, "sim.record_dt": 0.01})
    s = physics_run(scene).summary()
    w = kv * 2 / (kv + b)  # transients decay as exp(-(kv + b) t / I): e^-200 by the settle
    assert s["actuator_power_W"] == pytest.approx(b * w ** 2, rel=1e-6)
    assert s["positive_power_W"] == pytest.approx(b * w ** 2, rel=1e-6)


def test_a_python_controller_is_the_scene_control_it_computes(tmp_path):
    path = _arm(tmp_path)
    # one method named: auto could price the Python controller's steps dearer and choose another step
    base = UserScene().replace(**{"model.path": str(path), "model.bodies": ["rod"], "sim.duration": 0.5,
                                  "sim.dt": 1e-3, "sim.record_dt": 0.01, "sim.method": "newton"})
    scene = base.replace(**{"control.0.actuator": "motor", "control.0.kind": "sine", "control.0.offset": 0.1,
                            "control.0.amplitude": 0.3, "control.0.frequency": 2.0, "control.0.phase": 0.2})
    by_scene = finrft.run_robot(scene)
    by_python = run_robot(base, control=lambda t, d: [0.1 + 0.3 * math.sin(2 * math.pi * 2 * t + 0.2)])
    assert by_python.link_quat == pytest.approx(by_scene.link_quat, abs=1e-12)
    assert np.ptp(by_scene.link_quat[:, 0, 3]) > 0.05  # it moved
    with pytest.raises(SceneError, match="not both"):
        run_robot(scene, control=lambda t, d: [0.0])
    with pytest.raises(SceneError, match="returned 2 values"):
        run_robot(base, control=lambda t, d: [0.0, 1.0])
    with pytest.raises(SceneError, match="returned str"):
        run_robot(base, control=lambda t, d: "abc")
    with pytest.raises(SceneError, match="not finite at t = 0.2"):
        run_robot(base, control=lambda t, d: [math.nan if t >= 0.2 else 0.0])


def test_a_table_control_interpolates_its_csv_relative_to_the_scene(tmp_path):
    _arm(tmp_path)
    (tmp_path / "ctrl.csv").write_text("time_s,ctrl\n0,0\n0.2,0.5\n0.4,-0.1\n")
    (tmp_path / "scene.toml").write_text('[model]\npath = "arm.xml"\nbodies = ["rod"]\n[[control]]\n'
                                         'actuator = "motor"\nkind = "table"\ntable = "ctrl.csv"\nramp = 0.1\n'
                                         '[sim]\nduration = 0.6\ndt = 1e-3\nrecord_dt = 0.01\n')
    run = finrft.run_robot(load_scene(tmp_path / "scene.toml", cls=UserScene))
    expected = np.interp(run.time, [0, 0.2, 0.4], [0, 0.5, -0.1]) * np.minimum(1, run.time / 0.1)
    assert run.ctrl[:, 0] == pytest.approx(expected, abs=1e-12)


def test_a_free_body_resting_on_the_sand_runs_and_does_not_move(tmp_path):
    # A 0.5 kg box on a free joint, no floor, newton at 1 ms: the medium alone holds it.
    (tmp_path / "box.xml").write_text("""<mujoco><option gravity="0 0 -9.81"/><worldbody>
      <body name="box" pos="0 0 0.01"><freejoint/><geom type="box" size="0.05 0.05 0.01" mass="0.5"/></body>
      </worldbody></mujoco>""")
    scene = UserScene().replace(**{"model.path": str(tmp_path / "box.xml"), "model.bodies": ["box"],
                                   "medium.law": "li2013-planar", "sim.duration": 1.0, "sim.settle": 0.5,
                                   "sim.method": "newton"})
    s = finrft.run_robot(scene).summary()
    # resting: it creeps at about v_reg atanh(m g / F) < v_reg, far below 0.1 mm/s; the medium carries the weight
    assert s["com_velocity_m_s"] == pytest.approx([0, 0, 0], abs=1e-4)
    assert s["medium_force_N"] == pytest.approx([0, 0, 0.5 * 9.81], abs=1e-3)
    # li2013 resists only downward motion, so the drop overshoots to where the force is twice the weight and
    # sticks there: 2 m g / (zeta A) = 0.98 mm below the surface, plus the creep of the ramp (0.05 mm in 1 s)
    assert 0.01 - s["com_position_m"][2] == pytest.approx(2 * 0.5 * 9.81 / (1e6 * 0.01) + 5e-5, abs=2e-5)
    assert s["cost_of_transport"] is None and "does not move" in s["cost_of_transport_note"]


def test_a_run_starts_from_the_keyframe_the_scene_names(tmp_path):
    # The free body of FREE falls freely for 0.1 s from the keyframe's height h and upward speed v, the medium far
    # below: each step v -= g dt, then z += v dt, so z = h + v t - g (t^2 + t dt) / 2. A drive still starts where
    # its [[drive]] says.
    (tmp_path / "m.xml").write_text(FREE.replace("</mujoco>", '<keyframe><key name="up" qpos="0 0 0.3 1 0 0 0 '
                                                 '0.02" qvel="0 0 0.5 0 0 0 0"/></keyframe></mujoco>'))
    scene = UserScene().replace(**{"model.path": str(tmp_path / "m.xml"), "model.bodies": ["b"],
                                   "model.keyframe": "up", "sim.duration": 0.1, "sim.record_dt": 0.01,
                                   "drive.0.joint": "slide", "drive.0.speed": 0.0, "drive.0.stroke": 0.0,
                                   "drive.0.start": -0.01})
    run = finrft.run_robot(scene)
    t, dt = run.time, run.scene.sim.dt  # the step auto chose
    assert run.body_position[:, 0, 2] == pytest.approx(0.3 + 0.5 * t - 9.81 * (t ** 2 + t * dt) / 2, abs=1e-9)
    assert run.drive_position[:, 0] == pytest.approx(-0.01, abs=1e-9)


def test_window_mean_is_the_time_average_from_the_settle():
    t = np.linspace(0, 1, 11)
    assert window_mean(t, 3 * t, 0.25) == pytest.approx(3 * (1 + 0.25) / 2)  # linear: its midpoint value


def test_the_recordings_hold_the_series_and_the_geometry(tmp_path, capsys):
    path = _arm(tmp_path)
    (tmp_path / "scene.toml").write_text('[model]\npath = "arm.xml"\nbodies = ["rod"]\n[[control]]\n'
                                         'actuator = "motor"\nkind = "constant"\nvalue = 0.3\n[[drive]]\n'
                                         'joint = "hinge"\nprofile = "sine"\namplitude = 0.2\n'
                                         '[sim]\nduration = 0.2\ndt = 1e-3\nrecord_dt = 0.01\n')
    h5, rrd = tmp_path / "run.h5", tmp_path / "run.rrd"
    assert main(["run", str(path), "--scene", str(tmp_path / "scene.toml"), "--out", str(h5), "--rrd", str(rrd)]) == 0
    text = capsys.readouterr().out
    assert "mm/s" in text and "deg" in text and "N m" in text
    with h5py.File(h5) as f:
        assert f.attrs["schema"] == "finrft.user/2" and "[[drive]]" in f.attrs["scene_toml"]
        n = len(f["time"])
        for name, shape in {"com_position": (n, 3), "medium_force": (n, 1, 3), "link_quat": (n, 1, 4),
                            "drive_load": (n, 1), "actuator_force": (n, 1), "ctrl": (n, 1)}.items():
            assert f[name].shape == shape, name
        assert f["drive_load"].attrs["units"] == "N m" and f["ctrl"][:, 0] == pytest.approx(0.3)
        assert "error_estimate_position_percent" in f.attrs
    printed = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", str(rrd)], capture_output=True,
                             text=True, timeout=120).stdout
    for entity, archetype in (("/robot/rod/geom0", "Capsules3D"), ("/robot/rod ", "Transform3D"),
                              ("/robot/medium_force", "Arrows3D"), ("/robot/surface", "Mesh3D"),
                              ("/robot/rod/elements", "Points3D")):
        assert any(entity in line and archetype in line for line in printed.splitlines()), entity


def test_drives_and_controls_are_arrays_of_tables():
    scene = UserScene().replace(**{"drive.0.joint": "a", "drive.1.joint": "b", "drive.1.profile": "sine"})
    assert [j.joint for j in scene.drive] == ["a", "b"] and scene.drive[1].profile == "sine"
    text = to_toml(scene)
    assert text.count("[[drive]]") == 2 and "# [[control]]: none" in text
    import tomllib
    assert finrft.scene.scene_from_dict(tomllib.loads(text.replace("# [[control]]: none", "")), UserScene) == scene
    with pytest.raises(SceneError, match="name one as drive.N.speed"):
        scene.replace(**{"drive.speed": 1.0})
    with pytest.raises(SceneError, match="drive.1.profile = 'step' is not allowed"):
        scene.replace(**{"drive.1.profile": "step"})


FREE = """<mujoco><worldbody><body name="b" pos="0 0 0.05"><freejoint name="free"/>
  <geom type="sphere" size="0.01"/></body><body name="c"><joint name="slide" type="slide"/>
  <geom type="sphere" size="0.01"/></body></worldbody><actuator><motor name="m" joint="slide"/></actuator></mujoco>"""


@pytest.mark.parametrize("sets,named", [
    (["control.0.actuator=arm"], "no actuator named 'arm' (its actuators: m)"),
    (["drive.0.joint=elbow"], "drive.0.joint: the model has no joint named 'elbow'"),
    (["drive.0.joint=free"], "drive.0.joint 'free' is a free joint: drive a slide or hinge joint"),
    (["control.0.actuator=m", "control.0.ramp=2"], "control.0.ramp = 2 s must be shorter than the run (1 s)"),
    (["sim.settle=1"], "sim.settle = 1 s must be shorter than the run"),
    (["sim.duration=0"], "sim.duration = 0 needs a constant [[drive]]"),
    (["control.0.actuator=m", "control.0.kind=table", "control.0.table=none.csv"], "cannot read"),
    (["control.0.actuator=m", "control.0.kind=table", "control.0.table={tmp}/bad.csv"], "two numbers"),
    (["drive.0.joint=slide", "drive.0.stroke=0.07", "drive.0.speed=0.3"], "not a whole number of the drives' strokes"),
    (["model.keyframe=home"], "model.keyframe: the model has no keyframe named 'home' (its keyframes: none)"),
])
def test_bad_robot_input_is_one_line_and_exit_2_before_running(tmp_path, capsys, sets, named):
    (tmp_path / "m.xml").write_text(FREE)
    (tmp_path / "bad.csv").write_text("time_s,ctrl\n0,1\n1,x\n")
    (tmp_path / "scene.toml").write_text('[model]\npath = "m.xml"\nbodies = ["b"]\n[sim]\nduration = 1.0\n')
    argv = ["run", "--scene", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "o.h5")]
    assert main([*argv, *[a for s in sets for a in ("--set", s.format(tmp=tmp_path))]]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err, err
    assert not (tmp_path / "o.h5").exists()


def test_the_error_limit_is_a_share_of_the_run_s_scale(tmp_path):
    scene = _plate(tmp_path, '[[drive]]\njoint = "drag"\nspeed = 0.1\nstroke = 0', "dt = 1e-3\nduration = 2.0\n"
                   "record_dt = 0.01")
    run = finrft.run_robot(scene)
    s = run.summary()
    assert s["scale_m"] == pytest.approx(0.2)  # the plate travels 200 mm, more than its size (125 mm diagonal)
    assert s["error_estimate"]["position_percent"] == pytest.approx(
        100 * s["error_estimate"]["position_mm"] / 200, rel=1e-9)


def test_geoms_chosen_by_name_in_the_scene(tmp_path):
    # The plate's body carries a second, heavy geom standing in the sand beside it; model.geoms takes the plate's
    # geom alone: the drive's load is the plate's closed form (test above), as if the other geom were not there.
    (tmp_path / "plate.xml").write_text(PLATE.replace(
        '<geom type="box"', '<geom name="blade" type="box"').replace(
        'mass="10"/>', 'mass="10"/><geom name="post" type="box" size="0.01 0.01 0.03" pos="0 0.1 -0.03"/>'))
    scene = UserScene().replace(**{"model.path": str(tmp_path / "plate.xml"), "model.geoms": ["blade"],
                                   "drive.0.joint": "drag", "drive.0.speed": 0.1, "drive.0.stroke": 0.0,
                                   "sim.duration": 0.3, "sim.settle": 0.1, "sim.record_dt": 0.01})
    s = finrft.run_robot(scene).summary()
    assert s["bodies"] == ["plate"]
    assert s["drive_load"][0] == pytest.approx(DRAG_N, rel=1e-6)
    with pytest.raises(SceneError, match="no geom named 'wing'"):
        finrft.run_robot(scene.replace(**{"model.geoms": ["wing"]}))


def test_the_forces_behind_a_state_are_taken_once_per_state(monkeypatch):
    # a recorded instant that is also a step of the means' window asks twice at one state: one forward pass, and a
    # new one as soon as anything it reads changes (the velocity, the plugins' state)
    import mujoco

    from finrft.experiments.attached_model import applied_state
    from finrft.experiments.user_model import UserModel, example
    from finrft.scene import UserScene, load_scene

    scene = load_scene(example("wheel_rig"), cls=UserScene)
    built = UserModel.of(scene).build(scene)
    m = built.model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(scene.model.keyframe).id)
    d.qvel[:] = 0.01
    applied = applied_state(built, "newton")
    calls = []
    forward = mujoco.mj_forward
    monkeypatch.setattr(mujoco, "mj_forward", lambda m, d: (calls.append(d), forward(m, d))[1])
    first = applied(d).qfrc_passive.copy()
    assert np.abs(first).max() > 0 and applied(d).qfrc_passive.tolist() == first.tolist() and len(calls) == 1
    d.qvel[:] = 0.02
    assert np.abs(applied(d).qfrc_passive - first).max() > 0 and len(calls) == 2
    d.plugin_state[:] += 0.0  # the same state: no new pass
    applied(d)
    assert len(calls) == 2
    other = mujoco.MjData(m)
    other.qpos[:], other.qvel[:] = d.qpos, d.qvel
    applied(other)  # another MjData at the same state is another state
    assert len(calls) == 3
