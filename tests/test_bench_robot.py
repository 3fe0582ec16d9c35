"""The robot benchmark: one gait's eta against a converged run of the same scene, computed in the same call."""

import numpy as np
import pytest

from finrft.studies import bench
from finrft.experiments.swim import RobotScene
from finrft.scene import preset


@pytest.mark.slow  # the bench's gait and its converged reference, end to end
def test_physical_gait_is_measured_against_a_converged_run():
    scene = preset("physical", RobotScene)
    out = bench.robot(scene, budget=2, workers=1, repeat=1, log=lambda text: None)
    assert out["gait_reference"] == f"adaptive-newton, tolerance {scene.sim.tolerance / 100:g}"
    assert out["gait_eta_error"] == pytest.approx(abs(out["gait_eta"] - out["gait_eta_reference"]))
    assert 0 < out["gait_eta_error"] < 5e-4  # the preset's target: 0.05 points of eta
    # a fixed step's reference is the same method at a tenth of the step
    fixed = bench._converged(scene.replace(**{"sim.method": "newton", "sim.dt": 3e-4}))
    assert fixed[0].sim.dt == pytest.approx(3e-5) and fixed[1] == "newton, dt 3e-05 s"


def test_a_robots_force_is_held_to_its_worst_component():
    # The wheel's force is mostly its load, which any stable run carries: its drawbar pull 2 % off is 0.05 % of the
    # norm. A component below 1 % of the whole (Fy at no slip angle) is not held; a speed is relative alone.
    reference = np.array([0.5, 1e-24, 21.0])
    assert bench._relative(np.array([0.49, 3e-24, 21.0]), reference) == pytest.approx(0.02)
    assert bench._relative(np.array([0.5, 0.0, 21.21]), reference) == pytest.approx(0.01)
    assert bench._relative(np.array([0.0463]), np.array([0.0462])) == pytest.approx(0.1 / 46.2)


def test_step_costs_compare_one_step_of_each_from_the_same_state():
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    scene = load_scene(example("wheel_rig"), cls=UserScene)
    elements = bench._elements(scene)
    costs = bench._step_costs(scene, 5e-4, 0.0, elements)
    # a newton step takes the wrench, its slope and Newton's iterates: more calls of the law than mj_step's one
    assert costs["implicit_over_explicit_step"] > 1
    assert costs["implicit_over_explicit_step"] == pytest.approx(costs["implicit_step_us"] / costs["explicit_step_us"])
    for kind in ("implicit", "explicit"):
        assert costs[f"{kind}_ns_per_element_step"] == pytest.approx(1e3 * costs[f"{kind}_step_us"] / elements)


def test_each_explicit_step_timed_starts_from_one_of_the_runs_states():
    # The wheel rig's explicit step at its own 62.5 ms throws the wheel out of the sand within three steps: steps
    # taken on from there would be timed in the air. Each timed step starts from one of the run's states, in turn.
    import mujoco
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    scene = load_scene(example("wheel_rig"), cls=UserScene)
    implicit, explicit = bench.step_start(scene, scene.sim.dt)
    m, d, states = explicit.held
    assert len(states) == bench.STEP_COST_STATES
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    own = mujoco.MjData(m)
    for steps in (1, bench.STEP_COST_STATES + 3):
        mujoco.mj_setState(m, own, states[(steps - 1) % len(states)], spec)
        mujoco.mj_step(m, own)
        explicit(steps)
        np.testing.assert_array_equal(d.qpos, own.qpos)
        np.testing.assert_array_equal(d.qvel, own.qvel)
    mujoco.mj_setState(m, own, states[0], spec)
    mujoco.mj_step(m, own)
    assert own.qpos[1] < 0  # still in the sand after one step: 27 mm deep at the start
    mujoco.mj_step(m, own, 3)
    assert own.qpos[1] > 0.1  # three steps on it has left it
    # the run's states: the wheel rolls on between them (0.32 rad/s, 1 s over the ten)
    assert np.ptp([s[1 + m.jnt_qposadr[m.joint("axle").id]] for s in states]) > 0.2


def test_the_states_steps_are_timed_from_carry_their_own_instants_controls():
    # A step from one instant with a sine servo's ctrl of another is a violent step: the sandfish's newton-midpoint
    # step cost 100 explicit steps so. Each state holds the ctrl of its own time: 60 deg sin(2 pi t + phase_j) on
    # the sand-swimmer's joints j, past its 0.5 s ramp-in.
    import math
    import mujoco
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    scene = load_scene(example("sand_swimmer"), cls=UserScene)
    implicit, explicit = bench.step_start(scene, scene.sim.dt)
    m, d, states = explicit.held
    own = mujoco.MjData(m)
    for state in states:
        mujoco.mj_setState(m, own, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        assert own.time >= 0.5
        wave = [math.radians(60) * math.sin(2 * math.pi * own.time - math.pi / 3 * (j + 1)) for j in range(m.nu)]
        np.testing.assert_allclose(own.ctrl, wave, atol=1e-6)


def test_step_counts_names_an_unknown_robot_in_one_line_and_exits_2():
    import subprocess
    import sys
    from pathlib import Path
    script = Path(__file__).parents[1] / "scripts" / "step_counts.py"
    done = subprocess.run([sys.executable, str(script), "no_such_robot"], capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "no_such_robot" in done.stderr and "hexapod" in done.stderr
