"""The speed-against-accuracy study: its outputs, its failure labels, and the physical case's target."""

import csv

import pytest

from finrft.cli import main


@pytest.mark.slow  # a study: every method at every step on four scenes, minutes on two cores
def test_quick_accuracy_study(tmp_path, capsys):
    out = tmp_path / "acc"
    assert main(["bench", "accuracy", "--quick", "--out", str(out), "--workers", "2"]) == 0
    rows = list(csv.DictReader((out / "accuracy.csv").open()))
    assert (out / "accuracy.png").stat().st_size > 20_000
    assert "fastest within 0.1°" in (out / "accuracy.md").read_text()
    result = {(r["scene"], r["backend"], r["method"], float(r["dt"])): r for r in rows if r["method"] != "adaptive"}
    assert {r["scene"] for r in rows} == {"plate, paper inertia", "plate, physical inertia", "robot, paper",
                                          "robot, physical"}
    # With the paper's 1 kg m^2 inertias MuJoCo's own step is fine at 1 ms.
    paper = result[("plate, paper inertia", "native", "explicit (implicitfast)", 1e-3)]
    assert paper["failure"] == "" and float(paper["angle_error_deg"]) < 0.01
    assert float(paper["force_error_pct"]) < 0.1
    # With physical inertias the explicit coupling chatters and RK4 blows up; newton holds at 1 ms in both
    # backends, with the same trajectory.
    physical = {key[1:]: r for key, r in result.items() if key[0] == "plate, physical inertia"}
    assert physical[("native", "explicit (implicitfast)", 1e-3)]["failure"] == "chatter"
    assert physical[("native", "explicit (rk4)", 1e-3)]["failure"] == "unstable"
    native, python = physical[("native", "newton", 1e-3)], physical[("python", "newton", 1e-3)]
    assert native["failure"] == python["failure"] == "" and float(native["angle_error_deg"]) < 0.5
    assert abs(float(native["angle_error_deg"]) - float(python["angle_error_deg"])) < 1e-9
