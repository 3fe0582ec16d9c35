"""Inputs that a run would ignore or misread, found by trying the command line and the API as a user would."""

from pathlib import Path

import mujoco
import pytest

from finrft.cli import main
from finrft.errors import SceneError
from finrft.experiments.swim import RobotScene
from finrft.scene import preset


def _box() -> mujoco.MjSpec:
    """A free box to attach the medium to."""
    return mujoco.MjSpec.from_string("<mujoco><worldbody><body name='b'><freejoint/><geom type='box' "
                                     "size='.05 .05 .01'/></body></worldbody></mujoco>")


@pytest.mark.parametrize("override", ["sim.max_step=1", "sim.tolerance=1e-3"])
def test_a_fixed_step_method_refuses_the_adaptive_keys(capsys, override):
    # The plate's newton method takes steps of sim.dt: a largest step or a tolerance given to it changed nothing.
    assert main(["drag", "--distance", "5", "--set", override]) == 2
    err = capsys.readouterr().err
    assert f"{override.split('=')[0]} is used by method = 'adaptive' or 'adaptive-newton' only" in err
    assert len(err.splitlines()) == 1
    with pytest.raises(SceneError, match="sim.max_step is used by method"):
        preset("physical").replace(**{"sim.max_step": 1e-2})


def test_switching_to_a_fixed_step_drops_the_presets_adaptive_keys():
    # The robot's physical preset is adaptive-newton with its own max_step and tolerance; newton asked by --set
    # runs without them, and sets them back when the method goes back.
    scene = preset("physical", RobotScene)
    fixed = scene.replace(**{"sim.method": "newton"})
    assert (fixed.sim.max_step, fixed.sim.tolerance) == (RobotScene().sim.max_step, RobotScene().sim.tolerance)
    assert scene.replace(**{"sim.method": "adaptive", "sim.max_step": 0.01}).sim.max_step == 0.01


@pytest.mark.parametrize("scene", [None, RobotScene()])
def test_run_wheel_refuses_a_scene_of_another_kind(scene):
    # was an AttributeError ('NoneType' object has no attribute 'wheel') from building the wheel
    from finrft import run_wheel
    with pytest.raises(SceneError, match="wheel: the scene must be a finrft.WheelScene"):
        run_wheel(scene)


def test_bounds_name_a_unit_of_the_wrong_dimension():
    # was "bounds must be numbers", for two numbers with units, one of them no angle
    from finrft.studies.bounds import parse_bounds
    with pytest.raises(SceneError, match="mm is no unit of gait.theta1, whose unit is rad"):
        parse_bounds(["gait.theta1=0deg:90mm"], RobotScene)
    assert parse_bounds(["gait.theta1=0deg:90deg"], RobotScene)["gait.theta1"] == pytest.approx((0.0, 1.5707963))


def test_a_zeta_in_newtons_per_cubic_metre_is_refused_not_run():
    # 6e5 (the literature's 0.6 N/cm^3 in N/m^3) ran into "Newton's method did not converge ... reduce sim.dt"
    from finrft import UserScene, attach, load_scene
    with pytest.raises(SceneError, match="zeta = 600000 N/cm\\^3 is more than 100 N/cm\\^3"):
        attach(_box(), "b", zeta=6e5)
    with pytest.raises(SceneError, match="medium.zeta = 600000 N/cm\\^3 .* give zeta in N/cm\\^3"):
        load_scene(Path(__file__).parents[1] / "mjcf" / "hexapod.toml", cls=UserScene,
                   overrides={"medium.law": "li2013", "medium.name": "", "medium.zeta": 6e5})
    attach(_box(), "b", zeta=3.05)  # the hardest catalogued medium


def test_a_density_that_no_term_uses_is_refused():
    # li2013 reads no density: bulk_density there feeds DRFT's term alone, and with the term off it changed nothing
    from finrft import UserScene, attach, load_scene
    with pytest.raises(SceneError, match="attach: bulk_density is used by drft_lambda > 0"):
        attach(_box(), "b", bulk_density=1500.0)
    with pytest.raises(SceneError, match="medium.bulk_density is used by drft_lambda > 0"):
        load_scene(Path(__file__).parents[1] / "mjcf" / "hexapod.toml", cls=UserScene,
                   overrides={"medium.law": "li2013", "medium.name": "", "medium.bulk_density": 1500.0})
    assert attach(_box(), "b", bulk_density=1500.0, drft_lambda=1.0).bulk_density == 1500.0


def test_a_step_far_longer_than_the_stroke_is_one_line(capsys):
    # was numpy's "overflow encountered in scalar divide" warning on the line before the error
    assert main(["drag", "--distance", "20", "--set", "sim.dt=1e300"]) == 2
    err = capsys.readouterr().err
    assert "is longer than a stroke" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("kind,key,value", [("soft", "plate.stop", "limit"), ("rigid", "plate.stop_stiffness", 5.0),
                                            ("origami", "plate.rigid_as", "welds")])
def test_a_plate_key_its_kind_has_not_is_refused(capsys, kind, key, value):
    # the origami stop is no part of a soft or rigid plate, nor are welds of a hinged one: they ran unchanged
    assert main(["drag", "--distance", "5", "--plate", kind, "--set", f"{key}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"{key} is used by kind = " in err and len(err.splitlines()) == 1


def test_a_plate_kind_set_drops_the_presets_stop():
    # the preset's origami stop goes with --plate soft; a stop given beside it is still refused
    assert preset("physical").replace(**{"plate.kind": "soft"}).plate.kind == "soft"
    with pytest.raises(SceneError, match="plate.stop is used by kind = 'origami' only"):
        preset("physical").replace(**{"plate.kind": "soft", "plate.stop": "limit"})


@pytest.mark.parametrize("angles,said", [("", "--angles expects comma-separated degrees"),
                                         (",", "--angles expects comma-separated degrees"),
                                         ("30,30", "--angles: an angle is given twice")])
def test_intrude_angles_name_what_is_wrong(capsys, angles, said):
    # an empty list was "each angle must be within -90..90 degrees"; an angle given twice ran twice
    assert main(["intrude", "--angles", angles]) == 2
    err = capsys.readouterr().err
    assert said in err and len(err.splitlines()) == 1


def test_the_robot_template_with_robot_says_which_flag_to_drop(capsys):
    # was "unknown preset 'robot': use one of paper, physical", though --dump robot is a template
    assert main(["scene", "--robot", "--dump", "robot"]) == 2
    err = capsys.readouterr().err
    assert "leave out --robot" in err and len(err.splitlines()) == 1
    assert main(["scene", "--dump", "robot"]) == 0


def test_ctrl_c_while_the_commands_load_is_one_line_and_130(monkeypatch, capsys):
    # was a KeyboardInterrupt traceback from the commands' imports and death by SIGINT (-2)
    import finrft.cli as cli

    def interrupted():
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert main(["drag", "--distance", "5"]) == 130
    assert capsys.readouterr().err == "finrft: interrupted\n"


@pytest.mark.parametrize("override", ["plate.segment_length=33", "plate.rod_length=7", "medium.depth=10",
                                      "medium.height=55"])
def test_a_chain_length_in_mm_is_refused(capsys, override):
    # 33 m segments and a 10 m depth ran with exit 0; a 55 m tall plate failed as "give the driven body more mass"
    assert main(["drag", "--distance", "20", "--set", override]) == 2
    err = capsys.readouterr().err
    assert "must be <= 1 m (scene lengths are in metres; a value in mm is 1000 times larger" in err
    assert len(err.splitlines()) == 1
    assert main(["swim", "--arm-length", "65000"]) == 2  # the flag is in mm: a 65 m arm
    assert "arm.length must be <= 1 m" in capsys.readouterr().err


@pytest.mark.parametrize("preset_name,key", [("paper", "medium.bulk_density=1500"),
                                             ("paper", "medium.internal_friction=0.4"),
                                             ("physical", "medium.surface_friction=0.3")])
def test_a_plate_medium_its_law_does_not_read_is_refused(capsys, preset_name, key):
    # the paper law, and sandswim with its own c_s, c_f, gamma0, never read the medium's properties: they ran unchanged
    assert main(["drag", "--distance", "5", "--preset", preset_name, "--set", key]) == 2
    err = capsys.readouterr().err
    assert f"{key.split('=')[0]} is used by rft.law = 'sandswim'" in err and len(err.splitlines()) == 1
    with pytest.raises(SceneError, match="leave rft.c_s, c_f, gamma0 out to derive them from"):
        preset("physical").replace(**{key.split("=")[0]: float(key.split("=")[1])})
    # the robot's arms and body read them under any fin law: kept there
    robot = preset("paper", RobotScene).replace(**{"medium.bulk_density": 1500.0, "medium.internal_friction": 0.4,
                                                   "body.drag_law": "velocity"})
    assert robot.medium.bulk_density == 1500.0
    # and sandswim left to the medium reads them
    derived = preset("physical").replace(**{"rft.c_s": 0.0, "rft.c_f": 0.0, "rft.gamma0": 0.0, "medium.name": "",
                                            "medium.bulk_density": 1500.0, "medium.internal_friction": 0.4})
    assert derived.medium.internal_friction == 0.4


def test_an_element_size_in_mm_is_refused(capsys):
    # 5 m elements (5 mm meant) ran, one element per face
    assert main(["run", "--example", "sand_swimmer", "--set", "medium.element_size=5"]) == 2
    err = capsys.readouterr().err
    assert "medium.element_size must be <= 1 m (scene lengths are in metres" in err and len(err.splitlines()) == 1
    from finrft import attach
    with pytest.raises(SceneError, match="attach: element_size = 5 m is more than 1 m: it is in metres"):
        attach(_box(), "b", element_size=5.0)
    assert attach(_box(), "b", element_size=0.02).element_size == 0.02


def test_a_regularisation_speed_beyond_rfts_speeds_is_refused(capsys):
    # rft.v_reg = 5 m/s ran a 30 mm/s drag at tanh(0.006), 1 % of the law's force, with exit 0
    assert main(["drag", "--distance", "5", "--set", "rft.v_reg=5"]) == 2
    err = capsys.readouterr().err
    assert "rft.v_reg must be <= 1 m/s (RFT's force is rate-independent" in err and len(err.splitlines()) == 1
    from finrft import UserScene, attach
    from finrft.scene import scene_from_dict
    with pytest.raises(SceneError, match="medium.v_reg must be <= 1 m/s"):
        scene_from_dict({"medium": {"v_reg": 30.0}}, UserScene)
    with pytest.raises(SceneError, match="attach: v_reg must be <= 1 m/s"):
        attach(_box(), "b", v_reg=5.0)
    assert preset("paper").replace(**{"rft.v_reg": 0.01}).rft.v_reg == 0.01  # the accuracy study's widest


def test_a_rotate_stroke_past_a_turn_names_its_unit(capsys):
    # Drive(kind='rotate', stroke=90) turned the plate 90 rad (14 turns), the 90 degrees meant taken as radians
    from finrft.drive import Drive
    with pytest.raises(SceneError, match="a rotate drive's stroke is in radians, and 90 looks like degrees: give "
                                         "math.radians\\(90\\) = 1.571 rad"):
        Drive(kind="rotate", stroke=90.0)
    assert Drive(kind="rotate", stroke=6.28).stroke == 6.28
    assert Drive(kind="drag", stroke=2.0).stroke == 2.0  # metres: no turn
    assert main(["rotate", "--amplitude", "720", "--omega", "1"]) == 2
    err = capsys.readouterr().err
    assert "--amplitude 720 deg is more than one turn" in err and len(err.splitlines()) == 1


@pytest.mark.slow  # a stroke long enough to drift; test_user_model stops a drifting drive in the fast suite
def test_a_drive_too_slow_to_hold_names_its_speed_and_stroke(capsys):
    # a 15-minute stroke let the load drift the armature; the advice was "give the driven body more mass", though
    # the plate's mass is the scene's and the drift grows with the stroke's time
    assert main(["rotate", "--amplitude", "90", "--omega", "0.1", "--set", "sim.dt=0.03"]) == 1
    err = capsys.readouterr().err
    assert "its stroke of 90 deg at 0.1 deg/s lasts 900 s" in err and "drive faster or over a shorter stroke" in err
    assert "more mass" not in err and len(err.splitlines()) == 1
    # ten times faster holds: the cause was the drive's rate
    assert main(["rotate", "--amplitude", "90", "--omega", "1", "--set", "sim.dt=0.03", "--quiet"]) == 0


@pytest.mark.parametrize("argv,form", [
    (["wheel", "--slip", "0.2", "--sinkage", "10", "--set", "sim.dt=0.01", "--max-error", "Fx_N=0.1%"],
     "--max-error Fx_N=X%"),
    (["drag", "--distance", "5", "--max-error", "1e-4"], "--max-error angle_deg=X")])
def test_an_error_over_its_limit_shows_how_to_raise_it(capsys, argv, form):
    # "raise the limit (--max-error)": a robot's figure stayed over after a bare --max-error 1000, which bounds
    # angles, eta and positions alone; the message now shows the NAME=X% form of what is over
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert f"raise the limit ({form}; a bare --max-error X bounds angles, eta and positions only" in err
    assert len(err.splitlines()) == 1


def test_a_record_interval_longer_than_the_run_is_refused(capsys):
    # 100 s between samples of a 0.17 s drag recorded its start and end alone, with exit 0
    assert main(["drag", "--distance", "5", "--set", "sim.record_dt=100"]) == 2
    err = capsys.readouterr().err
    assert "sim.record_dt = 100 s is longer than the run (0.1667 s)" in err and len(err.splitlines()) == 1
    import finrft
    with pytest.raises(SceneError, match="sim.record_dt = 1 s is longer than the run"):
        finrft.simulate(preset("paper").replace(**{"sim.record_dt": 1.0}), finrft.Drive(stroke=0.005))
    # the default interval on a run shorter than it is no one's choice: it runs
    assert len(finrft.simulate(preset("paper"), finrft.Drive(stroke=0.0003, speed=0.03)).time) == 2


def test_a_robot_runs_summary_is_taken_once_for_its_error_check(monkeypatch):
    # the error check computed the run's summary twice per companion (its differences, then its limits) and the
    # companion's once: each a walk over the run's means; once each now
    import finrft
    from finrft.experiments import user_model
    from finrft.scene import load_scene
    calls = []
    summary = user_model.robot_summary
    monkeypatch.setattr(user_model, "robot_summary", lambda experiment, run: calls.append(run) or summary(experiment,
                                                                                                          run))
    scene = load_scene(Path(__file__).parents[1] / "mjcf" / "sand_swimmer.toml", cls=finrft.UserScene,
                       overrides={"sim.duration": 0.6, "sim.settle": 0.3})
    run = finrft.run_robot(scene, max_error=None)
    assert len(calls) == 2 and len({id(r) for r in calls}) == 2  # the run's and its one companion's
    assert run.figure_values() == {key: run.summary()[key] for key in run.figure_values()}
