"""The 3D-RFT law of Agarwal, Goldman & Kamrin 2023: its sanity value, its reduction to Li et al. 2013's 2D law in
the vertical plane (which decides between the two public coefficient sets), the frame-free form against the angles,
the friction cap, dissipation (and where it fails), the C twin, and attach on both backends."""

import ctypes
import dataclasses
import json

import mujoco
import numpy as np
import pytest
from test_attach import passive as attach_passive

from finrft import native
from finrft.attach import attach
from finrft.cli import main
from finrft.laws import li2013, rft3d
from finrft.scene import SceneError

RNG = np.random.default_rng(2023)
PAPER = rft3d.AGARWAL_2023
# The other public transcription (jnskkmhr/IsaacLab soft_contact_model.py, Material3DRFTCfg): c2 of T_17 and c3 of
# T_16 differ.
c2, c3 = list(PAPER.c2), list(PAPER.c3)
c2[16], c3[15] = 0.18519, -0.20770
ISAACLAB = dataclasses.replace(PAPER, c2=tuple(c2), c3=tuple(c3))


@pytest.mark.parametrize("coefficients, value", [(PAPER, 0.87504), (ISAACLAB, 1.05614)])
def test_horizontal_plate_pushed_down(coefficients, value):
    # beta = 0, gamma = 90 deg: p1 = p2 = p3 = 1, every T_i = 1, alpha_gen = (0, 0, -sum(c1 + c2 + c3)) at any psi
    np.testing.assert_array_equal(rft3d.terms(1.0, 1.0, 1.0), np.ones(20))
    assert -sum(coefficients.values()) == pytest.approx(value, abs=1e-12)
    for psi in (0.0, 0.7, -1.2):
        np.testing.assert_allclose(rft3d.alpha_gen(0.0, np.pi / 2, psi, coefficients), [0, 0, value], atol=1e-6)
    # an element 2 cm deep, 1 cm^2, pushed down in a medium of rho_c = 1500 kg/m^3, mu_int = 0.4:
    # xi_n = 1500 x 9.81 x (894 x 0.064 - 386 x 0.16 + 89 x 0.4) = 1500 x 9.81 x 31.056 N/m^3
    assert rft3d.xi(1500.0, 0.4) == pytest.approx(456989.04, rel=1e-12)
    force = rft3d.element_forces([[0, 0, -1.0]], [[0, 0, -0.05]], [0.02], [1e-4], 1500.0, 0.4, 0.3, coefficients)
    np.testing.assert_allclose(force, [[0, 0, 456989.04 * value * 0.02 * 1e-4]], rtol=1e-9, atol=1e-12)


BETA, GAMMA = np.meshgrid(np.linspace(-np.pi / 2, np.pi / 2, 181), np.linspace(-np.pi / 2, np.pi / 2, 181),
                          indexing="ij")


def reduction(coefficients):
    """3D-RFT at psi = 0 against Li et al.'s generic 2D law (both normalised to about 1 for a horizontal plate
    pushed down; Li's x axis is -r): rms differences of alpha_r and alpha_z in those units, and the share of the
    extraction half (gamma < 0) where Li's |alpha_z| >= 0.1 and the two disagree in sign."""
    alpha = rft3d.alpha_gen(BETA, GAMMA, 0.0, coefficients)
    x, z = (a / li2013.N_PER_CM3 for a in li2013.alpha(BETA, GAMMA))
    firm = (GAMMA < 0) & (np.abs(z) >= 0.1)
    wrong = np.sign(alpha[..., 2][firm]) != np.sign(z[firm])
    return (np.sqrt(np.mean((alpha[..., 0] + x) ** 2)), np.sqrt(np.mean((alpha[..., 2] - z) ** 2)), wrong.mean(),
            np.abs(alpha[..., 1]).max())


def test_in_the_vertical_plane_3d_rft_is_li2013s_2d_rft():
    # Measured: alpha_r rms 0.077 for both sets; alpha_z rms 0.123 (paper set) vs 0.155 (IsaacLab set); the sign of
    # alpha_z on extraction wrong on 14 % vs 54 % of the firm part of that half. Neither is Li's fit to better than
    # ~0.1 (a refit on other data), but only the paper set keeps its extraction physics.
    r, z, wrong, theta = reduction(PAPER)
    assert theta == 0.0                   # psi = 0: the stress stays in the plane of motion
    assert r < 0.08 and z < 0.125 and wrong < 0.15
    r_other, z_other, wrong_other, _ = reduction(ISAACLAB)
    assert r_other == pytest.approx(r, abs=1e-3)  # the c2 entries differ by 7e-4
    assert z_other > 0.15 and wrong_other > 0.5


def test_horizontal_plate_pulled_up_is_held_back():
    # beta = 0, gamma = -90 deg (Li: alpha_z = -0.250 N/cm^3, pulling down): p = (-1, 1, -1), T_i = +-1 and
    # alpha_z = -f1 + f2 - f3. The IsaacLab set pushes the plate up.
    signs = np.array([1, -1, 1, -1, 1, 1, 1, -1, -1, 1, -1, 1, -1, -1, 1, 1, -1, -1, -1, 1])
    for coefficients, value in ((PAPER, -0.07966), (ISAACLAB, 0.10144)):
        f1, f2, f3 = (signs @ np.array(c) for c in (coefficients.c1, coefficients.c2, coefficients.c3))
        assert -f1 + f2 - f3 == pytest.approx(value, abs=1e-12)
        np.testing.assert_allclose(rft3d.alpha_gen(0.0, -np.pi / 2, 0.0, coefficients), [0, 0, value], atol=1e-6)


def random_leading(n, rng):
    normal = rng.normal(size=(n, 3))
    velocity = rng.normal(size=(n, 3))
    normal[: n // 10, :2] = 0          # horizontal faces
    velocity[n // 20: n // 5, :2] = 0   # vertical motion
    velocity[n // 5: n // 4, 2] = 0     # horizontal motion
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    velocity *= np.sign(np.einsum("ij,ij->i", normal, velocity))[:, None]
    return normal, velocity


def test_frame_free_form_equals_the_angles_form():
    # element_forces evaluates alpha_gen = f1 n_low + f2 v - f3 z; alpha_gen() evaluates the paper's components in
    # (r, theta, z) from the angles. Uncapped (mu_surf huge), unit scale.
    normal, velocity = random_leading(2000, RNG)
    beta, gamma, psi = rft3d.angles(normal, velocity)
    assert (np.abs(beta) <= np.pi / 2).all() and (np.abs(gamma) <= np.pi / 2).all()
    assert (psi > -np.pi / 2).all() and (psi <= np.pi / 2).all()
    local = rft3d.alpha_gen(beta, gamma, psi)
    horizontal = np.where((np.hypot(velocity[:, 0], velocity[:, 1]) > 0)[:, None], velocity, normal)[:, :2]
    length = np.linalg.norm(horizontal, axis=1, keepdims=True)
    r = np.where(length > 0, horizontal / np.where(length > 0, length, 1), [1.0, 0.0])
    world = np.column_stack([local[:, 0] * r[:, 0] - local[:, 1] * r[:, 1],
                             local[:, 0] * r[:, 1] + local[:, 1] * r[:, 0], local[:, 2]])
    unit = rft3d.xi(1.0, 1.0) ** -1
    force = rft3d.element_forces(normal, velocity, np.ones(2000), np.full(2000, unit), 1.0, 1.0, 1e12)
    np.testing.assert_allclose(force, world, atol=1e-12)
    # the angles rebuild the lower face's normal
    low = np.column_stack([np.sin(beta) * np.cos(psi), np.sin(beta) * np.sin(psi), -np.cos(beta)])
    expected = np.where((normal[:, 2] < 0)[:, None], normal, -normal)
    local_low = np.column_stack([expected[:, 0] * r[:, 0] + expected[:, 1] * r[:, 1],
                                 -expected[:, 0] * r[:, 1] + expected[:, 1] * r[:, 0], expected[:, 2]])
    np.testing.assert_allclose(low, local_low, atol=1e-12)


@pytest.mark.parametrize("mu_surf", [0.0, 0.2, 0.5])
def test_friction_caps_the_tangential_stress(mu_surf):
    normal, velocity = random_leading(3000, RNG)
    free = rft3d.element_forces(normal, velocity, np.ones(3000), np.ones(3000), 1.0, 1.0, 1e12)
    capped = rft3d.element_forces(normal, velocity, np.ones(3000), np.ones(3000), 1.0, 1.0, mu_surf)
    along = np.einsum("ij,ij->i", capped, normal)
    np.testing.assert_allclose(along, np.einsum("ij,ij->i", free, normal), rtol=1e-12, atol=1e-12)
    tangential = np.linalg.norm(capped - along[:, None] * normal, axis=1)
    free_tangential = np.linalg.norm(free - along[:, None] * normal, axis=1)
    tolerance = 1e-12 * np.linalg.norm(free, axis=1)
    assert (tangential <= mu_surf * np.abs(along) + tolerance).all()
    assert (np.abs(tangential - np.minimum(free_tangential, mu_surf * np.abs(along))) <= tolerance).all()
    assert (free_tangential > mu_surf * np.abs(along)).mean() > 0.2  # the cap acts often


def test_dissipation_fails_only_on_small_stresses_of_grazing_faces():
    # F . v <= 0 per element, except (found by sampling, not hidden): the fit's normal stress pulls outward on
    # 4.9 % of leading (normal, velocity) pairs, all grazing (n . v < 0.2 of the speed). With mu_surf = 0 the force
    # is that normal stress alone and feeds energy in there; surface friction mostly hides it (0.06 % of pairs left
    # for mu_surf >= 0.2, upward faces rising, n . v < 0.33). Power at most 0.8 % of a horizontal plate pushed
    # down, per unit speed. The IsaacLab set feeds in up to 10 % (a horizontal plate pulled straight up).
    normal = RNG.normal(size=(400000, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    velocity = RNG.normal(size=(400000, 3))
    depth, area = RNG.uniform(1e-3, 0.1, 400000), RNG.uniform(1e-6, 1e-4, 400000)
    speed = np.linalg.norm(velocity, axis=1)
    slip = np.einsum("ij,ij->i", normal, velocity) / speed
    leading = slip > 0

    def power(mu_surf, coefficients=PAPER):
        force = rft3d.element_forces(normal, velocity, depth, area, 1500.0, 0.4, mu_surf, coefficients)
        return np.einsum("ij,ij->i", force, velocity) / (rft3d.xi(1500.0, 0.4) * depth * area * speed)

    for mu_surf, share in ((0.0, 0.055), (0.2, 1e-3), (0.3, 1e-3), (1.0, 1e-3)):
        p = power(mu_surf)
        bad = p > 0
        assert 0 < bad.sum() / leading.sum() < share
        assert slip[bad].max() < 0.33 and p.max() < 0.008 and p.min() < -0.5
        if mu_surf >= 0.2:
            assert normal[bad, 2].min() > 0.3 and (velocity[bad, 2] / speed[bad]).min() > -0.25
    assert power(0.3, ISAACLAB).max() > 0.09


def test_only_leading_submerged_elements_feel_the_medium():
    normal = np.array([[1.0, 0, 0]] * 3)
    velocity = np.array([[-0.1, 0, 0], [0.1, 0, 0], [0.1, 0, 0]])
    force = rft3d.element_forces(normal, velocity, [0.02, -0.01, 0.02], [1e-4] * 3, 1500.0, 0.4, 0.3)
    assert not force[:2].any() and force[2, 0] < 0
    assert not rft3d.element_forces([[0, 0, -1.0]], [[0, 0, 0.0]], [0.02], [1e-4], 1500.0, 0.4, 0.3).any()


@pytest.fixture(scope="module")
def library():
    assert native.available(), native._status["error"]
    lib = ctypes.CDLL(str(native.library_path()))
    double_p = ctypes.POINTER(ctypes.c_double)
    lib.finrft_rft3d_element_force.argtypes = [double_p, ctypes.c_double, ctypes.c_double, double_p, double_p,
                                               ctypes.c_double, ctypes.c_double, double_p]
    return lib


def _p(array):
    return array.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@pytest.mark.parametrize("coefficients", [PAPER, ISAACLAB])
def test_c_twin_element_force_equals_numpy(library, coefficients):
    coef = np.array(coefficients.values())
    n = 3000
    normal, velocity = random_leading(n, RNG)
    velocity[::3] *= -1  # trailing ones too
    depth = RNG.uniform(-0.01, 0.05, n)
    area = RNG.uniform(1e-6, 1e-4, n)
    mu_surf = RNG.choice([0.0, 0.3, 100.0], n)
    xi = rft3d.xi(1600.0, 0.45)
    out = np.zeros(3)
    expected = np.array([rft3d.element_forces(normal[i], velocity[i], depth[i], area[i], 1600.0, 0.45,
                                              mu_surf[i], coefficients) for i in range(n)])
    assert np.abs(expected).max(axis=1).astype(bool).sum() > n / 3
    for i in range(n):
        library.finrft_rft3d_element_force(_p(coef), xi, mu_surf[i], _p(normal[i].copy()), _p(velocity[i].copy()),
                                           depth[i], area[i], _p(out))
        np.testing.assert_allclose(out, expected[i], rtol=1e-12, atol=1e-12 * max(np.abs(expected[i]).max(), 1e-300))


MEDIUM = {"rho_c": 1500.0, "mu_int": 0.4, "mu_surf": 0.3}


def passive(xml, qvel, qpos=None, backend="native", **kwargs):
    """test_attach's probe with the rft3d law in the test medium."""
    return attach_passive(xml, qvel, qpos, backend, law="rft3d", **{**MEDIUM, **kwargs})


def body(geoms, joint='<joint type="free"/>', pos="0 0 0"):
    return f"""<mujoco><option gravity="0 0 0"/><worldbody><body name="probe" pos="{pos}">{joint}{geoms}</body>
      </worldbody></mujoco>"""


@pytest.mark.parametrize("backend", ["native", "python"])
def test_attach_horizontal_plate_pushed_down(backend):
    # the bottom face 5 cm deep, 4 cm x 6 cm: xi_n x 0.87504 x 0.05 m x 24 cm^2 up; its sides move parallel to
    # themselves and take nothing
    xml = body('<geom type="box" size="0.02 0.03 0.0005" pos="0 0 -0.0495" mass="1"/>',
               '<joint type="slide" axis="0 0 1"/>')
    force, attached = passive(xml, [-0.05], backend=backend)
    assert attached.law == "rft3d" and attached.coefficients is PAPER
    assert force[0] == pytest.approx(rft3d.xi(1500.0, 0.4) * 0.87504 * 0.05 * 0.0024, rel=1e-9)


def test_attach_native_equals_python():
    xml = body("""<geom type="box" size=".02 .01 .005" mass=".1"/>
                  <geom type="capsule" fromto="0 0 0 .03 .02 -.03" size=".006"/>
                  <geom type="ellipsoid" size=".015 .008 .01" pos=".02 -.01 .01" euler="10 0 40"/>""")
    for _ in range(5):
        quat = RNG.normal(size=4)
        qpos = np.concatenate([[0.01, -0.02, RNG.uniform(-0.03, 0.01)], quat / np.linalg.norm(quat)])
        qvel = RNG.normal(scale=[0.1, 0.1, 0.1, 3, 3, 3])
        fast, attached = passive(xml, qvel, qpos, element_size=0.003)
        slow, _ = passive(xml, qvel, qpos, backend="python", element_size=0.003)
        assert np.abs(fast).max() > 0.1 and sum(attached.elements.values()) > 200
        np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-9 * np.abs(slow).max())


@pytest.mark.parametrize("kwargs, message", [
    ({"rho_c": None}, "law rft3d needs rho_c"),
    ({"mu_surf": None}, "law rft3d needs mu_surf"),
    ({"mu_int": 0.0}, "mu_int must be > 0"),
    ({"rho_c": float("nan")}, "rho_c must be > 0"),
    ({"mu_surf": -0.1}, "mu_surf must be >= 0"),
    ({"coefficients": li2013.GENERIC}, "takes finrft.laws.rft3d.Coefficients"),
    ({"law": "li2013"}, "rho_c, mu_int, mu_surf belong to law rft3d"),
])
def test_bad_input_names_the_problem(kwargs, message):
    spec = mujoco.MjSpec.from_string(body('<geom size=".01"/>'))
    with pytest.raises(SceneError, match=message):
        attach(spec, ["probe"], **{"law": "rft3d", **MEDIUM, **kwargs})


def _last_json(out):
    return json.loads(out.strip().splitlines()[-1])


def test_law_rft3d_json_is_the_vertical_plane_in_units_of_xi(capsys):
    assert main(["law", "rft3d", "--json", "--quiet"]) == 0
    data = _last_json(capsys.readouterr().out)
    assert list(data) == ["law", "units", "beta_deg", "gamma_deg", "alpha_x", "alpha_z"] and data["law"] == "rft3d"
    assert {len(data[k]) for k in list(data)[2:]} == {37 * 37}
    at = {(b, g): (x, z) for b, g, x, z in zip(data["beta_deg"], data["gamma_deg"], data["alpha_x"], data["alpha_z"])}
    # the generic medium has no bulk density: xi_n = 1 N/cm^3, so a horizontal plate pushed down takes 0.87504
    assert at[(0, 90)] == pytest.approx((0.0, 0.87504), abs=1e-6)
    assert at[(0, -90)][1] == pytest.approx(-0.07966, abs=1e-6)  # pulled up: held back
    # Li's x axis is -r: the map's alpha_x is -alpha_r of the law at psi = 0, and alpha_z the law's
    for (b, g), (x, z) in list(at.items())[::97]:
        r, theta, vertical = rft3d.alpha_gen(np.radians(b), np.radians(g), 0.0)
        assert (x, z) == pytest.approx((-r, vertical), abs=1e-12)


def test_law_rft3d_in_a_medium_with_its_values(monkeypatch, capsys):
    from finrft import media
    poppy = media.medium("poppy_seeds_lp")
    values = {**poppy.values, "bulk_density": media.Value(1500.0, "kg/m^3", "test"),
              "internal_friction_angle": media.Value(np.arctan(0.4), "rad", "test")}
    monkeypatch.setattr(media, "medium", lambda name: dataclasses.replace(poppy, values=values))
    assert main(["law", "rft3d", "--medium", "poppy_seeds_lp", "--json"]) == 0
    out, err = capsys.readouterr()
    data = json.loads(out)
    i = list(zip(data["beta_deg"], data["gamma_deg"])).index((0, 90))
    assert data["alpha_z"][i] == pytest.approx(0.87504 * rft3d.xi(1500.0, 0.4) / 1e6, rel=1e-5)  # 0.3999 N/cm^3
    assert "xi_n = 0.457 N/cm^3" in err  # the text goes to stderr beside --json


def test_law_rft3d_plot_and_media_it_cannot_scale(tmp_path, capsys):
    png = tmp_path / "map.png"
    assert main(["law", "rft3d", "--plot", str(png), "--quiet"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["law", "rft3d", "--medium", "poppy_seeds_cp", "--json"]) == 2
    captured = capsys.readouterr()
    assert len(captured.err.strip().splitlines()) == 1 and not captured.out
    assert "bulk_density nor internal_friction_angle" in captured.err and "Traceback" not in captured.err


def test_a_scene_file_selects_rft3d(tmp_path):
    # [medium] law = "rft3d" on the intrusion: a horizontal plate pushed straight down takes xi_n x 0.87504 (the
    # fit's sum, see test_horizontal_plate_pushed_down) x its area x its depth, upwards, nothing sideways.
    from finrft.experiments.intrusion import intrude
    from finrft.experiments.intrusion import IntrusionScene
    from finrft.scene import load_scene, scene_from_dict

    path = tmp_path / "intrusion.toml"
    path.write_text('[medium]\nlaw = "rft3d"\nbulk_density = 1500.0\ninternal_friction = 0.4\n'
                    'surface_friction = 0.3\n\n[plate]\ndepth = 0.03\n')
    scene = load_scene(path, cls=IntrusionScene)
    run = intrude(scene, [0.0])[0]
    p, deep = scene.plate, run.depth > 0.01
    up = rft3d.alpha_gen(0.0, np.pi / 2, 0.0)[2]
    assert up == pytest.approx(0.87504, abs=1e-6)
    assert run.force_z[deep] == pytest.approx(rft3d.xi(1500.0, 0.4) * up * p.width * p.length * run.depth[deep],
                                              rel=1e-6)
    assert np.abs(run.force_x).max() < 1e-9 * np.abs(run.force_z).max()
    for medium, message in [({"law": "rft3d", "internal_friction": 0.4}, "rft3d needs medium.bulk_density"),
                            ({"law": "rft3d", "bulk_density": 1500.0}, "rft3d needs medium.internal_friction"),
                            ({"law": "surface"}, "use one of li2013, li2013-planar, rft3d")]:
        with pytest.raises(SceneError, match=message):
            scene_from_dict({"medium": medium}, IntrusionScene)
