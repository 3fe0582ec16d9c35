"""finrft.attach: RFT on the bodies of any MjSpec, checked against closed forms (a vertical plate dragged, a
horizontal plate pushed down), a quadrature of the law over a sphere, symmetry and dissipation; the native
plugin against the Python backend; bad input."""

import mujoco
import numpy as np
import pytest

import finrft
from finrft.attach import MAX_ELEMENTS, attach
from finrft.laws import li2013, li2013_planar
from finrft.scene import SceneError

CM3 = li2013.N_PER_CM3
RNG = np.random.default_rng(1408)


def body_xml(geoms: str, joint: str = '<joint type="slide" axis="1 0 0"/>', pos: str = "0 0 0") -> str:
    return f"""<mujoco><option gravity="0 0 0"/>
      <asset><mesh name="cube" vertex="-.01 -.01 -.01  .01 -.01 -.01  -.01 .01 -.01  .01 .01 -.01
                                       -.01 -.01 .01  .01 -.01 .01  -.01 .01 .01  .01 .01 .01"/></asset>
      <worldbody><body name="probe" pos="{pos}">{joint}{geoms}</body></worldbody></mujoco>"""


def passive(xml: str, qvel, qpos=None, backend: str = "native", **kwargs) -> tuple[np.ndarray, finrft.attach]:
    """qfrc_passive of the probe at a state, with RFT attached to it."""
    spec = mujoco.MjSpec.from_string(xml)
    attached = attach(spec, ["probe"], backend=backend, **kwargs)
    assert attached.backend == backend
    model = spec.compile()
    data = mujoco.MjData(model)
    if qpos is not None:
        data.qpos[:] = qpos
    data.qvel[:] = qvel
    with attached.installed(model):
        mujoco.mj_forward(model, data)
    return data.qfrc_passive.copy(), attached


PLATE = '<geom type="box" size="0.0005 0.02 0.03" pos="0 0 {z}" mass="1"/>'  # 4 cm wide, 6 cm deep, 1 mm thick


@pytest.mark.parametrize("backend", ["native", "python"])
def test_vertical_plate_dragged_normal_to_its_face(backend):
    # alpha_x(90 deg, 0) w H^2 / 2 = 0.370 N/cm^3 x 4 cm x 18 cm^2 = 26.64 N against the motion
    force, attached = passive(body_xml(PLATE.format(z=-0.03)), [0.1], backend=backend)
    assert force[0] == pytest.approx(-26.64, rel=0.03)
    # the depth is linear over the face, which the midpoint rule integrates exactly at any element size
    assert force[0] == pytest.approx(-26.64, rel=1e-9)
    assert attached.elements == {"probe": 232}


def test_element_size_convergence_where_the_surface_cuts_elements():
    # The plate's top 7.3 mm above the surface: elements straddle it. The midpoint rule misses at most h^2 / 8 of
    # the depth integral per unit width there: the error is bounded by alpha_x w h^2 / 8, second order in h.
    top = 0.0073
    exact = -0.370 * CM3 * 0.04 * (0.06 - top) ** 2 / 2
    for h in (0.008, 0.004, 0.002, 0.001):
        force, _ = passive(body_xml(PLATE.format(z=top - 0.03)), [0.1], element_size=h)
        assert abs(force[0] - exact) <= 0.370 * CM3 * 0.04 * h ** 2 / 8 * (1 + 1e-9)
        assert abs(force[0] / exact - 1) < 0.03


def sphere_drag(radius: float) -> float:
    """The planar law integrated over the leading, submerged quarter of a sphere centred on the surface, moving along
    +x at 0.1 m/s, unregularised: the x force, by Gauss-Legendre quadrature in theta and phi (the integrand is smooth
    there: 100 x 100 nodes agree with adaptive quadrature at 1e-10 to 1e-13, 100 times faster)."""
    x, w = np.polynomial.legendre.leggauss(100)
    theta, phi = np.meshgrid(3 * np.pi / 4 + np.pi / 4 * x, np.pi / 2 * x, indexing="ij")
    weights = np.outer(np.pi / 4 * w, np.pi / 2 * w).ravel()
    n = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1).reshape(-1, 3)
    force = li2013_planar.element_forces(n, np.tile([0.1, 0, 0], (len(n), 1)), -radius * n[:, 2],
                                         radius ** 2 * np.sin(theta).ravel())
    return float(force[:, 0] @ weights)


def test_sphere_converges_to_the_integrated_law():
    # Moving along an axis, the leading face's edge falls on cell edges: second order in h (errors 0.86 %, 0.32 %,
    # 0.22 %, 0.055 %, 0.014 % at 8, 5, 4, 2, 1 mm). Cells cut by that edge make it first to second order.
    exact = sphere_drag(0.03)
    errors = {}
    for h in (0.005, 0.004, 0.002, 0.001):
        force, _ = passive(body_xml('<geom type="sphere" size="0.03" mass="1"/>'), [0.1], element_size=h,
                           law="li2013-planar", v_reg=0.0)  # the ramp's 0.3 mm band: tests/test_regularisation.py
        errors[h] = abs(force[0] / exact - 1)
    assert errors[0.005] < 0.01
    assert errors[0.002] < errors[0.004] / 3 and errors[0.001] < errors[0.002] / 3


def test_sphere_dragged_sideways_feels_no_lateral_force():
    joint = '<joint type="free"/>'
    for geom in ('<geom type="sphere" size="0.03" mass="1"/>', '<geom type="capsule" size="0.01 0.02" mass="1"/>'):
        force, _ = passive(body_xml(geom, joint, pos="0 0 -0.01"), [0.1, 0, 0, 0, 0, 0])
        assert force[0] < 0 and force[2] > 0
        assert abs(force[1]) < 1e-9 * abs(force[0])
        assert max(abs(force[3]), abs(force[5])) < 1e-9 * abs(force[0])  # mirror y -> -y: no roll or yaw
        # any horizontal direction: drag along -v, lateral force from the cells' layout only
        direction = np.array([np.cos(0.7), np.sin(0.7), 0.0])
        force, _ = passive(body_xml(geom, joint, pos="0 0 -0.01"), [*0.1 * direction, 0, 0, 0])
        lateral = np.cross(direction, force[:3])[2]
        assert force[:3] @ direction < 0 and abs(lateral) < 0.02 * abs(force[:3] @ direction)


@pytest.mark.parametrize("zeta", [1.0, 0.4])
def test_horizontal_plate_pushed_down(zeta):
    # alpha_z(0, 90 deg) = zeta x 1.000 N/cm^3, at 5 cm depth on 4 cm x 6 cm: zeta x 120 N up (the plate's
    # bottom face at 5 cm; its edges move parallel to themselves and take nothing)
    xml = body_xml('<geom type="box" size="0.02 0.03 0.0005" pos="0 0 -0.0495" mass="1"/>',
                   '<joint type="slide" axis="0 0 1"/>')
    for backend in ("native", "python"):
        force, _ = passive(xml, [-0.05], backend=backend, zeta=zeta)
        assert force[0] == pytest.approx(zeta * 120.0, rel=1e-9)


def test_mesh_cube_feels_what_the_box_feels():
    joint = '<joint type="free"/>'
    velocity = [0.05, -0.02, -0.03, 0, 0, 0]
    box, _ = passive(body_xml('<geom type="box" size=".01 .01 .01" mass="1"/>', joint, pos="0 0 -0.03"), velocity)
    mesh, attached = passive(body_xml('<geom type="mesh" mesh="cube" mass="1"/>', joint, pos="0 0 -0.03"), velocity)
    assert np.abs(box[:3]).max() > 1
    # the depth integrand is linear on every face: both tessellations integrate the force exactly (MuJoCo keeps
    # mesh vertices in single precision); the torque's integrand is quadratic: equal to the elements' accuracy
    np.testing.assert_allclose(mesh[:3], box[:3], rtol=1e-6)
    np.testing.assert_allclose(mesh[3:], box[3:], rtol=0.05, atol=0.01 * np.abs(box[3:]).max())


MIXED = """<geom type="box" size=".02 .01 .005" mass=".1"/>
           <geom type="capsule" fromto="0 0 0 .03 .02 -.03" size=".006"/>
           <geom type="sphere" size=".012" pos="-.02 .01 -.01"/>
           <geom type="cylinder" size=".008 .015" pos="0 -.02 -.02" euler="30 60 0"/>
           <geom type="ellipsoid" size=".015 .008 .01" pos=".02 -.01 .01" euler="10 0 40"/>
           <geom type="mesh" mesh="cube" pos="-.01 -.02 .01" euler="0 45 0"/>"""


def random_state(rng):
    quat = rng.normal(size=4)
    qpos = np.concatenate([[0.01, -0.02, rng.uniform(-0.03, 0.01)], quat / np.linalg.norm(quat)])
    return qpos, rng.normal(scale=[0.1, 0.1, 0.1, 3, 3, 3])


def test_native_equals_python_on_a_multi_geom_body():
    xml = body_xml(MIXED, '<joint type="free"/>')
    for _ in range(5):
        qpos, qvel = random_state(RNG)
        native, attached = passive(xml, qvel, qpos, element_size=0.003)
        python, _ = passive(xml, qvel, qpos, backend="python", element_size=0.003)
        assert np.abs(native).max() > 0.1 and sum(attached.elements.values()) > 500
        np.testing.assert_allclose(native, python, rtol=1e-9, atol=1e-9 * np.abs(python).max())


def test_recordings_read_the_wrench_the_forward_pass_applied():
    # What a recording reads after mj_forward, the plugin's own sum as that pass applied it, is the sum at the
    # state; after a native implicit step, whose forward pass took the medium's force itself (the plugin paused),
    # there is none applied and the reader sums the elements at the state again.
    spec = mujoco.MjSpec.from_string(body_xml(MIXED, '<joint type="free"/>'))
    attached = attach(spec, ["probe"], element_size=0.003)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = random_state(RNG)
    recorded, summed = attached.wrenches(model, applied=True), attached.wrenches(model)
    mujoco.mj_forward(model, data)
    assert np.abs(summed(data)).max() > 0.1
    np.testing.assert_array_equal(recorded(data), summed(data))
    model.opt.timestep = 1e-4
    assert finrft.integrate.stepper(model, finrft.scene.Sim(method="newton", dt=1e-4), "native", [],
                                    attached)(data, 1) == 0
    np.testing.assert_array_equal(recorded(data), summed(data))


def test_total_force_on_closed_bodies_dissipates():
    # The power of the RFT force, qfrc_passive . qvel = sum of F_i . v_i, for random poses and twists
    xml = body_xml(MIXED, '<joint type="free"/>')
    spec = mujoco.MjSpec.from_string(xml)
    attach(spec, ["probe"], element_size=0.004)
    model = spec.compile()
    data = mujoco.MjData(model)
    powers = []
    for _ in range(200):
        data.qpos[:], data.qvel[:] = random_state(RNG)
        mujoco.mj_forward(model, data)
        powers.append(data.qfrc_passive @ data.qvel)
    assert max(powers) <= 0 and min(powers) < -1e-3


def test_a_body_above_the_surface_feels_nothing():
    force, _ = passive(body_xml(MIXED, '<joint type="free"/>', pos="0 0 0.2"), RNG.normal(size=6))
    assert not force.any()
    # the surface height moves with surface_z
    force, _ = passive(body_xml(MIXED, '<joint type="free"/>', pos="0 0 0.2"), [0, 0, -0.1, 0, 0, 0],
                       surface_z=0.25)
    assert force[2] > 1


def test_rollout_threads_share_nothing():
    from mujoco import rollout
    spec = mujoco.MjSpec.from_string(body_xml(MIXED, '<joint type="free"/>'))
    attach(spec, ["probe"], element_size=0.004)
    model = spec.compile()
    states = []
    for _ in range(4):
        qpos, qvel = random_state(RNG)
        states.append(np.concatenate([[0.0], qpos, qvel]))
    state0 = np.array(states)
    datas = [mujoco.MjData(model) for _ in range(2)]
    threaded, _ = rollout.rollout(model, datas, state0, nstep=20)
    single, _ = rollout.rollout(model, datas[:1], state0, nstep=20)
    np.testing.assert_array_equal(threaded, single)
    assert np.isfinite(threaded).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"bodies": ["nobody"]}, "no body named 'nobody'"),
    ({"bodies": ["empty"]}, "body 'empty' has no geoms"),
    ({"bodies": ["floor"]}, "is a plane"),
    ({"bodies": ["probe", "probe"]}, "named twice"),
    ({"bodies": []}, "at least one body"),
    ({"element_size": 0.0}, "element_size must be > 0"),
    ({"element_size": -1e-3}, "element_size must be > 0"),
    ({"element_size": 1e-5}, f"more than {MAX_ELEMENTS}"),
    ({"zeta": 0.0}, "zeta must be > 0"),
    ({"zeta": float("nan")}, "zeta must be > 0"),
    ({"law": "maladen2009"}, "law must be one of li2013"),
    ({"backend": "gpu"}, "backend must be one of"),
])
def test_bad_input_names_the_problem(kwargs, message):
    spec = mujoco.MjSpec.from_string("""<mujoco><worldbody><body name="floor"><geom type="plane" size="1 1 1"/>
      </body><body name="empty"/><body name="probe"><geom size=".01"/></body></worldbody></mujoco>""")
    with pytest.raises(SceneError, match=message):
        attach(spec, **{"bodies": ["probe"], **kwargs})


def test_a_body_takes_one_plugin():
    spec = mujoco.MjSpec.from_string(body_xml('<geom size=".01"/>'))
    attach(spec, ["probe"])
    with pytest.raises(SceneError, match="already has a plugin"):
        attach(spec, ["probe"])


def test_a_body_turning_about_its_origin_away_from_its_centre_of_mass():
    # A hinge at the body's origin; the plate 0.1 m out on +x, a heavy ball above the surface 0.5 m out on -x, so
    # the centre of mass lies on the ball's side. Turning at +1 rad/s, the plate moves along +y, its face leading:
    # -26.64 N along y (as dragged; its thin end faces add 0.13 N along x), a torque of -26.64 N x 0.1 m about the hinge. A velocity taken at the centre
    # of mass instead of the origin would move the plate along -y.
    xml = body_xml('<geom type="box" size="0.02 0.0005 0.03" pos="0.1 0 -0.03" mass="0.001"/>'
                   '<geom type="sphere" size="0.05" pos="-0.5 0 0.5" mass="10"/>',
                   joint='<joint type="hinge" axis="0 0 1"/>')
    for backend in ("native", "python"):
        torque, attached = passive(xml, [1.0], backend=backend)
        # to 1e-4: the plate's faces, 1 mm apart, turn 0.5 mrad off its centre line
        assert torque[0] == pytest.approx(-2.664, rel=1e-4)
    spec = mujoco.MjSpec.from_string(xml)
    attached = attach(spec, ["probe"], backend="python")
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[:] = 1.0
    mujoco.mj_forward(model, data)
    force, moment = attached.forces(model, data)["probe"]
    # and the lift on a vertical plate dragged: alpha_z(90 deg, 0) / alpha_x(90 deg, 0) = 0.037 / 0.370
    assert force[1:] == pytest.approx([-26.64, 2.664], rel=1e-4)
    assert moment[2] == pytest.approx(torque[0], rel=1e-9)


CHAIN = """<mujoco><option gravity="0 0 0"/><worldbody>
  <body name="link1" pos="0 0 -0.03"><joint type="slide" axis="1 0 0"/>
    <geom name="box1" type="box" size="0.02 0.005 0.01" mass="0.1"/>
    <body name="link2" pos="0.04 0 0"><joint type="hinge" axis="0 0 1" pos="-0.02 0 0"/>
      <geom name="box2" type="box" size="0.02 0.005 0.01" mass="0.1"/>
      <geom name="fin" type="box" size="0.02 0.0005 0.01" pos="0 0 0.02" mass="0.01"/></body>
  </body></worldbody></mujoco>"""


@pytest.mark.parametrize("cull", [True, False])
def test_a_chain_dragged_along_itself_feels_its_nose_only(cull):
    # Two box links end to end, dragged along -x: the grains reach link1's nose, not link2's end face behind it,
    # which touches link1's tail. alpha_x(90 deg, 0) w (z2^2 - z1^2) / 2 = 0.370 N/cm^3 x 1 cm x 6 cm^2 = 2.22 N, and
    # the nose of link2's fin, 1 mm x 2 cm from the surface down: 0.370 N/cm^3 x 0.1 cm x 2 cm^2 = 0.074 N.
    spec = mujoco.MjSpec.from_string(CHAIN)
    attached = attach(spec, ["link1", "link2"], law="li2013", backend="python", cull=cull)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[0] = -0.1
    mujoco.mj_forward(model, data)
    total = sum(f for f, _ in attached.forces(model, data).values())
    assert total[0] == pytest.approx(2.22 * (1 if cull else 2) + 0.074, rel=1e-3)
    # culled: the two touching end faces (2 x 4 elements of 5 mm each) and the fin's underside (8) on link2's top
    full = sum(attach(mujoco.MjSpec.from_string(CHAIN), ["link1", "link2"], cull=False).elements.values())
    assert sum(attached.elements.values()) == full - (16 + 8 if cull else 0)


def test_geoms_chosen_by_name():
    spec = mujoco.MjSpec.from_string(CHAIN)
    attached = attach(spec, geoms=["fin"], backend="python")
    whole = attach(mujoco.MjSpec.from_string(CHAIN), geoms=["fin"], backend="python", cull=False)
    assert list(attached.elements) == ["link2"]
    # the fin's elements only (not box2's), less the 8 of its underside that lie on box2's top face
    assert attached.elements["link2"] == whole.elements["link2"] - 8 == 2 * (8 * 4 + 8 * 1 + 1 * 4) - 8
    with pytest.raises(SceneError, match="no geom named 'wing'"):
        attach(mujoco.MjSpec.from_string(CHAIN), geoms=["wing"])


def _boxes():
    import mujoco
    return mujoco.MjSpec.from_string(
        '<mujoco><worldbody><body name="b" pos="0 0 0.04"><freejoint/><geom type="box" size=".05 .05 .05" '
        'mass="1"/></body><body name="c" pos=".3 0 .04"><freejoint/><geom type="box" size=".05 .05 .05" mass="1"/>'
        '</body></worldbody></mujoco>')


@pytest.mark.parametrize("backend", ["native", "python"])
def test_attach_refuses_what_cannot_work(backend):
    """A body attached twice, a model compiled before attach, and (Python backend) a model stepped outside its
    own block while another's is installed: each refused, where each gave no force or double force silently."""
    import mujoco
    spec = _boxes()
    early = spec.compile()
    attached = attach(spec, "b", backend=backend)
    for again in ("native", "python"):
        with pytest.raises(SceneError, match="'b' (already has a plugin|has RFT attached already)"):
            attach(spec, "b", backend=again)
    with pytest.raises(SceneError, match="compiled before attach"):
        with attached.installed(early):
            pass
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[2] = -0.1
    with attached.installed(model):
        mujoco.mj_step(model, data)
    assert data.qfrc_passive[2] > 0  # the box, 1 cm deep and sinking: the medium holds it up
    if backend == "python":
        other = _boxes()
        other_attached = attach(other, "c", backend="python")
        other_model = other.compile()
        with attached.installed(model), pytest.raises(SceneError, match="outside its own Attached.installed"):
            mujoco.mj_step(other_model, mujoco.MjData(other_model))
        with other_attached.installed(other_model):
            mujoco.mj_step(other_model, mujoco.MjData(other_model))
    assert mujoco.get_mjcb_passive() is None


def test_python_backend_stepped_without_its_callback_stops_at_the_step():
    """With no callback installed anywhere, a Python-backend model's steps had no medium force and nothing said so:
    its native guard (plugins/finrft_guard.c) stops the step itself. MuJoCo's compiler steps a model once on its own
    data, so a data's first evaluation passes; the second stops. Installed for model A, stepping model B with its own
    attachment is refused by the dispatcher (test above): both cases are loud, and neither adds a force."""
    spec, other = _boxes(), _boxes()
    attached = attach(spec, "b", backend="python")
    attach(other, "c", backend="python")
    model, other_model = spec.compile(), other.compile()
    data = mujoco.MjData(model)
    data.qvel[2] = -0.1
    with pytest.raises(mujoco.FatalError, match=r"step inside `with attached.installed\(model\):`"):
        mujoco.mj_step(model, data, 2)
    with attached.installed(model), pytest.raises(SceneError, match="outside its own Attached.installed"):
        mujoco.mj_step(other_model, mujoco.MjData(other_model), 2)
    # installed, every step is stamped, and the force is the native plugin's (the guard adds none)
    native_spec = _boxes()
    native = attach(native_spec, "b", backend="native")
    native_model = native_spec.compile()
    datas = []
    for m, a in ((model, attached), (native_model, native)):
        d = mujoco.MjData(m)
        d.qvel[2] = -0.1
        with a.installed(m):
            mujoco.mj_step(m, d)
            assert d.qfrc_passive[2] > 0  # the box, 1 cm deep and sinking: the medium holds it up
            mujoco.mj_step(m, d, 4)
        datas.append(d)
    np.testing.assert_allclose(datas[0].qpos, datas[1].qpos, rtol=1e-9, atol=1e-12)
    assert mujoco.get_mjcb_passive() is None
