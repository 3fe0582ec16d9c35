"""`finrft report --quick`: every section, figure and recording is produced from the public API."""

import re

from rerun.chunk import RrdReader

from finrft.cli import main


def test_quick_report(tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", "--quick", "--out", str(out), "--workers", "2"]) == 0
    text = (out / "report.md").read_text()
    for section in ("1. Dragging and rotating", "2. Effective flapping", "3. Model against experiment",
                    "4. The robot", "5. Speed"):
        assert f"## {section}" in text
    for image in re.findall(r"\]\((\w+\.png)\)", text):
        assert (out / image).stat().st_size > 20_000
    assert len(re.findall(r"\]\(\w+\.png\)", text)) == 4
    assert text.count("| Optimized |") == 1 and "paper η_sim" in text
    assert re.search(r"RMSE .*origami_v30 [0-9.]+ deg", text)  # the measurements were fitted
    for recording in ("drag_origami.rrd", "robot_optimum.rrd", "optimization.rrd"):
        assert list(RrdReader(out / recording).stream())
