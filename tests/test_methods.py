"""The time-stepping methods: the implicit step is MuJoCo's implicitfast plus the RFT Jacobian, in both twins;
the adaptive method follows its tolerance."""

import mujoco
import numpy as np
import pytest

from finrft import integrate, models
from finrft.drive import Drive
from finrft.scene import SceneError, preset
from finrft.simulate import simulate


@pytest.mark.parametrize("backend", ["python", "native"])
def test_implicit_step_without_rft_is_implicitfast(backend):
    # A model with no RFT (python-backend model, no callback installed): only MuJoCo's own forces.
    scene = preset("paper").replace(**{"sim.backend": "python", "plate.stop": "limit", "plate.segment_inertia": 1e-3,
                                       "sim.dt": 5e-4, "sim.method": "implicit"})
    plate = models.build_plate(scene)
    m = plate.model
    ours, theirs = mujoco.MjData(m), mujoco.MjData(m)
    for d in (ours, theirs):
        d.qvel[:] = [0.03, 1.0, -2.0, 3.0]
        d.qpos[1:] = [0.2, -0.3, 0.1]
    mujoco.mj_step(m, theirs, 1000)
    step = integrate.stepper(m, scene.sim, backend, [])
    assert step(ours, 1000) == 0
    np.testing.assert_allclose(ours.qpos, theirs.qpos, atol=1e-12)
    np.testing.assert_allclose(ours.qvel, theirs.qvel, atol=1e-12)


@pytest.mark.parametrize("method,atol", [("implicit", 1e-9), ("adaptive", 1e-6)])
def test_native_and_numpy_methods_agree(method, atol):
    scene = preset("paper").replace(**{"sim.method": method, "plate.segment_inertia": 1e-3, "sim.dt": 1e-3})
    drive = Drive(stroke=0.05, cycles=1)
    native = simulate(scene, drive)
    python = simulate(scene.replace(**{"sim.backend": "python"}), drive)
    np.testing.assert_allclose(native.segment_angle, python.segment_angle, atol=atol)
    assert np.degrees(np.abs(native.hinge_angle).max()) > 5


def test_adaptive_error_falls_with_the_tolerance():
    scene = preset("paper").replace(**{"sim.method": "adaptive", "plate.segment_inertia": 1e-3, "sim.dt": 1e-3})
    drive = Drive(stroke=0.1)
    truth = simulate(scene.replace(**{"sim.tolerance": 1e-8}), drive).segment_angle
    errors = [np.abs(simulate(scene.replace(**{"sim.tolerance": tol}), drive).segment_angle - truth).max()
              for tol in (1e-3, 1e-4, 1e-5)]
    assert errors[0] > errors[1] > errors[2]


def test_methods_need_implicitfast():
    with pytest.raises(SceneError, match="implicitfast"):
        preset("paper").replace(**{"sim.method": "adaptive", "sim.integrator": "rk4"})


def test_adaptive_step_underflow_stops_loudly():
    from finrft.simulate import SimulationUnstable
    scene = preset("paper").replace(**{"sim.method": "adaptive", "sim.tolerance": 1e-6, "plate.stop": "limit",
                                       "plate.segment_inertia": 2.6e-7, "plate.rod_inertia": 4e-8})
    with pytest.raises(SimulationUnstable, match="fell below 1e-9 s at t = .* raise sim.tolerance"):
        simulate(scene, Drive(cycles=1))
