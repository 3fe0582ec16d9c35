"""finrft: compliant fins and a two-fin robot in granular media, simulated on MuJoCo with granular resistive
force theory (RFT).

A scene (a plate test, or the robot) holds every parameter in SI units; a drive moves the plate's base; a run holds
the results and their summary. The presets are "physical" (real inertias, a dissipative law) and "paper" (the
authors' model, with its quirks)::

    import finrft
    run = finrft.simulate(finrft.preset("physical"), finrft.Drive(speed=0.03, stroke=0.2, cycles=2))
    print(run.summary())

The API, by topic:

- scenes: `Scene` (a plate test), `RobotScene` (the robot), `preset`, `load_scene` (TOML file and overrides),
  `to_toml`; their keys, units and bounds in one schema (finrft.schema; each law declares its own keys)
- errors (finrft.errors): `Error`, the root of everything finrft raises on purpose: `SceneError` (bad input, also
  a ValueError) and `SimulationFailed` (a run that cannot give a trustworthy result)
- experiments: `run(experiment, scene)` -> `Result` runs any `Experiment` (finrft.experiment); the built-in ones,
  each in its module of finrft.experiments with its command (`finrft.experiments.REGISTRY`): `PlateTest`,
  `Swim`, `UserModel` (a user's MJCF model as a robot, `UserScene`; `run_robot(scene, control=...)`), `Intrusion` (a plate pushed into the medium,
  `IntrusionScene`), `Wheel` (a wheel on a single-wheel rig, `WheelScene`; `run_wheel(scene)`); `SimulationUnstable`
  when a run blows up or chatters
- plate tests: `Drive`, `simulate` (`run` of a `PlateTest`)
- the robot: `swim` (`run` of a `Swim`); the paper's Table I with `table_scenes` and `table_rows`
- many runs on all cores: `run_experiments` (any experiment), `run_many` (plate tests), `map_jobs` (any
  module-level function), `local_executor`; `PlateRollouts`, `rollout_plates` (plate tests' states stepped in C on threads)
- RFT on any MuJoCo model: `attach` (the Li, Zhang & Goldman 2013 law on the named bodies of an MjSpec)
- granular media: `medium(name)`, one of the catalogue of named media (every one: ``finrft.media.media()``), each
  value with its unit and source; ``finrft.media.sandswim_coefficients`` derives a segment's sand-swimming law
  from 3D-RFT (a plate or robot scene's ``[medium]`` does it for its chain)
- fitting plate parameters to measured drags: `read_drag`, `resolve_params`, `fit` -> `Fit`
- optimising the robot's gait: `optimize`, `Variable`
- files: `write_h5`, `write_rrd` (any result); they load h5py and rerun on first use, not on ``import finrft``

The studies built on the engine (the CMA-ES search, the fit, Table I, the report, the benchmarks) are in
finrft.studies: import other names from their modules by their full path (``from finrft.studies.fit import
simulated_drag``). ``finrft.__version__`` is the installed version.
"""

from __future__ import annotations

from importlib import import_module, metadata
from typing import Any

try:
    __version__ = metadata.version("finrft")
except metadata.PackageNotFoundError:  # a source tree on the path, not installed
    __version__ = "0+unknown"

from .attach import attach
from .batch import PlateRollouts, local_executor, map_jobs, rollout_plates, run_experiments, run_many
from .drive import Drive
from .errors import Error, SceneError, SimulationFailed, SimulationUnstable
from .experiment import Experiment, Result, run
from .experiments.intrusion import Intrusion, IntrusionScene
from .experiments.plate import PlateTest, simulate
from .experiments.swim import RobotScene, Swim, swim
from .experiments.user_model import UserModel, run_robot
from .experiments.wheel import Wheel, WheelScene, run_wheel
from .media import medium
from .scene import Scene, UserScene, load_scene, preset, to_toml
from .studies.fit import Fit, fit, read_drag, resolve_params
from .studies.optimize import Variable, optimize
from .studies.table import table_rows, table_scenes

_RECORDING = ("write_h5", "write_rrd")

__all__ = ["Drive", "Error", "Experiment", "Fit", "Intrusion", "IntrusionScene", "PlateRollouts", "PlateTest",
           "Result", "RobotScene", "Scene", "SceneError", "SimulationFailed", "SimulationUnstable", "Swim",
           "UserModel", "UserScene", "Variable", "attach", "fit", "load_scene", "local_executor", "map_jobs", "medium",
           "optimize", "preset", "read_drag", "resolve_params", "rollout_plates", "run", "run_experiments",
           "run_many", "run_robot", "run_wheel", "simulate", "swim", "table_rows", "table_scenes", "to_toml", "Wheel",
           "WheelScene", *_RECORDING]


def __getattr__(name: str) -> Any:
    # The writers live in finrft.record, which imports h5py and rerun: load it on first use.
    if name in _RECORDING:
        return getattr(import_module(".record", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_RECORDING))
