"""`finrft report --quick`: every section, figure and recording is produced from the public API."""

import re

import pytest

from rerun.chunk import RrdReader

from finrft.cli import main


@pytest.mark.slow  # every figure of the paper regenerated: minutes on two cores
def test_quick_report(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # away from the repository: the measurements come with the package
    out = tmp_path / "report"
    assert main(["report", "--quick", "--out", str(out), "--workers", "2"]) == 0
    text = (out / "report.md").read_text()
    for section in ("1. Dragging and rotating", "2. Effective flapping", "3. Model against experiment",
                    "4. The robot", "5. The physical robot against the experiments", "6. Speed"):
        assert f"## {section}" in text
    for image in re.findall(r"\]\((\w+\.png)\)", text):
        assert (out / image).stat().st_size > 20_000
    assert len(re.findall(r"\]\(\w+\.png\)", text)) == 5
    assert text.count("| Optimized |") == 2 and "paper η_sim" in text and "| fitted |" in text
    assert re.search(r"RMSE .*origami_v30 [0-9.]+ deg", text)  # the measurements were fitted
    for recording in ("drag_origami.rrd", "robot_optimum.rrd", "optimization.rrd"):
        assert list(RrdReader(out / recording).stream())


def test_a_report_without_its_measurements_fails_before_running(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["report", "--quick", "--data", str(tmp_path / "empty"), "--out", str(tmp_path / "report")]) == 2
    err = capsys.readouterr().err
    assert "no drag data" in err and "empty" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]


def test_a_failing_part_leaves_nothing_behind(tmp_path, monkeypatch):
    from finrft.studies import report

    def broken(out, *args):
        (out / "forces.png").write_bytes(b"half a figure")
        raise RuntimeError("the part failed")
    monkeypatch.setattr(report, "forces", broken)
    with pytest.raises(RuntimeError):
        report.write_report(tmp_path / "report", quick=True, workers=1)
    assert list(tmp_path.iterdir()) == []
