"""The command line: outputs, units, and how bad input and failures are reported."""

import json
import subprocess
import sys
import tomllib

import h5py
import mujoco
import numpy as np
import pytest

from finrft import rft
from finrft.cli import main
from finrft.scene import preset, to_toml

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
    (["drag", "--scene", "missing.toml"], "missing.toml"),
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
])
def test_bad_scene_files(tmp_path, capsys, text, named):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    assert main(["drag", "--scene", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err


def test_unstable_run_exits_1_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "run.h5"
    argv = ["drag", "--cycles", "1", "--out", str(out), "--set", "plate.segment_inertia=2.6e-7",
            "--set", "plate.rod_inertia=4e-8", "--set", "plate.damping=0", "--set", "sim.integrator='euler'",
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


@pytest.mark.parametrize("file_value,override,expected", [
    ("RK4", None, "rk4"), ("Euler", None, "euler"), ("rk4", "sim.integrator=implicitFAST", "implicitfast"),
    ("implicit", "sim.integrator=Euler", "euler")])
def test_mujoco_spellings_of_the_integrator_are_accepted(tmp_path, capsys, file_value, override, expected):
    from finrft.models import build_plate
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
    rft.write_table(tmp_path / "forces.csv", rft.paper_table(1.2, -0.2, samples=1801))
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
    done = subprocess.run([sys.executable, "-m", "finrft", "rotate", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "degrees/s" in done.stdout


def test_robot_scene_dump_round_trips(capsys):
    from finrft.scene import RobotScene
    assert main(["scene", "--robot", "--dump", "physical"]) == 0
    assert tomllib.loads(capsys.readouterr().out) == preset("physical", RobotScene).to_dict()
