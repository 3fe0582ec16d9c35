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
- optimising the robot's gait: `optimize`, `Variable`; any figure of any robot scene over any of its keys (the
  model's design keys too, `finrft.design`): `optimize_scene` with an `Objective` and `Constraint`s; its variants
  over a grid or at random: `sweep`
- files: `write_h5`, `write_rrd` (any result)

Each name loads its module on first use, so ``import finrft`` (and ``finrft --version``) loads neither MuJoCo nor
numpy, scipy, h5py or rerun; ``finrft.NAME`` of a module (``finrft.convergence``) imports it too.

The studies built on the engine (the CMA-ES search, the fit, Table I, the report, the benchmarks) are in
finrft.studies: import other names from their modules by their full path (``from finrft.studies.fit import
simulated_drag``). ``finrft.__version__`` is the installed version.
"""

from __future__ import annotations

import sys
import types
from importlib import import_module
from typing import Any

# Every exported name and the module it lives in, loaded on first use (`__getattr__`).
_HOMES = {
    ".attach": ("attach",),
    ".batch": ("PlateRollouts", "local_executor", "map_jobs", "rollout_plates", "run_experiments", "run_many"),
    ".drive": ("Drive",),
    ".errors": ("Error", "SceneError", "SimulationFailed", "SimulationUnstable"),
    ".experiment": ("Experiment", "Result", "run"),
    ".experiments.intrusion": ("Intrusion", "IntrusionScene"),
    ".experiments.plate": ("PlateTest", "simulate"),
    ".experiments.swim": ("RobotScene", "Swim", "swim"),
    ".experiments.user_model": ("UserModel", "run_robot"),
    ".experiments.wheel": ("Wheel", "WheelScene", "run_wheel"),
    ".media": ("medium",),
    ".scene": ("Scene", "UserScene", "load_scene", "preset", "to_toml"),
    ".studies.fit": ("Fit", "fit", "read_drag", "resolve_params"),
    ".studies.optimize": ("Constraint", "Objective", "Variable", "optimize", "optimize_scene"),
    ".studies.sweep": ("sweep",),
    ".studies.table": ("table_rows", "table_scenes"),
    ".record": ("write_h5", "write_rrd"),
}
_HOME = {name: module for module, names in _HOMES.items() for name in names}

__all__ = sorted(_HOME)


def _version() -> str:
    # Read on first use: importlib.metadata was a third of the command line's start, where `finrft --help` needs
    # no version.
    from importlib import metadata
    try:
        return metadata.version("finrft")
    except metadata.PackageNotFoundError:  # a source tree on the path, not installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        globals()[name] = _version()
        return globals()[name]
    home = _HOME.get(name)
    if home is not None:
        value = getattr(import_module(home, __name__), name)
        globals()[name] = value
        return value
    try:
        return import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))


class _Package(types.ModuleType):
    def __setattr__(self, name: str, value: Any) -> None:
        # Importing a submodule sets it on its package: finrft.attach, the module, would hide the function attach.
        if name in _HOME and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
