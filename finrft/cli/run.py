"""The one path every registered experiment runs through: its flags come from its module, the rest is here."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import SimulationFailed
from ..experiment import Result, run as run_experiment
from ..experiments.command import Command
from ..experiments.flags import limits
from ..files import keep_existing
from .common import check_output, print_json, progress, said_written, say


def add_experiment(sub: Any, command: Command) -> None:
    """The subcommand of a registered experiment."""
    parser = sub.add_parser(command.name, help=command.help, description=command.description)
    command.add_flags(parser)
    parser.set_defaults(handler=lambda args: run_command(command, args))


def run_command(command: Command, args: argparse.Namespace) -> int:
    """Check the outputs before anything is read or run, resolve the scene, run, write the files, report."""
    outputs = command.outputs(args)
    for output in outputs:
        check_output(output.path, output.suffix, output.flag, args.force, append=output.append)
    scene = command.scene(args)
    runs = _run_all(args, command, command.jobs(args, scene))
    for output in outputs:
        if output.path:
            with keep_existing(not (args.force or output.append)):  # a file added to is replaced by design
                output.write(runs, output.path)
    say(args, command.describe(args, runs))
    said_written(args, [(output.what, output.path) for output in outputs])
    print_json(args, command.to_json(runs))
    return 0


def _run_all(args: argparse.Namespace, command: Command, jobs: list[tuple[Any, Any]]) -> list[Result]:
    """Each job in turn, one progress bar over all, with the error limits of --max-error; a failure among several
    jobs names the one that failed."""
    runs = []
    with progress(args, 1, command.name, "%") as bar:
        for i, (experiment, scene) in enumerate(jobs):
            part = None if bar is None else (lambda f, i=i: bar((i + f) / len(jobs)))
            try:
                runs.append(run_experiment(experiment, scene, progress=part, max_error=limits(args)))
            except SimulationFailed as exc:
                if len(jobs) == 1:
                    raise
                name = command.job_name(experiment, scene)
                raise type(exc)(f"run {i + 1} of {len(jobs)}{f' ({name})' if name else ''}: {exc}") from exc
    return runs
