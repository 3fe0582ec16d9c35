"""finrft run (RFT on a user's MJCF model, a joint prescribed; the robot runner's own tests: test_robot_run.py) against the closed form of a plate dragged through
the medium; its files and bad input. The intrusion experiment against the Li 2013 closed form of a plate pushed
straight down, and its figure."""

import json
import math
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

import finrft
from finrft.cli import main
from finrft.experiments.intrusion import Intrusion, intrude
from finrft.laws import li2013
from finrft.experiments.intrusion import IntrusionScene
from finrft.scene import UserScene, load_scene
from finrft.experiments.user_model import UserModel
from conftest import dragged_plate_scene

# A 4 cm x 6 cm plate (1 mm thick), its top at the surface, on a slide along x: the README's attach example.
MODEL = """<mujoco><option gravity="0 0 -9.81"/><worldbody><body name="plate">
  <joint name="drag" type="slide" axis="1 0 0"/><geom type="box" size="0.0005 0.02 0.03" pos="0 0 -0.03" mass="10"/>
</body></worldbody></mujoco>"""
SCENE = dragged_plate_scene(0.02, drive="cycles = {cycles}", record_dt=0.01)
CLOSED_FORM = 0.370 * 4 * 6 ** 2 / 2  # alpha_x(90 deg, 0) w H^2 / 2 in N/cm^3 x cm^3: 26.64 N


def _files(tmp_path, cycles: int = 0):
    (tmp_path / "plate.xml").write_text(MODEL)
    (tmp_path / "scene.toml").write_text(SCENE.format(cycles=cycles))
    return tmp_path / "plate.xml", tmp_path / "scene.toml"


def _last_json(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def test_plate_dragged_through_the_medium_needs_the_closed_form_force(tmp_path, capsys):
    model, scene = _files(tmp_path, cycles=1)
    out, rrd = tmp_path / "run.h5", tmp_path / "run.rrd"
    assert main(["run", str(model), "--scene", str(scene), "--json", "--out", str(out), "--rrd", str(rrd)]) == 0
    summary = _last_json(capsys.readouterr().out)
    assert summary["com_position_m"][0] == pytest.approx(0, abs=1e-9)  # out and back
    assert summary["error_estimate"]["position_mm"] < 1e-3
    with h5py.File(out) as f:
        assert f.attrs["schema"] == "finrft.user/2"
        assert f["drive_load"].attrs["units"] == "N" and f["drive_position"].attrs["units"] == "m"
        assert f["medium_force"].shape == (len(f["time"]), 1, 3) and f["medium_force"].attrs["units"] == "N"
        assert f["body_position"].attrs["bodies"] == "plate"
        t, load = f["time"][:], f["drive_load"][:, 0]
        # the drive pushes +26.64 N out and pulls -26.64 N back: the medium resists the motion both ways
        assert load[(t > 0) & (t < 0.2 - 1e-9)] == pytest.approx(CLOSED_FORM, rel=0.03)
        assert load[(t > 0.2) & (t < 0.4 - 1e-9)] == pytest.approx(-CLOSED_FORM, rel=0.03)
        # the medium's force recomputed on the body is what the drive needs, against the motion
        moving = np.abs(f["medium_force"][:, 0, 0]) > 1
        assert f["medium_force"][:, 0, 0][moving] == pytest.approx(-load[moving], rel=1e-6)
    assert rrd.stat().st_size > 1000


def test_a_drive_its_load_moves_stops_the_run_and_writes_nothing(tmp_path, capsys):
    # The plate at 0.1 g dragged 200 mm: the drive's armature (1e10 x 0.1 g) lets 26.6 N move it behind its motion,
    # 0.1 % of the stroke by 3.9 s, which the error estimate cannot see (its companion lags alike); at 10 kg it holds.
    model, scene = _files(tmp_path)
    model.write_text(MODEL.replace('mass="10"', 'mass="0.0001"'))
    out = tmp_path / "run.h5"
    argv = ["run", str(model), "--scene", str(scene), "--set", "drive.stroke=0.2", "--set", "drive.speed=0.01",
            "--set", "sim.dt=0.005"]  # a constant drag: the lag grows with the time alone, not with the step
    assert main([*argv, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "off its prescribed motion" in err and "% of its stroke" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    model.write_text(MODEL)
    assert main([*argv, "--json", "--quiet"]) == 0
    assert _last_json(capsys.readouterr().out)["com_position_m"][0] == pytest.approx(0.2, abs=1e-6)


# the run stepped in numpy beside the native one: with the slow studies
@pytest.mark.slow
def test_python_backend_gives_the_native_run(tmp_path):
    model, scene_file = _files(tmp_path)
    scene = load_scene(scene_file, cls=UserScene)
    assert scene.model.path == str(model)  # relative to the scene file
    runs = [finrft.run(UserModel.of(scene), scene.replace(**{"sim.backend": b}))
            for b in ("native", "python")]
    assert runs[1].backend == "python"
    assert runs[0].drive_load == pytest.approx(runs[1].drive_load, abs=1e-9)


@pytest.mark.parametrize("edit,named", [
    ({"model": "missing.xml"}, "missing.xml: no such file"),
    ({"xml": "<mujoco><worldbody><body"}, "XML parse error"),
    ({"xml": MODEL.replace('size="0.0005 0.02 0.03"', 'size="0 0.02 0.03"')}, "size 0 must be positive"),
    ({"set": "drive.joint=slider"}, "no joint named 'slider' (its joints: drag)"),
    ({"set": "model.bodies=arm"}, "no body named 'arm'"),
    ({"set": "drive.profile=step"}, "drive.0.profile = 'step' is not allowed: use one of constant, sine"),
    ({"xml": MODEL.replace('type="slide" axis="1 0 0"', 'type="ball"')}, "ball joint: drive a slide or hinge"),
    # each of these once ran to exit 0 with a wrong result: a key the entry's kind ignores, a sine with no kind
    # (constant 0), a sine faster than the step (aliased: never moves), a surface out of reach or absurdly deep,
    # a regularisation narrower than Newton's tolerance (a wrong rest force), a keyframe of NaN
    ({"set": "drive.amplitude=0.01"}, "drive.0.amplitude is used by profile = 'sine' only"),
    ({"set": ("control.0.actuator=a", "control.0.amplitude=1", "control.0.frequency=2")},
     "this entry's kind is 'constant' (its default): set control.0.kind, or leave amplitude out"),
    ({"set": ("medium.law=rft3d", "medium.zeta=2", "medium.bulk_density=1500", "medium.internal_friction=0.5")},
     "medium.zeta is used by law = 'li2013' or 'li2013-planar' only"),
    ({"set": ("drive.profile=sine", "drive.speed=0.1", "drive.stroke=0.05", "drive.frequency=1000",
              "sim.duration=0.1")}, "drive.0.frequency = 1000 Hz has 1 steps per period"),
    ({"set": ("drive.profile=sine", "drive.stroke=0.05", "drive.frequency=200", "sim.duration=0.1")},
     "set sim.dt <= 0.000625 s"),
    ({"set": "medium.surface_z=1e10"}, "medium.surface_z = 1e+10 m lies"),
    ({"set": "medium.surface_z=-1e10"}, "cannot reach it"),
    ({"set": "medium.v_reg=3e-10"}, "medium.v_reg = 3e-10 m/s is implausibly small"),
    ({"set": "sim.dt=1deg"}, "deg is no unit of sim.dt, whose unit is s"),
    ({"set": "model.keyframe=start", "xml": MODEL.replace("</worldbody>", '</worldbody><keyframe><key name="start" '
                                                          'qpos="nan"/></keyframe>')},
     "model.keyframe 'start': its qpos[0] is nan"),
    ({"set": "model.keyframe=start", "xml": MODEL.replace("</worldbody>", '</worldbody><keyframe><key name="start" '
                                                          'qvel="inf"/></keyframe>')}, "its qvel[0] is inf"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, edit, named):
    model, scene = _files(tmp_path)
    if "xml" in edit:
        model.write_text(edit["xml"])
    argv = ["run", edit.get("model", str(model)), "--scene", str(scene), "--out", str(tmp_path / "run.h5")]
    sets = edit.get("set", ())
    assert main([*argv, *(item for key in ((sets,) if isinstance(sets, str) else sets) for item in ("--set", key))]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and named in err, err
    assert not (tmp_path / "run.h5").exists()


def _closed_form(scene: IntrusionScene, depth: np.ndarray) -> np.ndarray:
    """Li 2013's vertical force on the submerged plate pushed straight down (gamma = pi/2): alpha_z times the
    mean depth times the area of each leading face, the lower face at beta and, on a tilted plate, the lower edge
    at pi/2 - beta (a horizontal plate's edges move in their own plane and take nothing). The depth is linear over
    a flat face, so its mean is the depth at its centre. Each face's force is ramped by tanh(n.v / v_reg)
    (`finrft.laws.regularised`): 4e-9 off on the lower face at 10 mm/s, 1e-6 on a 30 deg plate's edge, and the
    faces of a vertical plate, parallel to the motion, take nothing (no longer a face leading by rounding)."""
    p, beta, v_reg = scene.plate, abs(scene.plate.angle), scene.medium.v_reg
    face = li2013.alpha(beta, math.pi / 2, scene.medium.zeta)[1] * (depth - p.length / 2 * math.sin(beta))
    edge = li2013.alpha(math.pi / 2 - beta, math.pi / 2, scene.medium.zeta)[1] * (depth - p.thickness / 2
                                                                                  * math.cos(beta))
    ramp_face, ramp_edge = (math.tanh(p.speed * c / v_reg) for c in (math.cos(beta), math.sin(beta)))
    return face * p.width * p.length * ramp_face + (edge * p.width * p.thickness * ramp_edge if beta > 0 else 0.0)


def test_intrusion_matches_the_closed_form_when_submerged():
    scene = IntrusionScene()
    p = scene.plate
    runs = {r.scene.plate.angle: r for r in intrude(scene, [0, 30, -30, 90])}
    for beta, run in runs.items():
        reach = p.length * abs(math.sin(beta)) + p.thickness * math.cos(beta)  # lowest to highest point
        submerged = run.depth > reach + 1e-3
        assert submerged.sum() > 10
        # exact (the elements' depth is linear over each face), so far inside the 3 % asked of it
        assert run.force_z[submerged] == pytest.approx(_closed_form(run.scene, run.depth[submerged]), rel=1e-9)
        assert run.force_z[run.depth < 0] == pytest.approx(0, abs=1e-12)  # above the surface
    flat = runs[0.0]
    # a horizontal plate: zeta x 1 N/cm^3 x w L d, nothing sideways
    deep = flat.depth > 0.01
    assert flat.force_z[deep] == pytest.approx(1e6 * p.width * p.length * flat.depth[deep], rel=1e-6)
    assert np.max(np.abs(flat.force_x)) < 1e-9
    # tilted plates mirror each other sideways; the vertical plate cutting in edge first takes much less
    assert runs[math.radians(30)].force_x == pytest.approx(-runs[math.radians(-30)].force_x, rel=1e-9, abs=1e-9)
    assert runs[math.radians(30)].force_x[-1] > 1
    assert runs[math.radians(90)].force_z[-1] < 0.15 * flat.force_z[-1]


def test_intrude_writes_the_figure_and_json(tmp_path, capsys):
    plot = tmp_path / "curves.png"
    assert main(["intrude", "--angles", "0,90", "--set", "plate.depth=0.02", "--plot", str(plot), "--json"]) == 0
    rows = _last_json(capsys.readouterr().out)
    assert [row["angle_deg"] for row in rows] == [0, 90]
    assert rows[0]["final_force_z_N"] > 5 * rows[1]["final_force_z_N"] > 0
    assert len(rows[0]["depth_mm"]) == len(rows[0]["force_z_N"])
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["intrude", "--angles", "0,120"]) == 2
    assert "within -90..90" in capsys.readouterr().err


def test_intrusion_is_an_experiment_of_the_engine():
    run = finrft.run(Intrusion(), IntrusionScene().replace(**{"plate.depth": 0.01}))
    assert set(run.quantities) == {"depth", "force_z", "force_x"}
    assert run.error_estimate["force_N"] < 1e-6


def test_the_guide_scene_runs_the_guide_plate(tmp_path, capsys):
    guide = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "own-model.md").read_text()
    (block,) = [b for b in re.findall(r"^```toml\n(.*?)^```", guide, flags=re.S | re.M) if "[model]" in b]
    (tmp_path / "plate.xml").write_text(MODEL)
    (tmp_path / "scene.toml").write_text(block)
    assert main(["run", "--scene", str(tmp_path / "scene.toml"), "--json", "--quiet"]) == 0
    (force,) = _last_json(capsys.readouterr().out)["drive_load"]  # the mean over its one stroke
    assert force == pytest.approx(CLOSED_FORM, rel=0.03)


# A robot's sim.method = "auto" is resolved before it steps: its messages are those of the method it chose.
@pytest.mark.parametrize("scene", [UserScene().replace(**{"sim.method": "newton"}), IntrusionScene()])
def test_failures_advise_only_what_the_scene_allows(scene):
    # A user's model steps explicitly only: its messages must not send the user to a method it refuses.
    from finrft.convergence import advice
    from finrft.stepping import chatter, unstable
    for text in (advice(scene), str(chatter(scene, 0.1)), str(unstable(scene, 0.1, []))):
        for method in re.findall(r"sim\.method = '([\w-]+)'", text):
            scene.replace(**{"sim.method": method})  # raises SceneError for a method the scene refuses
        assert "rft." not in text  # no [rft] section here


def test_a_model_naming_a_pipe_or_a_device_is_refused_before_mujoco_reads_it(tmp_path, capsys):
    # MuJoCo reads an MJCF's includes and meshes itself: a mesh that is a named pipe once hung `finrft run` for ever
    import os
    box = '<worldbody><body name="b"><freejoint/><geom type="box" size=".01 .01 .01"/></body></worldbody>'
    os.mkfifo(tmp_path / "pipe.stl")
    (tmp_path / "meshes").mkdir()
    os.mkfifo(tmp_path / "meshes" / "deep.stl")
    (tmp_path / "part.xml").write_text('<mujoco><asset><mesh name="d" file="deep.stl"/></asset></mujoco>')
    cases = {"pipe.xml": ('<mujoco><asset><mesh name="m" file="pipe.stl"/></asset>' + box + '</mujoco>',
                          r"model asset \(mesh\) .*pipe.stl is not a regular file"),
             "device.xml": ('<mujoco><include file="/dev/zero"/>' + box + '</mujoco>',
                            "model file /dev/zero is not a regular file"),
             "nested.xml": ('<mujoco><compiler meshdir="meshes"/><include file="part.xml"/>' + box + '</mujoco>',
                            r"model asset \(mesh\) .*deep.stl is not a regular file")}
    for name, (xml, message) in cases.items():
        (tmp_path / name).write_text(xml)
        (tmp_path / f"{name}.toml").write_text(f'[model]\npath = "{name}"\nbodies = ["b"]\n[sim]\nduration = 0.01\n')
        assert main(["run", "--scene", str(tmp_path / f"{name}.toml"), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert re.search(message, err) and len(err.strip().splitlines()) == 1, err


def test_a_control_table_is_read_as_every_file_is(tmp_path):
    # read with open() once: a binary table ended in a raw UnicodeDecodeError, a huge one was read whole
    from finrft.experiments.user_model import read_table
    binary = tmp_path / "ctrl.csv"
    binary.write_bytes(bytes(range(128, 256)) * 4)
    for path, message in ((binary, "control.0.table .*is not a text file"),
                          ("/dev/zero", "control.0.table /dev/zero is not a regular file"),
                          (tmp_path / "none.csv", "cannot read control.0.table .*none.csv")):
        with pytest.raises(finrft.SceneError, match=message):
            read_table(str(path), "control.0")


def test_values_take_unit_suffixes_in_the_toml_and_in_set(tmp_path):
    # --bounds took deg and mm; --set and the TOML refused them. One parser now reads all three.
    _, scene = _files(tmp_path)
    scene.write_text(SCENE.format(cycles=0).replace("stroke = 0.02", 'stroke = "20mm"'))
    given = load_scene(scene, cls=UserScene, overrides=dict(
        finrft.scene.parse_override(item, UserScene) for item in (
            "drive.profile=sine", "drive.stroke=0.05", "drive.speed=0.1", "drive.amplitude=5mm", "drive.phase=90deg",
            "sim.duration=0.5", "medium.zeta=6e5 N/m3")))
    assert given.drive[0].amplitude == pytest.approx(0.005) and given.drive[0].phase == pytest.approx(math.pi / 2)
    assert given.medium.zeta == pytest.approx(0.6)  # zeta's unit is N/cm^3: 6e5 N/m^3 is 0.6 of it
    assert load_scene(scene, cls=UserScene).drive[0].stroke == pytest.approx(0.02)
    # a key set back to its default is no key the kind ignores: a dumped scene reads back
    assert load_scene(scene, cls=UserScene, overrides={"drive.amplitude": 0.0}).drive[0].amplitude == 0.0



def test_a_model_at_another_step_steps_as_the_one_built_at_it_and_a_run_builds_once(monkeypatch):
    # The run's model at half its step (its companion's, `auto`'s pilots') is the run's own with the step changed
    # (`AttachedModel.at_step`): the wheel rig stepped 300 times by MuJoCo with the native plugin from the same
    # state is bitwise the model built again at that step; a run and its companion build the model once.
    import mujoco

    from finrft import experiment
    from finrft.experiments.user_model import example
    scene = load_scene(example("wheel_rig"), cls=UserScene)
    half = scene.replace(**{"sim.dt": scene.sim.dt / 2})
    built = UserModel.of(scene).build(scene)
    again, fresh = built.at_step(half.sim.dt), UserModel.of(half).build(half)
    assert again.model is not built.model and built.model.opt.timestep == scene.sim.dt
    states = []
    for m in (again.model, fresh.model):
        d = mujoco.MjData(m)
        d.qvel[:] = 0.1
        for _ in range(300):
            mujoco.mj_step(m, d)
        states.append(np.concatenate([d.qpos, d.qvel]))
    assert np.array_equal(states[0], states[1]) and np.abs(states[0]).max() > 0
    calls = []
    monkeypatch.setattr(UserModel, "build", lambda self, s, build=UserModel.build: calls.append(s.sim.dt) or
                        build(self, s))
    run = experiment.run(UserModel.of(scene), scene)
    assert calls == [scene.sim.dt] and run.error_companion
