"""A robot run's figures by path, with their error estimates: what `finrft optimize --objective` searches and
`finrft sweep` tables. A path names one number of a run's JSON (`user_model.robot_summary`): ``com_speed_m_s``,
``com_velocity_m_s.0`` (x), ``medium_force_N.2`` (z), ``body_medium_force_N.link1.0``, ``drive_load.1``,
``cost_of_transport``; its estimate is the same path in the run's ``error_estimate``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..convergence import ErrorLimits, SimulationFailed
from ..errors import SceneError
from ..scene import UserScene

# The figures of a robot run a path may name (`UserModel.figures`), and the vectors among them (x, y, z).
ROBOT_FIGURES = ("com_velocity_m_s", "com_speed_m_s", "com_position_m", "medium_force_N", "body_medium_force_N",
                 "drive_load", "actuator_power_W", "positive_power_W", "cost_of_transport")
VECTORS = ("com_velocity_m_s", "com_position_m", "medium_force_N")


def flatten(figures: dict[str, Any], keys: tuple[str, ...] = ROBOT_FIGURES) -> dict[str, float]:
    """Every number of ``figures`` (a run's summary or its error estimate) under ``keys``, by path; a figure the
    run does not report (a cost of transport where the robot does not move): NaN."""
    out: dict[str, float] = {}

    def walk(path: str, value: Any) -> None:
        if isinstance(value, dict):
            for name, item in value.items():
                walk(f"{path}.{name}", item)
        elif isinstance(value, (list, tuple, np.ndarray)):
            for i, item in enumerate(value):
                walk(f"{path}.{i}", item)
        else:
            out[path] = math.nan if value is None else float(value)

    for key in keys:
        if key in figures:
            walk(key, figures[key])
    return out


def check_path(path: str, scene: UserScene, bodies: tuple[str, ...]) -> str:
    """``path`` when it names one number a run of ``scene`` reports (its attached ``bodies`` by name); SceneError
    in one line otherwise, before anything runs."""
    root, _, rest = path.partition(".")
    if root not in ROBOT_FIGURES:
        raise SceneError(f"no figure {path!r}: a path starts with one of {', '.join(ROBOT_FIGURES)} (e.g. "
                         f"com_velocity_m_s.0, cost_of_transport, medium_force_N.2)")
    where = {**{k: [str(i) for i in range(3)] for k in VECTORS},
             "drive_load": [str(i) for i in range(len(scene.drive))]}
    if root == "body_medium_force_N":
        body, _, axis = rest.partition(".")
        if body not in bodies or axis not in ("0", "1", "2"):
            raise SceneError(f"figure {path!r}: give body_medium_force_N.BODY.AXIS, BODY one of {', '.join(bodies)} "
                             f"and AXIS 0, 1 or 2 (x, y, z)")
    elif root in where:
        if rest not in where[root]:
            raise SceneError(f"figure {path!r}: {root} has {len(where[root])} numbers: give {root}.N, N from 0 to "
                             f"{len(where[root]) - 1}" if where[root] else f"figure {path!r}: the scene has no drives")
    elif rest:
        raise SceneError(f"figure {path!r}: {root} is one number: leave out the .{rest}")
    return path


def evaluate(scene: UserScene, max_error: ErrorLimits | None = None) -> dict[str, Any]:
    """One run of a robot scene: its figures and their error estimates by path (`flatten`), and "" or why it
    failed (an unstable run, or one whose estimate exceeds ``max_error``; None: the estimate reported only):
    marked, not raised, so that one variant does not stop a search or a sweep."""
    from ..experiments.user_model import run_robot
    try:
        run = run_robot(scene, max_error=max_error)
    except (SimulationFailed, SceneError) as exc:
        return {"figures": {}, "estimates": {}, "error": str(exc), "wall_s": math.nan}
    summary = run.summary()
    return {"figures": flatten(summary), "estimates": flatten(summary.get("error_estimate") or {}), "error": "",
            "wall_s": float(summary["wall_s"])}


def evaluate_job(job: tuple[UserScene, ErrorLimits | None]) -> dict[str, Any]:
    """`evaluate` for a pool (a module-level function of one argument)."""
    return evaluate(*job)
