"""Train the sand-swimmer (finrft/SandSwimmer-v0) to swim forward from scratch with stable-baselines3's PPO, on
a vector environment of robot worlds stepped in native threads, and plot the learning curve (mean episode reward,
the forward speed in m/s averaged over the episode, against environment steps). Needs the rl extra:
``pip install 'finrft[rl]'`` (stable-baselines3 and torch).

    python scripts/train_swimmer.py [--steps 200000] [--worlds 4] [--seed 0] [--plot swimmer_ppo.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import finrft.envs as envs


def train(steps: int, worlds: int, seed: int, episode_s: float = 2.0,
          progress: bool = False) -> tuple[list[tuple[int, float]], float]:
    """PPO on ``worlds`` swimmers (episodes of ``episode_s`` seconds, control every 50 ms): the learning curve
    as (environment steps, mean reward of the episodes ended since the last point), and the wall time (s)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecMonitor
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv

    class Worlds(VecEnv):
        """finrft's threaded vector environment in stable-baselines3's interface (which predates gymnasium's)."""

        def __init__(self, vec: envs.RobotVectorEnv) -> None:
            self.vec = vec
            super().__init__(vec.num_envs, vec.single_observation_space, vec.single_action_space)
            self._actions = None

        def reset(self):
            return self.vec.reset(seed=seed)[0]

        def step_async(self, actions):
            self._actions = actions

        def step_wait(self):
            obs, rewards, terminated, truncated, _ = self.vec.step(self._actions)
            done = terminated | truncated
            infos = [{} for _ in range(self.num_envs)]
            for i in np.flatnonzero(done):  # stable-baselines3 resets at once: take the world's first observation
                infos[i]["terminal_observation"] = obs[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                obs[i] = self.vec.reset_world(i)
            return obs, rewards, done, infos

        def close(self):
            self.vec.close()

        def get_attr(self, name, indices=None):
            return [getattr(self.vec, name)] * self.num_envs

        def set_attr(self, name, value, indices=None):
            pass

        def env_method(self, name, *args, indices=None, **kwargs):
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * self.num_envs

        def seed(self, seed=None):
            return [seed] * self.num_envs

    vec = envs.make_vector("sand_swimmer", worlds, reset_noise=0.05, overrides={"sim.duration": episode_s})
    env = VecMonitor(Worlds(vec))
    curve: list[tuple[int, float]] = []

    class Curve(BaseCallback):
        def _on_rollout_end(self) -> None:
            rewards = [e["r"] for e in self.model.ep_info_buffer]
            if rewards:
                curve.append((self.num_timesteps, float(np.mean(rewards[-worlds:]))))
                if progress:
                    print(f"{self.num_timesteps:8d} steps, {time.perf_counter() - start:6.0f} s: mean episode reward "
                          f"{curve[-1][1]:+.4f}", flush=True)

        def _on_step(self) -> bool:
            return True

    torch.set_num_threads(1)  # the cores step the worlds; the small networks need no more
    # a policy's first actions near the servos' centre (std e^-1 of the range's half): full-range noise every
    # interval makes the swimmer thrash, which teaches nothing and costs many Newton iterations a step
    model = PPO("MlpPolicy", env, n_steps=max(64, 512 // worlds), batch_size=64, learning_rate=3e-4, gamma=0.98,
                seed=seed, verbose=0, device="cpu", policy_kwargs={"log_std_init": -1.0})
    start = time.perf_counter()
    model.learn(total_timesteps=steps, callback=Curve())
    env.close()
    return curve, time.perf_counter() - start


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=200_000, help="environment steps (control intervals) in all")
    p.add_argument("--worlds", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--plot", default="swimmer_ppo.png")
    args = p.parse_args()
    curve, wall = train(args.steps, args.worlds, args.seed, progress=True)
    steps_per_episode = 40  # 2 s at 50 ms
    print(f"trained in {wall:.0f} s; the last episodes' mean forward speed "
          f"{1e3 * np.mean([r for _, r in curve[-3:]]) / steps_per_episode:+.2f} mm/s")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot([n for n, _ in curve], [1e3 * r / steps_per_episode for _, r in curve])
    ax.set(xlabel="environment steps (50 ms each)", ylabel="mean forward speed (mm/s)",
           title="Sand-swimmer, PPO from scratch")
    fig.tight_layout()
    fig.savefig(args.plot, dpi=120)
    print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
