"""The free surfaces in runs (finrft.attach's ``surface``, a scene's ``[medium] surface``): depth along the model's
gravity from the local surface and the laws' angles against it, in the native plugin and the numpy callback alike.
Rotating a whole scene (surface, gravity, body) leaves every force and motion the same, rotated; the twins agree;
a plane at no tilt is the flat surface; a tilted gravity over the flat surface is refused."""

import mujoco
import numpy as np
import pytest

from finrft import surfaces
from finrft.attach import attach
from finrft.errors import SceneError
from finrft.surfaces import hfield
from conftest import dragged_plate_scene

# A free body of three kinds of geom, no contacts: what moves it is gravity and the medium.
BODY = """
<mujoco>
  <option timestep="2e-4" integrator="implicitfast"/>
  <worldbody>
    <body name="probe" pos="0 0 0.01">
      <freejoint/>
      <geom type="box" size="0.02 0.015 0.01" contype="0" conaffinity="0"/>
      <geom type="capsule" fromto="0.02 0 -0.01 0.04 0.01 -0.03" size="0.006" contype="0" conaffinity="0"/>
      <geom type="sphere" pos="-0.02 0 -0.012" size="0.008" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""
G = np.array([0.0, 0.0, -9.81])
QVEL = np.array([0.05, -0.02, -0.03, 0.4, -0.3, 0.2])  # linear (world), angular (body frame)
SLOPE = np.radians(12)
NORMAL = np.array([-np.sin(SLOPE), 0.0, np.cos(SLOPE)])  # rising along +x


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    return q


def _grid(R: np.ndarray) -> surfaces.Field:
    """A heightfield rising at SLOPE with ripples, turned with the scene by R."""
    field = hfield.generated("noise", G, (0.005, -0.003, -0.002), extent=0.15, spacing=0.005, slope=SLOPE,
                             height=0.003, length=0.02, seed=3)
    p = field.parameters
    return surfaces.Field("hfield", {**p, "centre": tuple(R @ p["centre"]), "frame": R @ p["frame"]})


def _surface(kind: str, R: np.ndarray) -> dict:
    if kind == "plane":
        return {"surface": "plane", "surface_point": R @ [0.0, 0.0, 0.004], "surface_normal": R @ NORMAL}
    return {"surface": _grid(R)}


def _run(kind: str, R: np.ndarray, backend: str, steps: int = 150, law: str = "li2013"):
    """The body's origin, orientation and the medium's wrench on it, every 10 steps, rotated back by R."""
    spec = mujoco.MjSpec.from_string(BODY)
    spec.option.gravity = R @ G
    body = spec.body("probe")
    body.pos = R @ body.pos
    body.quat = _quat(R)
    extra = {"medium": "poppy_seeds_lp"} if law == "li2013" else {"rho_c": 1617.0, "mu_int": 1.07, "mu_surf": 0.2}
    attached = attach(spec, "probe", law=law, element_size=0.006, backend=backend, **_surface(kind, R), **extra)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[:3], data.qvel[3:] = R @ QVEL[:3], QVEL[3:]
    wrench = attached.wrenches(model)
    out = []
    with attached.installed(model):
        for step in range(steps):
            mujoco.mj_step(model, data)
            if step % 10 == 9:
                mujoco.mj_forward(model, data)
                w = wrench(data)[0]
                out.append(np.concatenate([R.T @ data.xpos[1], (R.T @ data.xmat[1].reshape(3, 3)).ravel(),
                                           R.T @ w[:3], R.T @ w[3:]]))
    return np.array(out)


def _scale(run: np.ndarray) -> np.ndarray:
    """Each column's largest size, so that 1e-9 is relative to the force or length it compares."""
    return np.maximum(np.abs(run).max(axis=0), 1e-300)


@pytest.mark.parametrize("kind", ["plane", "hfield"])
@pytest.mark.parametrize("backend", ["native", "python"])
def test_rotating_the_whole_scene_changes_no_force_or_motion(kind, backend):
    plain = _run(kind, np.eye(3), backend)
    forces = np.abs(plain[:, 12:]).max()
    assert forces > 0.05  # the medium holds the body
    for seed in (0, 1):
        turned = _run(kind, _rotation(seed), backend)
        assert np.all(np.abs(turned - plain) <= 1e-9 * _scale(plain)), np.abs(turned - plain).max(axis=0)


@pytest.mark.parametrize("kind", ["plane", "hfield"])
@pytest.mark.parametrize("law", ["li2013", "rft3d"])
def test_native_and_numpy_agree_on_a_surface(kind, law):
    R = _rotation(2)
    native, numpy = _run(kind, R, "native", law=law), _run(kind, R, "python", law=law)
    assert np.all(np.abs(native - numpy) <= 1e-9 * _scale(numpy)), np.abs(native - numpy).max(axis=0)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_a_plane_at_no_tilt_is_the_flat_surface(backend):
    def run(**surface):
        spec = mujoco.MjSpec.from_string(BODY)
        attached = attach(spec, "probe", medium="poppy_seeds_lp", element_size=0.006, backend=backend, **surface)
        model = spec.compile()
        data = mujoco.MjData(model)
        data.qvel[:] = QVEL
        wrench, out = attached.wrenches(model), []
        with attached.installed(model):
            for _ in range(100):
                mujoco.mj_step(model, data)
                mujoco.mj_forward(model, data)
                out.append(np.concatenate([data.qpos, wrench(data)[0]]))
        return np.array(out)

    flat = run(surface_z=0.004)
    assert np.abs(flat[:, -3:]).max() > 0.05
    plane = run(surface="plane", surface_point=(0.3, -0.2, 0.004), surface_normal=(0, 0, 2.0))
    assert np.all(np.abs(plane - flat) <= 1e-12 * _scale(flat))


def _moving(backend: str = "native", **surface):
    """The body (held in place: no joint) attached over ``surface``, its model and an MjData moving it at QVEL."""
    spec = mujoco.MjSpec.from_string(BODY.replace("<freejoint/>", "<joint type='free'/>"))
    attached = attach(spec, "probe", medium="poppy_seeds_lp", element_size=0.006, backend=backend, **surface)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[:] = QVEL
    mujoco.mj_forward(model, data)
    return attached, model, data


def _by_hand(attached, model, data, depth_of) -> np.ndarray:
    """The force on the body from the law on each element at the depth ``depth_of(centres)``, gravity along -z."""
    (centre, normal, area), = attached.world_elements(model, data).values()
    arm = centre - data.xpos[1]
    velocity = data.qvel[:3] + np.cross(data.xmat[1].reshape(3, 3) @ data.qvel[3:], arm)
    return attached.element_forces(normal, velocity, depth_of(centre), area).sum(axis=0)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_depth_is_measured_along_gravity_below_the_local_surface(backend):
    # on a 12 deg slope under gravity along -z, each element's depth is the height of the slope above it
    attached, model, data = _moving(backend, surface="plane", surface_point=(0.0, 0.0, 0.004), surface_normal=NORMAL)
    force = attached.wrenches(model)(data)[0, 3:]
    expected = _by_hand(attached, model, data, lambda c: 0.004 + np.tan(SLOPE) * c[:, 0] - c[:, 2])
    across = _by_hand(attached, model, data, lambda c: (0.004 - c @ [0, 0, 1]) * np.cos(SLOPE)
                      + np.sin(SLOPE) * c[:, 0] * np.cos(SLOPE))  # the distance across the slope instead
    assert np.abs(force).max() > 0.05 and np.abs(force - expected).max() <= 1e-9 * np.abs(expected).max()
    assert np.abs(force - across).max() > 1e-3 * np.abs(expected).max()


def test_a_tilted_gravity_over_the_flat_surface_is_refused():
    spec = mujoco.MjSpec.from_string(BODY)
    spec.option.gravity = [9.81 * np.sin(SLOPE), 0.0, -9.81 * np.cos(SLOPE)]  # a slope faked by gravity
    with pytest.raises(SceneError, match='medium.surface = "plane"'):
        attach(spec, "probe", medium="poppy_seeds_lp")
    attach(spec, "probe", medium="poppy_seeds_lp", surface="plane", surface_normal=(0, 0, 1))  # said: level sand


HFIELD = """
<mujoco>
  <asset><hfield name="ground" nrow="3" ncol="4" size="0.2 0.1 0.03 0.01"
                 elevation="0 1 2 3  1 2 3 4  2 3 4 5"/></asset>
  <worldbody>
    <geom name="shown" type="hfield" hfield="ground" pos="0.01 0.02 -0.02" contype="0" conaffinity="0"/>
    <body name="probe"><freejoint/><geom type="sphere" size="0.01" contype="0" conaffinity="0"/></body>
  </worldbody>
</mujoco>
"""


def test_an_hfield_of_the_model_is_measured_where_its_geom_shows_it():
    spec = mujoco.MjSpec.from_string(HFIELD)
    attached = attach(spec, "probe", medium="poppy_seeds_lp", surface="hfield", hfield="ground")
    # MuJoCo's own ray onto the geom that shows the field finds its surface where the depths put it (its
    # triangles and the bilinear heights agree here: the elevation is a plane, r + c)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rng = np.random.default_rng(4)
    xy = rng.uniform([-0.18, -0.08], [0.2, 0.11], size=(20, 2))
    points = np.c_[xy, np.full(20, -0.1)]
    surface = np.empty(20)
    for k, (x, y, _) in enumerate(points):
        found = np.zeros(1, np.int32)
        distance = mujoco.mj_ray(model, data, np.array([x, y, 0.5]), np.array([0.0, 0.0, -1.0]), None, 1, -1, found)
        assert found[0] == model.geom("shown").id
        surface[k] = 0.5 - distance
    assert np.abs(attached.free_surface.depth(points, G) - (surface - points[:, 2])).max() < 1e-6
    with pytest.raises(SceneError, match="names no <hfield>"):
        attach(mujoco.MjSpec.from_string(HFIELD), "probe", medium="poppy_seeds_lp", surface="hfield", hfield="sand")
    with pytest.raises(SceneError, match='contype="0"'):
        attach(mujoco.MjSpec.from_string(HFIELD.replace(' contype="0" conaffinity="0"/>\n    <body', '/>\n    <body')),
               "probe", medium="poppy_seeds_lp", surface="hfield", hfield="ground")


@pytest.mark.parametrize("kind", ["plane", "hfield"])
@pytest.mark.parametrize("law", ["li2013", "rft3d"])
def test_the_implicit_steps_agree_and_turn_with_the_scene(kind, law):
    # newton's steps take the submerged elements and each one's Jacobian in the law's frame: native and numpy
    # agree, and the turned scene moves as the plain one, turned
    from finrft import integrate
    from finrft.scene import Sim

    medium = {"medium": "poppy_seeds_lp"} if law == "li2013" else {"rho_c": 1617.0, "mu_int": 1.07, "mu_surf": 0.2}
    runs = {}
    for backend, seed in (("native", None), ("python", None), ("native", 5)):
        R = np.eye(3) if seed is None else _rotation(seed)
        spec = mujoco.MjSpec.from_string(BODY)
        spec.option.gravity = R @ G
        spec.body("probe").pos = R @ spec.body("probe").pos
        spec.body("probe").quat = _quat(R)
        attached = attach(spec, "probe", law=law, element_size=0.006, backend=backend, v_reg=1e-3,
                          **_surface(kind, R), **medium)
        m = spec.compile()
        m.opt.timestep = 1e-3
        d = mujoco.MjData(m)
        d.qvel[:3], d.qvel[3:] = R @ QVEL[:3], QVEL[3:]
        advance = integrate.stepper(m, Sim(method="newton", dt=1e-3), backend, [], attached)
        out = []
        with attached.installed(m):
            for _ in range(60):
                assert advance(d, 1) == 0
                out.append(np.concatenate([R.T @ d.xpos[1], (R.T @ d.xmat[1].reshape(3, 3)).ravel()]))
        runs[backend, seed] = np.array(out)
    plain = runs["native", None]
    free = 0.06 * QVEL[:3] + 0.5 * 0.06 ** 2 * G  # where it would be in 60 ms without the medium
    assert np.abs(plain[-1, :3] - plain[0, :3] - free).max() > 1e-3  # the medium held it
    for other in (runs["python", None], runs["native", 5]):
        assert np.abs(other - plain).max() <= 1e-9, np.abs(other - plain).max(axis=0)


def _settled_bottom(bed_depth: float) -> float:
    """The lowest point of a heavy box dropped onto the sand, after 0.5 s of newton's steps."""
    from finrft import integrate
    from finrft.scene import Sim

    spec = mujoco.MjSpec.from_string("""<mujoco><option timestep="1e-3"/><worldbody>
      <body name="box" pos="0 0 0.01"><freejoint/><geom type="box" size="0.02 0.02 0.01" mass="20"/></body>
      </worldbody></mujoco>""")
    attached = attach(spec, "box", medium="poppy_seeds_lp", element_size=0.01, bed_depth=bed_depth, v_reg=1e-3)
    m = spec.compile()
    d = mujoco.MjData(m)
    advance = integrate.stepper(m, Sim(method="newton", dt=1e-3), "native", [], attached)
    with attached.installed(m):
        assert advance(d, 500) == 0
    return float(d.qpos[2] - 0.01)


def test_a_bed_of_finite_depth_rests_the_body_on_its_floor():
    unbounded = _settled_bottom(0.0)
    assert unbounded < -0.04  # 20 kg on 16 cm^2 of poppy seeds: the sand alone holds it deep
    assert _settled_bottom(0.02) == pytest.approx(-0.02, abs=2e-3)  # on the floor, to MuJoCo's soft contact
    spec = mujoco.MjSpec.from_string(BODY)
    attach(spec, "probe", medium="poppy_seeds_lp", surface="plane", surface_point=(0, 0, 0.004),
           surface_normal=NORMAL, bed_depth=0.03)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    floor = model.geom("finrft_bed").id
    # parallel to the slope, 3 cm below it along gravity
    assert data.geom_xmat[floor].reshape(3, 3)[:, 2] == pytest.approx(NORMAL)
    below = surfaces.module("plane").depth(data.geom_xpos[floor][None], G, surface_point=(0, 0, 0.004),
                                           surface_normal=NORMAL)
    assert below == pytest.approx([0.03])


TILTED = """<mujoco><option gravity="1.7 0 -9.66"/><worldbody><body name="plate">
  <joint name="drag" type="slide" axis="1 0 0"/><geom type="box" size="0.0005 0.02 0.03" pos="0 0 -0.03" mass="10"/>
</body></worldbody></mujoco>"""
PLATE = TILTED.replace("1.7 0 -9.66", "0 0 -9.81")
SCENE = dragged_plate_scene(0.01, record_dt=0.01)


@pytest.mark.parametrize("model,sets,named", [
    (TILTED, (), 'is not along -z over the flat surface (medium.surface = "flat" is horizontal, not a slope): for a '
                 'slope give medium.surface = "plane" with its surface_normal'),
    (PLATE, ("medium.surface=deforming",), 'medium.surface = "deforming" needs an angle of repose: medium (unnamed) '
                                           'catalogues none; set medium.angle_of_repose (rad)'),
    (PLATE, ("medium.surface=plane", "medium.surface_normal=[0, 1]"), "medium.surface_normal must be 3 numbers"),
    (PLATE, ("medium.surface=plane", "medium.surface_normal=[0, 0, -1]"), "does not point against gravity"),
    (PLATE, ("medium.surface=hfield", "medium.hfield=sand"), "names no <hfield> of the model"),
    (PLATE, ("medium.hfield_slope=0.1",), "medium.hfield_slope is used by surface = 'hfield' or 'deforming' only"),
])
def test_a_scene_s_bad_surface_is_one_line_exit_2(tmp_path, capsys, model, sets, named):
    from finrft.cli import main

    (tmp_path / "plate.xml").write_text(model)
    (tmp_path / "scene.toml").write_text(SCENE)
    argv = ["run", str(tmp_path / "plate.xml"), "--scene", str(tmp_path / "scene.toml"), "--out",
            str(tmp_path / "run.h5"), *(item for key in sets for item in ("--set", key))]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and named in err, err
    assert not (tmp_path / "run.h5").exists()


def test_a_scene_on_a_level_plane_or_hfield_runs_as_on_the_flat_surface(tmp_path):
    import finrft
    from finrft.experiments.user_model import UserModel
    from finrft.scene import UserScene, load_scene

    (tmp_path / "plate.xml").write_text(PLATE)
    (tmp_path / "scene.toml").write_text(SCENE)
    scene = load_scene(tmp_path / "scene.toml", cls=UserScene)
    flat = finrft.run(UserModel.of(scene), scene)
    for surface in ({"medium.surface": "plane", "medium.surface_point": (0.5, 0.1, 0.0)},
                    {"medium.surface": "hfield", "medium.hfield_extent": 0.2, "medium.hfield_spacing": 0.02}):
        other = finrft.run(UserModel.of(scene), scene.replace(**surface))
        assert np.abs(flat.drive_load).max() > 1.0
        assert other.drive_load == pytest.approx(flat.drive_load, abs=1e-9 * np.abs(flat.drive_load).max())


@pytest.mark.parametrize("command,named", [
    ("intrude", "the intrusion pushes its plate down from the flat surface at medium.surface_z only"),
    ("swim", "unknown scene key 'medium.surface'"),  # a chain of segments lies below the flat surface
    ("drag", "unknown scene key 'medium.surface'"),
])
def test_the_commands_on_the_flat_surface_refuse_another(capsys, command, named):
    from finrft.cli import main

    assert main([command, "--set", "medium.surface=plane"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err, err


def test_generated_heightfields_are_the_shapes_they_name():
    rng = np.random.default_rng(8)
    points = np.c_[rng.uniform(-0.3, 0.3, (50, 2)), rng.uniform(-0.2, 0.1, 50)]
    centre = (0.01, -0.02, 0.003)
    # a slope turned a quarter about up rises along y: the plane of that slope, on the grid's points and between
    slope = hfield.generated("slope", G, centre, extent=0.4, spacing=0.02, slope=SLOPE, heading=np.pi / 2)
    plane = surfaces.module("plane").depth(points, G, surface_point=centre,
                                           surface_normal=(0.0, -np.sin(SLOPE), np.cos(SLOPE)))
    assert np.abs(slope.depth(points, G) - plane).max() < 1e-12
    # steps 1 cm high every 5 cm along x; a cone 3 cm high, 10 cm in radius
    steps = hfield.generated("steps", G, (0, 0, 0), extent=0.4, spacing=0.01, height=0.01, length=0.05)
    at = np.array([[0.0, 0.0, 0.0], [0.06, 0.1, 0.0], [0.11, -0.2, 0.0], [-0.06, 0.0, 0.0]])
    assert steps.depth(at, G) == pytest.approx([0.0, 0.01, 0.02, -0.01], abs=1e-12)
    pile = hfield.generated("pile", G, (0, 0, 0), extent=0.2, spacing=0.01, height=0.03, length=0.1)
    at = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, -0.15, 0.0]])
    assert pile.depth(at, G) == pytest.approx([0.03, 0.015, 0.0], abs=1e-12)
    noise = hfield.generated("noise", G, (0, 0, 0), extent=0.5, spacing=0.005, height=0.004, length=0.03, seed=2)
    h = noise.parameters["heights"]
    assert h.std() == pytest.approx(0.004) and abs(np.corrcoef(h[:, :-1].ravel(), h[:, 1:].ravel())[0, 1]) > 0.9
    with pytest.raises(SceneError, match="hfield shape 'dunes'"):
        hfield.generated("dunes", G)


@pytest.mark.parametrize("surface,named", [
    ({"surface": "deforming"}, "surface 'deforming' needs its grid"),
    ({"surface": "slope"}, "surface must be one of flat, plane, hfield"),
    ({"surface": "plane", "surface_normal": (0, 1)}, "surface_normal must be three finite numbers"),
    ({"surface": "plane", "surface_point": (0, 0, float("nan"))}, "surface_point must be three finite numbers"),
    ({"bed_depth": -0.01}, "bed_depth must be >= 0 m"),
])
def test_attach_refuses_a_bad_surface(surface, named):
    with pytest.raises(SceneError, match=named):
        attach(mujoco.MjSpec.from_string(BODY), "probe", medium="poppy_seeds_lp", **surface)


def test_gravity_is_the_models_at_every_step():
    # set on the compiled model (after attach), a new gravity measures the depths and turns the laws in both twins
    wrenches = {}
    for backend in ("native", "python"):
        attached, model, data = _moving(backend, surface="plane", surface_point=(0.0, 0.0, 0.004),
                                        surface_normal=NORMAL)
        read = attached.wrenches(model)
        with attached.installed(model):
            before = read(data)[0].copy()
            model.opt.gravity[:] = 9.81 * -NORMAL  # square to the slope: its depths are across it now
            mujoco.mj_forward(model, data)
            wrenches[backend] = before, read(data)[0].copy()
    (before, after), (numpy_before, numpy_after) = wrenches["native"], wrenches["python"]
    assert np.abs(after - before).max() > 1e-3 * np.abs(before).max()
    assert np.abs(after - numpy_after).max() <= 1e-9 * np.abs(after).max()
    assert np.abs(before - numpy_before).max() <= 1e-9 * np.abs(before).max()
