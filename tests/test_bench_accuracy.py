"""The speed-against-accuracy study: its outputs, and that its failure criterion tells chatter from a good run."""

import csv

from finrft.cli import main


def test_quick_accuracy_study(tmp_path, capsys):
    out = tmp_path / "acc"
    assert main(["bench", "accuracy", "--quick", "--out", str(out), "--workers", "2"]) == 0
    rows = list(csv.DictReader((out / "accuracy.csv").open()))
    assert (out / "accuracy.png").stat().st_size > 20_000
    assert "fastest within 0.1°" in (out / "accuracy.md").read_text()
    result = {(r["scene"], r["method"], float(r["dt"])): r for r in rows}
    # With the paper's 1 kg m^2 inertias MuJoCo's own step is fine at 1 ms; with physical inertias RK4 blows up.
    paper = result[("plate, paper inertia", "explicit (implicitfast)", 1e-3)]
    assert paper["failure"] == "" and float(paper["angle_error_deg"]) < 0.01
    assert float(paper["force_error_pct"]) < 0.1
    assert result[("plate, physical inertia", "explicit (rk4)", 1e-3)]["failure"] == "unstable"
