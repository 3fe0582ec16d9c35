"""The example robots of mjcf/ (sand_swimmer, hexapod, wheel_rig) in the medium, each against physics computed
apart from the element code: the swimmer's wave efficiency against sand-swimming's published range, the hexapod's
speed against its legs' rolling speed and its rest on the sand, the wheel's static sinkage against a quadrature of
Li et al. 2013's law over the submerged arc; and their TOML scenes against the models they name.

The robots run as `finrft run --example NAME` does, at the scenes' default numerics (newton-midpoint at 1 ms, the
wheel rig newton at 62.5 ms); the wheel's static sinkage with MuJoCo's own step at 0.1 ms and a damped lift."""

import dataclasses
import math
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy import integrate, optimize, special

import finrft
from finrft import laws
from finrft.errors import Chatter
from finrft.integrate import stepper
from finrft.laws import li2013
from finrft.models import mjcf_path
from finrft.experiments import wheel
from finrft.experiments.attached_model import medium_forces
from finrft.experiments.user_model import UserModel, example
from finrft.scene import Medium, Sim, UserScene, load_scene

SAND = dict(law="rft3d", medium="sand_3d_rft_code", mu_surf=0.1806)  # the hexapod's sand (mjcf/hexapod.toml)
LEGS = ["front_left", "middle_left", "rear_left", "front_right", "middle_right", "rear_right"]
ROBOTS = ["sand_swimmer", "hexapod", "wheel_rig"]


# --- the TOML scenes -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ROBOTS)
def test_scene_names_what_the_model_has(name):
    """Every body, actuator and drive of mjcf/NAME.toml is in the model it names, the law is a surface law, and the
    ramps and the averaging window fit in the run (what the runner refuses otherwise)."""
    path = Path(str(mjcf_path(f"{name}.toml")))
    scene = tomllib.loads(path.read_text())
    model = mujoco.MjModel.from_xml_path(str(path.parent / scene["model"]["path"]))
    for body in scene["model"]["bodies"]:
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body) >= 0, body
    assert scene["medium"]["law"] in laws.names(laws.SURFACE)
    assert set(scene["medium"]) <= {f.name for f in dataclasses.fields(Medium)}   # the scene schema's keys
    duration = scene["sim"]["duration"]
    assert 0 <= scene["sim"]["settle"] < duration
    for control in scene.get("control", []):
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, control["actuator"]) >= 0, control
        assert control.get("ramp", 0.0) < duration
    for drive in scene.get("drive", []):
        joint = model.joint(drive["joint"])
        assert int(joint.type[0]) in (mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE), drive
    # a robot's numerics: implicit steps of 0.5 ms or longer, where their figures are estimated within the default
    # limits (the hexapod's cost of transport at 1 ms is not: docs/guide/methods.md)
    assert scene["sim"]["dt"] >= 0.0005 and scene["sim"]["method"] in ("newton", "newton-midpoint")


MEDIA = {"sand_swimmer": ([f"link{i}" for i in range(1, 8)], 0.005, dict(law="li2013", medium="glass_beads_treers2021")),
         "hexapod": (["chassis", *LEGS], 0.004, SAND),
         "wheel_rig": (["wheel"], 0.004, dict(law="li2013", zeta=0.6))}
# Where each robot is put into the sand for the twins' test: (the joint's qpos index from its start, m lower).
SUNK = {"sand_swimmer": ("root", 2, 0.0), "hexapod": ("root", 2, 0.05), "wheel_rig": ("lift", 0, 0.015)}


@pytest.mark.parametrize("name", ROBOTS)
def test_native_plugin_and_python_twin_agree(name):
    """The medium's generalised force on each robot, in the sand (the swimmer as built, the hexapod with its
    chassis half buried, the wheel 15 mm deep) and moving at random, from the native plugin and from its Python
    twin: the same to 1e-9."""
    bodies, size, medium = MEDIA[name]
    joint, index, depth = SUNK[name]
    forces = []
    for backend in ("native", "python"):
        spec = mujoco.MjSpec.from_file(str(mjcf_path(f"{name}_scene.xml")))
        attached = finrft.attach(spec, bodies, element_size=size, backend=backend, **medium)
        model = spec.compile()
        data = mujoco.MjData(model)
        data.qvel[:] = np.random.default_rng(23).normal(0.0, 0.1, model.nv)
        data.qpos[model.joint(joint).qposadr[0] + index] -= depth
        with attached.installed(model):
            mujoco.mj_forward(model, data)
        forces.append(data.qfrc_passive.copy())
    assert np.abs(forces[0]).max() > 0.01                    # the medium acts
    np.testing.assert_allclose(forces[0], forces[1], rtol=1e-9, atol=1e-9 * np.abs(forces[0]).max())


# --- the sand-swimmer --------------------------------------------------------------------------------------------

LINK = 0.04                 # m, a link's length
THETA0 = math.radians(60)   # the wave's heading amplitude, equal to the joint amplitude at a lag of pi/3


def test_swimmer_joint_lag_makes_a_serpenoid_of_a_over_lambda_0_2():
    """The gait's derivation (mjcf/sand_swimmer.xml): links l apart on a serpenoid of arc wavelength 6 l differ in
    heading by 2 theta0 sin(pi/6) = theta0, and the wave's amplitude over its wavelength along the travel is
    H0(theta0) / (4 J0(theta0)) = 0.198, checked here on the discrete chain's shape."""
    heading = lambda s: THETA0 * np.cos(2 * math.pi * s / (6 * LINK))
    along = np.linspace(0, 6 * LINK, 6001)
    assert np.abs(heading(along + LINK) - heading(along)).max() == pytest.approx(THETA0, rel=1e-6)
    # The chain's centre line as it is built: six links in one wavelength, each turned by the joints' sum.
    n = 6 * 200
    s = (np.arange(n) + 0.5) * 6 * LINK / n
    x, y = np.cumsum(np.cos(heading(s))) * 6 * LINK / n, np.cumsum(np.sin(heading(s))) * 6 * LINK / n
    amplitude, wavelength = (y.max() - y.min()) / 2, x[-1]
    assert wavelength == pytest.approx(6 * LINK * special.j0(THETA0), rel=1e-3)
    assert amplitude / wavelength == pytest.approx(0.198, abs=0.002)


def robot_run(name: str, **overrides) -> dict:
    """The example's run (finrft run --example NAME) at its default numerics, its summary; without the companion run
    of its error estimate, as these tests check the physics, not the step."""
    scene = load_scene(example(name), overrides=overrides, cls=UserScene)
    return finrft.run(UserModel.of(scene), scene, max_error=None, estimate_error=False).summary()


# The swimmer's wave: lambda = 6 links' arc wavelength along the travel (test above), 1 Hz.
WAVELENGTH = 6 * LINK * special.j0(THETA0)


@pytest.mark.parametrize("medium", [
    {},  # li2013 (3D) in Treers et al.'s glass beads, the example's own
    # rft3d's fitted stress feeds energy in on grazing faces: on this swimmer its steps flip between two balances
    # every 3-4 steps, which the chatter probe stops, with newton at 0.5 ms and newton-midpoint at 0.5 and 1 ms
    # (newton at 1 ms and 0.25 ms, newton-midpoint at 0.25 ms and 2 ms run through): the law's, not the step's
    {"medium.law": "rft3d", "medium.name": "sand_3d_rft_code", "medium.surface_friction": 0.4,
     "sim.method": "newton"}])
def test_swimmer_swims_forward_at_a_sand_swimmers_wave_efficiency(medium):
    """Undulating in the medium, the free swimmer moves towards its head at a wave efficiency eta = v / (f lambda)
    inside the range sand-swimming studies report (0.2-0.5: sandfish robot 0.34 +- 0.02, sandfish 0.5; Maladen et
    al. 2011), in li2013's glass beads and in rft3d's sand with a skin friction of 0.4 (the lab's robot of the
    notes; a slicker skin swims faster: 0.73 at the code's 0.18); the lateral drift stays small."""
    s = robot_run("sand_swimmer", **{"sim.duration": 3.0, **medium})
    vx, vy, _ = s["com_velocity_m_s"]
    assert 0.2 < vx / WAVELENGTH < 0.5, vx / WAVELENGTH
    assert abs(vy) < 0.25 * vx


def test_planar_li2013_warns_that_it_cannot_swim(monkeypatch):
    monkeypatch.setattr(laws, "_cautioned", set())  # it warns once per process: this process may have been told
    with pytest.warns(UserWarning, match="planar"):
        finrft.attach(mujoco.MjSpec.from_file(str(mjcf_path("sand_swimmer_scene.xml"))), ["link1", "link2"],
                      law="li2013-planar")


# --- the hexapod -------------------------------------------------------------------------------------------------

def test_c_leg_mesh_is_a_closed_half_annulus_with_outward_normals():
    """The divergence theorem over the leg's triangles gives its volume, positive only if every face's winding
    points outward: the half annulus's pi R t w (R 20 mm, t 3 mm, w 10 mm), its 12 straight segments along the
    half circle making it sin(d) / d smaller (d = pi/12, each segment's angle)."""
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("hexapod.xml")))
    mesh = model.mesh("c_leg").id
    vert = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    face = model.mesh_face[model.mesh_faceadr[mesh]:model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
    tri = vert[face].astype(float)
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    chords = math.sin(math.pi / 12) / (math.pi / 12)
    assert volume == pytest.approx(math.pi * 0.02 * 0.003 * 0.01 * chords, rel=1e-5)


def test_hexapod_walks_forward_slower_than_its_legs_roll():
    """At 2 Hz the hexapod walks forward, upright, no faster than its legs rolling without slip (omega 2R: a
    C-leg reaches 2R = 40 mm below its hip) and much faster than nothing."""
    s = robot_run("hexapod", **{"sim.duration": 2.0})
    omega = 4 * math.pi
    speed = math.hypot(*s["com_velocity_m_s"][:2])
    assert 0.2 * omega * 0.04 < speed < omega * 0.04, speed


def test_hexapod_standing_still_does_not_creep():
    """With its legs held (ctrl 0: each intvelocity servo holds its leg), the hexapod settles on the sand and then
    stays: the rate-independent medium holds a body at rest; the regularisation lets it creep at about v_reg
    (0.1 mm/s) times atanh(load / full force), below 0.1 mm/s; the medium carries its weight."""
    still = {f"control.{i}.value": 0.0 for i in range(6)}
    s = robot_run("hexapod", **{"sim.duration": 3.0, "sim.settle": 2.0, **still})
    assert np.linalg.norm(s["com_velocity_m_s"]) < 1e-4
    weight = mujoco.MjModel.from_xml_path(str(mjcf_path("hexapod_scene.xml"))).body_subtreemass[0] * 9.81
    assert s["medium_force_N"][2] == pytest.approx(weight, rel=1e-3)


# --- the wheel rig -----------------------------------------------------------------------------------------------

RADIUS, WIDTH, ZETA = 0.0625, 0.06, 0.6


def pressed_cylinder_force(sinkage: float) -> float:
    """Li et al. 2013's vertical force on a horizontal cylinder pushed straight down with its lowest point at
    ``sinkage`` below the surface, by quadrature over the submerged lower arc (the leading half): the element at
    angle theta from the bottom is a plate tilted by theta, at depth sinkage - R (1 - cos theta), taking
    alpha_z(theta, pi/2); the flat ends move along themselves and take nothing."""
    edge = math.acos(1 - sinkage / RADIUS)
    stress = lambda theta: li2013.alpha(theta, math.pi / 2, ZETA)[1] * (sinkage - RADIUS * (1 - math.cos(theta)))
    return WIDTH * RADIUS * integrate.quad(stress, -edge, edge)[0]


def test_wheel_at_rest_sinks_until_the_sand_holds_its_weight():
    """The wheel lowered onto the sand under its 21 N load (the rig's lift slide damped, so it arrives without
    overshoot), stepped by newton at 1 ms, settles where the closed form's force equals the weight; released, the
    medium's mean vertical force on it is the weight. The medium's ramp is made 100 times narrower than its default
    (v_reg 1e-6 m/s): at the default a resting body creeps at about 0.2 mm/s, 3 % of this sinkage in 2 s."""
    spec = mujoco.MjSpec.from_file(str(mjcf_path("wheel_rig_scene.xml")))
    attached = finrft.attach(spec, ["wheel"], element_size=0.004, law="li2013", zeta=ZETA, v_reg=1e-6)
    model = spec.compile()
    data = mujoco.MjData(model)
    lift = model.joint("lift").dofadr[0]
    held = [model.joint(j).dofadr[0] for j in ("carriage", "slip_angle", "axle")]
    weight = model.body_subtreemass[model.body("load").id] * -model.opt.gravity[2]
    assert weight == pytest.approx(21.0, rel=0.01)             # the experiments' measured load
    model.dof_damping[lift] = 200.0                            # N s/m: settles in about c / (dF/dz) = 0.1 s
    advance = stepper(model, Sim(method="newton", dt=1e-3), attached.backend, [], attached)
    model.opt.timestep = 1e-3
    for _ in range(2000):
        data.qvel[held] = 0.0
        assert advance(data, 1) == 0
    expected = optimize.brentq(lambda s: pressed_cylinder_force(s) - weight, 1e-4, RADIUS)
    assert -data.qpos[lift] == pytest.approx(expected, rel=5e-3)
    model.dof_damping[lift] = 0.0
    force = []
    for _ in range(500):
        data.qvel[held] = 0.0
        assert advance(data, 1) == 0
        mujoco.mj_forward(model, data)
        force.append(data.qfrc_passive[lift])                  # the medium's force along the lift: its Fz
    assert np.mean(force) == pytest.approx(weight, rel=2e-3)

def test_wheel_rig_starts_at_the_depth_where_the_sand_carries_it_as_it_drives():
    """The keyframe the rig's scene starts from ("steady", mjcf/wheel_rig_scene.xml) is the free wheel's steady
    state under the rig's own sand and drive (`finrft wheel`'s start: the held wheel's vertical force equals the
    load, by bisection), and started there the wheel stays: its hub's mean vertical speed over the run is below
    0.01 mm/s. From the surface it settles over about 20 s, still sinking at 0.15 mm/s over 4-10 s."""
    scene = wheel.default_scene()
    assert scene.medium == load_scene(example("wheel_rig"), cls=UserScene).medium
    rig = wheel.Wheel.of(scene)
    sinkage = wheel.equilibrium_sinkage(scene, rig.build(scene), rig)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("wheel_rig_scene.xml")))
    assert -model.key("steady").qpos[model.joint("lift").qposadr[0]] == pytest.approx(sinkage, abs=1e-6)
    summary = finrft.run_robot(load_scene(example("wheel_rig"), cls=UserScene)).summary()
    assert abs(summary["com_velocity_m_s"][2]) < 1e-5


def test_wheel_rigs_newton_step_holds_below_its_load_axis_period():
    """Newton's step takes the positions at its start: the load axis (2.14 kg) on the sand's vertical stiffness k
    (dFz/dz of the wheel driven at its steady depth, by differences) is a spring the step resolves only below
    dt = 2 sqrt(m / k), 86 ms: at 0.9 of that it runs (the rig's scene steps at 0.72), at 1.15 it stops as
    chattering."""
    scene = wheel.default_scene()
    rig = wheel.Wheel.of(scene)
    built = rig.build(scene)
    model, data = built.model, mujoco.MjData(built.model)
    for j, qpos, dof in zip(rig.robot_scene(scene).drive, built.drive_qpos, built.drive_dofs):
        data.qpos[qpos], data.qvel[dof] = j.start, j.speed
    lift, force = model.joint("lift").qposadr[0], medium_forces(built)
    depth = wheel.equilibrium_sinkage(scene, built, rig)

    def vertical(sinkage: float) -> float:
        data.qpos[lift] = -sinkage
        mujoco.mj_forward(model, data)
        return float(force(data)[0, 2])
    k = (vertical(depth + 5e-4) - vertical(depth - 5e-4)) / 1e-3
    limit = 2 * math.sqrt(model.body_subtreemass[model.body("load").id] / k)
    assert limit == pytest.approx(0.086, abs=0.002)
    rig_scene = load_scene(example("wheel_rig"), cls=UserScene).replace(**{"sim.duration": 4.0, "sim.settle": 2.0})
    for dt in (0.9 * limit, 1.15 * limit):
        s = rig_scene.replace(**{"sim.dt": dt, "sim.record_dt": dt})
        if dt < limit:
            finrft.run_robot(s)
        else:
            with pytest.raises(Chatter):
                finrft.run_robot(s)


def test_wheel_rigs_carriage_load_balances_the_sands_drawbar_pull():
    """The carriage's prescribed slide pushes the wheel's assembly, and nothing but the sand acts on it along x: the
    load its drive applies is minus the sand's mean force along x, and at the rig's step both are within 1 % of a
    run at a tenth of it. Read at the state after each step rather than where the step took them, both came out
    7.6 % short at 10 ms on the wheel sinking from the surface."""
    dt = load_scene(example("wheel_rig"), cls=UserScene).sim.dt  # 10 s from the keyframe, averaged over 4-10 s
    coarse, fine = robot_run("wheel_rig"), robot_run("wheel_rig", **{"sim.dt": dt / 10})
    for s in (coarse, fine):
        assert s["drive_load"][0] == pytest.approx(-s["medium_force_N"][0], rel=1e-4)
    assert coarse["drive_load"][0] == pytest.approx(fine["drive_load"][0], rel=0.01)
