"""The scripts of examples/ run as a user runs them, from a fresh folder, and show what their text says."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run(name: str, *args: str, cwd: Path) -> str:
    done = subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_every_example_is_tested():
    tested = set(re.findall(r'run\("(\w+\.py)"', Path(__file__).read_text()))
    assert tested == {p.name for p in EXAMPLES.glob("*.py")}


def test_plate_drag(tmp_path):
    out = run("plate_drag.py", cwd=tmp_path)
    assert "recovery stroke" in out and "net impulse per cycle" in out


def test_robot_swim_origami_beats_rigid(tmp_path):
    """The paper's claim on the physical robot: the origami fin swims forward, far better than a rigid one."""
    eta = {fin: float(value) for fin, value in re.findall(r"^(\w+)\s+eta = ([-+\d.]+) %", run("robot_swim.py",
                                                                                             cwd=tmp_path), re.M)}
    assert set(eta) == {"origami", "rigid"}
    assert eta["origami"] > 0 and eta["origami"] - eta["rigid"] > 2


def test_own_model_matches_the_closed_form(tmp_path):
    """0.370 N/cm^3 x 4 cm x (6 cm)^2 / 2 on a plate standing in the generic medium (Li, Zhang & Goldman 2013)."""
    drag = float(re.search(r"drag (-?[\d.]+) N", run("own_model.py", cwd=tmp_path))[1])
    assert abs(drag + 26.64) < 0.01


def test_scene_from_toml_writes_h5(tmp_path):
    """A stiffer plate bends less: the first segment's final angle shrinks as k grows."""
    out = run("scene_from_toml.py", "soft.h5", cwd=tmp_path)
    first = [float(m) for m in re.findall(r"angles \[(-?[\d.]+),", out)]
    assert len(first) == 3 and abs(first[0]) > abs(first[1]) > abs(first[2]) > 0
    assert (tmp_path / "soft.h5").stat().st_size > 0


@pytest.mark.slow  # a figure of several drags
def test_plate_shapes_draws_the_picture(tmp_path):
    run("plate_shapes.py", "shapes.png", cwd=tmp_path)
    assert (tmp_path / "shapes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
