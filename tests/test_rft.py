"""The RFT laws against their closed forms and each other, the registry that finds them, and each law's C twin
against its numpy source of truth."""

import math
import sys

import mujoco
import numpy as np
import pytest

from finrft import laws
from finrft.callbacks import installed
from finrft.coupling import PythonCoupling
from finrft.experiments.plate import build_plate
from finrft.laws import paper, sandswim, table
from finrft.scene import SceneError, preset

from conftest import law_cases

F_PERP, F_PAR, V_REG = 1.2, -0.2, 1e-3


def frames(angle):
    x = np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=-1)
    y = np.stack([-np.sin(angle), np.cos(angle), 0 * angle], axis=-1)
    return x, y


def paper_force(v, x, y):
    return paper.force(v, x, y, V_REG, f_perp=F_PERP, f_par=F_PAR)


@pytest.mark.parametrize("attack_deg", [0.0, 15.0, 45.0, 60.0, 90.0])
def test_paper_law_closed_form(attack_deg):
    # A segment along x moving at angle of attack theta: normal part f_perp sin(theta), tangential f_par cos(theta).
    theta = np.radians(attack_deg)
    speed = 0.03
    v = speed * np.array([[np.cos(theta), np.sin(theta), 0.0]])
    x, y = frames(np.zeros(1))
    force = paper_force(v, x, y)[0]
    ramp = np.tanh(speed / V_REG)
    np.testing.assert_allclose(force, -ramp * np.array([F_PAR * np.cos(theta), F_PERP * np.sin(theta), 0]),
                               atol=1e-15)


def test_paper_law_is_odd_in_velocity_and_vanishes_at_rest():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(50, 3)) * 0.01
    x, y = frames(rng.uniform(-np.pi, np.pi, 50))
    forward = paper_force(v, x, y)
    np.testing.assert_allclose(paper_force(-v, x, y), -forward, atol=1e-15)
    assert np.all(paper_force(np.zeros((3, 3)), x[:3], y[:3]) == 0.0)


def test_regularisation_ramp():
    x, y = frames(np.zeros(1))
    for speed in (1e-5, 1e-3, 5e-3):
        force = paper_force(np.array([[0.0, speed, 0.0]]), x, y)[0]
        assert force[1] == pytest.approx(-F_PERP * np.tanh(speed / V_REG), rel=1e-12)


def test_table_of_the_paper_law_reproduces_it():
    # Linear interpolation of sin/cos sampled every 0.25 deg is exact to ~1e-5 relative.
    forces = table.paper_table(F_PERP, F_PAR, samples=361)
    rng = np.random.default_rng(2)
    v = rng.normal(size=(200, 3)) * 0.02
    v[:, 2] = 0.0
    x, y = frames(rng.uniform(-np.pi, np.pi, 200))
    np.testing.assert_allclose(table.force(v, x, y, V_REG, table=forces), paper_force(v, x, y), atol=2e-5)


def test_table_round_trip_and_bad_tables(tmp_path):
    forces = table.paper_table(F_PERP, F_PAR, samples=19)
    path = tmp_path / "forces.csv"
    table.write_table(path, forces)
    back = table.read_table(path)
    np.testing.assert_array_equal(back.f_perp, forces.f_perp)
    np.testing.assert_array_equal(back.attack_deg, forces.attack_deg)

    (tmp_path / "cols.csv").write_text("angle,a,b\n0,1,2\n90,1,2\n")
    (tmp_path / "short.csv").write_text("attack_deg,f_perp_N_m3,f_par_N_m3\n0,0,1\n45,1,1\n")
    (tmp_path / "text.csv").write_text("attack_deg,f_perp_N_m3,f_par_N_m3\n0,x,1\n90,1,1\n")
    (tmp_path / "per_segment.csv").write_text("attack_deg,f_perp_N,f_par_N\n0,0,1\n90,1,0\n")  # not read as N/m^3
    with pytest.raises(SceneError, match="forces per segment"):
        table.read_table(tmp_path / "per_segment.csv")
    for name in ("cols.csv", "short.csv", "text.csv", "missing.csv", "per_segment.csv"):
        with pytest.raises(SceneError):
            table.read_table(tmp_path / name)


@pytest.fixture
def extra_laws(tmp_path, monkeypatch):
    """The registry with two more modules beside its own: a segment law and a module of another kind."""
    (tmp_path / "viscous.py").write_text(
        "KIND = 'segment'\n"
        "def parameters(rft):\n    return {'f_perp': rft.f_perp}\n"
        "def force(v, x_axis, y_axis, v_reg, f_perp):\n    return -f_perp * v / v_reg\n")
    (tmp_path / "surface.py").write_text("KIND = 'surface'\ndef force_at_depth(depth):\n    return depth\n")
    monkeypatch.setattr(laws, "__path__", [*laws.__path__, str(tmp_path)])
    for cache in (laws._modules, laws._registry):
        cache.cache_clear()
    yield
    monkeypatch.undo()  # the registry must be rebuilt from the package's own path
    for cache in (laws._modules, laws._registry):
        cache.cache_clear()
    for name in ("viscous", "surface"):
        sys.modules.pop(f"finrft.laws.{name}", None)


def test_registry_finds_the_laws_by_name_and_skips_other_modules(extra_laws):
    assert "viscous" in laws.names() and "surface" not in laws.names()
    # The scene's choices follow; the keys of the law it replaces fall back to the section's defaults (a key a
    # module found on the path reads is not one the section, built as finrft is imported, gives it).
    scene = preset("paper").replace(**{"rft.law": "viscous"})
    f_perp = scene.rft.f_perp
    assert f_perp > 0
    v = np.array([[0.0, 1e-3, 0.0]])
    law = laws.per_segment(scene.rft, 1.0, 1.0, 0.5)  # a law without INTENSIVE keys takes them as given
    np.testing.assert_allclose(laws.bind(law)(v, *frames(np.zeros(1))), -f_perp * v / scene.rft.v_reg)
    assert laws.plugin_config(law) == {"law": "viscous", "v_reg": repr(scene.rft.v_reg), "f_perp": repr(f_perp)}
    with pytest.raises(SceneError, match=f"use one of {', '.join(laws.names())}"):
        preset("paper").replace(**{"rft.law": "surface"})


C_S, C_F, GAMMA0 = 1.7, 0.6, np.radians(20.0)  # shapes only: no published values are built in


def sandswim_force(v, x, y, c_s=C_S, c_f=C_F, gamma0=GAMMA0):
    return sandswim.force(v, x, y, V_REG, c_s=c_s, c_f=c_f, gamma0=gamma0)


def _moving_at(psi, speed=0.05):
    """Segments along x moving in the plane at angles psi to their axis."""
    v = speed * np.stack([np.cos(psi), np.sin(psi), 0 * psi], axis=-1)
    return v, *frames(np.zeros_like(psi))


def test_sandswim_is_the_papers_formula():
    # The law's force against F_par = C_F cos psi, F_perp = C_S sin beta0 + C_F sin psi with
    # tan beta0 = cot(gamma0) sin psi written out per angle, each opposing its part of the motion.
    psi = np.radians(np.linspace(0.0, 90.0, 91))
    v, x, y = _moving_at(psi)
    ramp = np.tanh(0.05 / V_REG)
    beta0 = np.array([math.atan(math.sin(p) / math.tan(GAMMA0)) for p in psi])
    perp = C_S * np.sin(beta0) + C_F * np.sin(psi)
    par = C_F * np.cos(psi)
    force = sandswim_force(v, x, y)
    np.testing.assert_allclose(force[:, 0], -ramp * par, rtol=0, atol=1e-12)
    np.testing.assert_allclose(force[:, 1], -ramp * perp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.c_[perp, par], np.c_[sandswim.magnitudes(psi, C_S, C_F, GAMMA0)], atol=1e-12)


def test_sandswim_published_shape():
    psi = np.radians(np.linspace(0.0, 90.0, 901))
    perp, par = sandswim.magnitudes(psi, C_S, C_F, GAMMA0)
    # Broadside drag over axial drag: at psi = 90 deg, tan beta0 = cot gamma0, so sin beta0 = cos gamma0 (the
    # ratio tends to (C_S + C_F) / C_F only as gamma0 -> 0).
    assert perp[-1] / par[0] == pytest.approx((C_S * math.cos(GAMMA0) + C_F) / C_F, rel=1e-12)
    assert perp[0] == 0.0 and par[-1] == pytest.approx(0.0, abs=1e-15) and par[0] == C_F
    assert np.all(np.diff(perp) > 0) and np.all(np.diff(par) < 0)  # rises to its broadside value, as in the figures
    # The steep rise at small psi that gamma0 sets: dF_perp/dpsi(0) = C_S cot gamma0 + C_F.
    slope = (sandswim.magnitudes(1e-7, C_S, C_F, GAMMA0)[0]) / 1e-7
    assert slope == pytest.approx(C_S / math.tan(GAMMA0) + C_F, rel=1e-6)


def test_sandswim_without_c_s_is_isotropic_friction_and_speed_independent():
    rng = np.random.default_rng(7)
    v = rng.normal(size=(100, 3))
    v *= 0.05 / np.linalg.norm(v, axis=1, keepdims=True)  # 50 v_reg: the ramp is 1
    x, y = frames(rng.uniform(-np.pi, np.pi, 100))
    # C_S = 0 leaves Coulomb-like drag C_F opposite the motion: the paper law with f_perp = f_par = C_F.
    np.testing.assert_allclose(sandswim_force(v, x, y, c_s=0.0),
                               paper.force(v, x, y, V_REG, f_perp=C_F, f_par=C_F), atol=1e-15)
    # A frictional fluid: above v_reg the force does not depend on speed.
    np.testing.assert_allclose(sandswim_force(10 * v, x, y), sandswim_force(v, x, y), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(sandswim_force(-v, x, y), -sandswim_force(v, x, y), atol=1e-15)


@pytest.mark.parametrize("values", [{}, {"rft.c_s": 1e5, "rft.c_f": 5e4}, {"rft.c_f": 5e4, "rft.gamma0": 0.3}])
def test_sandswim_needs_its_coefficients(values):
    with pytest.raises(SceneError, match="none are built in"):
        preset("paper").replace(**{"rft.law": "sandswim", **values})
    with pytest.raises(SceneError, match="rft.gamma0 must be <="):
        preset("paper").replace(**{"rft.law": "sandswim", "rft.c_s": 1e5, "rft.c_f": 5e4, "rft.gamma0": 2.0})


def test_every_law_has_a_c_twin_giving_the_same_forces(tmp_path):
    rng = np.random.default_rng(5)
    for name in laws.names():
        values = law_cases(name).twin(tmp_path)
        scene = preset("physical").replace(**{"rft.law": name, "plate.segments": 6, **values})
        native = build_plate(scene.replace(**{"sim.backend": "native"}))
        python = build_plate(scene.replace(**{"sim.backend": "python"}))
        assert native.backend == "native"
        m_native, m_python = native.model, python.model
        d_native, d_python = mujoco.MjData(m_native), mujoco.MjData(m_python)
        for trial in range(50):
            qpos = np.r_[0.0, rng.uniform(-0.6, 0.6, m_native.nq - 1)]  # hinges both ways: the stop engaged
            qvel = rng.normal(size=m_native.nv) * rng.choice([1e-4, 1e-3, 1e-1]) * (trial > 0)  # first: at rest
            for m, d in ((m_native, d_native), (m_python, d_python)):
                d.qpos[:], d.qvel[:] = qpos, qvel
            mujoco.mj_forward(m_native, d_native)
            with installed(m_python, PythonCoupling(python.groups)):
                mujoco.mj_forward(m_python, d_python)
            scale = np.abs(d_python.qfrc_passive).max()
            np.testing.assert_allclose(d_native.qfrc_passive, d_python.qfrc_passive, rtol=0, atol=1e-12 * scale,
                                       err_msg=f"law {name}")
        assert np.abs(d_python.qfrc_passive).max() > 0
