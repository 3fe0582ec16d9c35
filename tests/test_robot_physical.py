"""The physical robot: forces from geometry, steady eta, reversibility of a rigid fin, the table's fields."""

import json

import numpy as np
import pytest

from finrft import geometry
from finrft.cli import main
from finrft.models import arm_law, body_drag, body_law, fin_law
from finrft.scene import RobotScene, SceneError, preset
from finrft.swim import steady, swim


@pytest.fixture(scope="module")
def physical():
    return preset("physical", RobotScene)


def test_forces_follow_the_depth_moment_formula(physical):
    """A vertical face of length l from depth z1 to z2 takes the stress per depth times l (z2^2 - z1^2) / 2."""
    s = physical
    z1 = s.robot.depth
    per_depth = s.rft.c_s * np.cos(s.rft.gamma0) + s.rft.c_f  # the sandswim law broadside, N/m^3
    segment = s.fin.segment_length * ((z1 + s.fin.height) ** 2 - z1 ** 2) / 2
    assert geometry.broadside(fin_law(s)) == pytest.approx(per_depth * segment, rel=1e-9)
    arm = s.arm.length * ((z1 + s.arm.height) ** 2 - z1 ** 2) / 2
    assert geometry.broadside(arm_law(s)) == pytest.approx(per_depth * arm, rel=1e-9)
    moment = ((z1 + s.body.height) ** 2 - z1 ** 2) / 2
    front, sides = per_depth * s.body.width * moment, 2 * s.rft.c_f * s.body.length * moment
    assert body_drag(s) == pytest.approx(front + sides + s.body.cart, rel=1e-9)
    assert body_law(s).f_perp == pytest.approx(0.5 * body_drag(s))  # the half robot carries half
    # the magnitudes are those of a small robot: a few newtons per segment
    assert 1.0 < geometry.broadside(fin_law(s)) < 20.0


def test_geometry_needs_a_scalable_law_and_a_velocity_drag(physical):
    with pytest.raises(SceneError, match="drag_law"):
        physical.replace(**{"body.drag_law": "stroke"})


def test_steady_eta_is_net_over_forward_after_the_first_cycle():
    rows = [{"D1_mm": 10.0, "D2_mm": 9.0, "net_speed_mm_s": 0.1, "eta": 0.1},
            {"D1_mm": 20.0, "D2_mm": 15.0, "net_speed_mm_s": 1.0, "eta": 0.25},
            {"D1_mm": 30.0, "D2_mm": 30.0, "net_speed_mm_s": 0.0, "eta": 0.0}]
    s = steady(rows)
    assert s["eta"] == pytest.approx((50 - 45) / 50)  # not the mean of 0.25 and 0
    assert s["D1_mm"] == pytest.approx(25.0) and s["D2_mm"] == pytest.approx(22.5)
    assert s["net_speed_mm_s"] == pytest.approx(0.5)
    assert steady(rows[:1])["eta"] == pytest.approx(0.1)


def test_rigid_fin_does_not_swim(physical):
    """Rate-independent, dissipative forces and negligible inertia make the motion kinematically reversible: a
    rigid fin flapping back and forth comes back where it started (scallop theorem). What remains is the
    regularisation below v_reg and the real inertias: below 0.2 points of eta."""
    run = swim(physical.replace(**{"fin.kind": "rigid", "gait.cycles": 2}), 2)
    summary = run.summary()
    assert abs(summary["eta_steady"]) < 2e-3
    assert summary["D1_mm_steady"] > 10.0  # it moves, and comes back


def test_physical_table_json_fields(capsys):
    assert main(["table", "--preset", "physical", "--json", "--quiet", "--workers", "1"]) == 0
    rows = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(rows) == 6
    for row in rows:
        for key in ("eta", "eta_first_cycle", "D1_mm", "D2_mm", "net_speed_mm_s", "paper_eta_exp",
                    "paper_net_speed_exp_mm_s", "fitted"):
            assert key in row
        assert row["eta"] == pytest.approx((row["D1_mm"] - row["D2_mm"]) / row["D1_mm"])
    assert [row["gait"] for row in rows if row["fitted"]] == ["Optimized"]
