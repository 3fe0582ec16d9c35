"""finrft.laws.drft: DRFT's dynamic inertial term on top of the surface laws, against its closed form on a plate
(lambda rho_c v^2 A), its C twin, its speed^2 scaling, its dissipation and the default's bit-identity."""

import ctypes

import mujoco
import numpy as np
import pytest
from test_attach import body_xml, passive

from finrft import native
from finrft.attach import attach
from finrft.cli import main
from finrft.experiments.intrusion import intrude
from finrft.laws import drft, li2013, rft3d
from finrft.experiments.intrusion import IntrusionScene
from finrft.scene import SceneError, scene_from_dict

RNG = np.random.default_rng(2021)
RFT3D = {"law": "rft3d", "rho_c": 1500.0, "mu_int": 0.4, "mu_surf": 0.3}
LI2013 = {"bulk_density": 1500.0}


def off(law):
    """A law's arguments with the term off: li2013's density is the term's alone, and refused without it."""
    return {k: v for k, v in law.items() if k != "bulk_density"}
# 4 cm x 6 cm horizontal plate, its lower face 5 cm deep, on a vertical slide
FLAT = body_xml('<geom type="box" size="0.02 0.03 0.0005" pos="0 0 -0.0495" mass="1"/>',
                '<joint type="slide" axis="0 0 1"/>')
AREA = 0.04 * 0.06


def random_elements(n):
    normal = RNG.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    velocity = RNG.normal(scale=0.5, size=(n, 3))
    return normal, velocity, RNG.uniform(-0.01, 0.05, n), RNG.uniform(1e-6, 1e-4, n)


@pytest.mark.parametrize("law", [LI2013, RFT3D])
@pytest.mark.parametrize("backend", ["native", "python"])
def test_horizontal_plate_pushed_down_takes_lambda_rho_v2_a_more(law, backend):
    speed, lam = 0.8, 1.7
    still, _ = passive(FLAT, [-speed], backend=backend, **off(law))
    fast, attached = passive(FLAT, [-speed], backend=backend, drft_lambda=lam, **law)
    assert attached.drft_lambda == lam and attached.bulk_density == 1500.0
    assert fast[0] - still[0] == pytest.approx(lam * 1500.0 * speed ** 2 * AREA, rel=1e-9)  # 3.917 N, up
    assert still[0] > 10  # the quasi-static force, unchanged underneath


@pytest.mark.parametrize("law", [LI2013, RFT3D])
def test_term_goes_as_speed_squared_and_leaves_the_quasi_static_part(law):
    xml = body_xml('<geom type="box" size=".02 .01 .005" pos="0 0 -0.02" mass=".1"/>'
                   '<geom type="capsule" fromto="0 0 -.01 .03 .02 -.04" size=".006"/>', '<joint type="free"/>')
    for _ in range(3):
        qvel = RNG.normal(scale=[0.2, 0.2, 0.2, 3, 3, 3])
        # the bare laws (v_reg = 0): the ramp of the regularisation is rate-dependent by design
        static = [passive(xml, k * qvel, backend="python", v_reg=0.0, **off(law))[0] for k in (1, 2)]
        total = [passive(xml, k * qvel, backend="python", drft_lambda=1.0, v_reg=0.0, **law)[0] for k in (1, 2)]
        np.testing.assert_allclose(static[1], static[0], rtol=1e-9, atol=1e-9 * np.abs(static[0]).max())
        extra = [t - s for t, s in zip(total, static)]
        assert np.abs(extra[0]).max() > 1e-3
        np.testing.assert_allclose(extra[1], 4 * extra[0], rtol=1e-9, atol=1e-9 * np.abs(extra[1]).max())


def test_numpy_closed_form_and_only_leading_submerged_elements():
    normal = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [0.6, 0, 0.8]])
    velocity = np.array([[0, 0, -2.0], [0, 0, 2.0], [0, 0, -2.0], [1.0, 0, 0]])
    force = drft.element_forces(normal, velocity, [0.02, 0.02, -0.01, 0.02], [1e-4] * 4, 0.5, 2000.0)
    np.testing.assert_allclose(force[0], [0, 0, 0.5 * 2000.0 * 4 * 1e-4], rtol=1e-15)
    assert not force[1:3].any()  # trailing; above the surface
    np.testing.assert_allclose(force[3], -0.5 * 2000.0 * 0.36 * 1e-4 * normal[3], rtol=1e-15)


def test_dissipates_with_and_without_the_quasi_static_part():
    normal, velocity, depth, area = random_elements(20000)
    inertial = drft.element_forces(normal, velocity, depth, area, 2.0, 1500.0)
    power = np.einsum("ij,ij->i", inertial, velocity)
    assert (power <= 0).all() and (power < 0).sum() > 5000
    # Li 2013 dissipates on every element; the sum does too
    total = inertial + li2013.element_forces(normal, velocity, depth, area, 1.0)
    assert (np.einsum("ij,ij->i", total, velocity) <= 0).all()
    # 3D-RFT alone feeds energy in on a few grazing elements (test_rft3d.py); the term never adds to that
    quasi = rft3d.element_forces(normal, velocity, depth, area, 1500.0, 0.4, 0.3)
    assert (np.einsum("ij,ij->i", quasi + inertial, velocity) <= np.einsum("ij,ij->i", quasi, velocity)).all()


@pytest.fixture(scope="module")
def library():
    assert native.available(), native._status["error"]
    lib = ctypes.CDLL(str(native.library_path()))
    double_p = ctypes.POINTER(ctypes.c_double)
    lib.finrft_drft_element_force.argtypes = [ctypes.c_double, ctypes.c_double, double_p, double_p, ctypes.c_double,
                                              ctypes.c_double, double_p]
    return lib


def _p(array):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def test_c_twin_equals_numpy(library):
    n = 3000
    normal, velocity, depth, area = random_elements(n)
    lam = RNG.uniform(0, 3, n)
    expected = np.array([drft.element_forces(normal[i], velocity[i], depth[i], area[i], lam[i], 1600.0)
                         for i in range(n)])
    assert np.abs(expected).max(axis=1).astype(bool).sum() > n / 3
    out = np.zeros(3)
    for i in range(n):
        library.finrft_drft_element_force(lam[i], 1600.0, _p(normal[i].copy()), _p(velocity[i].copy()), depth[i],
                                          area[i], _p(out))
        np.testing.assert_allclose(out, expected[i], rtol=1e-9, atol=1e-9 * max(np.abs(expected[i]).max(), 1e-300))


@pytest.mark.parametrize("law", [LI2013, RFT3D])
def test_native_plugin_equals_python_backend(law):
    xml = body_xml('<geom type="box" size=".02 .01 .005" mass=".1"/>'
                   '<geom type="ellipsoid" size=".015 .008 .01" pos=".02 -.01 .01" euler="10 0 40"/>',
                   '<joint type="free"/>')
    for _ in range(4):
        quat = RNG.normal(size=4)
        qpos = np.concatenate([[0.01, -0.02, RNG.uniform(-0.03, 0.0)], quat / np.linalg.norm(quat)])
        qvel = RNG.normal(scale=[0.5, 0.5, 0.5, 5, 5, 5])
        fast, _ = passive(xml, qvel, qpos, drft_lambda=2.0, element_size=0.003, **law)
        slow, _ = passive(xml, qvel, qpos, backend="python", drft_lambda=2.0, element_size=0.003, **law)
        still, _ = passive(xml, qvel, qpos, backend="python", element_size=0.003, **off(law))
        assert np.abs(slow - still).max() > 1e-2
        np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-9 * np.abs(slow).max())


def _forces(medium, speed=0.5):
    scene = scene_from_dict({"medium": medium, "plate": {"speed": speed}}, IntrusionScene)
    run = intrude(scene, [0.0])[0]
    return run.depth, run.force_z, run.force_x


def test_off_by_default_bit_identical():
    plain = _forces({})
    for a, b in zip(plain, _forces({"drft_lambda": 0.0})):
        assert np.array_equal(a, b)
    # a density the term would not use is refused rather than ignored
    with pytest.raises(SceneError, match="medium.bulk_density is used by drft_lambda > 0"):
        _forces({"drft_lambda": 0.0, "bulk_density": 1500.0})


def test_intrusion_at_two_speeds_differs_by_lambda_rho_v2_a():
    medium = {"drft_lambda": 1.0, "bulk_density": 1500.0}
    p = IntrusionScene().plate
    (d1, f1, _), (d2, f2, _) = _forces(medium, 0.5), _forces(medium, 1.0)
    submerged = d2 > p.thickness + 1e-3
    assert submerged.sum() >= 4
    # the quasi-static force is linear in depth on the submerged plate: interpolation is exact there
    slow = np.interp(d2[submerged], d1, f1)
    expected = 1.0 * 1500.0 * (1.0 ** 2 - 0.5 ** 2) * p.width * p.length  # 1.069 N
    np.testing.assert_allclose(f2[submerged] - slow, expected, rtol=1e-6)


def test_bad_input_names_what_to_set(capsys):
    spec = mujoco.MjSpec.from_string(FLAT)
    with pytest.raises(SceneError, match="attach: drft_lambda > 0 needs the medium's bulk density: set bulk_density"):
        attach(spec, ["probe"], drft_lambda=1.0)
    with pytest.raises(SceneError, match="drft_lambda must be >= 0"):
        attach(spec, ["probe"], drft_lambda=-1.0, bulk_density=1500.0)
    with pytest.raises(SceneError, match="bulk_density is rho_c by the scene files. name: give one of them"):
        attach(spec, ["probe"], drft_lambda=1.0, **RFT3D, **LI2013)
    with pytest.raises(SceneError, match="set medium.bulk_density"):
        scene_from_dict({"medium": {"drft_lambda": 1.0}}, IntrusionScene)
    assert main(["intrude", "--angles", "0", "--set", "medium.drft_lambda=1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "medium.bulk_density" in err and "Traceback" not in err
