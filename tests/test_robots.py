"""The example robots of mjcf/ (sand_swimmer, hexapod, wheel_rig) in the medium, each against physics computed
apart from the element code: the swimmer's wave efficiency against sand-swimming's published range, the hexapod's
speed against its legs' rolling speed and its rest on the sand, the wheel's static sinkage against a quadrature of
Li et al. 2013's law over the submerged arc; and their TOML scenes against the models they name.

The runs use the Python API with MuJoCo's own step at 0.1 ms, where the explicitly integrated surface forces have
converged to about 1 % (the scenes' 1 ms defaults need the implicit steps)."""

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
from finrft.laws import li2013
from finrft.models import mjcf_path
from finrft.scene import Medium

DT = 1e-4
SAND = dict(law="rft3d", rho_c=1500.0, mu_int=0.4, mu_surf=0.4)  # the robots' sand: rho_c kg/m^3, frictions
LEGS = ["front_left", "middle_left", "rear_left", "front_right", "middle_right", "rear_right"]
ROBOTS = ["sand_swimmer", "hexapod", "wheel_rig"]


def build(name: str, bodies: list[str], element_size: float, **medium) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The robot's scene as installed with the package (mjcf/NAME_scene.xml), with RFT on ``bodies``."""
    spec = mujoco.MjSpec.from_file(str(mjcf_path(f"{name}_scene.xml")))
    finrft.attach(spec, bodies, element_size=element_size, **medium)
    model = spec.compile()
    model.opt.timestep = DT
    return model, mujoco.MjData(model)


def steps(seconds: float) -> int:
    return int(round(seconds / DT))


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
    assert scene["sim"]["dt"] == 0.001 and scene["sim"]["method"] == "newton"


MEDIA = {"sand_swimmer": ([f"link{i}" for i in range(1, 8)], 0.005, SAND),
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


def test_swimmer_swims_forward_at_a_sand_swimmers_wave_efficiency():
    """Undulating in rft3d sand, the free swimmer moves towards its head at a wave efficiency eta = v / (f lambda)
    inside the range sand-swimming studies report (0.2-0.5: sandfish robot 0.34 +- 0.02, sandfish 0.5; Maladen et
    al. 2011); the lateral drift stays small against the forward speed."""
    model, data = build("sand_swimmer", [f"link{i}" for i in range(1, 8)], 0.005, **SAND)
    f, ramp, window = 1.0, 0.5, 1.5
    positions = []
    for k in range(steps(4.0)):
        data.ctrl[:] = min(data.time / ramp, 1.0) * THETA0 * np.sin(
            2 * math.pi * f * data.time - np.arange(1, 7) * math.pi / 3)
        mujoco.mj_step(model, data)
        if data.time >= window and k % 100 == 0:
            positions.append((data.time, *data.subtree_com[1, :2]))
    t, x, y = np.array(positions).T
    vx, vy = np.polyfit(t, x, 1)[0], np.polyfit(t, y, 1)[0]
    eta = vx / (f * 6 * LINK * special.j0(THETA0))
    assert 0.2 < eta < 0.5, eta
    assert abs(vy) < 0.25 * vx


# --- the hexapod -------------------------------------------------------------------------------------------------

HEXAPOD_BODIES = ["chassis", *LEGS]


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
    """At 2 Hz the hexapod walks towards +x, upright, no faster than its legs rolling without slip (omega 2R: a
    C-leg reaches 2R = 40 mm below its hip) and much faster than nothing."""
    model, data = build("hexapod", HEXAPOD_BODIES, 0.004, **SAND)
    omega = 4 * math.pi
    track = []
    for k in range(steps(2.5)):
        data.ctrl[:] = omega * min(data.time / 0.5, 1.0)
        mujoco.mj_step(model, data)
        if data.time >= 1.0 and k % 100 == 0:
            track.append((data.time, *data.qpos[:2]))
    t, x, y = np.array(track).T
    speed = np.hypot(np.polyfit(t, x, 1)[0], np.polyfit(t, y, 1)[0])
    assert 0.2 * omega * 0.04 < speed < omega * 0.04, speed
    assert np.polyfit(t, x, 1)[0] > 0.8 * speed              # mostly along its heading
    assert data.xmat[model.body("chassis").id][8] > 0.8      # the chassis's z axis still points up


@pytest.mark.xfail(strict=True, reason="a hexapod resting on its legs creeps: in rft3d sand 1.5 mm/s at 0.1 ms and "
                   "at 25 us alike (not the step: rft3d's grazing faces that feed energy in are a candidate); in "
                   "li2013 sand 3.3 mm/s at 0.1 ms, 0.6 mm/s at 25 us (the explicit step's chatter, ~dt)")
def test_hexapod_standing_still_does_not_creep():
    """With its legs held (ctrl 0: each intvelocity servo holds its leg), the hexapod settles on the sand and then
    stays: the rate-independent medium holds a body at rest, so once settled it creeps < 0.1 mm/s."""
    model, data = build("hexapod", HEXAPOD_BODIES, 0.004, **SAND)
    track = []
    for k in range(steps(3.0)):
        mujoco.mj_step(model, data)
        if data.time >= 2.0 and k % 100 == 0:
            track.append((data.time, *data.qpos[:3]))
    track = np.array(track)
    creep = np.polyfit(track[:, 0], track[:, 1:], 1)[0]
    assert np.linalg.norm(creep) < 1e-4, creep


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
    overshoot) settles where the closed form's force equals the weight; released, the medium's mean vertical force
    on it is the weight."""
    model, data = build("wheel_rig", ["wheel"], 0.004, law="li2013", zeta=ZETA)
    lift = model.joint("lift").dofadr[0]
    held = [model.joint(j).dofadr[0] for j in ("carriage", "slip_angle", "spin")]
    weight = model.body_subtreemass[model.body("axle").id] * -model.opt.gravity[2]
    assert weight == pytest.approx(21.0, rel=0.01)             # the experiments' measured load
    model.dof_damping[lift] = 200.0                            # N s/m: settles in about c / (dF/dz) = 0.1 s
    for _ in range(steps(2.0)):
        data.qvel[held] = 0.0
        mujoco.mj_step(model, data)
    expected = optimize.brentq(lambda s: pressed_cylinder_force(s) - weight, 1e-4, RADIUS)
    assert -data.qpos[lift] == pytest.approx(expected, rel=5e-3)
    model.dof_damping[lift] = 0.0
    force = []
    for _ in range(steps(0.5)):
        data.qvel[held] = 0.0
        mujoco.mj_step(model, data)
        force.append(data.qfrc_passive[lift])                  # the medium's force along the lift: its Fz
    assert np.mean(force) == pytest.approx(weight, rel=2e-3)
