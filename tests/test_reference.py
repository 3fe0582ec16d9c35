"""MuJoCo against an independent solution of the same equations of motion (finrft.reference: hand-derived
planar chain in absolute angles, integrated by scipy's Radau, here at rtol 1e-7)."""

import ast
from pathlib import Path

import numpy as np
import pytest

from finrft import reference
from finrft.drive import Drive
from finrft.scene import preset
from finrft.experiments.plate import simulate


def _compare(scene, drive):
    run = simulate(scene, drive, estimate_error=False)
    # Radau at rtol 1e-7: within 4e-7 deg and 3e-7 of the peak force of its solution at 1e-10, in a fifth of the time
    ref = reference.solve(scene, drive, run.time, rtol=1e-7, atol=1e-10)
    angle = np.degrees(np.abs(run.segment_angle - ref.segment_angle)).max()
    force = np.abs(run.drive_force - ref.drive_force).max()
    return angle, force, run


# The one-way drag is the cycle's first stroke, which the fast suite checks in the cycle.
@pytest.mark.parametrize("cycles", [pytest.param(None, marks=pytest.mark.slow), 1])
def test_paper_preset_drag_matches_reference(paper, cycles):
    assert paper.plate.stop == "penalty"
    angle, force, run = _compare(paper, Drive(cycles=cycles))
    assert angle < 0.1
    assert force < 1e-3 * run.peak_drive_force
    assert np.degrees(np.abs(run.segment_angle).max()) > 20.0  # the plate did bend


def test_paper_preset_rotation_matches_reference(paper):
    angle, force, run = _compare(paper, Drive(kind="rotate", speed=np.radians(60), stroke=np.radians(120)))
    assert angle < 0.1
    assert force < 1e-3 * run.peak_drive_force


@pytest.mark.slow  # 80,000 steps of 0.1 ms and the reference's solution over them
def test_light_soft_plate_matches_reference(paper):
    # Inertia 1e-4 kg m^2 (1e4 x below the preset): the hinges respond within millimetres of travel, so the
    # reversal must fall on the step grid (4 s strokes, 0.1 ms steps) for the two to reverse at the same instant.
    scene = paper.replace(**{"plate.kind": "soft", "plate.segment_inertia": 1e-4, "plate.rod_inertia": 1e-4,
                             "plate.damping": 0.05, "sim.dt": 1e-4})
    angle, force, run = _compare(scene, Drive(speed=0.025, stroke=0.1, cycles=1))
    assert angle < 0.1
    assert force < 3e-3 * run.peak_drive_force
    assert np.degrees(np.abs(run.hinge_angle).max()) > 20.0


def test_reference_shares_no_code_with_what_it_checks():
    # Only plain data from finrft (the drive and, for type hints, the scene); the law, the stop, the robot's parts
    # are written out anew there.
    tree = ast.parse(Path(reference.__file__).read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.level}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert imported <= {"drive", "scene", "numpy", "scipy.integrate", "dataclasses", "typing", "__future__"}, imported
    with pytest.raises(ValueError, match="reference solves the paper"):
        reference.solve(preset("paper").replace(**{"rft.law": "table", "rft.table": "forces.csv"}), Drive(), [0.0])
