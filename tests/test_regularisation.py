"""The one regularisation of every surface law (finrft.laws.regularised, and element_force in the plugin):
continuous onset of a face moving along itself, equal on both backends, and its effect on attach's closed forms
bounded."""

import dataclasses

import mujoco
import numpy as np
import pytest

from finrft import laws
from test_attach import PLATE, body_xml, passive

LAWS = [{"law": "li2013"}, {"law": "li2013-planar"}, {"law": "rft3d", "rho_c": 1600.0, "mu_int": 0.5, "mu_surf": 0.3}]


@pytest.mark.parametrize("law", LAWS, ids=lambda law: law["law"])
def test_a_face_moving_along_itself_ramps_smoothly(law):
    # An element of normal x sliding along y at 0.1 m/s while its normal speed u goes 0 -> 10 v_reg: its force
    # starts at 0 and follows the bare law times tanh(u / v_reg), none at all up to RAMP_FLOOR v_reg (where the
    # plugin skips the law: rounding puts a face moving along itself on either side of 0); the plugin applies it
    # as the Python backend.
    v_reg = laws.SURFACE_V_REG
    xml = body_xml(PLATE.format(z=-0.03), '<joint type="free"/>')
    bare_force = None
    for u in (0.0, 0.5 * laws.RAMP_FLOOR * v_reg, 2 * laws.RAMP_FLOOR * v_reg, 0.5 * v_reg, v_reg, 3 * v_reg,
              10 * v_reg):
        qvel = [u, 0.1, 0, 0, 0, 0]
        native, attached = passive(xml, qvel, **law)
        python, _ = passive(xml, qvel, backend="python", **law)
        np.testing.assert_allclose(native, python, rtol=1e-9, atol=1e-9 * np.abs(python).max())
        element = ([[1.0, 0, 0]], [[u, 0.1, 0]], [0.02], [1e-4])
        ramped = attached.element_forces(*element)
        bare_force = dataclasses.replace(attached, v_reg=0.0).element_forces(*element)
        ramp = np.tanh(u / v_reg) if u > laws.RAMP_FLOOR * v_reg else 0.0
        np.testing.assert_allclose(ramped, ramp * bare_force, rtol=1e-12, atol=1e-300)
    assert np.abs(bare_force).max() > 1e-3


def test_the_closed_forms_move_less_than_half_a_percent():
    # attach's closed forms run at 0.05-0.1 m/s; the ramp costs a face 1 - tanh(u / v_reg) of its force, so only
    # grazing cells of curved bodies feel it: measured 0.024 % (sphere, li2013), 3e-8 (capsule), 0 (plate).
    for geom, pos in (('<geom type="sphere" size="0.03" mass="1"/>', "0 0 0"),
                      ('<geom type="capsule" size="0.01 0.02" mass="1"/>', "0 0 -0.01"),
                      (PLATE.format(z=-0.03), "0 0 0")):
        xml = body_xml(geom, '<joint type="free"/>', pos=pos)
        for law in LAWS:
            ramped, _ = passive(xml, [0.1, 0, 0, 0, 0, 0], element_size=0.003, **law)
            bare, _ = passive(xml, [0.1, 0, 0, 0, 0, 0], element_size=0.003, v_reg=0.0, **law)
            assert np.linalg.norm(ramped[:3] - bare[:3]) <= 0.005 * np.linalg.norm(bare[:3])


def test_bad_v_reg_is_refused():
    from finrft.scene import SceneError
    from finrft.attach import attach
    with pytest.raises(SceneError, match="v_reg must be >= 0"):
        attach(mujoco.MjSpec.from_string(body_xml(PLATE.format(z=0))), ["probe"], v_reg=-1.0)


@pytest.mark.parametrize("v_reg, resolved", [(laws.LEAST_V_REG, True), (1e-11, True), (1e-12, False)])
def test_a_box_at_rest_takes_its_weight_down_to_the_least_v_reg(v_reg, resolved):
    # A 0.5 kg box resting 1 mm deep (newton, 1 ms): its medium force is its weight, upright, at LEAST_V_REG and, with
    # the law's exact velocity Jacobian, down to a ramp of 1e-11 m/s; at 1e-12 m/s, a ramp ten times narrower than
    # the velocities Newton's method resolves, the solve gives out, loudly, rather than leave a tilted force.
    from finrft import integrate
    from finrft.attach import attach
    from finrft.scene import Sim
    spec = mujoco.MjSpec.from_string("""<mujoco><option timestep="0.001" integrator="implicitfast"/><worldbody>
      <body name="box" pos="0 0 0.009"><freejoint/><geom type="box" size="0.05 0.05 0.01" mass="0.5"/></body>
    </worldbody></mujoco>""")
    attached = attach(spec, "box", backend="native", element_size=0.01, v_reg=v_reg)
    m = spec.compile()
    d = mujoco.MjData(m)
    advance = integrate.stepper(m, Sim(method="newton", dt=1e-3), "native", [], attached)
    with attached.installed(m):
        failed = advance(d, 500) != 0
        force, torque = attached.forces(m, d)["box"]
    weight = 0.5 * -m.opt.gravity[2]
    upright = abs(force[2] - weight) < 1e-6 * weight and np.abs(force[:2]).max() < 1e-9 and np.abs(torque).max() < 1e-9
    assert (upright, failed) == (resolved, not resolved), (force, torque)
