"""The physical robot: forces from its medium, steady eta, reversibility of a rigid fin, the table's fields."""

import json
import math

import numpy as np
import pytest

from finrft import geometry, media
from finrft.cli import main
from finrft.experiments.swim import body_law
from finrft.experiments.swim import RobotScene
from finrft.scene import SceneError, preset
from finrft.experiments.swim import steady, swim


@pytest.fixture(scope="module")
def physical():
    return preset("physical", RobotScene)


def _broadside(law):
    """The sand-swimming law's force on a segment moving along its normal: C_S sin(beta0) + C_F at psi = 90 deg,
    tan beta0 = cot gamma0."""
    p = law.parameters
    return p["c_s"] * math.cos(p["gamma0"]) + p["c_f"]


def test_faces_take_3d_rft_forces_from_the_medium(physical):
    """Fin segments, arms and body take 3D-RFT on vertical faces at medium.depth, from the [medium]'s values."""
    s, m = physical, physical.medium
    props = (m.bulk_density, m.internal_friction, m.surface_friction)
    broadside = np.array([math.pi / 2])
    # the body: only its front face (W x H, broadside) resists in 3D-RFT; the sides slide along themselves
    front, _ = media.plate_forces(broadside, s.body.width, m.depth, s.body.height, *props)
    assert geometry.body_resistance(s)["faces"] == pytest.approx(front[0], rel=1e-9)
    resolved = geometry.resolve(s)
    assert resolved.body_drag == pytest.approx(front[0] + s.body.cart, rel=1e-9)
    # the half robot carries half
    assert body_law(s, resolved).parameters["f_perp"] == pytest.approx(0.5 * resolved.body_drag)
    # fins and arms: the sand-swimming law fitted to 3D-RFT on their faces, as close as the fit is
    for law, length, height in ((resolved.chain, s.fin.segment_length, m.height),
                                (resolved.arm, s.arm.length, s.arm.height)):
        fit = media.sandswim_coefficients(length, m.depth, height, *props)
        p = law.parameters
        assert (law.law, p["c_s"], p["c_f"], p["gamma0"]) == ("sandswim", fit.c_s, fit.c_f, fit.gamma0)
        perp, _ = media.plate_forces(broadside, length, m.depth, height, *props)
        assert abs(_broadside(law) - perp[0]) <= fit.max_error
    # the magnitudes are those of a small robot: a few newtons per segment
    assert 1.0 < _broadside(resolved.chain) < 20.0
    # the scene keeps what its user gave: the law's coefficients are left to the medium
    assert (s.rft.c_s, s.rft.c_f, s.rft.gamma0) == (0.0, 0.0, 0.0)


def test_without_a_medium_the_coefficients_are_as_given():
    paper = preset("paper", RobotScene)
    assert geometry.properties(paper) is None
    a = paper.arm
    resolved = geometry.resolve(paper)
    assert resolved.arm.parameters["f_perp"] == pytest.approx(a.f_perp_base + a.f_perp_per_length * a.length)
    assert resolved.body_drag == paper.body.drag


def test_a_robot_in_a_medium_needs_a_velocity_drag(physical):
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
    regularisation below v_reg (1 mm/s, against ~80 mm/s at the arm's tip) and the real inertias: below 0.5 points
    of eta, against 8.6 for the origami fin."""
    run = swim(physical.replace(**{"fin.kind": "rigid", "gait.cycles": 2}), 2)
    summary = run.summary()
    assert abs(summary["eta_steady"]) < 5e-3
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


# a swim and its independent ODE solution, half a minute on two cores: with the slow studies
@pytest.mark.slow
def test_the_robot_in_its_medium_matches_the_independent_solution(physical):
    # The hand-derived equations (finrft.reference), given the arm's law and the body's drag the medium derives, as
    # numbers: the same hinge angles, body travel and eta as MuJoCo with the adaptive-newton method at a tight
    # tolerance, over the first cycle (the fin slaps flat at the start and folds in the recovery stroke).
    from finrft.reference import solve_robot
    scene = physical.replace(**{"sim.tolerance": 1e-5})
    run = swim(scene, 1, estimate_error=False)
    resolved = geometry.resolve(scene)
    ref = solve_robot(scene, 1, run.time, rtol=1e-8, atol=1e-11, arm=resolved.arm, body_drag=resolved.body_drag,
                      fin=resolved.chain)
    assert np.degrees(np.abs(run.series["hinge_angle"] - ref.hinge_angle).max()) < 0.005
    assert 1e3 * np.abs(run.body_y - ref.body_y).max() < 0.05                  # of ~180 mm strokes
    eta_ref = (np.diff(ref.stroke_y)[1] + np.diff(ref.stroke_y)[0]) / np.diff(ref.stroke_y)[1]
    assert abs(run.series["eta"][0] - eta_ref) < 1e-4
    assert np.degrees(ref.hinge_angle.min()) < -10  # the fin folded in the recovery stroke (13 deg)
    with pytest.raises(ValueError, match="arm and body_drag"):  # not the [arm] keys the medium replaces
        solve_robot(scene, 1, run.time[:3])


def test_quiet_table_still_prints_the_table(capsys):
    # --quiet drops the progress bar and commentary, not the result the command was asked for
    assert main(["table", "--preset", "physical", "--quiet", "--workers", "1"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("| gait |") and sum(line.startswith("| Optimized |") for line in lines) == 1
