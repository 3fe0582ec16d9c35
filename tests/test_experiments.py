"""The registry of experiments: every entry is a CLI subcommand, a new one needs no edit of the CLI, and the
commands run the physical presets unless asked for the authors' model."""

import argparse
import json

import pytest

import finrft
import finrft.laws
from finrft.cli import build_parser, main
from finrft.geometry import segment_law
from finrft.experiments import REGISTRY, Command, register
from finrft.experiments.plate import PlateTest, add_plate_scene, resolve_plate


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_every_registered_experiment_is_a_subcommand():
    commands = _subcommands(build_parser())
    assert {"drag", "rotate", "swim", "run", "intrude", "wheel"} <= set(REGISTRY)
    for name, command in REGISTRY.items():
        assert name in commands and command.help and command.description
        assert commands[name].description == command.description


@pytest.fixture
def registry():
    saved = dict(REGISTRY)
    yield REGISTRY
    REGISTRY.clear()
    REGISTRY.update(saved)


def test_a_new_experiment_needs_no_edit_of_the_cli(registry, capsys):
    @register
    class Nudge(Command):  # a short rigid-plate drag at a speed of its own flag
        name = "nudge"
        help = "a short drag of a rigid plate"
        description = "Drag a rigid plate 5 mm at --speed."

        def add_flags(self, p):
            p.add_argument("--speed", type=float, default=20.0)
            add_plate_scene(p)
            p.add_argument("--json", action="store_true")
            p.add_argument("--quiet", action="store_true")
            p.add_argument("--force", action="store_true")

        def scene(self, args):
            return resolve_plate(args).replace(**{"plate.kind": "rigid"})

        def jobs(self, args, scene):
            return [(PlateTest(finrft.Drive(speed=args.speed / 1000, stroke=0.005)), scene)]

        def outputs(self, args):
            return []

        def describe(self, args, runs):
            return f"nudged: peak force {runs[0].peak_drive_force:.4g} N"

    assert "nudge" in _subcommands(build_parser())
    assert main(["nudge", "--speed", "40", "--json"]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("nudged: peak force")  # the text beside --json: stdout is the JSON's
    summary = json.loads(captured.out)
    # The same drag through the Python API, on the preset every command defaults to.
    direct = finrft.simulate(finrft.preset("physical").replace(**{"plate.kind": "rigid"}),
                             finrft.Drive(speed=0.04, stroke=0.005))
    assert summary["peak_drive_force_N"] == pytest.approx(direct.peak_drive_force, rel=1e-12)
    with pytest.raises(ValueError, match="registered already"):
        register(Nudge)


def test_fresh_swim_is_the_physical_robot_swimming_forward_without_warning(capsys):
    assert main(["swim", "--json"]) == 0
    captured = capsys.readouterr()
    assert "warning" not in captured.err  # which holds the summary text beside --json
    summary = json.loads(captured.out)
    assert summary["eta_steady"] > 0  # the physical robot swims forward; the paper preset's eta is -7 %
    assert "authors' model" not in captured.err
    assert finrft.laws.feeds_energy(segment_law(finrft.preset("physical", finrft.RobotScene))) == ""  # warned or not before


def test_fresh_drag_warns_of_nothing_and_the_paper_preset_says_what_it_is(capsys):
    assert main(["drag", "--distance", "5"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "authors' model" not in captured.out
    assert finrft.laws.feeds_energy(segment_law(finrft.preset("physical"))) == ""
    assert main(["drag", "--distance", "5", "--preset", "paper"]) == 0
    captured = capsys.readouterr()
    assert "preset paper: the authors' model" in captured.out and "feeds energy in" in captured.out


def test_version(capsys):
    with pytest.raises(SystemExit) as exit:
        main(["--version"])
    assert exit.value.code == 0
    assert capsys.readouterr().out.strip() == f"finrft {finrft.__version__}"
    assert finrft.__version__[0].isdigit()
