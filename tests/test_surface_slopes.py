"""The surface laws' analytic velocity Jacobians (li2013 in 3D, rft3d; `element_slopes`), which the implicit steps
take for each element: against central differences of the force, with the ramp and DRFT's term
(`Attached.element_slopes`), and the C twins (finrft_*_element_slope) against the numpy ones."""

import ctypes

import mujoco
import numpy as np
import pytest

from finrft import media, native
from finrft.attach import attach
from finrft.laws import li2013, rft3d

RNG = np.random.default_rng(41)
RFT3D = (1617.0, 1.07)  # rho_c, mu_int: the hexapod's sand


def _elements(n: int = 2000):
    """Leading elements below the surface of every orientation: horizontal and nearly horizontal faces (li2013's
    blend), horizontal motion; not exactly vertical motion, where the velocity's own plane turns by a half turn."""
    normal = RNG.normal(size=(n, 3))
    velocity = RNG.normal(size=(n, 3))
    normal[: n // 10, :2] = 0
    normal[n // 10: n // 4, :2] *= 0.02
    velocity[n // 4: n // 3, 2] = 0
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    velocity *= np.where(np.einsum("ei,ei->e", normal, velocity) > 0, 1, -1)[:, None]
    return normal, velocity, RNG.uniform(1e-3, 0.05, n), RNG.uniform(1e-6, 1e-4, n)


def _central(force, normal, velocity, depth, area, step: float = 1e-7) -> np.ndarray:
    """dF/dv (N, 3, 3) by central differences along each axis."""
    return np.stack([(force(normal, velocity + step * e, depth, area) - force(normal, velocity - step * e, depth, area))
                     / (2 * step) for e in np.eye(3)], axis=2)


def _close(slope: np.ndarray, reference: np.ndarray, rtol: float, least: float = 0.99) -> None:
    """Each element's Jacobian within rtol of its largest entry; ``least`` of them (the rest lie on a kink of the
    law: the sign of the motion across a face, a face seen edge-on, the friction cap switching)."""
    scale = np.abs(reference).max(axis=(1, 2))
    worst = np.abs(slope - reference).max(axis=(1, 2)) / np.where(scale > 0, scale, 1.0)
    assert np.mean(worst <= rtol) >= least, np.sort(worst)[-5:]


LAWS = {"li2013": (li2013, dict(zeta=1.3)),
        "li2013-poppy": (li2013, dict(zeta=1.0, coefficients=li2013.medium_parameters(media.medium(
            "poppy_seeds_cp"))[1])),
        "rft3d-frictionless": (rft3d, dict(rho_c=RFT3D[0], mu_int=RFT3D[1], mu_surf=0.0)),
        "rft3d": (rft3d, dict(rho_c=RFT3D[0], mu_int=RFT3D[1], mu_surf=0.1806)),
        "rft3d-rough": (rft3d, dict(rho_c=RFT3D[0], mu_int=RFT3D[1], mu_surf=0.6))}


@pytest.mark.parametrize("name", LAWS)
def test_element_slopes_are_the_derivative_of_the_force(name):
    law, parameters = LAWS[name]
    normal, velocity, depth, area = _elements()
    force, slope = law.element_slopes(normal, velocity, depth, area, **parameters)
    np.testing.assert_allclose(force, law.element_forces(normal, velocity, depth, area, **parameters),
                               rtol=1e-12, atol=1e-12 * np.abs(force).max())
    central = _central(lambda *a: law.element_forces(*a, **parameters), normal, velocity, depth, area)
    _close(slope, central, 1e-6)
    # the law depends on the direction of v alone: dF/dv v = 0
    np.testing.assert_allclose(np.einsum("eij,ej->ei", slope, velocity), 0, atol=1e-9 * np.abs(force).max())


@pytest.mark.parametrize("medium", [dict(law="li2013", v_reg=1e-3),
                                    dict(law="rft3d", rho_c=RFT3D[0], mu_int=RFT3D[1], mu_surf=0.1806, v_reg=1e-3,
                                         drft_lambda=2.0)])
def test_attached_slopes_take_the_ramp_and_drfts_term(medium):
    spec = mujoco.MjSpec.from_string('<mujoco><worldbody><body name="box"><freejoint/>'
                                     '<geom type="box" size="0.05 0.05 0.01"/></body></worldbody></mujoco>')
    attached = attach(spec, "box", backend="python", element_size=0.01, **medium)
    normal, velocity, depth, area = _elements()
    velocity *= 0.02 / np.linalg.norm(velocity, axis=1, keepdims=True)
    # a third on the ramp: n . v = 3e-4 m/s, 0.3 v_reg
    third = len(area) // 3
    velocity[:third] -= (np.einsum("ei,ei->e", normal[:third], velocity[:third]) - 3e-4)[:, None] * normal[:third]
    force, slope = attached.element_slopes(normal, velocity, depth, area)
    np.testing.assert_allclose(force, attached.element_forces(normal, velocity, depth, area), rtol=1e-12,
                               atol=1e-12 * np.abs(force).max())
    _close(slope, _central(attached.element_forces, normal, velocity, depth, area, 1e-9), 1e-5)


@pytest.fixture(scope="module")
def library():
    assert native.available(), native._status["error"]
    lib = ctypes.CDLL(str(native.library_path()))
    double_p, double = ctypes.POINTER(ctypes.c_double), ctypes.c_double
    lib.finrft_li2013_element_slope.argtypes = [double_p, double, double_p, double_p, double, double, double_p,
                                                double_p]
    lib.finrft_rft3d_element_slope.argtypes = [double_p, double, double, double_p, double_p, double, double,
                                               double_p, double_p]
    return lib


def _p(array):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@pytest.mark.parametrize("name", LAWS)
def test_c_twin_element_slopes_equal_numpy(library, name):
    law, parameters = LAWS[name]
    normal, velocity, depth, area = _elements(3000)
    velocity[:100, :2] = 0  # vertical motion too: both twins take the same plane
    depth[-300:] *= -1      # above the surface: nothing
    velocity[-600:-300] *= -1  # trailing: nothing
    force, slope = law.element_slopes(normal, velocity, depth, area, **parameters)
    out, jac = np.zeros(3), np.zeros(9)
    for i in range(len(area)):
        n, v = normal[i].copy(), velocity[i].copy()
        if law is li2013:
            library.finrft_li2013_element_slope(_p(np.array(parameters.get("coefficients", li2013.GENERIC).values())),
                                                parameters["zeta"], _p(n), _p(v), depth[i], area[i], _p(out),
                                                _p(jac))
        else:
            library.finrft_rft3d_element_slope(_p(np.array(rft3d.AGARWAL_2023.values())),
                                               rft3d.xi(parameters["rho_c"], parameters["mu_int"]),
                                               parameters["mu_surf"], _p(n), _p(v), depth[i], area[i], _p(out),
                                               _p(jac))
        scale = np.abs(slope[i]).max()
        np.testing.assert_allclose(out, force[i], rtol=0, atol=1e-9 * np.abs(force[i]).max())
        np.testing.assert_allclose(jac.reshape(3, 3), slope[i], rtol=0, atol=1e-9 * scale)
        assert (scale > 0) == (depth[i] > 0 and normal[i] @ velocity[i] > 0)
