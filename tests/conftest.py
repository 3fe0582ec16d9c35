"""Scenes shared by the physics tests."""

import pytest

from finrft.scene import Scene, preset


@pytest.fixture(scope="session")
def paper() -> Scene:
    return preset("paper")


@pytest.fixture(scope="session")
def responsive(paper: Scene) -> Scene:
    """A plate that bends and recovers within a fraction of a stroke (light inertia, little damping), with a
    MuJoCo limit stop, at a time step where its results have converged."""
    return paper.replace(**{"plate.segment_inertia": 1e-2, "plate.rod_inertia": 1e-2, "plate.damping": 0.2,
                            "plate.stop": "limit", "sim.dt": 2.5e-4})
