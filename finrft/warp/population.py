"""A population of one robot scene's variants in one batched rollout on MuJoCo Warp (``finrft sweep --backend
warp``, ``finrft optimize --objective ... --backend warp``): every variant is a world of one `WarpWorlds`, stepped
together for the scene's duration, its own medium set per world and its own open-loop [[control]] applied to it
at every step. Only keys a world can take apart from its neighbours vary (`check_keys`): the medium's parameters
(`MEDIUM_KEYS`) and the open-loop controls' (`CONTROL_FIELDS`).

Each world reports the figures the native run names (`finrft.experiments.user_model.robot_summary`) of its centre
of mass, ``com_velocity_m_s`` (its displacement over the window [sim.settle, end] / the window), ``com_speed_m_s``
and ``com_position_m``, and of the medium's force, ``medium_force_N`` and ``body_medium_force_N`` (means over the
window), each with the native run's kind of estimate: a companion batch at half the step, SAFETY |run -
companion| / (1 - 1/2) (`finrft.convergence`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from typing import Any, Callable, Sequence

import numpy as np

from .. import laws, media
from ..convergence import FINER, ROBOT_HEADLINE, SAFETY, ErrorLimits, figure_map
from ..errors import SceneError
from ..laws import drft
from ..scene import UserScene
from . import METHODS, WarpWorlds, scene_worlds

# The scene keys a world takes as its own medium (`WarpWorlds.set_medium`), and the fields of an open-loop
# [[control]] entry a world's ctrl follows (`control.N.FIELD`, N an entry's index or *).
MEDIUM_KEYS = ("medium.zeta", "medium.internal_friction", "medium.surface_friction", "medium.bulk_density",
               "medium.drft_lambda", "medium.surface_z")
CONTROL_FIELDS = ("amplitude", "frequency", "phase", "offset", "value", "ramp")
OPEN_LOOP = ("sine", "constant", "table")
FIGURES = ("com_velocity_m_s", "com_speed_m_s", "com_position_m", "medium_force_N", "body_medium_force_N")


def check_keys(scene: UserScene, keys: Sequence[str]) -> None:
    """SceneError in one line unless every key is one a Warp world sets for itself, and the scene one the batched
    rollout runs (open-loop controls, no [[drive]] joints)."""
    for key in keys:
        parts = key.split(".")
        control = (len(parts) == 3 and parts[0] == "control" and (parts[1] == "*" or parts[1].isdigit())
                   and parts[2] in CONTROL_FIELDS)
        if key not in MEDIUM_KEYS and not control:
            raise SceneError(f"--backend warp varies {key!r} in no world: it sets the medium ({', '.join(MEDIUM_KEYS)})"
                             f" and open-loop controls (control.N.{{{','.join(CONTROL_FIELDS)}}}) per world; use "
                             f"--backend native for {key}")
    if scene.drive:
        raise SceneError("--backend warp runs robot scenes without [[drive]] joints: use --backend native")
    closed = [f"control.{i} ({c.kind})" for i, c in enumerate(scene.control) if c.kind not in OPEN_LOOP]
    if closed:
        raise SceneError(f"--backend warp applies open-loop controls only, not {', '.join(closed)}: use "
                         f"--backend native")


def medium_of(scene: UserScene) -> dict[str, float]:
    """What `WarpWorlds.set_medium` takes for a scene's [medium], resolved as `finrft.attach` resolves it (the
    named medium's values where the scene gives none)."""
    m = scene.medium
    module = laws.module(m.law, laws.SURFACE)
    material = media.medium(m.name) if m.name else None
    parameters, _ = laws.surface_parameters(m.law, module.given(m), material, "medium")
    out = {**parameters, "drft_lambda": m.drft_lambda, "surface_z": m.surface_z}
    if not module.DENSITY:
        known = material.get("bulk_density") if material is not None else None
        out["bulk_density"] = drft.density(m.drft_lambda, m.bulk_density or None,
                                           None if known is None else known.value, "medium.bulk_density", "medium")
    return out


def _controller(worlds: WarpWorlds, scenes: Sequence[UserScene]) -> Callable[[float], np.ndarray]:
    """ctrl(t): every world's ctrl at time t, its scene's open-loop entries (`control_value`) over the worlds'
    starting ctrl. Worlds with the same entries share one evaluation."""
    from ..experiments.user_model import UserModel, control_value
    m = worlds.model
    base = worlds.d.ctrl.numpy().astype(float)
    columns = [m.actuator(c.actuator).id for c in scenes[0].control]
    groups: dict[tuple, list[int]] = {}
    for i, s in enumerate(scenes):
        groups.setdefault(tuple(s.control), []).append(i)
    tables = UserModel.of(scenes[0]).tables  # a table's file is no key a world varies

    def ctrl(t: float) -> np.ndarray:
        out = base.copy()
        for entries, rows in groups.items():
            out[np.ix_(rows, columns)] = [control_value(c, table, t) for c, table in zip(entries, tables)]
        return out

    return ctrl


def rollout(scene: UserScene, scenes: Sequence[UserScene], *, dt: float | None = None,
            device: str | None = None) -> list[dict[str, Any]]:
    """Every scene a world of one `WarpWorlds` (the first scene's model; ``dt``: its step, None: sim.dt), stepped
    for the scene's duration: each world's figures (`FIGURES`) as `robot_summary` computes them, the centre of
    mass's at sim.settle linear between the steps around it, the medium's force the mean over the window of its
    value at every step (`WindowMeans`). A world that became unstable reports NaN."""
    from ..experiments.user_model import WindowMeans
    sim = scene.sim
    dt = sim.dt if dt is None else dt
    stepped = copy.copy(scene)  # a step finer than the scene's limits is the companion's purpose: not replace
    object.__setattr__(stepped, "sim", dataclasses.replace(sim, dt=dt))
    method = sim.method if sim.method in METHODS else "newton"
    worlds = scene_worlds(stepped, len(scenes), method=method, device=device)
    mediums = [medium_of(s) for s in scenes]
    worlds.set_medium(**{key: [m[key] for m in mediums] for key in worlds.medium_keys()})
    ctrl = _controller(worlds, scenes)
    steps = max(1, round(scene.duration / dt))
    settle = min(sim.settle / dt, steps)
    before = min(int(math.floor(settle)), steps - 1)
    com: dict[int, np.ndarray] = {}
    means = WindowMeans(sim.settle, len(scenes) * worlds.nbody, 0, 0)
    for k in range(steps):
        worlds.set_ctrl(ctrl(k * dt))
        worlds.step(1)
        # the step's forward pass ran at its start: the state, and the medium's force, at k dt
        if k in (before, before + 1):
            com[k] = worlds.d.subtree_com.numpy()[:, 0].astype(float)
        if (k + 1) * dt > sim.settle:
            means.add(k * dt, worlds.forces().ravel())
    worlds.forward()
    com[steps] = worlds.d.subtree_com.numpy()[:, 0].astype(float)
    means.add(steps * dt, worlds.forces().ravel())
    force = means.parts(steps * dt)["medium_force"].reshape(len(scenes), worlds.nbody, 3)
    end = com[steps].copy()
    unstable = ~np.all(np.isfinite(worlds.qpos), axis=1)
    end[unstable], force[unstable] = np.nan, np.nan
    start = com[before] + (com[before + 1] - com[before]) * (settle - before)
    velocity = (end - start) / (steps * dt - sim.settle)
    return [{"com_velocity_m_s": v.tolist(), "com_speed_m_s": float(np.hypot(*v[:2])), "com_position_m": p.tolist(),
             "medium_force_N": f.sum(axis=0).tolist(),
             "body_medium_force_N": {b: f[i].tolist() for i, b in enumerate(worlds.bodies)}}
            for v, p, f in zip(velocity, end, force)]


def _flat(figure: dict[str, Any]) -> dict[str, float]:
    from ..studies.figures import flatten
    return flatten(figure, FIGURES)


def evaluate(scene: UserScene, scenes: Sequence[UserScene], max_error: ErrorLimits | None = None, *,
             device: str | None = None) -> list[dict[str, Any]]:
    """Every variant's figures and estimates by path, its error ("" or why it failed) and wall_s (the whole
    batch's, run and companion), as `finrft.studies.figures.evaluate` reports a native run: one batched rollout at
    the scene's step and a companion at half of it (`rollout`)."""
    check_keys(scene, [])
    begun = time.perf_counter()
    sim = scene.sim
    run = rollout(scene, scenes, device=device)
    companion = rollout(scene, scenes, dt=FINER * sim.dt, device=device)
    wall = time.perf_counter() - begun
    out = []
    for fine, half in zip(run, companion):
        estimate = {key: figure_map(lambda a, b: SAFETY * abs(a - b) / abs(FINER - 1), fine[key], half[key])
                    for key in FIGURES}
        flat = _flat(fine)
        if not all(math.isfinite(v) for v in flat.values()) or not all(
                math.isfinite(v) for v in _flat(half).values()):
            error = "the run became unstable on Warp (a state that is not finite): try a smaller sim.dt"
        else:
            over = [] if max_error is None else max_error.exceeded(estimate, fine, ROBOT_HEADLINE)
            error = "" if not over else (f"the estimated discretisation error is too large ({', '.join(over)}; from "
                                         f"a companion batch at dt {FINER * sim.dt:g} s): lower sim.dt")
        out.append({"figures": {} if error else flat, "estimates": {} if error else _flat(estimate),
                    "error": error, "wall_s": wall})
    return out
