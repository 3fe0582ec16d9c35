"""`finrft bench warp`: robot-steps per second of an example robot against the number of worlds, on MuJoCo Warp
with the surface laws in Warp kernels (whatever Warp device there is) and on MuJoCo's threaded rollout with the
native plugin (this machine's cores), and how far the Warp backend's forces are from the native plugin's."""

from __future__ import annotations

import dataclasses
import platform
import time
from datetime import date
from typing import Any, Callable, Sequence

import mujoco
import numpy as np
from mujoco import rollout

from .. import batch
from ..experiments.attached_model import build_attached, scene_spec
from ..experiments.user_model import control_value, example
from ..scene import UserScene, load_scene
from . import WarpWorlds, body_state, device_name, wp

WORLDS = (1, 16, 256, 4096)
SAMPLES = 10  # native states the forces are compared at, per compared world


def _built(scene: UserScene, backend: str) -> Any:
    sim = dataclasses.replace(scene.sim, backend=backend)
    return build_attached(scene_spec(scene), [j.joint for j in scene.drive], scene.model.bodies, scene.medium, sim,
                          scene.model.geoms)


def _start(scene: UserScene, m: mujoco.MjModel) -> mujoco.MjData:
    d = mujoco.MjData(m)
    if scene.model.keyframe:
        mujoco.mj_resetDataKeyframe(m, d, m.key(scene.model.keyframe).id)
    mujoco.mj_forward(m, d)
    return d


def _controls(scene: UserScene, m: mujoco.MjModel, worlds: int, steps: int) -> np.ndarray:
    """(worlds, steps, nu): the scene's [[control]] entries over the run, world k's amplitude scaled by 1 - k /
    (2 worlds): worlds that move otherwise, as a population would."""
    ctrl = np.zeros((steps, m.nu))
    for c in scene.control:
        a = m.actuator(c.actuator).id
        ctrl[:, a] = [control_value(c, None, k * m.opt.timestep) for k in range(steps)]
    return ctrl[None] * (1 - np.arange(worlds) / (2 * worlds))[:, None, None]


def _relative(got: np.ndarray, native: np.ndarray) -> float:
    """The largest force difference of any body against the largest force that body takes (samples, B, 6)."""
    size = np.abs(native[..., 3:]).max(axis=(0, 2))
    return float((np.abs(got - native)[..., 3:].max(axis=(0, 2)) / np.where(size > 0, size, 1.0)).max())


def bench(robot: str = "sand_swimmer", worlds: Sequence[int] = WORLDS, steps: int = 0, device: str | None = None,
          threads: int | None = None, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Robot-steps per second of ``robot`` (an example: `finrft.experiments.user_model.EXAMPLES`) at each number of
    worlds: MuJoCo Warp (`WarpWorlds`, ``steps`` steps per measurement, 0: about 20000 robot-steps, at least 5)
    against MuJoCo's rollout of the native-plugin model on ``threads`` threads (default: every core), both with the
    model's own integrator and step, the scene's controls (each world's amplitude its own). Each count's forces are
    compared at native states of its rollout: ``max_relative_difference`` the Warp step's (from the float32 state
    MuJoCo Warp holds), ``max_relative_difference_laws`` the laws' alone at the native float64 state; each the
    largest difference of any body's force over the samples against the largest force that body takes."""
    scene = load_scene(example(robot), cls=UserScene)
    native, warp = _built(scene, "native"), _built(scene, "warp")
    m = native.model
    threads = threads or batch.default_workers()
    datas = [mujoco.MjData(m) for _ in range(threads)]
    start = _start(scene, m)
    state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(m, start, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    read = native.attached.wrenches(m)
    bodies = [s.body for s in native.attached.surfaces]
    out: dict[str, Any] = {"date": date.today().isoformat(), "robot": robot, "device": device_name(device),
                           "machine": f"{platform.machine()}, {batch.default_workers()} cores, "
                           f"{platform.python_implementation()} {platform.python_version()}",
                           "mujoco": mujoco.__version__, "warp": wp.__version__, "dt": m.opt.timestep,
                           "integrator": mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower(),
                           "native_threads": threads,
                           "elements": int(sum(len(s.area) for s in native.attached.surfaces)),
                           "rows": []}
    log(f"{robot}: {out['elements']} elements, dt {m.opt.timestep:g} s, Warp on {out['device']}, native rollout "
        f"on {threads} threads")
    log(f"{'worlds':>7} {'warp steps/s':>14} {'native steps/s':>15} {'warp/native':>12} {'max rel diff':>13}")
    worst = worst_laws = 0.0
    for n in worlds:
        count = steps or max(5, min(200, 20000 // n))
        ctrl = _controls(scene, m, n, count)
        w = WarpWorlds(warp.model, warp.attached, n, device=device, data=_start(scene, warp.model))
        w.set_ctrl(ctrl[:, 0])
        w.step(1)  # compiles the kernels, once per process
        w.set_state(start.qpos, start.qvel)
        wp.synchronize_device(w.device)
        began = time.perf_counter()
        for k in range(count):
            w.set_ctrl(ctrl[:, k])
            w.step(1)
        wp.synchronize_device(w.device)
        warp_rate = n * count / (time.perf_counter() - began)

        initial = np.repeat(state[None], n, axis=0)
        began = time.perf_counter()
        states, _ = rollout.rollout(m, datas, initial, ctrl, nstep=count)
        native_rate = n * count / (time.perf_counter() - began)

        # forces at native states of the first and last worlds, spread over the run
        picks = [(world, k) for world in sorted({0, n - 1}) for k in np.linspace(0, count - 1, SAMPLES, dtype=int)]
        d = mujoco.MjData(m)
        expected, at_laws, at_step = [], [], []
        for world, k in picks:
            mujoco.mj_setState(m, d, states[world, k], mujoco.mjtState.mjSTATE_FULLPHYSICS)
            mujoco.mj_forward(m, d)
            expected.append(read(d))
            pose = body_state(m, d, bodies)
            at_laws.append(w.wrenches_at(*(np.repeat(x[None], n, axis=0) for x in pose))[0])
            w.set_state(d.qpos, d.qvel)
            w.forward()
            at_step.append(w.wrenches()[0])
        difference = _relative(np.array(at_step), np.array(expected))
        laws_difference = _relative(np.array(at_laws), np.array(expected))
        worst, worst_laws = max(worst, difference), max(worst_laws, laws_difference)
        out["rows"].append({"worlds": n, "steps": count, "warp_steps_per_s": warp_rate,
                            "native_steps_per_s": native_rate, "max_relative_difference": difference,
                            "max_relative_difference_laws": laws_difference})
        log(f"{n:>7} {warp_rate:>14.0f} {native_rate:>15.0f} {warp_rate / native_rate:>12.3g} {difference:>13.2g}")
    out["max_relative_difference"], out["max_relative_difference_laws"] = worst, worst_laws
    log(f"forces against the native plugin at native states: {worst:.2g} (the Warp step, from its float32 state), "
        f"{worst_laws:.2g} (the laws alone, at the float64 state)")
    return out
