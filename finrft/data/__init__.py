"""Measurements shipped with finrft.

``plate_drag``: the origami plate dragged from flat at 10, 30 and 50 mm/s (see its README.md for provenance,
columns and sign convention), in the format `finrft.studies.fit.read_drag` reads.
``wheel``: a smooth wheel driven through sand at 7 slip angles x 9 rim speeds, measured forces and the
experimenters' own RFT predictions (its README.md gives provenance and conventions).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def plate_drag_dir() -> Path:
    """The folder of the plate-drag measurements (README.md and origami_v{10,30,50}.csv)."""
    return Path(str(resources.files(__name__) / "plate_drag"))



def wheel_dir() -> Path:
    """The folder of the smooth-wheel data (README.md and smooth_wheel_by_condition.csv)."""
    return Path(str(resources.files(__name__) / "wheel"))
