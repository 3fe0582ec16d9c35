"""`finrft bench robots --scene`: a robot's speed-accuracy frontier, and the battery of robots it runs on."""

import csv
import json
import math

import mujoco
import numpy as np
import pytest

from conftest import settling_box
from finrft.cli import main
from finrft.experiments.user_model import UserModel
from finrft.scene import UserScene, load_scene
from finrft.studies import frontier
from finrft.studies.frontier import BATTERY, Run, battery_scene, relative_error



@pytest.fixture
def box(tmp_path):
    return settling_box(tmp_path, "newton")


def test_relative_error_is_the_norm_of_the_difference_over_the_reference():
    # (3, 4) against (0, 5): the difference (3, -1), sqrt(10) over 5
    assert relative_error([3.0, 4.0], [0.0, 5.0]) == pytest.approx(math.sqrt(10) / 5)
    # a dict of per-body figures is one vector: (1, 0, 2) against (1, 1, 1): sqrt(2) / sqrt(3)
    assert relative_error({"a": [1.0, 0.0], "b": 2.0}, {"a": [1.0, 1.0], "b": 1.0}) == pytest.approx(
        math.sqrt(2) / math.sqrt(3))
    # a speed near 0 is measured against the floor, not against itself
    assert relative_error(3e-5, 1e-6, floor=1e-4) == pytest.approx(2.9e-5 / 1e-4)
    # a figure the reference does not report (a cost of transport where it stands still) has no relative error
    assert relative_error(0.7, None, floor=0.0) is None
    # a run that does not report one the reference does is off by its whole size
    assert relative_error(None, 0.5) == pytest.approx(1.0)


def _first_order(monkeypatch, walls, midpoint=(40.0, 1)):
    """`frontier.measure` replaced by runs whose speed is v0 (1 + c dt) (first order in the step), estimated at
    2 c dt v0, taking ``walls[method] / dt`` seconds; explicit fails above 1 ms. `auto` chooses explicit at 1 ms
    and takes ``walls["auto"]`` seconds. newton-midpoint, a candidate of the converged run only, is v0 (1 + k
    dt^order), ``midpoint`` = (k, order): by default first order and further off than newton."""
    v0, c = 0.1, 20.0

    def measure(scene, method, dt, *, estimate=True):
        if method == "auto":
            row = measure(scene, "explicit", 1e-3)
            row.method, row.dt, row.wall_s, row.chosen = "auto", dt, walls["auto"], "explicit, 1 ms"
            return row
        row = Run(method, dt, wall_s=walls.get(method, walls["newton"]) / dt)
        if method == "explicit" and dt > 1e-3:
            row.failed = "Chatter: at the step"
            return row
        error = midpoint[0] * dt ** midpoint[1] if method == "newton-midpoint" else c * dt
        row.figures = {"com_speed_m_s": v0 * (1 + error), "cost_of_transport": 2.0}
        row.estimates = {"com_speed_m_s": 2 * c * dt * v0, "cost_of_transport": 0.0}
        return row
    monkeypatch.setattr(frontier, "measure", measure)
    return v0, c


def test_errors_against_the_reference_have_the_known_answer(monkeypatch, box):
    walls = {"newton": 1e-3, "explicit": 1e-4, "auto": 0.05}
    v0, c = _first_order(monkeypatch, walls)
    scene = load_scene(str(box), cls=UserScene)
    result = frontier.frontier(scene, method_names=("newton", "explicit"), steps=(2e-3, 1e-3, 5e-4), log=lambda s: None)
    reference = v0 * (1 + c * 2.5e-4)  # newton at half the finest step
    assert result["reference"].dt == pytest.approx(2.5e-4)
    assert [r.method for r in result["rows"]].count("auto") == 1  # beside the scene's own method, at its step
    for row in result["rows"]:
        if row.failed:
            assert row.method == "explicit" and row.dt > 1e-3
            continue
        exact = v0 * c * abs(row.dt - 2.5e-4) / reference
        assert row.errors["com_speed_m_s"] == pytest.approx(exact)
        assert row.estimated["com_speed_m_s"] == pytest.approx(2 * c * row.dt * v0 / reference)
        assert row.errors["cost_of_transport"] == 0
    summary = result["summary"]
    # the reference's own error: its difference from newton at the finest step, c (5e-4 - 2.5e-4) v0 / reference
    assert summary["reference_error"]["com_speed_m_s"] == pytest.approx(v0 * c * 2.5e-4 / reference)
    default = summary["default"]
    assert (default["method"], default["dt"]) == ("newton", 1e-3)
    assert default["errors"]["com_speed_m_s"] == pytest.approx(v0 * c * 7.5e-4 / reference)
    # the estimate 2 c dt v0 over the error c (dt - dt_ref) v0: 2 dt / (dt - dt_ref) = 8/3
    assert default["estimate_over_error"]["com_speed_m_s"] == pytest.approx(8 / 3)
    # within 2 %, the cheapest: explicit at 1 ms (0.1 s, 1.5 %), against newton at 1 ms (1 s)
    assert summary["fastest"]["method"] == "explicit" and summary["fastest"]["dt"] == pytest.approx(1e-3)
    assert summary["default_over_fastest"] == pytest.approx(10.0)
    # auto's run is not a setting of the sweep: the fastest is still explicit at 1 ms, though auto's wall is less
    assert summary["auto"]["chosen"] == "explicit, 1 ms" and summary["auto_over_fastest"] == pytest.approx(0.5)
    assert summary["auto"]["errors"]["com_speed_m_s"] == pytest.approx(v0 * c * 7.5e-4 / reference)
    # the fastest its own estimate passes: 2 c dt v0 within 2 % of v0 (1 + c dt) from 0.5 ms down, explicit there
    # (0.2 s, against newton's 2 s), though explicit at 1 ms is within 2 % of the reference
    assert (summary["known"]["method"], summary["known"]["dt"]) == ("explicit", pytest.approx(5e-4))
    assert summary["auto_over_known"] == pytest.approx(0.05 / 0.2)


def test_the_converged_run_is_the_method_that_differs_less_from_itself(monkeypatch, box):
    # newton-midpoint second order (v0 (1 + 1e4 dt^2)): at 0.25 and 0.5 ms it differs from itself by 1.9e-3 v0,
    # newton by 5e-3 v0, so the reference is newton-midpoint at 0.25 ms, v0 (1 + 6.25e-4)
    v0, c = _first_order(monkeypatch, {"newton": 1e-3, "explicit": 1e-4, "auto": 0.05}, midpoint=(1e4, 2))
    scene = load_scene(str(box), cls=UserScene)
    result = frontier.frontier(scene, method_names=("newton", "explicit"), steps=(2e-3, 1e-3, 5e-4), log=lambda s: None)
    reference = v0 * (1 + 6.25e-4)
    assert (result["reference"].method, result["reference"].dt) == ("newton-midpoint", pytest.approx(2.5e-4))
    summary = result["summary"]
    assert summary["reference"]["method"] == "newton-midpoint"
    assert summary["reference_error"]["com_speed_m_s"] == pytest.approx(v0 * 1e4 * (5e-4**2 - 2.5e-4**2) / reference)
    newton = next(r for r in result["rows"] if (r.method, r.dt) == ("newton", 1e-3))
    assert newton.errors["com_speed_m_s"] == pytest.approx(v0 * (c * 1e-3 - 6.25e-4) / reference)


def test_the_summary_gives_the_cost_of_a_step_per_element(monkeypatch, box):
    # The bench table's cost of a step: an implicit one (newton: the wrench, its slope and Newton's iterates) and
    # MuJoCo's explicit one from the same state, per element of the medium beyond the bare step, and their ratio.
    _first_order(monkeypatch, {"newton": 1e-3, "explicit": 1e-4, "auto": 0.05})
    scene = load_scene(str(box), cls=UserScene)
    result = frontier.frontier(scene, method_names=("newton", "explicit"), steps=(1e-3, 5e-4), log=lambda s: None)
    cost = result["summary"]["step_cost"]
    assert (cost["method"], cost["dt"]) == ("newton", scene.sim.dt)
    assert cost["elements"] == sum(UserModel.of(scene).build(scene).attached.elements.values())
    assert cost["implicit_over_explicit_step"] == pytest.approx(cost["implicit_step_us"] / cost["explicit_step_us"])
    assert cost["implicit_over_explicit_step"] > 1
    assert cost["implicit_ns_per_element_step"] > cost["explicit_ns_per_element_step"]
    row = frontier.markdown_row(result["summary"])
    assert f"{cost['implicit_over_explicit_step']:.1f} explicit steps" in row
    assert row.count("|") == frontier.MARKDOWN_HEADER.splitlines()[0].count("|")


def test_the_cli_writes_one_row_per_run_and_a_chart(box, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["bench", "robots", "--scene", str(box), "--method", "newton", "--method", "newton-midpoint",
                 "--dt", "0.001", "--dt", "0.0005", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)["robots"]["box"]
    with open(out / "box.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["method"], float(r["dt_s"])) for r in rows] == [("newton", 1e-3), ("newton", 5e-4),
                                                                ("newton-midpoint", 1e-3),
                                                                ("newton-midpoint", 5e-4), ("auto", 1e-3)]
    assert [r["default"] for r in rows] == ["1", "0", "0", "0", "0"]
    assert rows[-1]["chosen"] and rows[-1]["chosen"] == summary["auto"]["chosen"]
    for r in rows:
        assert not r["failed"] and float(r["wall_s"]) > float(r["companion_wall_s"]) > 0
        assert float(r["com_position_m_error"]) < 0.01 and r["com_position_m_estimate"] != ""
    assert (out / "box.png").stat().st_size > 10_000
    assert json.loads((out / "box.json").read_text())["default"]["method"] == "newton"
    assert "| box | newton, 1 ms |" in (out / "frontier.md").read_text()
    assert summary["default"]["method"] == "newton" and summary["reference"]["dt"] == pytest.approx(2.5e-4)


def test_a_scene_that_is_not_there_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["bench", "robots", "--scene", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "--scene" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", BATTERY)
def test_battery_robot_compiles_and_its_scene_validates(name):
    scene = load_scene(battery_scene(name), cls=UserScene)
    experiment = UserModel.of(scene)
    built = experiment.build(scene)
    assert sum(built.attached.elements.values()) > 0
    data = mujoco.MjData(built.model)
    mujoco.mj_forward(built.model, data)
    assert np.isfinite(data.qacc).all()
    # a lab's numerics: an implicit step of 1 ms or longer, a few seconds simulated; the paddle sled's paddles
    # cut in and out of the sand four times a turn, and its speed meets its 2 % limit only at 0.25 ms
    shortest = 2.5e-4 if name == "paddle_sled" else 1e-3
    assert scene.sim.dt >= shortest and 1.0 <= scene.sim.duration <= 5.0


def test_the_battery_spans_10_g_to_2_kg_links_and_both_laws():
    masses, laws = [], set()
    for name in BATTERY:
        scene = load_scene(battery_scene(name), cls=UserScene)
        model = UserModel.of(scene).build(scene).model
        masses += [model.body_mass[model.body(b).id] for b in UserModel.of(scene).bodies]
        masses.append(max(model.body_mass))
        laws.add(scene.medium.law)
    assert min(masses) == pytest.approx(0.01, rel=0.05) and max(masses) == pytest.approx(2.0, rel=0.05)
    assert laws == {"li2013", "rft3d"}
    kinds = " ".join(BATTERY.values())
    assert all(kind in kinds for kind in ("legged", "wheeled", "swimming", "burrowing"))


@pytest.mark.slow
@pytest.mark.parametrize("name", BATTERY)
def test_battery_robot_runs_at_its_defaults(name, capsys):
    """`finrft run --scene FILE` at the scene's defaults: exit 0, its error estimate within the default limits."""
    assert main(["run", "--scene", battery_scene(name), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sim_time_s"] == pytest.approx(load_scene(battery_scene(name), cls=UserScene).sim.duration,
                                                  abs=0.01)


@pytest.mark.parametrize("argv", [["--dt", "0.001"], ["--method", "newton"],
                                  ["--scene", "hexapod", "--robot", "hexapod"]])
def test_frontier_flags_without_a_scene_are_refused(argv, capsys):
    """--method, --dt and --out belong to the frontier, --robot to the examples' benchmark: mixed, exit 2, one line."""
    assert main(["bench", "robots", *argv]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_bench_steps_times_each_implicit_method_against_the_explicit_step():
    """`finrft bench steps`: each fixed-step implicit method's step and the explicit one from the same state, the
    ratio their times' and the cost per element per step beyond the bare step over the robot's elements."""
    from finrft.experiments.user_model import example
    row = frontier.steps(("wheel_rig",), log=lambda text: None)["robots"]["wheel_rig"]
    scene = load_scene(example("wheel_rig"), cls=UserScene)
    assert row["elements"] == sum(UserModel.of(scene).build(scene).attached.elements.values())
    assert set(frontier.STEP_METHODS) <= set(row)
    for method in frontier.STEP_METHODS:
        cost = row[method]
        assert cost["implicit_over_explicit_step"] == pytest.approx(cost["implicit_step_us"] / cost["explicit_step_us"])
        per_element = 1e3 * (cost["implicit_step_us"] - row["bare_us_per_step"]) / row["elements"]
        assert cost["implicit_ns_per_element_step"] == pytest.approx(per_element)
        assert cost["implicit_step_us"] > 0 and cost["explicit_step_us"] > 0
