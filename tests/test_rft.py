"""The RFT laws against their closed forms and each other."""

import numpy as np
import pytest

from finrft import rft
from finrft.scene import SceneError

F_PERP, F_PAR, V_REG = 1.2, -0.2, 1e-3


def frames(angle):
    x = np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=-1)
    y = np.stack([-np.sin(angle), np.cos(angle), 0 * angle], axis=-1)
    return x, y


@pytest.mark.parametrize("attack_deg", [0.0, 15.0, 45.0, 60.0, 90.0])
def test_paper_law_closed_form(attack_deg):
    # A segment along x moving at angle of attack theta: normal part f_perp sin(theta), tangential f_par cos(theta).
    theta = np.radians(attack_deg)
    speed = 0.03
    v = speed * np.array([[np.cos(theta), np.sin(theta), 0.0]])
    x, y = frames(np.zeros(1))
    force = rft.paper_force(v, x, y, F_PERP, F_PAR, V_REG)[0]
    ramp = np.tanh(speed / V_REG)
    np.testing.assert_allclose(force, -ramp * np.array([F_PAR * np.cos(theta), F_PERP * np.sin(theta), 0]),
                               atol=1e-15)


def test_paper_law_is_odd_in_velocity_and_vanishes_at_rest():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(50, 3)) * 0.01
    x, y = frames(rng.uniform(-np.pi, np.pi, 50))
    forward = rft.paper_force(v, x, y, F_PERP, F_PAR, V_REG)
    np.testing.assert_allclose(rft.paper_force(-v, x, y, F_PERP, F_PAR, V_REG), -forward, atol=1e-15)
    assert np.all(rft.paper_force(np.zeros((3, 3)), x[:3], y[:3], F_PERP, F_PAR, V_REG) == 0.0)


def test_regularisation_ramp():
    x, y = frames(np.zeros(1))
    for speed in (1e-5, 1e-3, 5e-3):
        force = rft.paper_force(np.array([[0.0, speed, 0.0]]), x, y, F_PERP, F_PAR, V_REG)[0]
        assert force[1] == pytest.approx(-F_PERP * np.tanh(speed / V_REG), rel=1e-12)


def test_table_of_the_paper_law_reproduces_it():
    # Linear interpolation of sin/cos sampled every 0.25 deg is exact to ~1e-5 relative.
    table = rft.paper_table(F_PERP, F_PAR, samples=361)
    rng = np.random.default_rng(2)
    v = rng.normal(size=(200, 3)) * 0.02
    v[:, 2] = 0.0
    x, y = frames(rng.uniform(-np.pi, np.pi, 200))
    np.testing.assert_allclose(rft.table_force(v, x, y, table, V_REG), rft.paper_force(v, x, y, F_PERP, F_PAR, V_REG),
                               atol=2e-5)


def test_table_round_trip_and_bad_tables(tmp_path):
    table = rft.paper_table(F_PERP, F_PAR, samples=19)
    path = tmp_path / "forces.csv"
    rft.write_table(path, table)
    back = rft.read_table(path)
    np.testing.assert_array_equal(back.f_perp, table.f_perp)
    np.testing.assert_array_equal(back.attack_deg, table.attack_deg)

    (tmp_path / "cols.csv").write_text("angle,a,b\n0,1,2\n90,1,2\n")
    (tmp_path / "short.csv").write_text("attack_deg,f_perp_N,f_par_N\n0,0,1\n45,1,1\n")
    (tmp_path / "text.csv").write_text("attack_deg,f_perp_N,f_par_N\n0,x,1\n90,1,1\n")
    for name in ("cols.csv", "short.csv", "text.csv", "missing.csv"):
        with pytest.raises(SceneError):
            rft.read_table(tmp_path / name)
