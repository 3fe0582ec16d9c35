"""What the command line asks of an experiment, and the registry it reads (in the spirit of dm_control's suite).

An experiment module registers a `Command`: its name, its flags, how its scene and its runs come from the flags,
the files it may write, and its summary text. `finrft.cli` gives each registered command a subcommand and runs it
on one generic path (check the outputs, run, write, report), so that a new experiment needs no edit of the CLI.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any, Callable

from .. import geometry
from ..experiment import Experiment, Result
from ..laws import feeds_energy


@dataclass(frozen=True)
class Output:
    """A file a command may write: its flag, the path given (None: not asked for), the suffix it must have, what
    it is (in 'wrote' lines), and its writer, given the runs; ``append``: a file added to, which may exist."""

    flag: str
    path: str | None
    suffix: str
    what: str
    write: Callable[[list[Result], str], None]
    append: bool = False


def _write_h5(runs: list[Result], path: str) -> None:
    from ..record import write_h5  # h5py and rerun load only when a file is asked for
    write_h5(runs[0], path, force=True)  # the command checked --force


def _write_rrd(runs: list[Result], path: str) -> None:
    from ..record import write_rrd
    write_rrd(runs[0], path, force=True)


def result_files(args: argparse.Namespace) -> list[Output]:
    """--out (HDF5) and --rrd (rerun) of a command of one run."""
    return [Output("--out", args.out, ".h5", "HDF5", _write_h5), Output("--rrd", args.rrd, ".rrd", "rerun recording",
                                                                    _write_rrd)]


class Command:
    """A registered experiment's subcommand; a subclass sets the names and overrides what differs."""

    name: str = ""
    help: str = ""
    description: str = ""

    def add_flags(self, parser: argparse.ArgumentParser) -> None:
        """The experiment's own flags, outputs included."""
        raise NotImplementedError

    def scene(self, args: argparse.Namespace) -> Any:
        """The resolved scene the flags ask for."""
        raise NotImplementedError

    def jobs(self, args: argparse.Namespace, scene: Any) -> list[tuple[Experiment, Any]]:
        """The runs to make, each an experiment and its scene; UsageError for flags that do not fit the scene."""
        raise NotImplementedError

    def outputs(self, args: argparse.Namespace) -> list[Output]:
        return result_files(args)

    def job_name(self, experiment: Experiment, scene: Any) -> str:
        """What tells one of several jobs from the others, in a failure's message."""
        return ""

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        """The summary text, in the CLI's units."""
        raise NotImplementedError

    def to_json(self, runs: list[Result]) -> Any:
        return runs[0].summary()


REGISTRY: dict[str, Command] = {}


def register(cls: type[Command]) -> type[Command]:
    """Class decorator: add a command to the registry the CLI and the tests iterate."""
    if cls.name in REGISTRY:
        raise ValueError(f"a command named {cls.name!r} is registered already")
    REGISTRY[cls.name] = cls()
    return cls


def steps_line(summary: dict[str, Any]) -> str:
    return f"{summary['steps']} steps taken ({summary['steps_rejected']} rejected)"


def choice_lines(run: Result) -> list[str]:
    """What sim.method = "auto" chose and why, in one line (none where the scene named its method)."""
    return [] if run.method_choice is None else [run.method_choice.line()]


def error_line(run: Result) -> str:
    # Any experiment's keys name their unit last (`experiment.Compared`): angle_deg, torque_Nm, eta_points, ...
    return (f"estimated discretisation error (companion run at {run.error_companion}): "
            + ", ".join(f"{what} {value:.2g} {unit.replace('Nm', 'N m')}" for (what, unit), value in
                        ((key.rsplit("_", 1), value) for key, value in run.error_estimate.items())))


def authors_model_line(args: argparse.Namespace, scene: Any) -> list[str]:
    """What the paper preset is, when it was asked for: the authors' model, and why its law can feed energy in."""
    if getattr(args, "preset", None) != "paper":
        return []
    reason = feeds_energy(geometry.segment_law(scene))
    return ["preset paper: the authors' model, quirks kept to reproduce their runs"
            + (f"; its law feeds energy in ({reason})" if reason else "")
            + "; --preset physical is the physical model"]
