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
