"""finrft sweep --backend warp: a population of a robot scene's variants as the worlds of one batched rollout on
MuJoCo Warp (finrft.warp.population) against the same variants run natively one by one, and the keys it refuses.
Runs on Warp's CPU device."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("warp", reason="the warp extra is not installed (pip install 'finrft[warp]')")
pytest.importorskip("mujoco_warp", reason="the warp extra is not installed (pip install 'finrft[warp]')")

import finrft.warp  # noqa: E402,F401  (Warp's kernel cache is set at its init: here, before the tests' own cache)
from finrft.cli import main  # noqa: E402
from finrft.errors import SceneError  # noqa: E402
from finrft.experiments.user_model import example, run_robot  # noqa: E402
from finrft.scene import UserScene, load_scene  # noqa: E402
from finrft.studies.sweep import sweep  # noqa: E402

# The sand-swimmer swimming from its start under its sines (no ramp) for 0.2 s at 1 ms, MuJoCo's step with the
# medium's force explicit on both backends (the native explicit run is MuJoCo's step with the plugin), the window
# from 0.05 s; li2013's generic coefficients scaled by zeta (0.1 and 0.2: at 1 ms the explicit step chatters from
# about 0.3).
SETS = {"medium.name": "", "sim.method": "explicit", "sim.dt": 1e-3, "sim.duration": 0.2, "sim.settle": 0.05,
        "control.*.ramp": 0.0}
# a medium twice as strong, and the surface 1 m down: the swimmer in the air, where the medium plays no part
GRID = ["medium.zeta=0.1,0.2", "medium.surface_z=0,-1"]
# |Warp - native| in each component of the mean velocity, m/s. The same explicit step in float32 on Warp and in
# float64 in MuJoCo: measured at most 1.2e-6 m/s here (the float32 state's rounding, carried through 200 steps; 0.2 s
# of the explicit step follow MuJoCo's to 1e-4 m, rad at most, docs/results/warp.md); ten times that, a hundredth
# of the figures' estimated discretisation error and of the two media's difference.
AGREE = 1e-5


def _velocity(figures: dict, name: str = "com_velocity_m_s") -> np.ndarray:
    return np.array([figures[f"{name}.{i}"] for i in range(3)])


# a Warp sweep and four native runs with their companions, end to end: with the slow studies
@pytest.mark.slow
def test_a_warp_sweep_follows_the_native_runs_one_by_one(capsys):
    args = ["sweep", "--example", "sand_swimmer", *(f"--set={k}={v}" for k, v in SETS.items()),
            *(f"--grid={g}" for g in GRID), "--backend", "warp", "--json", "--quiet"]
    assert main(args) == 0
    rows = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(rows) == 4 and not any(r["error"] for r in rows)
    scene = load_scene(example("sand_swimmer"), cls=UserScene).replace(**SETS)
    got, expected, estimates = {}, {}, {}
    for r in rows:
        key = r["keys"]["medium.zeta"], r["keys"]["medium.surface_z"]
        native = run_robot(scene.replace(**r["keys"]), max_error=None).summary()
        got[key], expected[key] = _velocity(r["figures"]), np.array(native["com_velocity_m_s"])
        estimates[key] = _velocity(r["estimates"])
        assert np.abs(got[key] - expected[key]).max() < AGREE, (key, got[key], expected[key])
        assert r["figures"]["com_speed_m_s"] == pytest.approx(np.hypot(*got[key][:2]))
        assert r["figures"]["com_position_m.2"] == pytest.approx(native["com_position_m"][2], abs=AGREE)
        # the medium's mean force on each body: measured to 7e-7 of the largest (0.7 N), float32's rounding again
        bodies = np.array(list(native["body_medium_force_N"].values()))
        for i, body in enumerate(native["body_medium_force_N"]):
            assert np.abs(_velocity(r["figures"], f"body_medium_force_N.{body}") - bodies[i]).max() \
                <= 1e-5 * np.abs(bodies).max()
        # its estimate is the native run's (both companions at half the step, means over every step): measured to
        # 1e-3 of it
        force_estimate = _velocity(r["estimates"], "medium_force_N")
        assert force_estimate == pytest.approx(native["error_estimate"]["medium_force_N"], rel=0.01, abs=1e-6)
        # the velocity's is of the same size, not the same: the native companion reads the window's start from
        # samples every 4 record_dt
        ratio = np.linalg.norm(estimates[key]) / np.linalg.norm(native["error_estimate"]["com_velocity_m_s"])
        assert 0.2 < ratio < 5, (key, estimates[key], native["error_estimate"]["com_velocity_m_s"])
    # in the air the medium plays no part; in the sand the stronger medium holds the swimmer up otherwise, beyond
    # both estimates, by what the native runs give
    assert np.array_equal(got[0.1, -1.0], got[0.2, -1.0])
    change = got[0.2, 0.0] - got[0.1, 0.0]
    assert abs(change[2]) > estimates[0.1, 0.0][2] + estimates[0.2, 0.0][2]
    assert np.abs(change - (expected[0.2, 0.0] - expected[0.1, 0.0])).max() < 2 * AGREE


def test_a_warp_sweep_refuses_keys_it_cannot_set_per_world(capsys):
    for key in ("model.geom.link1.size.0=0.01,0.02", "sim.dt=1e-3,2e-3", "medium.law=li2013,rft3d"):
        assert main(["sweep", "--example", "sand_swimmer", "--grid", key, "--backend", "warp", "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and key.split("=")[0] in err[0] and "--backend native" in err[0], err
    search = ["optimize", "--example", "sand_swimmer", "--backend", "warp", "--budget", "4", "--quiet"]
    for extra, named in ((["--objective", "cost_of_transport", "--bounds", "control.*.frequency=1,2"],
                          "cost_of_transport"),
                         (["--objective", "com_speed_m_s", "--bounds", "sim.dt=1e-4,1e-3"], "sim.dt")):
        assert main(search + extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0] and "--backend native" in err[0], err
    with pytest.raises(SceneError, match="without \\[\\[drive\\]\\] joints"):
        sweep(load_scene(example("wheel_rig"), cls=UserScene), [{"medium.surface_z": 0.0}], backend="warp")
