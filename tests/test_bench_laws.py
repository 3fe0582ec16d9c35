"""`finrft bench laws`: the native entry point it times gives each law's forces, as the numpy twins give them."""

import math

import numpy as np
import pytest

from finrft import media, native
from finrft.laws import li2013, li2013_planar, rft3d
from finrft.studies import bench


def _law_forces(law: str, elements: dict[str, np.ndarray], repeat: int = 2) -> tuple[int, np.ndarray]:
    force = np.full((len(elements["depth"]), 3), np.nan)
    return bench.law_forces_call(law, elements, force, repeat)(), force


def test_the_elements_lead_below_the_surface_facing_every_way():
    elements = bench.law_elements()
    assert (np.einsum("ij,ij->i", elements["normal"], elements["velocity"]) > 0).all()
    assert (elements["depth"] > 0).all()
    np.testing.assert_allclose(np.linalg.norm(elements["normal"], axis=1), 1, rtol=1e-15)
    # every octant of normals and of velocities holds about an eighth of the elements
    for key in ("normal", "velocity"):
        octant = (elements[key] > 0) @ [1, 2, 4]
        assert np.bincount(octant, minlength=8).min() > len(octant) / 16


@pytest.mark.parametrize("law", bench.LAW_MEDIA)
def test_the_timed_loop_gives_the_numpy_twins_forces(law):
    assert native.available(), native._status["error"]
    elements = bench.law_elements(200, seed=3)
    code, force = _law_forces(law, elements)
    coef, scale, mu_surf = bench._law_constants(law)
    args = (elements["normal"], elements["velocity"], elements["depth"], elements["area"])
    if law == "rft3d":
        medium = media.medium(bench.LAW_MEDIA[law])
        rho_c, mu_int = medium.get("bulk_density").value, math.tan(medium.get("internal_friction_angle").value)
        expected = rft3d.element_forces(*args, rho_c, mu_int, bench.RFT3D_MU_SURF)
    else:
        form = li2013 if law == "li2013" else li2013_planar
        expected = form.element_forces(*args, scale, li2013.Coefficients(*coef))
    assert code == 0
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_an_unknown_law_is_refused():
    code, force = _law_forces("li2014", bench.law_elements(4))
    assert code == -1 and np.isnan(force).all()


def test_the_bench_gives_each_law_its_time_per_call():
    figures = bench.laws(log=lambda text: None)
    assert set(figures["ns_per_call"]) == set(bench.LAW_MEDIA)
    assert all(ns > 0 for ns in figures["ns_per_call"].values())
