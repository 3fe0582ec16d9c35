"""The threaded batch against the serial path: the same steps, so the same states."""

import dataclasses

import mujoco
import numpy as np
import pytest

from finrft.errors import SceneError

from finrft import batch, native
from finrft.convergence import SimulationUnstable
from finrft.drive import Drive
from finrft.scene import preset
from finrft.experiments.plate import RETUNABLE, build_plate, retune, retune_key, simulate


def _same_as_serial(jobs, states):
    for (scene, drive), state in zip(jobs, states):
        run = simulate(scene, drive, estimate_error=False)
        plate = build_plate(scene)
        assert np.allclose(state[:, 0], run.time, rtol=0, atol=1e-9)  # MuJoCo sums dt, the result multiplies
        assert np.array_equal(state[:, 1 + plate.drive_qpos], run.displacement)
        hinges = 1 + np.asarray(plate.hinge_qpos)
        assert np.array_equal(state[:, hinges], run.hinge_angle[:, :len(hinges)])


@pytest.mark.parametrize("drive", [Drive(speed=0.03, stroke=0.2), Drive(speed=0.03, stroke=0.045, cycles=2)],
                         ids=["drag", "out-and-back"])
@pytest.mark.parametrize("changes", [{}, {"plate.stop": "limit"}, {"plate.kind": "rigid", "plate.rigid_as": "welds"}],
                         ids=["penalty stop", "limit stop", "welds"])
def test_rollout_states_equal_serial_runs(drive, changes):
    # Bit for bit: the same mj_step sequence, with the reversals' impulses applied between the strokes; a job's
    # solver warm start travels with it, so constrained models (limits, welds) match too.
    jobs = [(preset("paper").replace(**{**changes, "plate.damping": b}), drive) for b in (0.5, 2.5, 1.0)]
    _same_as_serial(jobs, batch.rollout_plates(jobs, workers=2))


def test_later_batches_reuse_models_and_match_serial_runs():
    # A sweep's second batch differs in stiffness and damping: it retunes the first batch's models, and a batch
    # larger than the last one copies them.
    drive = Drive(speed=0.03, stroke=0.045, cycles=1)
    with batch.PlateRollouts(2) as rollouts:
        first = [(preset("paper").replace(**{"plate.damping": b}), drive) for b in (0.5, 2.5)]
        rollouts(first)
        kept = [p.model for plates in rollouts._plates.values() for p in plates]
        later = [(preset("paper").replace(**{"plate.damping": b, "plate.stiffness": k}), drive)
                 for b, k in ((1.0, 0.1), (2.0, 0.4), (0.7, 0.3))]
        states = rollouts(later)
        reused = [p.model for plates in rollouts._plates.values() for p in plates]
    assert reused[:2] == kept[:2] and reused[2] is not kept[0]
    _same_as_serial(later, states)


@pytest.mark.parametrize("changes", [{"plate.damping": 0.3, "plate.stiffness": 0.05},
                                     {"plate.stop": "limit", "plate.damping": 2.0, "plate.stiffness": 1.0},
                                     {"plate.kind": "soft", "plate.segments": 5, "plate.damping": 0.0}])
def test_retuned_model_equals_a_fresh_compile(changes):
    # Every field of the model, not only those retune sets: nothing else may depend on the retuned keys.
    scene = preset("physical")
    source = build_plate(scene.replace(**{k: v for k, v in changes.items() if k.split(".")[1]
                                                 not in RETUNABLE}))
    plate = dataclasses.replace(source, model=mujoco.MjModel.__copy__(source.model))
    target = scene.replace(**changes)
    retune(plate, target.plate)
    fresh = build_plate(target).model
    assert retune_key(target) == retune_key(scene.replace(
        **{k: v for k, v in changes.items() if k.split(".")[1] not in RETUNABLE}))
    compared = 0
    for name in dir(fresh):
        value = getattr(fresh, name)
        if isinstance(value, np.ndarray) and not name.startswith("_"):
            assert np.array_equal(getattr(plate.model, name), value), name
            compared += 1
    assert compared > 100
    assert np.any(plate.model.dof_damping != source.model.dof_damping) or changes["plate.damping"] == \
        scene.plate.damping


def test_unstable_job_raises():
    drive = Drive(speed=0.03, stroke=0.045, cycles=1)
    scene = preset("physical").replace(**{"sim.method": "explicit", "plate.stop_stiffness": 1e9,
                                          "plate.segment_inertia": 1e-9})
    with pytest.raises(SimulationUnstable, match="job 1 went unstable .* MuJoCo: Nan"):
        batch.rollout_plates([(preset("paper"), drive), (scene, drive)], workers=2)


def _timer() -> int | None:
    timer = native._swap_timer(None)
    native._swap_timer(timer)
    return timer


def test_untimed_turns_mujocos_timer_off_and_back():
    before = _timer()
    assert before  # MuJoCo's Python bindings install one
    with native.untimed():
        assert _timer() is None
        with native.untimed():
            assert _timer() is None
        assert _timer() is None
    assert _timer() == before


def test_rollout_refuses_what_it_cannot_step():
    scene, drive = preset("paper"), Drive(speed=0.03, stroke=0.2)
    with pytest.raises(SceneError, match="same drive"):
        batch.rollout_plates([(scene, drive), (scene, Drive(speed=0.01, stroke=0.2))])
    with pytest.raises(SceneError, match="native"):
        batch.rollout_plates([(scene.replace(**{"sim.backend": "python"}), drive)])
    # the family of every bad argument: a job that is no (scene, drive) pair, threads that cannot be
    with pytest.raises(SceneError, match=r"every job is a \(finrft.Scene, finrft.Drive\) pair, got \('x'"):
        batch.rollout_plates([("x", drive)], workers=1)
    for workers in (0, -1, "2", 2.5, True):
        with pytest.raises(SceneError, match="workers: from 1 to 1024 threads"):
            batch.rollout_plates([(scene, drive)], workers=workers)


def test_rollout_jobs_with_other_laws_step_with_their_own():
    # A thread steps every job of a size on one MjData, whose plugin instance (law, coefficients, segments) is made
    # again for each job's model: each steps with its own law.
    drive = Drive(speed=0.03, stroke=0.045, cycles=1)
    jobs = [(preset("paper").replace(**changes), drive) for changes in (
        {}, {"rft.f_perp": 35000.0}, {"rft.law": "sandswim", "rft.c_s": 15000.0, "rft.c_f": 4400.0, "rft.gamma0": 0.4},
        {"plate.segments": 4, "plate.segment_length": 0.025})]
    for (scene, _), states in zip(jobs, batch.rollout_plates(jobs, workers=2)):
        run = simulate(scene, drive, estimate_error=False)
        plate = build_plate(scene)
        hinges = 1 + np.asarray(plate.hinge_qpos)
        assert np.array_equal(states[:, hinges], run.hinge_angle[:, :len(hinges)])
