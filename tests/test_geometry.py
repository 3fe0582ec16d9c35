"""Forces follow geometry: a segment's law is the scene's coefficients (per unit area and depth) times its face's
area and mean depth, resolved once at model build; the paper's per-segment values survive the conversion."""

import math

import numpy as np
import pytest

from conftest import face
from finrft import geometry, laws
from finrft.drive import Drive
from finrft.experiments.swim import build_robot
from finrft.experiments.swim import RobotScene
from finrft.scene import preset
from finrft.experiments.plate import build_plate, simulate

DRIVE = Drive(speed=0.03, stroke=0.03)  # broadside: attack 90 deg


def _broadside(scene) -> float:
    """The drive's steady force on a rigid plate dragged broadside (N): constant speed, so the medium's force."""
    return float(simulate(scene.replace(**{"plate.kind": "rigid"}), DRIVE).drive_force[-1])


def _sandswim_broadside(scene) -> float:
    """The closed form: N segments x face x (C_S sin beta0 + C_F) x tanh(v / v_reg) at psi = 90 deg, where
    tan beta0 = cot gamma0, so sin beta0 = cos gamma0."""
    r = scene.rft
    return (scene.plate.segments * face(scene) * (r.c_s * math.cos(r.gamma0) + r.c_f)
            * math.tanh(DRIVE.speed / r.v_reg))


def test_a_plate_twice_as_long_feels_twice_the_broadside_force():
    physical = preset("physical")
    short = physical.replace(**{"plate.segment_length": 0.02})
    long = physical.replace(**{"plate.segment_length": 0.04})
    assert _broadside(long) / _broadside(short) == pytest.approx(2.0, rel=0.03)
    for scene in (short, long):
        assert _broadside(scene) == pytest.approx(_sandswim_broadside(scene), rel=1e-6)


def test_a_fin_twice_as_tall_feels_twice_the_broadside_force():
    # Granular stress grows with depth: at the same mean depth, twice the height is twice the area and force; with
    # its top edge kept, the taller fin also reaches deeper, h (d + h / 2) in all.
    physical = preset("physical").replace(**{"medium.height": 0.03, "medium.depth": 0.04})
    h, d = physical.medium.height, physical.medium.depth
    tall_same_middle = physical.replace(**{"medium.height": 2 * h, "medium.depth": d - h / 2})
    assert _broadside(tall_same_middle) / _broadside(physical) == pytest.approx(2.0, rel=0.03)
    tall = physical.replace(**{"medium.height": 2 * h})
    assert _broadside(tall) / _broadside(physical) == pytest.approx(2 * (d + h) / (d + h / 2), rel=1e-6)


def test_a_fin_from_its_medium_follows_its_height_and_length():
    # The robot's fins take the sandswim law fitted to 3D-RFT on their faces: stress x area x mean depth, so the
    # fitted C_S and C_F scale as the face does and gamma0 stays.
    robot = preset("physical", RobotScene)
    h, d, base = robot.medium.height, robot.medium.depth, geometry.resolve(robot).chain.parameters
    for changes, ratio in (({"fin.segment_length": 2 * robot.fin.segment_length}, 2.0),
                           ({"medium.height": 2 * h}, 2 * (d + h) / (d + h / 2))):
        law = geometry.resolve(robot.replace(**changes)).chain.parameters
        assert law["c_s"] == pytest.approx(ratio * base["c_s"], rel=1e-5)
        assert law["c_f"] == pytest.approx(ratio * base["c_f"], rel=1e-5)
        assert law["gamma0"] == pytest.approx(base["gamma0"], rel=1e-5)


def test_the_paper_presets_keep_the_authors_per_segment_forces():
    # The authors' numbers (RA-L 2021 and their scripts), per segment: plate 1.2 N and -0.2 N, fin 6.779 N and
    # -1 N, arm 2 N + 17.94 N/mm x 65 mm and -0.3 N; the body 2.4612 N.
    plate, robot = build_plate(preset("paper")), build_robot(preset("paper", RobotScene))
    assert plate.groups[0].law.parameters == pytest.approx({"f_perp": 1.2, "f_par": -0.2}, rel=1e-15)
    fin, arm = robot.groups[0].law.parameters, robot.groups[1].law.parameters
    assert fin == pytest.approx({"f_perp": 6.779, "f_par": -1.0}, rel=1e-15)
    assert arm == pytest.approx({"f_perp": 2.0 + 17940.0 * 0.065, "f_par": -0.3}, rel=1e-15)
    assert robot.resolved.body_drag == 2.4612
    # and the rigid paper plate dragged broadside takes 3 x 1.2 N x tanh(v / v_reg), as the authors' model does
    assert _broadside(preset("paper")) == pytest.approx(3 * 1.2 * math.tanh(DRIVE.speed / 0.001), rel=1e-9)


def test_results_report_the_derived_per_segment_forces():
    scene = preset("physical")
    summary = simulate(scene, Drive(stroke=0.01)).summary()
    size = face(scene)
    assert summary["segment_scale_m3"] == pytest.approx(size, rel=1e-15)
    assert summary["segment_law"] == pytest.approx({"law": "sandswim", "c_s": scene.rft.c_s * size,
                                                    "c_f": scene.rft.c_f * size, "gamma0": scene.rft.gamma0})
    # the physical preset's fit, per segment: 0.1858 N and 0.1276 N
    assert summary["segment_law"]["c_s"] == pytest.approx(0.1858, rel=1e-12)
    assert summary["segment_law"]["c_f"] == pytest.approx(0.1276, rel=1e-12)


def test_a_table_law_scales_with_the_face_and_reads_its_file_once_per_version(tmp_path, monkeypatch):
    from finrft.laws import table
    path = tmp_path / "forces.csv"
    attack = np.linspace(0.0, 90.0, 10)
    table.write_table(path, table.ForceTable(attack, 20000 * np.sin(np.radians(attack)),
                                             3000 * np.cos(np.radians(attack))))
    reads = []
    original = table.read_table
    monkeypatch.setattr(table, "read_table", lambda p: reads.append(p) or original(p))
    table._read_cached.cache_clear()
    scene = preset("physical").replace(**{"rft.law": "table", "rft.table": str(path)})
    short, long = (scene.replace(**{"plate.segment_length": length}) for length in (0.02, 0.04))
    assert _broadside(long) / _broadside(short) == pytest.approx(2.0, rel=1e-9)
    assert _broadside(short) == pytest.approx(3 * 20000 * face(short) * math.tanh(30.0), rel=1e-9)
    assert len(reads) == 1  # every model build, companion run and check of both scenes
    law = laws.per_segment(short.rft, 1.0, 2.0, 0.0)  # a face 1 x 2 m at 1 m mean depth
    np.testing.assert_allclose(law.parameters["table"].f_perp, 40000 * np.sin(np.radians(attack)), rtol=1e-12)
