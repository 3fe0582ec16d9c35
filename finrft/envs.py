"""Gymnasium environments of robot scenes (``pip install 'finrft[gym]'``): any `UserScene` (a TOML file of
``finrft run``) as a `RobotEnv`, and N worlds of one scene stepped in native threads as a `RobotVectorEnv`,
or all at once on MuJoCo Warp as a `WarpVectorEnv` (the warp extra).

An action sets, each control interval (``control_dt``), every actuator's ctrl and the speed of every [[drive]] of
constant speed without reversals (stroke 0, a speed other than 0): in [-1, 1], mapped onto the actuator's
ctrlrange (an actuator without one: +-2 x the largest ctrl its [[control]] entry asks, else +-1) and onto +-2 x the
drive's speed. The scene's [[control]] entries are what the policy replaces; they only size the action.
Observations are the joints' positions (the free joints' horizontal position left out, so that a policy does not
depend on where the robot is) and velocities, and the model's MJCF <sensor> readings (``observation``). Rewards
are the run's figures over the control interval, in the JSON's names and units (`FIGURES`): one figure
maximised (``"com_velocity_m_s.0"``) or minimised (``"cost_of_transport:min"``), a weighted sum (``{"com_speed_m_s":
1, "positive_power_W": -0.1}``) or a callable of the figures. An episode lasts the scene's sim.duration; a step
that fails (the state not finite) ends it (``terminated``, with ``info["failure"]``).

Steps are the scene's own method (``sim.method``; ``auto``: newton), in the native plugin's C stepper, called
through ctypes, which releases the GIL: `RobotVectorEnv` steps its worlds on threads, in parallel. Importing this
module registers the example robots (`EXAMPLE_IDS`) with gymnasium: ``gymnasium.make("finrft/SandSwimmer-v0")``.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable, Mapping, Sequence

try:
    import gymnasium
    from gymnasium import spaces
    from gymnasium.vector import AutoresetMode, VectorEnv
except ImportError as exc:  # the extra is optional: the core installs and runs without it
    raise ImportError("finrft.envs needs gymnasium: pip install 'finrft[gym]'") from exc

import mujoco
import numpy as np

from . import methods
from .errors import SceneError
from .experiments.user_model import EXAMPLES, STILL_SPEED, UserModel, control_reach, control_value, example
from .integrate import stepper
from .experiments.swim import RobotScene, build_robot
from .scene import UserScene, load_scene, preset
from .stepping import jump_velocities

# The figures a reward may name, each over one control interval, in the units of the run's JSON: the centre of
# mass's mean velocity (a component: .0, .1, .2) and horizontal speed, the actuators' mechanical power and its
# positive part (at the interval's end), and the cost of transport P+ / (m g v) (v at least STILL_SPEED).
FIGURES = ("com_velocity_m_s", "com_speed_m_s", "actuator_power_W", "positive_power_W", "cost_of_transport")
OBSERVATIONS = ("joints", "sensors")
# The default: the robot's speed along +x.
FORWARD = "com_velocity_m_s.0"

Reward = str | Mapping[str, float] | Callable[[dict[str, Any]], float]


def _figure(values: dict[str, Any], key: str) -> float:
    name, _, index = key.partition(".")
    value = values[name]
    return float(value[int(index)] if index else value)


def reward_function(reward: Reward) -> Callable[[dict[str, Any]], float]:
    """The reward of a step's figures: ``FIGURE`` or ``FIGURE:max`` (the figure), ``FIGURE:min`` (minus it),
    ``{FIGURE: weight, ...}`` (the weighted sum), or a callable of the figures; SceneError naming a bad one."""
    if callable(reward):
        return reward
    if isinstance(reward, str):
        key, _, sense = reward.partition(":")
        if sense not in ("", "max", "min"):
            raise SceneError(f"reward {reward!r}: give FIGURE, FIGURE:max or FIGURE:min")
        weights = {key: -1.0 if sense == "min" else 1.0}
    elif isinstance(reward, Mapping):
        weights = dict(reward)
    else:
        raise SceneError(f"reward must be a figure's name, a mapping of figures to weights or a callable, got "
                         f"{type(reward).__name__}")
    for key, weight in weights.items():
        name, dot, index = str(key).partition(".")
        vector = name == "com_velocity_m_s"  # a reward is one number: the velocity by its component
        if name not in FIGURES or (index not in ("0", "1", "2") if vector else dot):
            raise SceneError(f"reward: no figure {key!r} (the figures: {', '.join(FIGURES)}; com_velocity_m_s.N, "
                             f"N = 0, 1, 2, a component)")
        if not isinstance(weight, (int, float)) or not math.isfinite(weight):
            raise SceneError(f"reward: the weight of {key!r} must be a finite number, got {weight!r}")
    return lambda values: sum(w * _figure(values, k) for k, w in weights.items())


class World:
    """A scene's compiled model, shared by the MjData of every copy: how an action is applied, a state observed
    and a control interval's figures measured."""

    def __init__(self, scene: UserScene, observation: Sequence[str], control_dt: float, pieces: int | None = None) -> None:
        if methods.chooses(scene.sim.method):
            scene = scene.replace(**{"sim.method": "newton"})
        if methods.get(scene.sim.method).adaptive:
            raise SceneError(f"sim.method = {scene.sim.method!r}: an environment steps a fixed dt; give newton, "
                             f"newton-midpoint, implicit or explicit")
        self.experiment = UserModel.of(scene)
        built = self.experiment.build(scene)
        if built.backend != "native":
            raise SceneError("an environment steps in the native plugin: the plugin is not loaded (finrft drag "
                             "--json says why); sim.backend = 'native'")
        self.built, m = built, built.model
        self._timing(scene, m, observation, control_dt, pieces, scene.duration)
        for i, j in enumerate(scene.drive):
            if j.profile != "constant" or j.stroke > 0:
                raise SceneError(f"drive.{i} ({j.joint}): an environment holds constant drives without reversals "
                                 f"(profile constant, stroke 0) only; a policy sets their speed")
        self.dofs, self.qpos = np.asarray(built.drive_dofs, int), np.asarray(built.drive_qpos, int)
        self.commanded = [i for i, j in enumerate(scene.drive) if j.speed != 0]
        reach = {c.actuator: control_reach(c, t) for c, t in zip(scene.control, self.experiment.tables)}
        low, high = [], []
        for a in range(m.nu):
            if m.actuator_ctrllimited[a]:
                lo, hi = m.actuator_ctrlrange[a]
            else:
                half = 2 * reach.get(self.experiment.actuators[a], 0.0) or 1.0
                lo, hi = -half, half
            low.append(lo)
            high.append(hi)
        for i in self.commanded:
            low.append(-2 * abs(scene.drive[i].speed))
            high.append(2 * abs(scene.drive[i].speed))
        self.low, self.high = np.array(low, float), np.array(high, float)
        # the observed coordinates: every qpos but a free joint's x and y
        free = [int(m.jnt_qposadr[j]) + k for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
                for k in (0, 1)]
        self._spaces(np.setdiff1d(np.arange(m.nq), free))

    def _timing(self, scene: Any, m: mujoco.MjModel, observation: Sequence[str], control_dt: float,
                pieces: int | None, duration: float) -> None:
        """The scene, the model, what is observed, and the control intervals: their steps, their ctrl's pieces
        (`advance`) and an episode's intervals; SceneError naming a bad option."""
        bad = [o for o in observation if o not in OBSERVATIONS]
        if bad or not observation:
            raise SceneError(f"observation: give some of {', '.join(OBSERVATIONS)}, got {list(observation)}")
        if pieces is not None and (not isinstance(pieces, int) or pieces < 1):
            raise SceneError(f"pieces must be a whole number >= 1 or None (one a step), got {pieces!r}")
        self.scene, self.observation, self.m, self.dt = scene, tuple(observation), m, scene.sim.dt
        self.substeps = max(1, round(control_dt / self.dt))
        self.control_dt = self.substeps * self.dt
        self.steps = max(1, round(duration / self.control_dt))
        self.pieces = self.substeps if pieces is None else min(pieces, self.substeps)
        # the steps of each piece of a control interval, as whole steps
        self.cuts = np.diff(np.linspace(0, self.substeps, self.pieces + 1).round().astype(int))

    def _spaces(self, observed: np.ndarray) -> None:
        """The spaces, for the observed qpos (`low` and `high` set), and the weight the cost of transport needs."""
        m = self.m
        self.observed = observed
        size = (len(observed) + m.nv if "joints" in self.observation else 0) + \
            (m.nsensordata if "sensors" in self.observation else 0)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, (len(self.low),), np.float32)
        self.mass, self.gravity = float(m.body_mass.sum()), float(np.linalg.norm(m.opt.gravity))

    def scene_action(self, t: float) -> np.ndarray:
        """The action that plays the scene's own open-loop [[control]] entries at time t (the others, and the
        commanded drives, at the middle of their range): the scene's gait, as a baseline for a policy."""
        value = 0.5 * (self.low + self.high)
        for c, table in zip(self.scene.control, self.experiment.tables):
            if c.kind in ("constant", "sine", "table"):
                value[self.experiment.actuators.index(c.actuator)] = control_value(c, table, t)
        return np.clip(2 * (value - self.low) / (self.high - self.low) - 1, -1, 1).astype(np.float32)

    def stepper(self) -> Callable[[mujoco.MjData, int], int]:
        """A stepper of its own for one MjData (its step counts are its own)."""
        return stepper(self.m, self.scene.sim, "native", (), self.built.attached)

    def reset(self, d: mujoco.MjData, rng: np.random.Generator, noise: float) -> None:
        """The start of an episode: the keyframe (or the model's rest pose), each drive at its start with its
        speed, the joints' positions off by up to ``noise`` (m or rad; not the free joints' or the drives')."""
        m = self.m
        mujoco.mj_resetData(m, d)
        if self.scene.model.keyframe:
            key = m.key(self.scene.model.keyframe)
            d.qpos[:], d.qvel[:], d.act[:] = key.qpos, key.qvel, key.act
        if noise:
            hinged = [int(m.jnt_qposadr[j]) for j in range(m.njnt)
                      if m.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)
                      and int(m.jnt_qposadr[j]) not in self.qpos]
            d.qpos[hinged] += rng.uniform(-noise, noise, len(hinged))
        for i, j in enumerate(self.scene.drive):
            d.qpos[self.qpos[i]], d.qvel[self.dofs[i]] = j.start, j.speed
        mujoco.mj_forward(m, d)

    def act(self, d: mujoco.MjData, action: np.ndarray) -> None:
        """An action in [-1, 1] as the actuators' ctrl and the commanded drives' speeds (a drive's change of speed
        an impulse, as at a reversal of a run's drive)."""
        a = np.clip(np.asarray(action, float).ravel(), -1.0, 1.0)
        value = self.low + 0.5 * (a + 1) * (self.high - self.low)
        d.ctrl[:] = value[:self.m.nu]
        if self.commanded:
            jump = np.zeros(len(self.dofs))
            jump[self.commanded] = value[self.m.nu:] - d.qvel[self.dofs[self.commanded]]
            if np.any(jump):
                jump_velocities(self.m, d, self.dofs, self.built.armature, jump)

    def advance(self, d: mujoco.MjData, step: Callable[[mujoco.MjData, int], int], start: np.ndarray) -> int:
        """A control interval of d: its ctrl goes from ``start`` (the last interval's) to the action's (`act`, in
        d.ctrl) in ``pieces`` equal pieces (by default one a step): a servo whose target jumps each interval flings
        light links (the sand-swimmer's centre of mass at a metre a second under random actions), and Newton's
        method of the implicit step failed on the swimmer's first step in 5 of 12 random actions at 10 pieces an
        interval (none in 72 at one a step). The first failure code of the stepper, or 0."""
        target = d.ctrl.copy()
        for k, n in enumerate(self.cuts):
            d.ctrl[:] = target if k == len(self.cuts) - 1 else start + (target - start) * (k + 1) / len(self.cuts)
            failure = step(d, int(n))
            if failure:
                return failure
        return 0

    def com(self, d: mujoco.MjData) -> np.ndarray:
        """The centre of mass of the state in d (its kinematics only)."""
        mujoco.mj_kinematics(self.m, d)
        mujoco.mj_comPos(self.m, d)
        return d.subtree_com[0].copy()

    def observe(self, d: mujoco.MjData) -> np.ndarray:
        parts = []
        if "joints" in self.observation:
            parts += [d.qpos[self.observed], d.qvel]
        if "sensors" in self.observation:
            parts.append(d.sensordata)
        return np.concatenate(parts).astype(np.float64)

    def figures(self, d: mujoco.MjData, before: np.ndarray, after: np.ndarray) -> dict[str, Any]:
        """A control interval's figures (`FIGURES`), from the centre of mass before and after it and the state at
        its end."""
        velocity = (after - before) / self.control_dt
        speed = float(np.hypot(*velocity[:2]))
        power = d.actuator_force * d.actuator_velocity
        positive = float(np.maximum(power, 0).sum())
        weight = self.mass * self.gravity
        return {"com_velocity_m_s": velocity.tolist(), "com_speed_m_s": speed,
                "actuator_power_W": float(power.sum()), "positive_power_W": positive,
                "cost_of_transport": positive / (weight * max(speed, STILL_SPEED)) if weight else 0.0}


class TwoFinWorld(World):
    """The paper's two-fin robot (`finrft.experiments.swim`, a `RobotScene`) as a world: its arms on position
    servos (``robot.servo = "position"``, integrated-velocity actuators whose setpoint stays within the gait's
    theta2..theta1), the action each servo's rate (+-2 x the gait's omega), an episode ``cycles`` of the gait's flap
    cycles; the body swims along +y (its reward ``com_velocity_m_s.1``)."""

    def __init__(self, scene: RobotScene, observation: Sequence[str], control_dt: float, pieces: int | None = None,
                 cycles: int = 4) -> None:
        if methods.chooses(scene.sim.method) or methods.get(scene.sim.method).adaptive:
            scene = scene.replace(**{"sim.method": "newton"})
        if scene.robot.servo != "position":
            scene = scene.replace(**{"robot.servo": "position"})
        if scene.body.drag_law != "velocity":
            raise SceneError("body.drag_law = 'stroke' follows the gait's strokes, which a policy sets: give "
                             "body.drag_law = 'velocity'")
        self.robot = robot = build_robot(scene)
        if robot.backend != "native":
            raise SceneError("an environment steps in the native plugin: the plugin is not loaded (finrft drag "
                             "--json says why); sim.backend = 'native'")
        m, g = robot.model, scene.gait
        self._timing(scene, m, observation, control_dt, pieces, cycles * 2 * (g.theta1 - g.theta2) / g.omega)
        self.dofs = self.qpos = np.zeros(0, int)
        self.commanded: list[int] = []
        self.high = np.full(m.nu, 2 * g.omega)
        self.low = -self.high
        self._spaces(np.arange(m.nq))

    def scene_action(self, t: float) -> np.ndarray:
        """The gait: each servo's rate +omega in the recovery strokes, -omega in the power strokes."""
        g = self.scene.gait
        k = int(t * g.omega / (g.theta1 - g.theta2) + 1e-9)
        return np.full(self.m.nu, 0.5 if k % 2 == 0 else -0.5, np.float32)

    def stepper(self) -> Callable[[mujoco.MjData, int], int]:
        return stepper(self.m, self.scene.sim, "native", self.robot.groups)

    def reset(self, d: mujoco.MjData, rng: np.random.Generator, noise: float) -> None:
        """The swim's start: at rest, the arms at theta2 (their servos' setpoints too; the fins' hinges off by up
        to ``noise`` rad)."""
        mujoco.mj_resetData(self.m, d)
        d.qpos[self.robot.servo_qpos] = self.scene.gait.theta2
        d.act[:] = self.scene.gait.theta2
        hinges = self.robot.fin_hinge_qpos.ravel()
        if noise and hinges.size:
            d.qpos[hinges] += rng.uniform(-noise, noise, hinges.size)
        mujoco.mj_forward(self.m, d)


def _world(scene: str | Path | UserScene | RobotScene, overrides: Mapping[str, Any] | None,
           observation: Sequence[str], control_dt: float, pieces: int) -> World:
    """The world of a robot scene: a `RobotScene` (or "two_fin", the physical preset) as a `TwoFinWorld`, any
    other scene (a TOML file, an example's name, a `UserScene`) as a `World`."""
    if isinstance(scene, str) and scene == TWO_FIN:
        scene = preset("physical", RobotScene)
    if isinstance(scene, RobotScene):
        return TwoFinWorld(scene.replace(**dict(overrides or {})), observation, control_dt, pieces)
    if isinstance(scene, str) and scene in EXAMPLES:
        scene = example(scene)
    if isinstance(scene, UserScene):
        scene = scene.replace(**dict(overrides or {}))
    else:
        scene = load_scene(scene, overrides=overrides, cls=UserScene)
    return World(scene, observation, control_dt, pieces)


# The paper's two-fin robot, by name (its physical preset).
TWO_FIN = "two_fin"


class RobotEnv(gymnasium.Env):
    """A robot scene as a Gymnasium environment (the module's docstring says what it observes, takes and
    rewards). ``scene``: a TOML file, an example's name (`EXAMPLES`) or a `UserScene`; ``overrides``: dotted scene
    keys; ``reward``: `reward_function`'s; ``observation``: some of `OBSERVATIONS`; ``control_dt``: the control
    interval (s, whole steps of sim.dt); ``pieces``: the ctrl's linear pieces over an interval, from the last
    action's to this one's (`World.advance`; None: one a step; 1: held, a step change); ``reset_noise``: the joints' start off by up
    to this (m or rad)."""

    metadata = {"render_modes": []}

    def __init__(self, scene: str | Path | UserScene, *, reward: Reward = FORWARD,
                 observation: Sequence[str] = OBSERVATIONS, control_dt: float = 0.05, pieces: int | None = None,
                 reset_noise: float = 0.0, overrides: Mapping[str, Any] | None = None) -> None:
        self.world = _world(scene, overrides, observation, control_dt, pieces)
        self.reward = reward_function(reward)
        self.observation_space, self.action_space = self.world.observation_space, self.world.action_space
        self.reset_noise = reset_noise
        self.data = mujoco.MjData(self.world.m)
        self._step = self.world.stepper()
        self._count = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.world.reset(self.data, self.np_random, self.reset_noise)
        self._count, self._com = 0, self.world.com(self.data)
        return self.world.observe(self.data), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        w, d = self.world, self.data
        start = d.ctrl.copy()
        w.act(d, action)
        failure = w.advance(d, self._step, start)
        self._count += 1
        *outcome, self._com = _outcome(w, d, self._com, failure, self._count, self.reward)
        return tuple(outcome)


def _outcome(w: World, d: mujoco.MjData, before: np.ndarray, failure: int, count: int,
             reward: Callable[[dict[str, Any]], float]) -> tuple[np.ndarray, float, bool, bool, dict[str, Any],
                                                                 np.ndarray]:
    """A world's observation, reward, terminated, truncated and info after a control interval, and its centre
    of mass (the next interval's start)."""
    observation = w.observe(d)
    if failure or not np.all(np.isfinite(observation)):
        return np.nan_to_num(observation), 0.0, True, False, {"failure": f"the step failed at t = {d.time:.4g} s "
                                                                         f"(code {failure})"}, before
    after = w.com(d)
    values = w.figures(d, before, after)
    return observation, float(reward(values)), False, count >= w.steps, {"figures": values}, after


class RobotVectorEnv(VectorEnv):
    """N worlds of one robot scene, stepped on ``threads`` threads (default: one per core, at most N): each
    world's steps run in the native C stepper with the GIL released. Autoreset is gymnasium's next-step mode (a
    world that ended resets at the next step). Arguments as `RobotEnv`'s; ``seed`` of `reset` seeds world i with
    seed + i."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, scene: str | Path | UserScene, num_envs: int, *, threads: int | None = None,
                 reward: Reward = FORWARD, observation: Sequence[str] = OBSERVATIONS, control_dt: float = 0.05,
                 pieces: int | None = None, reset_noise: float = 0.0, overrides: Mapping[str, Any] | None = None) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise SceneError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        self.world = w = _world(scene, overrides, observation, control_dt, pieces)
        self.num_envs, self.reward, self.reset_noise = num_envs, reward_function(reward), reset_noise
        self.single_observation_space, self.single_action_space = w.observation_space, w.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(w.observation_space, num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(w.action_space, num_envs)
        self.datas = [mujoco.MjData(w.m) for _ in range(num_envs)]
        self.steppers = [w.stepper() for _ in range(num_envs)]
        self.counts = np.zeros(num_envs, int)
        self.ended = np.zeros(num_envs, bool)
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        self.threads = min(num_envs, threads or len(_cores()))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        # contiguous blocks of worlds, one per thread: one task each per step
        self._blocks = [b for b in np.array_split(np.arange(num_envs), self.threads) if len(b)]

    def reset(self, *, seed: int | Sequence[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else list(seed)
            self.rngs = [np.random.default_rng(s) for s in seeds]
        for i, d in enumerate(self.datas):
            self.world.reset(d, self.rngs[i], self.reset_noise)
        self.counts[:], self.ended[:] = 0, False
        self.coms = [self.world.com(d) for d in self.datas]
        return np.stack([self.world.observe(d) for d in self.datas]), {}

    def reset_world(self, i: int) -> np.ndarray:
        """World i at the start of a new episode (its own random stream): its first observation."""
        self.world.reset(self.datas[i], self.rngs[i], self.reset_noise)
        self.counts[i], self.coms[i], self.ended[i] = 0, self.world.com(self.datas[i]), False
        return self.world.observe(self.datas[i])

    def advance(self, starts: Sequence[np.ndarray], skip: np.ndarray) -> list[int]:
        """A control interval of every world but those ``skip`` marks (`World.advance`, each from its ctrl in
        ``starts``) on the threads: the failure code of each (0: none)."""
        codes = [0] * self.num_envs

        def block(worlds: np.ndarray) -> None:
            for i in worlds:
                if not skip[i]:
                    codes[i] = self.world.advance(self.datas[i], self.steppers[i], starts[i])
        if self._pool is None:
            for worlds in self._blocks:
                block(worlds)
        else:
            list(self._pool.map(block, self._blocks))
        return codes

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        w = self.world
        restart = self.ended.copy()
        starts = [d.ctrl.copy() for d in self.datas]
        for i, d in enumerate(self.datas):
            if restart[i]:
                self.reset_world(i)
            else:
                w.act(d, actions[i])
        codes = self.advance(starts, restart)  # a world that resets this step is not stepped
        obs = np.zeros((self.num_envs, *w.observation_space.shape))
        rewards, terminated, truncated = np.zeros(self.num_envs), np.zeros(self.num_envs, bool), \
            np.zeros(self.num_envs, bool)
        for i, d in enumerate(self.datas):
            if restart[i]:
                obs[i] = w.observe(d)
                continue
            self.counts[i] += 1
            obs[i], rewards[i], terminated[i], truncated[i], _, self.coms[i] = _outcome(
                w, d, self.coms[i], codes[i], self.counts[i], self.reward)
        self.ended = terminated | truncated
        return obs, rewards, terminated, truncated, {}

    def close_extras(self, **kwargs: Any) -> None:
        if self._pool is not None:
            self._pool.shutdown()


class WarpVectorEnv(VectorEnv):
    """``num_envs`` worlds of one robot scene (a `World`: a TOML file, an example's name or a
    `UserScene`) on MuJoCo Warp, on ``device`` (None: Warp's default). Steps with the scene's method where Warp has
    it (explicit, implicit, newton), else newton. The scene's [[drive]] joints are not run here (SceneError).
    Observations, rewards and autoreset as `RobotVectorEnv`'s; a world's figures are read after a
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
        from .warp import METHODS, scene_worlds  # the warp extra, only when this backend is asked for
        method = w.scene.sim.method if w.scene.sim.method in METHODS else "newton"
        self.worlds = scene_worlds(w.scene, num_envs, device=device, method=method)
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


def _cores() -> set[int]:
    return os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set(range(os.cpu_count() or 1))


def make(scene: str | Path | UserScene, **options: Any) -> RobotEnv:
    """A robot scene (a TOML file, an example's name or a `UserScene`) as a Gymnasium environment: `RobotEnv`'s
    options (reward, observation, control_dt, reset_noise, overrides)."""
    return RobotEnv(scene, **options)


def make_vector(scene: str | Path | UserScene, num_envs: int, backend: str = "native", **options: Any) -> VectorEnv:
    """``num_envs`` worlds of a robot scene: stepped on threads of the native stepper (`RobotVectorEnv`), or with
    ``backend="warp"`` all at once on MuJoCo Warp (`WarpVectorEnv`, the warp extra; its option
    ``device`` instead of ``threads``)."""
    if backend == "warp":
        return WarpVectorEnv(scene, num_envs, **options)
    if backend != "native":
        raise SceneError(f"backend must be 'native' or 'warp', got {backend!r}")
    return RobotVectorEnv(scene, num_envs, **options)


# The example robots as registered environments: their id, the example's TOML scene, and the options.
EXAMPLE_IDS = {"finrft/SandSwimmer-v0": "sand_swimmer", "finrft/Hexapod-v0": "hexapod",
               "finrft/WheelRig-v0": "wheel_rig", "finrft/TwoFin-v0": TWO_FIN}


def _register() -> None:
    for env_id, name in EXAMPLE_IDS.items():
        if env_id not in gymnasium.registry:
            options = {"reward": "com_velocity_m_s.1"} if name == TWO_FIN else {}  # it swims along +y
            gymnasium.register(env_id, entry_point="finrft.envs:RobotEnv", kwargs={"scene": name, **options},
                               vector_entry_point="finrft.envs:RobotVectorEnv", disable_env_checker=True)


_register()
