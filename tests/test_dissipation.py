"""Every segment law dissipates (F.v <= 0 at every velocity and orientation) with dissipative parameters, each
law's `feeds_energy` says when it does not, and a run of a law that can feed energy in says so once on stderr and
in its result file."""

import warnings

import h5py
import numpy as np
import pytest

from finrft import geometry, laws
from finrft.cli import main
from finrft.scene import preset

from conftest import law_cases

V_REG = 1e-3
SAMPLES = 20000


def _random_segments(rng, n=SAMPLES):
    """Velocities of every direction in 3D (out of the segment's plane too) and speed (around v_reg and far
    above), and random orthonormal segment axes x, y."""
    v = rng.normal(size=(n, 3)) * rng.choice([1e-4, 1e-3, 1e-2, 1.0], size=(n, 1))
    x = rng.normal(size=(n, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(x, rng.normal(size=(n, 3)))
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    return v, x, y


def _max_power(name, params, seed=3):
    """The largest F.v over random samples, and the largest |F| |v| (its scale)."""
    v, x, y = _random_segments(np.random.default_rng(seed))
    force = laws.module(name).force(v, x, y, V_REG, **params)
    return np.einsum("ij,ij->i", force, v).max(), (np.linalg.norm(force, axis=1) * np.linalg.norm(v, axis=1)).max()


# Parameters that dissipate, per registered law, and parameters that can feed energy in: each law's own test
# module holds them (conftest.law_cases).
DISSIPATIVE = {name: law_cases(name).DISSIPATIVE for name in laws.names()}
FEEDING = {name: law_cases(name).FEEDING for name in laws.names()}


@pytest.mark.parametrize("name,params", [(n, p) for n, cases in DISSIPATIVE.items() for p in cases])
def test_dissipative_parameters_never_feed_energy_in(name, params):
    assert laws.module(name).feeds_energy(params) == ""
    power, scale = _max_power(name, params)
    assert power <= 1e-12 * scale


@pytest.mark.parametrize("name,params", [(n, p) for n, cases in FEEDING.items() for p in cases])
def test_feeding_parameters_are_detected_and_do_feed_energy_in(name, params):
    assert laws.module(name).feeds_energy(params) != ""
    power, scale = _max_power(name, params)
    assert power > 1e-3 * scale  # the sampling finds the motion that the law pushes along


def test_the_paper_preset_feeds_energy_in_and_says_why_and_the_physical_one_dissipates():
    assert "f_par = -0.2 N < 0" in laws.feeds_energy(geometry.segment_law(preset("paper")))  # per segment
    assert laws.feeds_energy(geometry.segment_law(preset("paper").replace(**{"rft.f_par": 2938.0}))) == ""
    assert laws.feeds_energy(geometry.segment_law(preset("physical"))) == ""


def test_a_run_says_once_that_its_law_feeds_energy_in(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(laws, "_warned", [])  # as in a fresh process
    fast = ["--preset", "paper", "--set", "sim.dt=0.001", "--distance", "5"]
    outs = [tmp_path / "first.h5", tmp_path / "second.h5", tmp_path / "dissipative.h5"]
    assert main(["drag", "--out", str(outs[0]), "--quiet", *fast]) == 0
    assert main(["drag", "--out", str(outs[1]), "--quiet", *fast]) == 0
    assert main(["drag", "--out", str(outs[2]), "--quiet", "--set", "rft.f_par=0.2", *fast]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("finrft: warning: ") and "f_par = -0.2 N < 0" in err[0], err
    reason = laws.feeds_energy(geometry.segment_law(preset("paper")))
    for out, expected in zip(outs, (reason, reason, "")):
        with h5py.File(out) as f:
            assert f.attrs["law_feeds_energy"] == expected


def test_attaching_the_published_3d_rft_says_once_that_it_feeds_energy_in(monkeypatch):
    import mujoco

    from finrft.attach import attach
    monkeypatch.setattr(laws, "_warned", [])  # as in a fresh process
    spec = mujoco.MjSpec.from_string('<mujoco><worldbody><body name="box" pos="0 0 -0.02"><freejoint/>'
                                     '<geom type="box" size="0.01 0.01 0.01"/></body></worldbody></mujoco>')
    with pytest.warns(laws.FeedsEnergy, match="rft3d.*grazing.*kept as published"):
        attach(spec, "box", law="rft3d", rho_c=1500.0, mu_int=0.4, mu_surf=0.3, backend="python")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        attach(mujoco.MjSpec.from_string(spec.to_xml()), "box", law="rft3d", rho_c=1500.0, mu_int=0.4, mu_surf=0.3,
               backend="python")  # once is enough
