"""The rollout batch against the serial path: the same steps, so the same states."""

import numpy as np
import pytest

from finrft import batch, models
from finrft.drive import Drive
from finrft.scene import preset
from finrft.simulate import simulate


@pytest.mark.parametrize("drive", [Drive(speed=0.03, stroke=0.2), Drive(speed=0.03, stroke=0.045, cycles=2)],
                         ids=["drag", "out-and-back"])
def test_rollout_states_equal_serial_runs(drive):
    # Bit for bit: the same mj_step sequence, with the reversals' impulses applied between the strokes.
    jobs = [(preset("paper").replace(**{"plate.damping": b}), drive) for b in (0.5, 2.5, 1.0)]
    for (scene, _), states in zip(jobs, batch.rollout_plates(jobs, workers=2)):
        run = simulate(scene, drive, estimate_error=False)
        plate = models.build_plate(scene)
        assert np.allclose(states[:, 0], run.time, rtol=0, atol=1e-9)  # MuJoCo sums dt, the result multiplies
        assert np.array_equal(states[:, 1 + plate.drive_qpos], run.displacement)
        hinges = 1 + np.asarray(plate.hinge_qpos)
        assert np.array_equal(states[:, hinges], run.hinge_angle[:, :len(hinges)])


def test_rollout_refuses_what_it_cannot_step():
    scene, drive = preset("paper"), Drive(speed=0.03, stroke=0.2)
    with pytest.raises(ValueError, match="same drive"):
        batch.rollout_plates([(scene, drive), (scene, Drive(speed=0.01, stroke=0.2))])
    with pytest.raises(ValueError, match="native"):
        batch.rollout_plates([(scene.replace(**{"sim.backend": "python"}), drive)])


def test_rollout_jobs_with_other_laws_step_with_their_own():
    # A thread's MjData carries the plugin instance (law, coefficients, segments) of the model it was made for:
    # jobs that differ there are rolled out apart, each with its own law.
    drive = Drive(speed=0.03, stroke=0.045, cycles=1)
    jobs = [(preset("paper").replace(**changes), drive) for changes in (
        {}, {"rft.f_perp": 2.4}, {"rft.law": "sandswim", "rft.c_s": 1.0, "rft.c_f": 0.3, "rft.gamma0": 0.4},
        {"plate.segments": 4, "plate.segment_length": 0.025})]
    for (scene, _), states in zip(jobs, batch.rollout_plates(jobs, workers=2)):
        run = simulate(scene, drive, estimate_error=False)
        plate = models.build_plate(scene)
        hinges = 1 + np.asarray(plate.hinge_qpos)
        assert np.array_equal(states[:, hinges], run.hinge_angle[:, :len(hinges)])
