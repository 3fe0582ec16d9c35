"""Searching and sweeping any robot scene: design keys of the model (MjSpec edits by name) against the closed form
of a plate dragged through the medium, finrft optimize --objective on a problem whose optimum follows from that
closed form, its log's bit-identical resume, finrft sweep against the same runs made directly, and bad keys."""

import csv
import json
import math

import h5py
import mujoco
import numpy as np
import pytest

from finrft import design
from finrft.cli import main
from finrft.errors import SceneError
from finrft.experiments.attached_model import scene_spec
from finrft.experiments.user_model import run_robot
from finrft.scene import UserScene, load_scene
from finrft.studies import searchlog
from finrft.studies.optimize import read_log
from conftest import dragged_plate_scene

# A 4 cm x 6 cm plate (1 mm thick) on a slide along x, its top edge at its body's origin: dragged at 0.1 m/s with
# its top d below the surface, li2013's generic medium (zeta 1) resists with alpha w ((d + H)^2 - d^2) / 2,
# alpha = 0.370 N/cm^3 (Li, Zhang & Goldman 2013; the README's 26.64 N at d = 0).
MODEL = """<mujoco><option gravity="0 0 -9.81"/><worldbody><body name="plate">
  <joint name="drag" type="slide" axis="1 0 0"/><geom name="plate" type="box" size="0.0005 0.02 0.03" pos="0 0 -0.03"
  mass="10"/></body></worldbody><actuator><position name="servo" joint="drag" kp="0.001"/></actuator></mujoco>"""
SCENE = dragged_plate_scene(0.01, method="newton", record_dt=0.01)


def closed_form(depth_cm: float, width_cm: float = 4.0, height_cm: float = 6.0) -> float:
    return 0.370 * width_cm * ((depth_cm + height_cm) ** 2 - depth_cm ** 2) / 2


@pytest.fixture
def scene_file(tmp_path):
    (tmp_path / "plate.xml").write_text(MODEL)
    (tmp_path / "scene.toml").write_text(SCENE)
    return tmp_path / "scene.toml"


def _json(capsys):
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_design_keys_edit_the_model_and_its_force_follows_the_closed_form(scene_file, capsys):
    # a plate twice as wide (geom size 1 = half-width), 2 cm deeper: the drag of the closed form at each
    for sets, width, depth in (((), 4.0, 0.0), (("model.geom.plate.size.1=40mm", "model.body.plate.pos.2=-0.02"),
                                                8.0, 2.0)):
        args = ["run", "--scene", str(scene_file), "--json", "--quiet", "--max-error", "drive_load=5%"]
        for s in sets:
            args += ["--set", s]
        assert main(args) == 0
        load = _json(capsys)["drive_load"][0]
        assert load == pytest.approx(closed_form(depth, width), rel=0.03)
    scene = load_scene(scene_file, cls=UserScene).replace(**{"model.actuator.servo.kp": 7.0,
                                                              "model.joint.drag.stiffness": 3.0})
    assert scene.model.design == ("actuator.servo.kp=7.0", "joint.drag.stiffness=3.0")
    spec = scene_spec(scene)
    assert spec.actuator("servo").gainprm[0] == 7.0 and spec.actuator("servo").biasprm[1] == -7.0
    m = spec.compile()
    assert m.jnt_stiffness[0] == 3.0 and m.actuator_gainprm[0, 0] == 7.0
    assert design.current(scene_spec(load_scene(scene_file, cls=UserScene)), "model.geom.plate.size.2") == 0.03


def test_kv_of_a_velocity_servo_is_its_gain():
    # a wheel's <velocity> servo pushes kv (ctrl - qdot): its kv is gainprm[0] = -biasprm[2]; a kp it has not
    spec = mujoco.MjSpec.from_string("""<mujoco><worldbody><body><joint name="axle"/><geom size="0.1" mass="1"/>
      </body></worldbody><actuator><velocity name="wheel" joint="axle" kv="0.2"/></actuator></mujoco>""")
    assert design.current(spec, "model.actuator.wheel.kv") == pytest.approx(0.2)
    design.apply(spec, ("actuator.wheel.kv=0.5",))
    m = spec.compile()
    assert m.actuator_gainprm[0, 0] == 0.5 and m.actuator_biasprm[0, 2] == -0.5 and m.actuator_biasprm[0, 1] == 0
    with pytest.raises(SceneError, match="not a position servo"):
        design.apply(spec, ("actuator.wheel.kp=3",))


@pytest.mark.parametrize("item, words", [
    ("model.geom.nope.size.0=1", "no geom named 'nope'"),
    ("model.geom.plate.size.3=1", "index from 0 to 2"),
    ("model.body.plate.mass.0=1", "one number"),
    ("model.joint.drag.colour=1", "no numeric attribute 'colour'"),
    ("model.geom.plate.size.0=abc", "must be a number"),
    ("model.actuator.nope.kp=1", "no actuator named 'nope'"),
    ("model.joint.drag.range.0=20mm", "m on a slide joint or rad on a hinge"),
])
def test_a_bad_design_key_is_one_line_and_exit_2_before_anything_runs(scene_file, capsys, item, words):
    for command in (["run", "--scene", str(scene_file), "--set", item],
                    ["optimize", "--scene", str(scene_file), "--objective", "drive_load.0",
                     "--bounds", f"{item.partition('=')[0]}=0.01,0.02"],
                    ["sweep", "--scene", str(scene_file), "--grid", f"{item.partition('=')[0]}=0.01,0.02"]):
        if ("abc" in item or "mm" in item) and command[0] != "run":  # a bad value, not a bad key
            continue
        assert main(command) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err


def test_bad_figures_keys_and_bounds_exit_2(scene_file, capsys):
    base = ["optimize", "--scene", str(scene_file), "--bounds", "drive.0.speed=0.05,0.2"]
    for extra, words in ((["--objective", "speed"], "no figure 'speed'"),
                         (["--objective", "com_velocity_m_s.3"], "com_velocity_m_s.N, N from 0 to 2"),
                         (["--objective", "drive_load.0", "--constraint", "cost_of_transport<5"], "FIGURE<=VALUE"),
                         (["--objective", "drive_load.0:fast"], "FIGURE:min"),
                         (["--objective", "drive_load.0", "--bounds", "drive.0.nope=1,2"], "unknown scene key"),
                         (["--objective", "drive_load.0", "--bounds", "medium.zeta=0.8,0.4"], "must be below")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err


def test_a_sweep_whose_figure_or_plot_cannot_be_drawn_is_refused_before_it_runs(scene_file, tmp_path, capsys):
    # a mistyped --figure printed nan for every variant; a text key to --plot failed after the whole sweep had run
    base = ["sweep", "--scene", str(scene_file), "--csv", str(tmp_path / "t.csv")]
    for extra, words in ((["--grid", "medium.zeta=0.5,1", "--figure", "com_sped"], "no figure 'com_sped'"),
                         (["--grid", "sim.method=newton,implicit", "--plot", "sim.method", "--png",
                           str(tmp_path / "p.png")], "its values are not numbers")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "t.csv").exists() and not (tmp_path / "p.png").exists()


def test_a_star_key_sets_every_entry():
    scene = load_scene(__import__("finrft").experiments.user_model.example("sand_swimmer"), cls=UserScene)
    changed = scene.replace(**{"control.*.frequency": 1.5, "control.*.amplitude": 0.5})
    assert [c.frequency for c in changed.control] == [1.5] * len(scene.control)
    assert [c.amplitude for c in changed.control] == [0.5] * len(scene.control)
    assert [c.phase for c in changed.control] == [c.phase for c in scene.control]


@pytest.mark.slow
def test_optimize_finds_the_deepest_plate_its_drive_can_pull(scene_file, tmp_path, capsys):
    # Deepest (lowest centre of mass) under a pull of at most F: the closed form gives F(d) linear in the depth, so
    # the optimum is the depth where the pull is F: 20 mm for F = closed_form(2 cm) = 44.4 N.
    limit = closed_form(2.0)
    log, chart = tmp_path / "search.h5", tmp_path / "search.png"
    assert main(["optimize", "--scene", str(scene_file), "--objective", "com_position_m.2:min",
                 "--bounds", "model.body.plate.pos.2=-40,0mm", "--constraint", f"drive_load.0<={limit}",
                 "--budget", "40", "--seed", "3", "--workers", "1", "--out", str(log), "--plot", str(chart),
                 "--json", "--quiet"]) == 0
    result = _json(capsys)
    depth = -result["best"]["model.body.plate.pos.2"]
    assert depth == pytest.approx(0.020, abs=0.0015)
    assert result["best_objective"] == pytest.approx(-depth - 0.03, abs=1e-6)  # the centre, 3 cm below the top
    assert 0 <= result["best_objective_estimate"] < 1e-4
    assert set(result) >= {"best", "best_objective", "best_objective_estimate", "best_ambiguous", "refined"}
    data = read_log(log, searchlog.SCENE)
    assert len(data["x"]) >= 40 and data["attrs"]["objective"] == "com_position_m.2:min"
    feasible = data["usable"] > 0
    assert np.all(data["constraint/drive_load.0"][feasible] <= limit)
    assert chart.stat().st_size > 5000


@pytest.mark.slow
def test_a_resumed_scene_search_is_the_uninterrupted_one_bit_for_bit(scene_file, tmp_path, capsys):
    whole, part = tmp_path / "whole.h5", tmp_path / "part.h5"
    common = ["--scene", str(scene_file), "--objective", "drive_load.0:min", "--bounds", "medium.zeta=0.5,1.5",
              "--bounds", "model.geom.plate.size.1=10,30mm", "--seed", "7", "--workers", "1", "--quiet", "--json"]
    assert main(["optimize", *common, "--budget", "12", "--out", str(whole)]) == 0
    uninterrupted = _json(capsys)
    assert main(["optimize", *common, "--budget", "6", "--out", str(part)]) == 0
    capsys.readouterr()
    assert main(["optimize", "--resume", str(part), "--budget", "12", "--workers", "1", "--quiet", "--json"]) == 0
    resumed = _json(capsys)
    assert resumed["best"] == uninterrupted["best"] and resumed["best_objective"] == uninterrupted["best_objective"]
    a, b = read_log(whole, searchlog.SCENE), read_log(part, searchlog.SCENE)
    for name in ("x", "cost", "objective", "objective_error", "state/mean", "state/C", "state/rng_key"):
        assert np.array_equal(a[name], b[name], equal_nan=True), name


@pytest.mark.slow
def test_a_sweep_reproduces_the_runs_made_directly(scene_file, tmp_path, capsys):
    table, out, png = tmp_path / "t.csv", tmp_path / "t.h5", tmp_path / "t.png"
    assert main(["sweep", "--scene", str(scene_file), "--grid", "medium.zeta=0.5,1", "--grid",
                 "model.body.plate.pos.2=0,-10mm", "--csv", str(table), "--out", str(out), "--plot", "medium.zeta",
                 "--figure", "drive_load.0", "--png", str(png), "--workers", "2", "--json", "--quiet"]) == 0
    rows = list(csv.DictReader(table.open()))
    assert [(float(r["medium.zeta"]), float(r["model.body.plate.pos.2"])) for r in rows] == [
        (0.5, 0.0), (0.5, -0.01), (1.0, 0.0), (1.0, -0.01)]
    base = load_scene(scene_file, cls=UserScene)
    for r in rows:
        direct = run_robot(base.replace(**{"medium.zeta": float(r["medium.zeta"]),
                                           "model.body.plate.pos.2": float(r["model.body.plate.pos.2"])}),
                           max_error=None).summary()
        assert float(r["drive_load.0"]) == direct["drive_load"][0]
        assert float(r["drive_load.0 estimate"]) == direct["error_estimate"]["drive_load"][0]
        # the force scales with zeta and follows the closed form in depth
        assert float(r["drive_load.0"]) == pytest.approx(
            float(r["medium.zeta"]) * closed_form(-100 * float(r["model.body.plate.pos.2"])), rel=0.03)
    with h5py.File(out) as f:
        assert list(f["keys/medium.zeta"][:]) == [0.5, 0.5, 1.0, 1.0]
        assert "geom.plate" not in f["scenes"][0].decode() and "plate.pos.2=-0.01" in f["scenes"][1].decode()
    assert png.stat().st_size > 5000


def test_random_variants_follow_their_seed_and_distribution(scene_file, capsys):
    args = ["sweep", "--scene", str(scene_file), "--random", "3", "--seed", "5", "--dist",
            "medium.zeta=uniform:0.4,0.8", "--workers", "1", "--json", "--quiet"]
    assert main(args) == 0
    first = _json(capsys)
    assert main(args) == 0
    assert _json(capsys) == first
    zetas = [v["keys"]["medium.zeta"] for v in first]
    assert zetas == list(np.random.default_rng(5).uniform(0.4, 0.8, size=3))
    for bad in (["--dist", "medium.zeta=gauss:1,2"], ["--dist", "medium.zeta=uniform:0.8,0.4"]):
        assert main(["sweep", "--scene", str(scene_file), "--random", "2", *bad]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_a_sweep_shows_its_progress_on_a_terminal(scene_file, monkeypatch, capsys):
    from test_cli import _bar_updates
    seen = _bar_updates(monkeypatch)
    assert main(["sweep", "--scene", str(scene_file), "--grid", "medium.zeta=0.5,1", "--workers", "1"]) == 0
    assert seen[-1] == (2, 2) and all(n <= total for n, total in seen)
    assert "2 variants of medium.zeta: 0 failed" in capsys.readouterr().out


@pytest.mark.slow  # a local cluster of two processes, started and stopped
def test_dask_gives_the_local_search_and_sweep(scene_file):
    distributed = pytest.importorskip("dask.distributed")
    from finrft.studies.optimize import Objective, Variable, optimize_scene
    from finrft.studies.sweep import sweep
    scene = load_scene(scene_file, cls=UserScene)
    variables, objective = [Variable("medium.zeta", 0.5, 1.5)], Objective.parse("drive_load.0:min")
    variants = [{"medium.zeta": 0.5}, {"medium.zeta": 1.0}]
    local = optimize_scene(scene, variables, objective, budget=4, seed=3, workers=1)
    table = sweep(scene, variants, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                                  processes=True) as cluster, distributed.Client(cluster) as client:
        remote = optimize_scene(scene, variables, objective, budget=4, seed=3, executor=client.get_executor())
        remote_table = sweep(scene, variants, executor=client.get_executor())
    assert remote.best == local.best and remote.best_objective == local.best_objective
    assert [r["figures"] for r in remote_table.results] == [r["figures"] for r in table.results]
