"""The MJCF files: each opens on its own with physical values, and the chains built from segment.xml sit where
the scene puts them."""

from importlib import resources

import mujoco
import numpy as np
import pytest

from finrft import models
from finrft.experiments.plate import build_plate
from finrft.experiments import swim
from finrft.experiments.swim import RobotScene
from finrft.scene import Scene, preset

FILES = sorted(f.name for f in resources.files("finrft.mjcf").iterdir() if f.name.endswith(".xml"))
# The example robots (docs/guide/robots.md) carry their own values, no preset's: tests/test_robots.py checks them.
EXAMPLES = ("sand_swimmer", "hexapod", "wheel_rig")
# Bodies heavier than a fin's kilogram, and why.
HEAVY = {("wheel_rig.xml", "load"): "the rig's load: 21 N with the wheel, as the wheel experiments measured"}


def test_the_package_holds_every_model_and_its_scene():
    assert {"plate.xml", "plate_scene.xml", "robot.xml", "robot_scene.xml", "segment.xml"} <= set(FILES)
    shipped = {f.name for f in resources.files("finrft.mjcf").iterdir()}
    assert {f"{n}{suffix}" for n in EXAMPLES for suffix in (".xml", "_scene.xml", ".toml")} <= shipped


@pytest.mark.parametrize("name", FILES)
def test_file_opens_alone_with_physical_inertias(name):
    model = mujoco.MjModel.from_xml_path(str(models.mjcf_path(name)))
    assert model.nbody > 1
    for b in range(1, model.nbody):
        mass, inertia = model.body_mass[b], model.body_inertia[b]
        heavy = (name.replace("_scene", ""), model.body(b).name) in HEAVY  # a scene includes its model
        assert 0.0 < mass < (3.0 if heavy else 1.0), model.body(b).name
        # No principal inertia can exceed the mass times the square of the body's reach from its centre of mass
        # (a 3 g, 33 mm segment: < 3e-6 kg m^2); a 1 kg m^2 placeholder fails by six orders of magnitude.
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b]
        reach = max(np.linalg.norm(model.geom_pos[g] - model.body_ipos[b]) + model.geom_rbound[g] for g in geoms)
        assert np.all(inertia > 0.0) and np.all(inertia <= mass * reach ** 2), (model.body(b).name, inertia)
    # The drive's and the servos' huge armature belongs to the code (ARMATURE_RATIO), not the files.
    assert np.all(model.dof_armature == 0.0)


def test_segment_inertia_is_its_box():
    # The segment's strip as a solid box of its geom's size: I_x = m (b^2 + c^2) / 3 for half-sizes a, b, c.
    model = mujoco.MjModel.from_xml_path(str(models.mjcf_path("segment.xml")))
    b = model.body("segment").id
    a = model.geom_size[model.geom("segment").id]
    box = model.body_mass[b] * np.array([a[1] ** 2 + a[2] ** 2, a[0] ** 2 + a[2] ** 2, a[0] ** 2 + a[1] ** 2]) / 3
    np.testing.assert_allclose(model.body_inertia[b], box, rtol=0.01)


@pytest.mark.parametrize("overrides", [{"plate.segments": 5}, {"plate.kind": "rigid"},
                                       {"plate.kind": "rigid", "plate.rigid_as": "welds"},
                                       {"plate.chain": "spatial", "plate.segment_length": 0.02}])
def test_attached_chain_lies_along_the_rod(paper, overrides):
    # At rest, segment i's midpoint lies at rod_length + (i - 1/2) segment_length along the plate, which the drag
    # heads along +x at 90 deg of attack; hinges follow in chain order, one per segment unless the plate is rigid.
    scene = paper.replace(**overrides)
    p = scene.plate
    plate = build_plate(scene)
    d = mujoco.MjData(plate.model)
    mujoco.mj_kinematics(plate.model, d)
    sites = plate.groups[0].sites
    expected = p.rod_length + (np.arange(p.segments) + 0.5) * p.segment_length
    np.testing.assert_allclose(d.site_xpos[sites], np.c_[expected, np.zeros((p.segments, 2))], atol=1e-12)
    hinged = p.kind != "rigid" or p.rigid_as == "welds"
    assert len(plate.hinge_qpos) == (p.segments if hinged else 0)
    anchors = d.xanchor[[plate.model.dof_jntid[v] for v in plate.hinge_dof]]
    np.testing.assert_allclose(anchors[:, 0], expected[:len(anchors)] - p.segment_length / 2, atol=1e-12)


def test_robot_fins_hang_from_the_arm_tips():
    # Full robot at rest: the right fin's midpoints along +x from the arm's tip, the left fin's mirrored.
    scene = preset("physical", RobotScene).replace(**{"robot.model": "full"})
    robot = swim.build_robot(scene)
    d = mujoco.MjData(robot.model)
    mujoco.mj_kinematics(robot.model, d)
    a, f = scene.arm, scene.fin
    x = a.pivot + a.length + (np.arange(f.segments) + 0.5) * f.segment_length
    np.testing.assert_allclose(d.site_xpos[robot.fin_sites][..., 0], [x, -x], atol=1e-12)
    assert robot.fin_hinge_qpos.shape == (2, f.segments)


def _xml(name):
    return mujoco.MjModel.from_xml_path(str(models.mjcf_path(name)))


def _carried(name):
    """The values a model file carries, by the physical preset's scene key, read from the compiled file."""
    m = _xml(name)
    if name == "segment.xml":
        joint, body = m.joint("hinge").id, m.body("segment").id
        return {"plate.stiffness": m.jnt_stiffness[joint], "plate.damping": m.dof_damping[m.jnt_dofadr[joint]],
                "plate.springref": m.qpos_spring[m.jnt_qposadr[joint]], "plate.segment_mass": m.body_mass[body],
                "plate.segment_inertia": m.body_inertia[body][2], "plate.segment_length": 2 * m.site_pos[0][0]}
    if name == "plate.xml":
        rod = m.body("rod").id
        return {"plate.rod_mass": m.body_mass[rod], "plate.rod_inertia": m.body_inertia[rod][2],
                "plate.rod_length": 2 * m.body_ipos[rod][0]}
    if name == "robot.xml":
        body, arm = m.body("body").id, m.body("r_arm").id
        return {"body.mass": m.body_mass[body], "arm.inertia": m.body_inertia[arm][2], "arm.pivot": m.body_pos[arm][0],
                "arm.length": 2 * m.body_ipos[arm][0], "arm.mass": m.body_mass[arm]}
    return {}


@pytest.mark.parametrize("name", [n for n in FILES if not n.endswith("_scene.xml") and n[:-4] not in EXAMPLES])
def test_every_model_carries_the_values_its_preset_uses(name):
    """One home per value: a model file opened alone has the physical preset's values (the scene files include
    the models), and the schema's defaults of the plate's segments and rod are the same."""
    carried = _carried(name)
    assert carried, f"{name}: say here which preset values it carries"
    plate, robot, defaults = preset("physical"), preset("physical", RobotScene), Scene()
    for key, value in carried.items():
        section, field = key.split(".")
        if section == "plate":
            assert value == pytest.approx(getattr(plate.plate, field), rel=1e-9, abs=1e-15), key
            assert value == pytest.approx(getattr(defaults.plate, field), rel=1e-9, abs=1e-15), f"default {key}"
        elif key == "arm.mass":
            a = robot.arm
            assert value == pytest.approx(a.mass_base + a.linear_density * a.length, rel=1e-9), key
        else:
            assert value == pytest.approx(getattr(getattr(robot, section), field), rel=1e-9), key
