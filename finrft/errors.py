"""The exceptions finrft raises, one family: catch `Error` for any of them.

- `SceneError` (also a ValueError): bad input, a scene file, preset, override or argument that cannot be used; the
  message names the key or file and what is allowed. The command line prints it on one line and exits with 2.
  `UsageError`, its kind for the command line's own flags (two that conflict, an output file that exists).
- `SimulationFailed` (also a RuntimeError): a run that cannot give a trustworthy result; the message says what
  happened and what to change. The command line exits with 1. Its kinds:

  - `SimulationUnstable`: the integration blew up, chattered (`Chatter`), its adaptive step underflowed
    (`StepUnderflow`) or its Newton solve found no root (`NotConverged`);
  - `InaccurateResult`: the run's estimated discretisation error exceeds the limit;
  - `UndefinedResult`: the run ended but its figure is undefined (eta, when a power stroke does not move the body
    forward).

This module imports nothing of finrft: every module may raise these.
"""

from __future__ import annotations


class Error(Exception):
    """Anything finrft raises on purpose: bad input (`SceneError`) or a run that failed (`SimulationFailed`)."""


class SceneError(Error, ValueError):
    """A scene file, preset or override that cannot be used; the message names the key and what is allowed."""


class UsageError(SceneError):
    """Bad input from the command line (flags that conflict or do not fit the scene, an output file that exists);
    reported in one line with exit status 2."""


class SimulationFailed(Error, RuntimeError):
    """A run that cannot give a trustworthy result; the message says what happened and what to change."""


class SimulationUnstable(SimulationFailed):
    """The integration blew up, chattered or did not converge."""


class Chatter(SimulationUnstable):
    """The segment law's force reversed at every step: the segments overshoot."""


class StepUnderflow(SimulationUnstable):
    """The adaptive step fell below its smallest size."""


class NotConverged(SimulationUnstable):
    """Newton's method of an implicit step found no root, even at the smallest step."""


class InaccurateResult(SimulationFailed):
    """The run's estimated discretisation error exceeds the limit."""


class UndefinedResult(SimulationFailed):
    """The run ended, but what it measures is undefined (a swim's eta when the body does not move forward)."""
