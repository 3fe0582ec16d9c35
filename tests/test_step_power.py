"""An actuator's power over a step (`attached_model.StepPower`): the force the step applied, checked against the
momentum the step gave a free hinge, I (v1 - v0) / dt, on MuJoCo's own step under each integrator."""

import mujoco
import numpy as np
import pytest

from finrft.experiments.attached_model import StepPower

# One hinge with no gravity or other force: a position servo (kp, kv) following a sine, a damper made of an affine
# gain in velocity (force = -0.3 v ctrl), and a servo clamped at its force range from the first step.
HINGE = """
<mujoco>
  <option gravity="0 0 0" integrator="{integrator}" timestep="0.001"/>
  <worldbody>
    <body>
      <joint name="hinge" type="hinge" axis="0 0 1"/>
      <geom type="box" size="0.05 0.01 0.01" mass="1"/>
    </body>
  </worldbody>
  <actuator>
    <position joint="hinge" kp="50" kv="0.5"/>
    <general joint="hinge" gaintype="affine" gainprm="0 0 -0.3" biastype="none"/>
    <position joint="hinge" kp="5" kv="0.05" forcelimited="true" forcerange="-0.01 0.01"/>
  </actuator>
</mujoco>
"""


@pytest.mark.parametrize("integrator", ["implicitfast", "implicit", "Euler"])
def test_a_steps_power_is_the_force_that_moved_the_hinge_times_its_new_velocity(integrator):
    m = mujoco.MjModel.from_xml_string(HINGE.format(integrator=integrator))
    d = mujoco.MjData(m)
    d.qvel[0], d.ctrl[:] = 3.0, [1.0, 1.0, 1.0]
    power = StepPower(m, "explicit")
    mujoco.mj_forward(m, d)
    power(d, d.time)
    inertia = m.dof_M0[0]  # the hinge's whole inertia about its axis (kg m^2)
    checked = 0
    for _ in range(50):
        before = d.qvel[0]
        mujoco.mj_step(m, d)
        d.ctrl[0] = np.sin(20 * d.time)  # the state's control, as MuJoCo's control callback sets it
        mujoco.mj_forward(m, d)  # the state's own forces, as a run's record reads them
        applied = inertia * (d.qvel[0] - before) / m.opt.timestep  # the momentum the step gave
        assert power(d, d.time).sum() == pytest.approx(applied * d.qvel[0], rel=1e-9, abs=1e-12)
        assert power(d, d.time).sum() == pytest.approx(applied * d.qvel[0], rel=1e-9, abs=1e-12)  # read twice
        checked += abs(d.qvel[0]) > 0.1
    assert checked > 10  # the hinge still turned: its servos had work to do
    # the damping taken at the start instead misses the step's momentum: what the step's slope changes
    if integrator != "Euler":
        start = d.actuator_force.sum()
        before = d.qvel[0]
        mujoco.mj_step(m, d)
        assert inertia * (d.qvel[0] - before) / m.opt.timestep != pytest.approx(start, rel=1e-3)
