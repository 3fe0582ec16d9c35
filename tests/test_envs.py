"""The Gymnasium environments (finrft.envs, the [gym] extra): every example passes gymnasium's checker, a scene's
gait played as actions swims as `finrft run` does, rewards are the run's figures, the vector environment's worlds
are the single environment's, and bad options are one line."""

import math

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium", reason="the environments need the [gym] extra: pip install "
                                                   "'finrft[gym]'")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import finrft  # noqa: E402
import finrft.envs as envs  # noqa: E402
from finrft.errors import SceneError  # noqa: E402
from finrft.experiments.user_model import example  # noqa: E402
from conftest import physics_run  # noqa: E402


@pytest.mark.parametrize("env_id", list(envs.EXAMPLE_IDS))
def test_every_example_environment_passes_the_checker(env_id):
    env = gymnasium.make(env_id).unwrapped
    check_env(env, skip_render_check=True)
    assert env.action_space.shape[0] > 0 and env.observation_space.shape[0] > 0


def test_an_environment_of_any_scene_observes_its_joints_and_sensors(tmp_path):
    (tmp_path / "arm.xml").write_text(
        '<mujoco><option gravity="0 0 -9.81"/><worldbody><body name="rod" pos="0 0 0.02">'
        '<joint name="hinge" type="hinge" axis="0 0 1"/><geom type="box" size="0.03 0.002 0.03" pos="0.03 0 0" '
        'mass="0.01"/></body></worldbody><actuator><motor name="motor" joint="hinge" ctrlrange="-0.01 0.01"/>'
        '</actuator><sensor><jointpos name="angle" joint="hinge"/></sensor></mujoco>')
    (tmp_path / "arm.toml").write_text('[model]\npath = "arm.xml"\nbodies = ["rod"]\n[sim]\nduration = 0.2\n')
    env = envs.make(str(tmp_path / "arm.toml"), reward="positive_power_W:min", control_dt=0.01)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (3,)  # qpos, qvel, the angle sensor
    obs, reward, *_ = env.step(np.array([1.0], np.float32))  # the motor's full 0.01 N m
    # the sensor as MuJoCo's step leaves it, read at the last step's start (dt earlier than qpos)
    assert obs[0] > 0 and obs[2] == pytest.approx(obs[0], rel=0.2) and reward <= 0
    only = envs.make(str(tmp_path / "arm.toml"), observation=["sensors"])
    assert only.observation_space.shape == (1,)


def test_the_scenes_gait_as_actions_swims_as_the_run_does():
    # the swimmer's [[control]] sines, sent every step (control_dt = sim.dt), ramp and all: the environment's
    # steps are the run's, so its mean reward over [1, 2] s is the run's forward speed
    scene = finrft.load_scene(example("sand_swimmer"), overrides={"sim.duration": 2.0}, cls=finrft.UserScene)
    env = envs.make(scene, control_dt=scene.sim.dt)
    env.reset(seed=0)
    rewards = []
    for k in range(env.world.steps):
        t = k * scene.sim.dt
        ctrl = [min(1, t / c.ramp) * c.amplitude * math.sin(2 * math.pi * c.frequency * t + c.phase)
                for c in scene.control]
        action = env.world.scene_action(t)
        assert action == pytest.approx(np.array(ctrl) / 1.2, abs=1e-6)  # the servos' ctrlrange is +-1.2 rad
        rewards.append(env.step(action)[1])
    run = physics_run(scene.replace(**{"sim.settle": 1.0}))
    assert np.mean(rewards[1000:]) == pytest.approx(run.summary()["com_velocity_m_s"][0], rel=0.02)
    assert np.mean(rewards[1000:]) > 0.03  # it swims forward


@pytest.mark.parametrize("reward", ["com_velocity_m_s.12", "com_velocity_m_s.01", "com_velocity_m_s.",
                                    "com_velocity_m_s", "com_speed_m_s.0", "speed"])
def test_a_reward_of_no_figure_is_refused_when_made(reward):
    # "12" and "01" passed a substring test: the first failed at the first step, the second read the y component
    with pytest.raises(SceneError, match="no figure"):
        envs.make("sand_swimmer", reward=reward)


def test_a_weighted_reward_is_the_sum_of_its_figures():
    env = envs.make("sand_swimmer", reward={"com_speed_m_s": 2.0, "positive_power_W": -0.5})
    env.reset(seed=0)
    env.action_space.seed(0)
    _, reward, _, _, info = env.step(env.action_space.sample())
    f = info["figures"]
    assert reward == pytest.approx(2 * f["com_speed_m_s"] - 0.5 * f["positive_power_W"])
    assert f["cost_of_transport"] == pytest.approx(
        f["positive_power_W"] / (env.world.mass * 9.81 * max(f["com_speed_m_s"], 1e-4)))


def test_the_vector_worlds_are_the_single_environments():
    vec = envs.make_vector("sand_swimmer", 3, threads=2, control_dt=0.02)
    single = [envs.make("sand_swimmer", control_dt=0.02) for _ in range(3)]
    obs, _ = vec.reset(seed=5)
    for i, env in enumerate(single):
        assert np.array_equal(env.reset(seed=5 + i)[0], obs[i])
    rng = np.random.default_rng(0)
    for _ in range(5):
        actions = rng.uniform(-1, 1, (3, 6)).astype(np.float32)
        obs, rewards, *_ = vec.step(actions)
        for i, env in enumerate(single):
            o, r, *_ = env.step(actions[i])
            assert np.array_equal(o, obs[i]) and r == rewards[i]
    vec.close()


@pytest.mark.parametrize("options, message", [
    ({"reward": "speed"}, "reward: no figure 'speed'"),
    ({"reward": "com_speed_m_s:most"}, "give FIGURE, FIGURE:max or FIGURE:min"),
    ({"observation": ["pixels"]}, "observation: give some of joints, sensors"),
    ({"overrides": {"sim.method": "rk45"}}, "sim.method"),
])
def test_bad_options_are_one_line(options, message):
    with pytest.raises(SceneError, match=message):
        envs.make("sand_swimmer", **options)


@pytest.mark.slow
def test_ppo_learns_to_swim_forward():
    # the example's training, a short budget: the reward of the last episodes beats that of the first
    pytest.importorskip("stable_baselines3", reason="PPO needs the rl extra: pip install 'finrft[rl]' (torch)")
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "scripts" / "train_swimmer.py"
    spec = importlib.util.spec_from_file_location("train_swimmer", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    curve, _ = module.train(steps=4096, worlds=2, seed=0)  # 108 s on the two shared cores
    first, last = curve[0][1], np.mean([r for _, r in curve[-3:]])
    assert last > first + 0.1  # 2.5 mm/s faster over a 40-step episode (measured: -0.24 to +0.22)


def test_the_two_fin_robots_gait_as_actions_swims_forward():
    # its servos' rate +-omega, stroke by stroke: the paper's gait, which swims along +y
    env = gymnasium.make("finrft/TwoFin-v0").unwrapped
    env.reset(seed=0)
    w = env.world
    rewards = [env.step(w.scene_action(k * w.control_dt))[1] for k in range(w.steps)]
    arm = env.data.qpos[w.robot.servo_qpos[0]]
    g = w.scene.gait
    assert g.theta2 - 1e-6 <= arm <= g.theta1 + 1e-6  # the servo's setpoint stays within the gait
    assert np.mean(rewards) > 1e-3  # mm/s forward
