"""N worlds of a robot scene as one Gymnasium vector environment stepped on MuJoCo Warp (`finrft.envs.make_vector(...,
backend="warp")`): the actions, observations, rewards and episodes of `finrft.envs.RobotVectorEnv`, its worlds'
steps all at once in `finrft.warp.WarpWorlds` instead of on threads of the native stepper."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping, Sequence

import gymnasium
import mujoco
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from ..envs import FORWARD, OBSERVATIONS, Reward, _world, reward_function
from ..errors import SceneError
from ..scene import UserScene
from . import METHODS, WarpWorlds


class WarpVectorEnv(VectorEnv):
    """``num_envs`` worlds of one robot scene (a `finrft.envs.World`: a TOML file, an example's name or a
    `UserScene`) on MuJoCo Warp, on ``device`` (None: Warp's default). Steps with the scene's method where Warp has
    it (explicit, implicit, newton), else newton. The scene's [[drive]] joints are not run here (SceneError).
    Observations, rewards and autoreset as `finrft.envs.RobotVectorEnv`'s; a world's figures are read after a
    forward pass at the interval's end (its actuators' power there)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, scene: str | Path | UserScene, num_envs: int, *, device: str | None = None,
                 reward: Reward = FORWARD, observation: Sequence[str] = OBSERVATIONS, control_dt: float = 0.05,
                 pieces: int | None = None, reset_noise: float = 0.0, overrides: Mapping[str, Any] | None = None
                 ) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise SceneError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        self.world = w = _world(scene, overrides, observation, control_dt, pieces)
        if not isinstance(w.scene, UserScene) or w.scene.drive:
            raise SceneError("the warp backend's environments run robot scenes without [[drive]] joints: use "
                             "backend='native'")
        from . import scene_worlds
        method = w.scene.sim.method if w.scene.sim.method in METHODS else "newton"
        self.worlds: WarpWorlds = scene_worlds(w.scene, num_envs, device=device, method=method)
        self.num_envs, self.reward, self.reset_noise = num_envs, reward_function(reward), reset_noise
        self.single_observation_space, self.single_action_space = w.observation_space, w.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(w.observation_space, num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(w.action_space, num_envs)
        self.counts = np.zeros(num_envs, int)
        self.ended = np.zeros(num_envs, bool)
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._scratch = mujoco.MjData(w.m)

    def _start(self, worlds: np.ndarray) -> None:
        """The worlds listed at the start of an episode (`World.reset` with each one's random stream)."""
        qpos, qvel, ctrl = self.worlds.qpos, self.worlds.qvel, self.worlds.d.ctrl.numpy().copy()
        for i in worlds:
            self.world.reset(self._scratch, self.rngs[i], self.reset_noise)
            qpos[i], qvel[i], ctrl[i] = self._scratch.qpos, self._scratch.qvel, self._scratch.ctrl
            self.counts[i], self.ended[i] = 0, False
        self.worlds.set_state(qpos, qvel)
        self.worlds.set_ctrl(ctrl)

    def _read(self) -> tuple[np.ndarray, np.ndarray, list[SimpleNamespace]]:
        """After a forward pass: every world's observation, centre of mass and what `World.figures` reads."""
        self.worlds.forward()
        d = self.worlds.d
        qpos, qvel = self.worlds.qpos, self.worlds.qvel
        parts = []
        if "joints" in self.world.observation:
            parts += [qpos[:, self.world.observed], qvel]
        if "sensors" in self.world.observation:
            parts.append(d.sensordata.numpy())
        force, velocity = d.actuator_force.numpy(), d.actuator_velocity.numpy()
        states = [SimpleNamespace(actuator_force=f, actuator_velocity=v) for f, v in zip(force, velocity)]
        return np.concatenate(parts, axis=1).astype(np.float64), d.subtree_com.numpy()[:, 0].astype(float), states

    def reset(self, *, seed: int | Sequence[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else list(seed)
            self.rngs = [np.random.default_rng(s) for s in seeds]
        self._start(np.arange(self.num_envs))
        observation, self.coms, _ = self._read()
        return observation, {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        w = self.world
        restart = self.ended.copy()
        if restart.any():
            self._start(np.flatnonzero(restart))
        start = self.worlds.d.ctrl.numpy().copy()
        a = np.clip(np.asarray(actions, float).reshape(self.num_envs, -1), -1.0, 1.0)
        target = (w.low + 0.5 * (a + 1) * (w.high - w.low))[:, :w.m.nu]
        target[restart] = start[restart]  # a world that resets this step starts from its reset
        qpos, qvel = self.worlds.qpos, self.worlds.qvel
        for k, n in enumerate(w.cuts):
            self.worlds.set_ctrl(target if k == len(w.cuts) - 1 else start + (target - start) * (k + 1) / len(w.cuts))
            self.worlds.step(int(n))
        # a world that resets this step is not stepped: it keeps its reset state
        now_qpos, now_qvel = self.worlds.qpos, self.worlds.qvel
        now_qpos[restart], now_qvel[restart] = qpos[restart], qvel[restart]
        self.worlds.set_state(now_qpos, now_qvel)
        observation, coms, states = self._read()
        rewards = np.zeros(self.num_envs)
        terminated, truncated = np.zeros(self.num_envs, bool), np.zeros(self.num_envs, bool)
        for i in np.flatnonzero(~restart):
            self.counts[i] += 1
            if not np.all(np.isfinite(observation[i])):
                observation[i], terminated[i] = np.nan_to_num(observation[i]), True
                continue
            rewards[i] = float(self.reward(w.figures(states[i], self.coms[i], coms[i])))
            truncated[i] = self.counts[i] >= w.steps
        self.coms = coms
        self.ended = terminated | truncated
        return observation, rewards, terminated, truncated, {}
