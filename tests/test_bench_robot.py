"""The robot benchmark: one gait's eta against a converged run of the same scene, computed in the same call."""

import pytest

from finrft.studies import bench
from finrft.experiments.swim import RobotScene
from finrft.scene import preset


def test_physical_gait_is_measured_against_a_converged_run():
    scene = preset("physical", RobotScene)
    out = bench.robot(scene, budget=2, workers=1, repeat=1, log=lambda text: None)
    assert out["gait_reference"] == f"adaptive-newton, tolerance {scene.sim.tolerance / 100:g}"
    assert out["gait_eta_error"] == pytest.approx(abs(out["gait_eta"] - out["gait_eta_reference"]))
    assert 0 < out["gait_eta_error"] < 5e-4  # the preset's target: 0.05 points of eta
    # a fixed step's reference is the same method at a tenth of the step
    fixed = bench._converged(scene.replace(**{"sim.method": "newton", "sim.dt": 3e-4}))
    assert fixed[0].sim.dt == pytest.approx(3e-5) and fixed[1] == "newton, dt 3e-05 s"
