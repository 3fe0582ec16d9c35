"""The Warp backend (finrft.warp) against the native plugin: the same per-body forces at the native runs' own states
over 1 s of each example robot, in every world, worlds of other controls and media differing as they should; and
MuJoCo Warp's float32 step with the laws as its passive callback following MuJoCo's own step. Runs on Warp's CPU
device; its kernels compile once into ~/.cache/warp."""

from __future__ import annotations

import dataclasses
import json
import functools

import mujoco
import numpy as np
import pytest

pytest.importorskip("warp", reason="the warp extra is not installed (pip install 'finrft[warp]')")
pytest.importorskip("mujoco_warp", reason="the warp extra is not installed (pip install 'finrft[warp]')")

import finrft.warp as fw  # noqa: E402
from finrft.attach import attach  # noqa: E402
from finrft.errors import SceneError  # noqa: E402
from finrft.experiments.attached_model import build_attached, scene_spec  # noqa: E402
from finrft.experiments.user_model import control_value, example  # noqa: E402
from finrft.scene import UserScene, load_scene  # noqa: E402

EXAMPLES = ("sand_swimmer", "hexapod", "wheel_rig")
DT, SECONDS, EVERY = 1e-3, 1.0, 20  # the native runs: 1 s at 1 ms, a sample every 20 ms


@functools.cache
def _scene(name: str) -> UserScene:
    return load_scene(example(name), cls=UserScene)


def _built(name: str, backend: str):
    scene = _scene(name)
    sim = dataclasses.replace(scene.sim, backend=backend, dt=DT, integrator="implicitfast")
    return build_attached(scene_spec(scene), [j.joint for j in scene.drive], scene.model.bodies, scene.medium, sim,
                          scene.model.geoms)


@functools.cache
def native_run(name: str, amplitude: float) -> tuple:
    """MuJoCo's step with the native plugin (its force explicit) for 1 s from the scene's start, the controls
    scaled by ``amplitude`` and the drives' joints held at their speeds: each sample's attached bodies' states and
    the plugin's own wrenches."""
    scene, built = _scene(name), _built(name, "native")
    m, d = built.model, mujoco.MjData(built.model)
    if scene.model.keyframe:
        mujoco.mj_resetDataKeyframe(m, d, m.key(scene.model.keyframe).id)
    actuators = [m.actuator(c.actuator).id for c in scene.control]
    bodies = [s.body for s in built.attached.surfaces]
    read = built.attached.wrenches(m)
    states, wrenches = [], []
    for step in range(int(round(SECONDS / DT))):
        for a, c in zip(actuators, scene.control):
            d.ctrl[a] = amplitude * control_value(c, None, d.time)
        for dof, j in zip(built.drive_dofs, scene.drive):
            d.qvel[dof] = amplitude * j.speed
        if step % EVERY == 0:
            mujoco.mj_forward(m, d)
            states.append(fw.body_state(m, d, bodies))
            wrenches.append(read(d))
        mujoco.mj_step(m, d)
    assert np.all(np.isfinite(d.qpos)), f"{name}: the native run diverged"
    return states, np.array(wrenches)


@functools.cache
def warp_worlds(name: str) -> fw.WarpWorlds:
    built = _built(name, "warp")
    return fw.WarpWorlds(built.model, built.attached, worlds=4, device="cpu")


def _scaled_medium(worlds: fw.WarpWorlds, scale: np.ndarray) -> None:
    """Each world's medium stronger by ``scale``: li2013's zeta, rft3d's density (its xi_n is linear in it)."""
    key = "zeta" if worlds.attached.law == "li2013" else "rho_c"
    worlds.set_medium(**{key: scale * worlds.attached.parameters[key]})


@pytest.mark.parametrize("name", EXAMPLES)
def test_forces_agree_with_the_native_plugin_in_every_world(name):
    # worlds 0, 1: the scene's controls in the medium and in one half as strong; 2, 3: the controls at half
    # amplitude, in the medium and in one twice as strong
    a_states, a_native = native_run(name, 1.0)
    b_states, b_native = native_run(name, 0.5)
    worlds = warp_worlds(name)
    scale = np.array([1.0, 0.5, 1.0, 2.0])
    _scaled_medium(worlds, scale)
    got = []
    for a, b in zip(a_states, b_states):
        origin, rotation, twist = (np.stack([x, x, y, y]) for x, y in zip(a, b))
        got.append(worlds.wrenches_at(origin, rotation, twist))
    got = np.array(got)                                    # (samples, worlds, bodies, 6)
    expected = np.stack([a_native, 0.5 * a_native, b_native, 2 * b_native], axis=1)
    # per body: the largest difference over the run against the largest force it takes
    size = np.abs(expected[..., 3:]).max(axis=(0, 3))      # (worlds, bodies)
    assert np.all(size > 0), "a body takes no force over the run: nothing is compared"
    difference = np.abs(got - expected).max(axis=(0, 3)) / size
    assert difference.max() < 1e-6, f"{name}: max relative difference {difference.max():.3g}"
    # the other controls' run is another motion: its forces differ from the first run's
    assert np.abs(b_native - a_native)[..., 3:].max() > 0.05 * np.abs(a_native[..., 3:]).max()


def test_mujoco_warp_steps_follow_mujoco():
    """MuJoCo Warp's step (float32) with the laws as its passive callback against MuJoCo's step with the native
    plugin: the sand-swimmer under its controls for 0.2 s, from the same state; the medium's force read from the
    float32 state at the start; a world in a medium twice as strong moves otherwise."""
    scene, name = _scene("sand_swimmer"), "sand_swimmer"
    native = _built(name, "native")
    m, d = native.model, mujoco.MjData(native.model)
    d.qpos[2] -= 0.01  # sunk 1 cm into the medium, moving
    d.qvel[:] = np.random.default_rng(1).normal(0.0, 0.05, m.nv)
    worlds = warp_worlds(name)
    worlds.set_medium(zeta=np.array([1.0, 2.0, 1.0, 1.0]) * worlds.attached.parameters["zeta"])
    mujoco.mj_forward(m, d)
    start = native.attached.wrenches(m)(d)
    worlds.set_state(d.qpos, d.qvel)
    worlds.forward()
    first = worlds.wrenches()[0]
    assert np.abs(start).max() > 0.1
    assert np.abs(first - start).max() < 1e-5 * np.abs(start).max()  # float32 positions and velocities
    actuators = [m.actuator(c.actuator).id for c in scene.control]
    for _ in range(200):
        ctrl = np.zeros(m.nu)
        for a, c in zip(actuators, scene.control):
            ctrl[a] = control_value(c, None, d.time + 0.5)
        d.ctrl[:] = ctrl
        worlds.set_ctrl(ctrl)
        mujoco.mj_step(m, d)
        worlds.step()
    qpos = worlds.qpos
    assert np.abs(qpos[0] - d.qpos).max() < 1e-4, np.abs(qpos[0] - d.qpos).max()
    assert np.abs(qpos[1] - d.qpos).max() > 1e-3  # the stronger medium's world went elsewhere
    assert np.array_equal(qpos[2], qpos[0])        # worlds alike stay alike


def test_warp_worlds_refuse_bad_input():
    spec = mujoco.MjSpec.from_string("""<mujoco><worldbody><body name="plate"><joint type="slide" axis="1 0 0"/>
      <geom type="box" size="0.01 0.01 0.01" mass="1"/></body></worldbody></mujoco>""")
    attached = attach(spec, ["plate"], zeta=1.0)
    model = spec.compile()
    with pytest.raises(SceneError, match="backend='warp'"):
        fw.WarpWorlds(model, attached, device="cpu")
    worlds = warp_worlds("sand_swimmer")
    with pytest.raises(SceneError, match="method must be one of explicit, implicit, newton"):
        fw.WarpWorlds(worlds.model, worlds.attached, device="cpu", method="newton-midpoint")
    with pytest.raises(SceneError, match="not a parameter"):
        worlds.set_medium(rho_c=1.0)
    with pytest.raises(SceneError, match="one finite number or 4"):
        worlds.set_medium(zeta=[1.0, 2.0])
    with pytest.raises(SceneError, match="ctrl must be"):
        worlds.set_ctrl(np.zeros(2))


def test_bench_warp_reports_rates_and_the_difference(capsys):
    from finrft.cli import main
    assert main(["bench", "warp", "--worlds", "1,2", "--steps", "5", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["device"].startswith("cpu") and [r["worlds"] for r in figures["rows"]] == [1, 2]
    assert all(r["warp_steps_per_s"] > 0 and r["native_steps_per_s"] > 0 for r in figures["rows"])
    assert figures["max_relative_difference_laws"] < 1e-12      # the same float64 arithmetic as the plugin's
    assert figures["max_relative_difference"] < 1e-5            # through MuJoCo Warp's float32 state


def test_bench_warp_refuses_bad_worlds(capsys):
    from finrft.cli import main
    assert main(["bench", "warp", "--worlds", "16,x"]) == 2
    assert "whole numbers of worlds" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["implicit", "newton"])
def test_implicit_step_is_the_native_one(method):
    """One step of a Warp implicit method from moving, sunk states of the sand-swimmer under random controls: the
    native plugin's step of the same method (finrft.integrate: the same linearisation; newton's root) to MuJoCo
    Warp's float32."""
    from finrft.integrate import stepper
    scene = _scene("sand_swimmer")
    sim = dataclasses.replace(scene.sim, method=method, dt=DT)
    native = build_attached(scene_spec(scene), [], scene.model.bodies, scene.medium, sim, scene.model.geoms)
    built = _built("sand_swimmer", "warp")
    m = native.model
    advance = stepper(m, sim, "native", (), native.attached)
    worlds = fw.WarpWorlds(built.model, built.attached, worlds=3, device="cpu", method=method)
    rng = np.random.default_rng(3)
    starts = []
    for k in range(3):
        d = mujoco.MjData(m)
        d.qpos[2] -= 0.005 * (k + 1)
        d.qvel[:] = rng.normal(0.0, 0.05, m.nv)
        d.ctrl[:] = rng.normal(0.0, 0.3, m.nu)
        starts.append(d)
    worlds.set_state(np.array([d.qpos for d in starts]), np.array([d.qvel for d in starts]))
    worlds.set_ctrl(np.array([d.ctrl for d in starts]))
    before = np.array([d.qvel for d in starts])
    explicit = []
    for d in starts:
        plain = mujoco.MjData(m)
        plain.qpos[:], plain.qvel[:], plain.ctrl[:] = d.qpos, d.qvel, d.ctrl
        mujoco.mj_step(m, plain)
        explicit.append(plain.qvel.copy())
        advance(d, 1)
    worlds.step()
    expected = np.array([d.qvel for d in starts])
    size = np.abs(expected - before).max()  # the step's largest change of velocity
    assert np.abs(worlds.qvel - expected).max() < 1e-4 * size
    assert np.abs(np.array(explicit) - expected).max() > 1e-2 * size  # the medium taken implicitly changes the step


def test_implicit_step_settles_a_light_box_at_1_ms(tmp_path):
    """A 50 g box settling into the medium at 1 ms (conftest.settling_box): the Warp implicit and newton steps come
    to the native newton run's depth, where the explicit step, light as the box is, throws it out of the medium."""
    from conftest import physics_run, settling_box
    path = settling_box(tmp_path, "newton")
    scene = load_scene(str(path), cls=UserScene)
    depth = physics_run(scene).com_position[-1, 2]
    built = build_attached(scene_spec(scene), [], scene.model.bodies, scene.medium,
                           dataclasses.replace(scene.sim, backend="warp"), scene.model.geoms)
    steps = int(round(scene.duration / scene.sim.dt))
    finals = {}
    for method in fw.METHODS:
        worlds = fw.WarpWorlds(built.model, built.attached, device="cpu", method=method)
        worlds.step(steps)
        finals[method] = worlds.qpos[0, 2]
    assert abs(finals["implicit"] - depth) < 1e-6 and abs(finals["newton"] - depth) < 1e-6, (finals, depth)
    assert abs(finals["explicit"] - depth) > 1e-3, (finals, depth)


def test_vector_env_on_warp_follows_the_native_one():
    """finrft.envs.make_vector(..., backend="warp"): the sand-swimmer's worlds under the same random actions,
    stepped explicitly at 1 ms, observe and earn what the native vector environment's do."""
    pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install 'finrft[gym]')")
    from finrft import envs
    options = {"control_dt": 0.02, "overrides": {"sim.method": "explicit"}}
    warp_env = envs.make_vector("sand_swimmer", 2, backend="warp", device="cpu", **options)
    native_env = envs.make_vector("sand_swimmer", 2, threads=1, **options)
    got, expected = warp_env.reset(seed=0)[0], native_env.reset(seed=0)[0]
    assert np.abs(got - expected).max() < 1e-6
    actions = np.random.default_rng(5).uniform(-1, 1, (3, 2, native_env.single_action_space.shape[0]))
    for action in actions:
        got, got_reward, *_ = warp_env.step(action)
        expected, reward, *_ = native_env.step(action)
        assert np.abs(got - expected).max() < 1e-3 * np.abs(expected).max(), np.abs(got - expected).max()
        assert np.abs(got_reward - reward).max() < 1e-3 * np.abs(reward).max() + 1e-9
    assert np.abs(got[0] - got[1]).max() > 1e-3  # other actions, other worlds
    with pytest.raises(SceneError, match="without \\[\\[drive\\]\\] joints"):
        envs.make_vector("wheel_rig", 2, backend="warp", device="cpu")
