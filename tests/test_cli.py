"""The command line: outputs, units, and how bad input and failures are reported."""

import argparse
import importlib.util
import json
import math
import re
import signal
import subprocess
import sys
import tempfile
import time
import tomllib

import h5py
import mujoco
import numpy as np
import pytest

from conftest import default_ctrl_c
from finrft.laws.table import paper_table, write_table
from finrft.cli import build_parser, main
from finrft.experiments.swim import RobotScene
from finrft.scene import Scene, preset, to_toml

# Subprocesses run outside the repository: from its root `python -m finrft` would import the source tree, which
# holds neither the built plugin nor the packaged models, instead of the installed package.
OUTSIDE = tempfile.gettempdir()

FAST = ["--set", "sim.dt=0.001", "--distance", "30"]


def _last_json(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def test_drag_json_and_files(tmp_path, capsys):
    h5, rrd = tmp_path / "drag.h5", tmp_path / "drag.rrd"
    assert main(["drag", "--json", "--out", str(h5), "--rrd", str(rrd), *FAST]) == 0
    summary = _last_json(capsys.readouterr().out)
    for key in ("final_segment_angle_deg", "final_hinge_angle_deg", "peak_drive_force_N", "steps", "sim_time_s",
                "wall_s", "backend", "integrator", "dt"):
        assert key in summary
    assert summary["sim_time_s"] == pytest.approx(1.0, abs=1e-3)  # 30 mm at 30 mm/s
    with h5py.File(h5) as f:
        np.testing.assert_allclose(np.degrees(f["segment_angle"][-1]), summary["final_segment_angle_deg"])
        assert f["displacement"].attrs["units"] == "m"
        assert f["displacement"][-1] == pytest.approx(0.03, abs=1e-6)  # mm on the command line, m in the file
    assert rrd.stat().st_size > 0


def test_cycles_report_power_recovery_and_impulse(capsys):
    assert main(["drag", "--json", "--cycles", "2", "--plate", "rigid", *FAST]) == 0
    summary = _last_json(capsys.readouterr().out)
    assert len(summary["cycles"]) == 2
    assert summary["first_cycle"] == summary["cycles"][0]
    assert summary["mean_power_force_N"] == pytest.approx(-summary["mean_recovery_force_N"], rel=1e-6)
    assert summary["net_impulse_Ns"] == pytest.approx(0.0, abs=1e-6)


def test_rotate_reports_torque(capsys):
    assert main(["rotate", "--json", "--amplitude", "30", "--set", "sim.dt=0.001"]) == 0
    summary = _last_json(capsys.readouterr().out)
    assert "peak_drive_torque_Nm" in summary and summary["test"] == "rotate"
    # One stroke of 30 deg from flat: the rod has turned by 30 deg, every segment at least as far back.
    assert np.all(np.array(summary["final_segment_angle_deg"]) <= 30.0 + 1e-9)


BAD = [
    (["drag", "--speed", "0"], "--speed"),
    (["drag", "--distance", "-5"], "--distance"),
    (["drag", "--attack", "200"], "--attack"),
    (["drag", "--cycles", "0"], "--cycles"),
    (["drag", "--plate", "foam"], "--plate"),
    (["drag", "--set", "plate.segments=0"], "plate.segments"),
    (["drag", "--set", "plate.segment_length=-0.01"], "plate.segment_length"),
    (["drag", "--set", "plate.segment_mass=0"], "plate.segment_mass"),
    (["drag", "--set", "plate.stiffness=soft"], "plate.stiffness"),
    (["drag", "--set", "plate.colour=red"], "plate.colour"),
    (["drag", "--set", "rft.law=li2013"], "rft.law"),
    (["drag", "--set", "sim.integrator=verlet"], "sim.integrator"),
    (["drag", "--set", "novalue"], "KEY=VALUE"),
    (["rotate", "--omega", "abc"], "--omega"),
    (["drag", "--speed", "inf"], "--speed: must be a finite number (mm/s), got inf"),
    (["drag", "--scene", "missing.toml"], "missing.toml"),
    (["drag", "--scene", "missing.toml", "--preset", "physical"], "--preset"),
    (["swim", "--scene", "missing.toml", "--preset", "paper"], "--preset"),
    (["drag", "--rrd", "run.h5"], ".rrd"),
    (["drag", "--forces-csv", "forces.csv"], "rigid"),
    (["rotate", "--plate", "rigid", "--forces-csv", "forces.csv"], "--forces-csv"),
]


@pytest.mark.parametrize("argv,named", BAD)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, argv, named):
    out = tmp_path / "run.h5"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("text,named", [
    ("[plate\nkind = 1", "malformed TOML"),
    ("[plate]\nkind = 'foam'", "plate.kind"),
    ("[plate]\nsegments = 2.5", "plate.segments"),
    ("[fluid]\nrho = 1", "[fluid]"),
    ("[rft]\nlaw = 'table'", "rft.table"),
    ("[sim]\nmethod = 'newton'\ntolerance = 1e-3", "sim.tolerance is used by method = 'adaptive' or 'adaptive-newton'"),
    ("[plate]\nkind = 'soft'\nstop_stiffness = 2e4", "plate.stop_stiffness is used by kind = 'origami'"),
])
def test_bad_scene_files(tmp_path, capsys, text, named):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    assert main(["drag", "--scene", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err


def test_unstable_run_exits_1_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "run.h5"
    argv = ["drag", "--preset", "paper", "--cycles", "1", "--out", str(out),
            "--set", "plate.segment_inertia=2.6e-7", "--set", "plate.rod_inertia=4e-8", "--set", "plate.damping=0", "--set", "sim.integrator='euler'",
            "--set", "sim.dt=1e-3"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "unstable" in err and "sim.dt" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_chattering_run_exits_1_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert main(["drag", "--preset", "physical", "--set", "sim.method='explicit'", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "chatters" in err and "newton" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_scene_dump_round_trips(tmp_path, capsys):
    assert main(["scene", "--dump", "paper"]) == 0
    text = capsys.readouterr().out
    assert tomllib.loads(text) == preset("paper").to_dict()
    path = tmp_path / "mine.toml"
    path.write_text(text.replace("stiffness = 0.209", "stiffness = 0.5"))
    assert main(["scene", "--scene", str(path), "--set", "sim.dt=2e-4"]) == 0
    resolved = tomllib.loads(capsys.readouterr().out)
    assert resolved["plate"]["stiffness"] == 0.5 and resolved["sim"]["dt"] == 2e-4


@pytest.mark.parametrize("argv,section,dropped", [
    (["--robot", "--dump", "paper", "--set", "sim.method=newton"], "sim", ("tolerance", "max_step")),
    (["--scene", "origami.toml", "--set", "plate.kind=rigid"], "plate", ("stop", "stop_stiffness"))])
def test_a_selector_switched_by_set_drops_the_keys_of_the_choice_it_replaces(tmp_path, monkeypatch, capsys, argv,
                                                                             section, dropped):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "origami.toml").write_text("[plate]\nkind = 'origami'\nstop = 'limit'\nstop_stiffness = 2e4\n")
    assert main(["scene", *argv]) == 0
    resolved = tomllib.loads(capsys.readouterr().out)[section]
    default = getattr(RobotScene() if "--robot" in argv else Scene(), section)
    assert all(resolved[key] == getattr(default, key) for key in dropped)


@pytest.mark.parametrize("file_value,override,expected", [
    ("RK4", None, "rk4"), ("Euler", None, "euler"), ("rk4", "sim.integrator=implicitFAST", "implicitfast"),
    ("implicit", "sim.integrator=Euler", "euler")])
def test_mujoco_spellings_of_the_integrator_are_accepted(tmp_path, capsys, file_value, override, expected):
    from finrft.experiments.plate import build_plate
    from finrft.scene import load_scene
    path = tmp_path / "mine.toml"
    path.write_text(f'[sim]\nmethod = "explicit"\nintegrator = "{file_value}"\n')
    assert main(["scene", "--scene", str(path), *(["--set", override] if override else [])]) == 0
    assert tomllib.loads(capsys.readouterr().out)["sim"]["integrator"] == expected
    scene = load_scene(path, overrides=dict([override.split("=")]) if override else None)
    assert scene.sim.integrator == expected
    names = {"rk4": "mjINT_RK4", "euler": "mjINT_EULER", "implicitfast": "mjINT_IMPLICITFAST"}
    assert build_plate(scene).model.opt.integrator == getattr(mujoco.mjtIntegrator, names[expected])


def test_a_wrong_integrator_lists_the_choices(capsys):
    assert main(["drag", "--set", "sim.integrator=Verlet"]) == 2
    assert capsys.readouterr().err.strip().endswith("use one of euler, implicitfast, implicit, rk4")


def test_table_law_from_a_scene_file_matches_the_paper_law(tmp_path, capsys):
    # The paper law written as a fine table must give the same drag: two laws, one result.
    paper_law = preset("paper").rft  # per unit area and depth, as the table is
    write_table(tmp_path / "forces.csv", paper_table(paper_law.f_perp, paper_law.f_par, samples=1801))
    text = to_toml(preset("paper")).replace('law = "paper"', 'law = "table"')
    scene = tmp_path / "table.toml"
    scene.write_text(text.replace('table = ""', 'table = "forces.csv"'))  # relative to the scene file
    assert main(["drag", "--json", "--scene", str(scene), *FAST]) == 0
    table = _last_json(capsys.readouterr().out)
    assert main(["drag", "--json", "--scene", str(scene), "--set", "rft.law='paper'", *FAST]) == 0
    paper = _last_json(capsys.readouterr().out)
    np.testing.assert_allclose(table["final_segment_angle_deg"], paper["final_segment_angle_deg"], atol=1e-5)
    assert abs(paper["final_segment_angle_deg"][-1]) > 1.0


def test_python_dash_m_entry_point():
    done = subprocess.run([sys.executable, "-m", "finrft", "rotate", "--help"], capture_output=True, text=True,
                          cwd=OUTSIDE)
    assert done.returncode == 0 and "degrees/s" in done.stdout


def test_robot_scene_dump_round_trips(capsys):
    from finrft.experiments.swim import RobotScene
    assert main(["scene", "--robot", "--dump", "physical"]) == 0
    assert tomllib.loads(capsys.readouterr().out) == preset("physical", RobotScene).to_dict()


# Every writer of every command: (argv without the output, the flag, a good file name for it).
WRITERS = [
    (["drag"], "--out", "run.h5"),
    (["drag"], "--rrd", "run.rrd"),
    (["swim"], "--out", "run.h5"),
    (["swim"], "--rrd", "run.rrd"),
    (["optimize"], "--out", "log.h5"),
    (["optimize"], "--rrd", "run.rrd"),
    (["fit", "--data", "drag.csv"], "--write-scene", "fitted.toml"),
    (["fit", "--data", "drag.csv"], "--plot", "fit.png"),
    (["fit", "--data", "drag.csv"], "--out", "log.h5"),
    (["fit", "--data", "drag.csv"], "--rrd", "run.rrd"),
    (["fit-rft", "--data", "forces.csv"], "--out", "rft.toml"),
    (["fit-rft", "--data", "forces.csv"], "--table", "rft.csv"),
    (["report"], "--out", "report"),
    (["bench", "accuracy"], "--out", "accuracy"),
    (["bench", "backends"], "--scaling", "scaling.png"),
    (["run", "model.xml", "--scene", "scene.toml"], "--out", "run.h5"),
    (["run", "model.xml", "--scene", "scene.toml"], "--rrd", "run.rrd"),
    (["intrude"], "--plot", "curves.png"),
    (["law", "li2013"], "--plot", "map.png"),
]


def _one_line(capsys, *named: str) -> str:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert all(n in err for n in named), err
    return err


@pytest.mark.parametrize("argv,flag,name", WRITERS)
def test_every_writer_refuses_a_path_it_cannot_write_before_running(tmp_path, capsys, argv, flag, name):
    # Each refusal comes before any simulation or data file is read (drag.csv and forces.csv do not exist).
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    for path, named in ((f"/proc/{name}", "cannot write in /proc"), (blocker / name, "not a directory"),
                        (tmp_path / "missing" / name, "does not exist")):
        assert main([*argv, flag, str(path)]) == 2
        _one_line(capsys, flag, named)
    if "." in name:  # a file: a directory in its place, and an existing file without --force
        folder = tmp_path / name
        folder.mkdir()
        assert main([*argv, flag, str(folder)]) == 2
        _one_line(capsys, "is a directory")
        folder.rmdir()
        folder.write_text("keep")
        assert main([*argv, flag, str(folder)]) == 2
        _one_line(capsys, "exists", "--force")
        assert folder.read_text() == "keep"
    else:  # a folder: a file in its place, and a folder with files in it without --force
        (tmp_path / name).write_text("keep")
        assert main([*argv, flag, str(tmp_path / name)]) == 2
        _one_line(capsys, "is a file")
        (tmp_path / name).unlink()
        (tmp_path / name).mkdir()
        (tmp_path / name / "mine.txt").write_text("keep")
        assert main([*argv, flag, str(tmp_path / name)]) == 2
        _one_line(capsys, "not empty", "--force")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["file", name])


def test_force_replaces_existing_files(tmp_path, capsys):
    out, rrd = tmp_path / "run.h5", tmp_path / "run.rrd"
    out.write_text("old")
    rrd.write_text("old")
    assert main(["drag", "--quiet", "--force", "--out", str(out), "--rrd", str(rrd), *FAST]) == 0
    with h5py.File(out) as f:
        assert f["displacement"][-1] == pytest.approx(0.03, abs=1e-6)
    assert rrd.stat().st_size > 100
    assert capsys.readouterr().out == ""  # --quiet: no summary
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5", "run.rrd"]  # no temporary left behind


def test_forces_csv_refuses_a_file_with_another_header(tmp_path, capsys):
    forces = tmp_path / "forces.csv"
    forces.write_text("angle,fn,ft\n45,1,2\n")
    assert main(["drag", "--plate", "rigid", "--distance", "5", "--forces-csv", str(forces)]) == 2
    _one_line(capsys, "header", "forces.csv")
    assert forces.read_text() == "angle,fn,ft\n45,1,2\n"


def test_scene_dump_with_a_scene_file_is_refused(capsys):
    assert main(["scene", "--dump", "physical", "--scene", "mine.toml"]) == 2
    _one_line(capsys, "--dump", "--scene")


def _run_cli(*argv: str, **options) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "finrft", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=OUTSIDE, **options)


def test_closed_stdout_is_no_traceback(errors_only):
    # finrft swim --json | head -c 10: the reader goes away before finrft writes (--quiet: stderr holds no text).
    done = _run_cli("swim", "--json", "--quiet")
    done.stdout.close()
    err = errors_only(done.stderr.read())
    assert done.wait() == 141 and err == ""


# Ctrl-C as main starts, while it imports the commands (MuJoCo's extension modules: an interrupt raised inside
# their initialisation was an ImportError and exit 1), and while it runs. (At once after 'ready' it may come before
# this script's own call of main, where Python's default handling is all there is.)
@pytest.mark.parametrize("delay", [0.03, 0.15, 0.5])
def test_interrupt_is_one_line_and_exit_130(errors_only, delay):
    code = ("import sys; from finrft.cli import main; print('ready', flush=True); "
            "sys.exit(main(sys.argv[1:]))")
    run = subprocess.Popen([sys.executable, "-c", code, "drag", "--distance", "100000"], cwd=OUTSIDE,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_ctrl_c)
    assert run.stdout.readline() == "ready\n"
    time.sleep(delay)
    run.send_signal(signal.SIGINT)
    assert run.wait(timeout=60) == 130
    assert errors_only(run.stderr.read()) == "finrft: interrupted\n"


def _robot_preset_facts(help_text: str, name: str) -> str:
    return re.search(rf"\b{name} = ([^;]*)", " ".join(help_text.split())).group(1)


@pytest.mark.parametrize("command,cls", [("drag", "plate"), ("fit", "plate"), ("swim", "robot"),
                                         ("optimize", "robot"), ("table", "robot")])
def test_preset_help_states_what_the_presets_hold(capsys, command, cls):
    # The --preset help names each preset's stops, body drag law, method and inertias: compare with the dumps.
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    help_text = text[text.index("--preset {"):]
    for name in ("paper", "physical"):
        assert main(["scene", "--dump", name, *(["--robot"] if cls == "robot" else [])]) == 0
        dump = tomllib.loads(capsys.readouterr().out)
        facts = _robot_preset_facts(help_text, name)
        plate = dump["fin"] if cls == "robot" else dump["plate"]
        assert f"{plate['stop']} stop" in facts and f"{dump['sim']['method']} method" in facts
        assert ("inertias of 1 kg m^2" in facts) == (plate["segment_inertia"] == 1.0)
        if cls == "robot":
            assert f"{dump['body']['drag_law']} body drag" in facts


def test_swim_help_defaults_are_the_presets():
    text = " ".join(subprocess.run([sys.executable, "-m", "finrft", "swim", "--help"], capture_output=True,
                                   text=True, cwd=OUTSIDE).stdout.split())
    options = text[text.index("options:"):]
    stated = {key: float(re.search(rf"{flag} [A-Z_]+ .*?default: the scene's, (-?\d+)", options).group(1))
              for flag, key in (("--theta1", "theta1"), ("--theta2", "theta2"), ("--omega", "omega"),
                                ("--arm-length", "length"))}
    for name in ("paper", "physical"):
        scene = preset(name, RobotScene)
        assert np.degrees(scene.gait.theta1) == pytest.approx(stated["theta1"])
        assert np.degrees(scene.gait.theta2) == pytest.approx(stated["theta2"])
        assert np.degrees(scene.gait.omega) == pytest.approx(stated["omega"])
        assert 1e3 * scene.arm.length == pytest.approx(stated["length"])


def _commands(parser=None, prefix=()):
    """Every command of the parser, sub-commands (bench's) included: what a new experiment's command joins."""
    parser = parser or build_parser()
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _commands(sub, (*prefix, name)) or [[*prefix, name]]
    return found


COMMANDS = _commands()


def test_the_commands_are_found():
    assert ["drag"] in COMMANDS and ["bench", "accuracy"] in COMMANDS and ["law"] in COMMANDS


@pytest.mark.parametrize("argv", COMMANDS, ids=" ".join)
def test_every_command_takes_quiet(capsys, argv):
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    text = capsys.readouterr().out
    assert "--quiet" in text
    assert ("--forces-csv FILE.csv" in text) == (argv == ["drag"])  # rotate refuses it, so does not offer it


def _takes_json(parser: argparse.ArgumentParser, argv: list[str]) -> bool:
    for name in argv:
        (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        parser = sub.choices[name]
    return any("--json" in action.option_strings for action in parser._actions)


# Cheap arguments for every command that takes --json ({tmp}: the test's folder, which holds the files below);
# the long ones run with the slow studies.
SLOW = pytest.mark.slow
NEEDS_WARP = pytest.mark.skipif(importlib.util.find_spec("mujoco_warp") is None,
                                reason="the warp extra is not installed: pip install '.[warp]'")
JSON_ARGS = {
    "drag": FAST,
    "rotate": ["--amplitude", "30", "--set", "sim.dt=0.001"],
    "intrude": ["--angles", "0", "--set", "plate.depth=0.02"],
    "swim": ["--preset", "paper"],
    "run": ["{tmp}/plate.xml", "--scene", "{tmp}/scene.toml"],
    "wheel": ["--slip", "0.5", "--sinkage", "20", "--set", "sim.duration=0.2", "--set", "sim.settle=0.1"],
    "sweep": ["--scene", "{tmp}/scene.toml", "--grid", "medium.zeta=0.5,1", "--workers", "1"],
    "medium": [],
    "law": ["sandswim"],
    "fit-rft": ["--data", "{tmp}/forces.csv"],
    "bench robot": pytest.param(["--budget", "1", "--workers", "1"], marks=SLOW),
    "optimize": pytest.param(["--budget", "1", "--workers", "1", "--set", "sim.dt=1e-4"], marks=SLOW),
    "fit": pytest.param(["--data", "{data}/origami_v30.csv", "--params", "b", "--budget", "1", "--workers", "1"],
                        marks=SLOW),
    "table": pytest.param(["--preset", "paper", "--workers", "1"], marks=SLOW),
    "bench backends": pytest.param(["--batch", "1", "--workers", "1"], marks=SLOW),
    "bench robots": pytest.param(["--robot", "sand_swimmer", "--duration", "0.6"], marks=SLOW),
    "bench steps": ["--robot", "wheel_rig"],
    "bench laws": [],
    "bench modelling": pytest.param([], marks=SLOW),
    "bench fit": pytest.param(["--budget", "1", "--workers", "1"], marks=SLOW),
    "bench warp": pytest.param(["--worlds", "1", "--steps", "5"], marks=NEEDS_WARP),
}


def test_every_command_with_json_is_tried():
    parser = build_parser()
    assert sorted(JSON_ARGS) == sorted(" ".join(argv) for argv in COMMANDS if _takes_json(parser, argv))


@pytest.mark.parametrize("command,args", [pytest.param(k, *v.values, marks=v.marks) if hasattr(v, "values")
                                          else (k, v) for k, v in JSON_ARGS.items()], ids=list(JSON_ARGS))
def test_json_is_alone_on_stdout(tmp_path, capsys, command, args):
    """finrft COMMAND --json | python -m json.tool: stdout holds the JSON and nothing else, the text goes to stderr."""
    from finrft.data import plate_drag_dir
    from test_user_model import MODEL, SCENE
    (tmp_path / "plate.xml").write_text(MODEL)
    (tmp_path / "scene.toml").write_text(SCENE.format(cycles=1))
    (tmp_path / "forces.csv").write_text("attack_deg,force_normal_N,force_tangential_N\n"
                                         "0,0,-0.5\n45,-1,-0.1\n90,-2,0\n")
    argv = [*command.split(), "--json", *(a.format(tmp=tmp_path, data=plate_drag_dir()) for a in args)]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    json.loads(out)  # the whole of stdout
    assert out.count("\n") == 1 and err.strip()  # one line; the text, still shown, on stderr


def test_json_moves_the_text_to_stderr_unchanged(capsys):
    assert main(["drag", *FAST]) == 0
    text = capsys.readouterr().out
    assert main(["drag", "--json", *FAST]) == 0
    out, err = capsys.readouterr()
    wall = re.compile(r" in [\d.]+ s\b")  # the one figure that differs between two runs
    assert wall.sub("", err) == wall.sub("", text)
    assert json.loads(out)["steps"] == int(err.split(" steps taken")[0].split()[-1])


def _bar_updates(monkeypatch) -> list[tuple[float, float]]:
    """Turn stderr into a terminal and record (count, total) at every progress bar update."""
    import tqdm
    seen = []
    update = tqdm.tqdm.update

    def spy(self, n=1):
        update(self, n)
        seen.append((self.n, self.total))
    monkeypatch.setattr(tqdm.tqdm, "update", spy)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    return seen


def test_progress_on_a_terminal_never_past_the_budget(monkeypatch, capsys):
    seen = _bar_updates(monkeypatch)
    # Three variables: CMA-ES asks for 7 gaits per generation, more than the budget of 5.
    assert main(["optimize", "--budget", "5", "--workers", "1", "--set", "sim.dt=1e-4"]) == 0
    assert seen and max(n for n, _ in seen) == 5 and {t for _, t in seen} == {5}
    assert "evaluations" in capsys.readouterr().err


@pytest.mark.parametrize("quiet", [False, True])
def test_progress_of_a_drag_and_quiet(monkeypatch, capsys, quiet):
    seen = _bar_updates(monkeypatch)
    assert main(["drag", *FAST, *(["--quiet"] if quiet else [])]) == 0
    assert bool(seen) != quiet
    if not quiet:
        assert seen[-1] == (100, 100)
    assert (capsys.readouterr().out == "") == quiet


def test_law_sandswim_is_the_papers_magnitudes_per_unit_coefficient(tmp_path, capsys):
    from finrft.laws import sandswim
    assert main(["law", "sandswim", "--json", "--plot", str(tmp_path / "map.png")]) == 0
    out, text = capsys.readouterr()
    data = json.loads(out)
    assert list(data) == ["law", "units", "psi_deg", "gamma0_deg", "f_perp_c_s", "f_perp_c_f", "f_par_c_f"]
    assert {len(data[k]) for k in list(data)[2:]} == {91 * 18} and "F_perp = C_S f_perp_c_s" in text
    assert sorted(set(data["psi_deg"])) == list(range(91))  # every degree
    psi, gamma0 = np.radians(data["psi_deg"]), np.radians(data["gamma0_deg"])
    # recombined with coefficients, the map is the law's magnitudes (the papers' form)
    c_s, c_f = 1.7, 0.6
    perp, par = sandswim.magnitudes(psi, c_s, c_f, gamma0)
    np.testing.assert_allclose(c_s * np.array(data["f_perp_c_s"]) + c_f * np.array(data["f_perp_c_f"]), perp,
                               rtol=1e-12)
    np.testing.assert_allclose(c_f * np.array(data["f_par_c_f"]), par, rtol=1e-12, atol=1e-15)
    # sin(beta0) by hand: tan(beta0) = cot(gamma0) sin(psi); at gamma0 = 45 deg, psi = 30 deg: atan(0.5)
    i = list(zip(data["psi_deg"], data["gamma0_deg"])).index((30, 45))
    assert data["f_perp_c_s"][i] == pytest.approx(np.sin(np.arctan(0.5)), abs=1e-12)
    assert (tmp_path / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_scene_reads_a_robot_scene_and_dumps_a_template_to_start_from(tmp_path, capsys):
    # `finrft scene --scene robot.toml` said "unknown scene section [model]"; there was no template to start from
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene, scene_from_dict
    assert main(["scene", "--scene", example("hexapod")]) == 0
    read = scene_from_dict(tomllib.loads(capsys.readouterr().out), UserScene)
    assert read == load_scene(example("hexapod"), cls=UserScene)
    assert main(["scene", "--dump", "robot"]) == 0
    text = capsys.readouterr().out
    data = tomllib.loads(text)
    assert {"model", "medium", "drive", "control", "sim"} <= set(data)
    # every key commented, its unit in brackets where it has one
    keys = [line for line in text.splitlines() if re.match(r"^\w+ = ", line)]
    assert keys and all("  # " in line for line in keys)
    assert all(re.search(r"  # \[(m|s|m/s|N/cm\^3|kg/m\^3|Hz|rad|m or rad|m/s or rad/s|actuator's unit[^\]]*)\]", line)
               for line in keys if line.split()[0] in ("surface_z", "dt", "zeta", "amplitude", "phase", "frequency"))
    path = tmp_path / "robot.toml"
    path.write_text(text)
    assert main(["scene", "--scene", str(path), "--set", "control.0.kind=sine", "--set", "control.0.phase=90deg"]) == 0
    assert tomllib.loads(capsys.readouterr().out)["control"][0]["phase"] == pytest.approx(math.pi / 2)
