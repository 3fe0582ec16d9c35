"""Scenes shared by the physics tests."""

import pytest

from finrft.scene import Scene, preset


@pytest.fixture(scope="session")
def paper() -> Scene:
    return preset("paper")


@pytest.fixture(scope="session")
def responsive(paper: Scene) -> Scene:
    """A plate that bends and recovers within a fraction of a stroke (light inertia, little damping), with the
    penalty stop, at a time step where its results have converged (estimated error 0.005 deg; the MuJoCo limit
    stop would need a step under 50 us for 0.5 deg, see test_limit_stop_holds)."""
    return paper.replace(**{"plate.segment_inertia": 1e-2, "plate.rod_inertia": 1e-2, "plate.damping": 0.2,
                            "sim.dt": 2.5e-4})
