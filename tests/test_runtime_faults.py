"""Runs and Python calls that used to end with a wrong result and no word: MuJoCo's warnings during a run, ctrl
beyond MuJoCo's limit, geoms changed after `attach`, an MjData of another model, a mesh wound inward, arguments of
the wrong type, and an implicit step that accepted a state whose force it never evaluated."""

import math

import mujoco
import numpy as np
import pytest

import finrft
from finrft.cli import main
from finrft.errors import SceneError, SimulationFailed
from finrft.integrate import stepper
from finrft.native import Code
from finrft.scene import UserScene

# A rod on a hinge, 5 cm above the sand, a velocity actuator on it.
ARM = """<mujoco><option gravity="0 0 0"/><worldbody><body name="rod" pos="0 0 0.05">
  <joint name="hinge" type="hinge" axis="0 0 1"/>
  <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.002" mass="0.001"/></body></worldbody>
  <actuator><velocity name="motor" joint="hinge" kv="1e-3"/></actuator></mujoco>"""


def _arm_scene(tmp_path, control: str) -> str:
    (tmp_path / "arm.xml").write_text(ARM)
    (tmp_path / "ctrl.csv").write_text("time_s,ctrl\n0,0\n0.1,2e11\n")
    (tmp_path / "scene.toml").write_text(f'[model]\npath = "arm.xml"\nbodies = ["rod"]\n[[control]]\n'
                                         f'actuator = "motor"\n{control}\n[sim]\nduration = 0.2\nrecord_dt = 0.01\n')
    return str(tmp_path / "scene.toml")


@pytest.mark.parametrize("control", ['kind = "constant"\nvalue = 2e10',
                                     'kind = "sine"\namplitude = 1e11\nfrequency = 1',
                                     'kind = "sine"\noffset = -6e9\namplitude = 6e9\nfrequency = 1',
                                     'kind = "table"\ntable = "ctrl.csv"'])
def test_a_ctrl_beyond_mujocos_limit_is_refused_before_the_run(tmp_path, capsys, control):
    # MuJoCo zeroes every ctrl of a model when one exceeds 1e10: the robot would lie still, reported as not moving.
    out = tmp_path / "o.h5"
    assert main(["run", "--scene", _arm_scene(tmp_path, control), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "control.0: its ctrl reaches" in err and "1e+10" in err, err
    assert not out.exists()


def test_a_python_controller_beyond_mujocos_limit_is_refused(tmp_path):
    (tmp_path / "arm.xml").write_text(ARM)
    scene = UserScene().replace(**{"model.path": str(tmp_path / "arm.xml"), "model.bodies": ["rod"],
                                   "sim.duration": 0.2, "sim.record_dt": 0.01})
    with pytest.raises(SceneError, match=r"beyond MuJoCo's limit \+-1e\+10 at t = 0\.05"):
        finrft.run_robot(scene, control=lambda t, d: [3e10 if t >= 0.05 else 1.0])


# A body of 40 spheres resting on a floor: 40 contacts, more than MuJoCo's arena of {memory} holds constraints for.
CROWD = """<mujoco><size memory="{memory}"/><option gravity="0 0 -9.81"/><worldbody>
  <geom type="plane" size="1 1 0.1"/><body name="b" pos="0 0 0.0099"><freejoint/>{spheres}</body>
  </worldbody></mujoco>"""


def test_a_mujoco_warning_during_a_run_fails_it_naming_the_warning(tmp_path, capsys):
    spheres = "".join(f'<geom type="sphere" size="0.01" pos="{0.03 * i} 0 0" mass="0.01"/>' for i in range(40))
    (tmp_path / "crowd.xml").write_text(CROWD.format(memory="30K", spheres=spheres))
    (tmp_path / "roomy.xml").write_text(CROWD.format(memory="10M", spheres=spheres))
    scene = tmp_path / "scene.toml"
    scene.write_text('[model]\npath = "crowd.xml"\nbodies = ["b"]\n[medium]\nsurface_z = -1\n'
                     '[sim]\nmethod = "explicit"\nduration = 0.05\nrecord_dt = 0.01\n')
    out = tmp_path / "o.h5"
    assert main(["run", "--scene", str(scene), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "constraint buffer is full" in err and "memory" in err, err
    assert not out.exists()
    # the same model with room for its contacts runs
    roomy = f"model.path={tmp_path / 'roomy.xml'}"
    assert main(["run", "--scene", str(scene), "--set", roomy, "--out", str(out)]) == 0


# The README's plate: 4 cm x 6 cm, its top at the surface, dragged normal to its face at 10 cm/s in the generic
# medium: 0.370 N/cm^3 x width x depth^2 / 2. Twice as wide and deep: eight times the force.
PLATE = """<mujoco><option gravity="0 0 0"/><worldbody><body name="plate"><joint type="slide" axis="1 0 0"/>
  <geom name="face" type="box" size="0.0005 {w} {h}" pos="0 0 -{h}" mass="10"/></body></worldbody></mujoco>"""


def _drag(spec, attached, model, step=mujoco.mj_step):
    data = mujoco.MjData(model)
    data.qvel[0] = 0.1
    with attached.installed(model):
        step(model, data)
    return -data.qfrc_passive[0]


@pytest.mark.parametrize("backend", ["native", "python"])
def test_a_geom_changed_after_attach_is_refused_not_given_the_old_force(backend):
    small, large = 0.370 * 4 * 6 ** 2 / 2, 0.370 * 8 * 12 ** 2 / 2  # 26.64 N, 213.1 N
    spec = mujoco.MjSpec.from_string(PLATE.format(w=0.04, h=0.06))
    attached = finrft.attach(spec, ["plate"], zeta=1.0, backend=backend)
    assert _drag(spec, attached, spec.compile()) == pytest.approx(large, rel=1e-9)

    # enlarged in the spec after attach, before compiling
    spec = mujoco.MjSpec.from_string(PLATE.format(w=0.02, h=0.03))
    attached = finrft.attach(spec, ["plate"], zeta=1.0, backend=backend)
    model = spec.compile()
    assert _drag(spec, attached, model) == pytest.approx(small, rel=1e-9)
    spec.geom("face").size = [0.0005, 0.04, 0.06]
    spec.geom("face").pos = [0, 0, -0.06]
    # (the native plugin stops MuJoCo's compiler, whose forward pass evaluates it: a ValueError as SceneError is)
    with pytest.raises(ValueError, match="geom 'face' of body 'plate' changed its type, size"):
        _drag(spec, attached, spec.compile())
    # or in the compiled model (domain randomisation), between steps too
    for key, value in (("geom_size", [0.0005, 0.04, 0.06]), ("geom_pos", [0, 0, -0.06])):
        saved = getattr(model, key)[0].copy()
        getattr(model, key)[0] = value
        with pytest.raises(SceneError, match="geom 'face' of body 'plate' changed"):
            _drag(spec, attached, model)
        data = mujoco.MjData(model)
        with pytest.raises(SceneError, match="geom 'face' of body 'plate' changed"):
            attached.forces(model, data)
        getattr(model, key)[0] = saved
    data = mujoco.MjData(model)
    with attached.installed(model):
        mujoco.mj_step(model, data)
        model.geom_size[0] *= 2
        with pytest.raises((SceneError, mujoco.FatalError), match="geom 'face' of body 'plate' changed"):
            mujoco.mj_step(model, data)
    if backend == "native":  # stepped outside any block of finrft's, the plugin itself refuses
        with pytest.raises(mujoco.FatalError, match="geom 'face' of body 'plate' changed"):
            mujoco.mj_step(model, mujoco.MjData(model))


def test_the_forces_of_an_mjdata_of_another_model_are_refused():
    spec = mujoco.MjSpec.from_string(PLATE.format(w=0.02, h=0.03))
    attached = finrft.attach(spec, ["plate"], zeta=1.0)
    model, other = spec.compile(), spec.compile()
    data = mujoco.MjData(model)
    data.qvel[0] = 0.1
    mujoco.mj_forward(model, data)
    force, _ = attached.forces(model, data)["plate"]
    assert -force[0] == pytest.approx(0.370 * 4 * 6 ** 2 / 2, rel=1e-9)
    with pytest.raises(SceneError, match="data is an MjData of another model"):
        attached.forces(other, data)
    plain = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
    with pytest.raises(SceneError, match="data is an MjData of another model"):
        attached.forces(model, mujoco.MjData(plain))
    with pytest.raises(SceneError, match="data must be a mujoco.MjData, got NoneType"):
        attached.forces(model, None)
    with pytest.raises(SceneError, match="data is an MjData of another model"):
        attached.world_elements(other, data)
    with pytest.raises(SceneError, match="model must be a mujoco.MjModel"):
        with attached.installed(spec):
            pass


@pytest.mark.parametrize("change,named", [
    ({"spec": None}, "spec must be a mujoco.MjSpec"), ({"bodies": None}, "bodies must be a name or a list of names"),
    ({"bodies": ["plate", 3]}, "bodies must be"), ({"geoms": 7}, "geoms must be"), ({"law": 3}, "law must be a str"),
    ({"backend": None}, "backend must be a str"), ({"medium": 1}, "medium must be a str"),
    ({"zeta": "1"}, "zeta must be a number or None"), ({"surface_z": None}, "surface_z must be a number, got"),
    ({"element_size": "5mm"}, "element_size must be a number"), ({"v_reg": [1e-4]}, "v_reg must be a number"),
    ({"drft_lambda": None}, "drft_lambda must be a number"), ({"rho_c": "dense"}, "rho_c must be a number"),
    ({"cull": "no"}, "cull must be True or False"),
])
def test_attach_refuses_arguments_of_the_wrong_type_naming_them(change, named):
    spec = mujoco.MjSpec.from_string(PLATE.format(w=0.02, h=0.03))
    given = {"spec": spec, "bodies": ["plate"], "zeta": 1.0, **change}
    with pytest.raises(SceneError, match=f"attach: {named}"):
        finrft.attach(given.pop("spec"), given.pop("bodies"), **given)


def test_the_run_api_refuses_arguments_of_the_wrong_type_naming_them(tmp_path):
    (tmp_path / "arm.xml").write_text(ARM)
    scene = UserScene().replace(**{"model.path": str(tmp_path / "arm.xml"), "model.bodies": ["rod"],
                                   "sim.duration": 0.05})
    with pytest.raises(SceneError, match="run_robot: the scene must be a finrft.UserScene"):
        finrft.run_robot(None)
    with pytest.raises(SceneError, match="run_robot: control must be a callable"):
        finrft.run_robot(scene, control=5)
    with pytest.raises(SceneError, match="run: progress must be a callable"):
        finrft.run_robot(scene, progress=5)
    plate, drive = finrft.preset("physical"), finrft.Drive(speed=0.03, stroke=0.01, cycles=1)
    with pytest.raises(SceneError, match="run: progress must be a callable"):
        finrft.simulate(plate, drive, progress=3)
    with pytest.raises(SceneError, match="run: estimate_error must be True or False"):
        finrft.simulate(plate, drive, estimate_error="no")


# A 4 cm cube as a mesh, each face two triangles counter-clockwise seen from outside (vertex i at
# (-1)^(1 + bit) 2 cm along x, y, z for bits 2, 1, 0 of i).
CUBE_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                       [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
CUBE = """<mujoco><option gravity="0 0 0"/><asset><mesh name="cube" vertex="{vertex}" face="{face}"/></asset>
  <worldbody><body name="b"><freejoint/><geom name="g" {geom} mass="1"/></body></worldbody></mujoco>"""


def _cube_force(faces=None) -> np.ndarray:
    vertex = " ".join(f"{0.02 * (2 * ((i >> k) & 1) - 1)}" for i in range(8) for k in (2, 1, 0))
    geom = 'type="box" size="0.02 0.02 0.02"' if faces is None else 'type="mesh" mesh="cube"'
    faces = CUBE_FACES if faces is None else faces
    spec = mujoco.MjSpec.from_string(CUBE.format(vertex=vertex, face=" ".join(map(str, faces.ravel())), geom=geom))
    attached = finrft.attach(spec, ["b"], zeta=1.0, surface_z=0.05)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[:3] = [0.05, 0.0, -0.1]  # sinking and moving sideways: the bottom and one side lead
    mujoco.mj_forward(model, data)
    return attached.forces(model, data)["b"][0]


def test_a_mesh_wound_inward_gives_the_force_of_the_mesh_wound_outward():
    box = _cube_force()  # the same cube as a box geom: flat faces, exact for both
    assert box[2] > 1.0
    assert _cube_force(CUBE_FACES) == pytest.approx(box, rel=1e-6)  # float32 vertices
    assert _cube_force(CUBE_FACES[:, ::-1]) == pytest.approx(box, rel=1e-6)  # float32 vertices
    mixed = CUBE_FACES.copy()
    mixed[3] = mixed[3, ::-1]
    with pytest.raises(SceneError, match="triangles of mesh geom 'g' are wound both ways"):
        _cube_force(mixed)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_newton_does_not_take_a_root_whose_residual_it_never_made_small(tmp_path, backend):
    # A 0.5 kg box 1e10 m below the surface at rest: the medium could hold 1e14 N, so the root's sinking speed
    # (about 5e-18 m/s) lies below the ramp's floor (1e-12 v_reg), where the law gives no force. The step's change
    # there is below Newton's velocity tolerance, which alone took the state with no medium force at all and the
    # box hanging in the air of its own accord; the residual (its whole weight) now stops the run instead.
    # A scene refuses such a surface (out of any RFT fit's reach); the step itself must not take that root either,
    # so it is tried on the attached model directly.
    spec = mujoco.MjSpec.from_string("""<mujoco><option gravity="0 0 -9.81"/><worldbody>
      <body name="box" pos="0 0 0.01"><freejoint/><geom type="box" size="0.05 0.05 0.01" mass="0.5"/></body>
      </worldbody></mujoco>""")
    attached = finrft.attach(spec, ["box"], law="li2013-planar", surface_z=1e10, backend=backend)
    model = spec.compile()
    data = mujoco.MjData(model)
    advance = stepper(model, UserScene().replace(**{"sim.method": "newton"}).sim, backend, [], attached)
    with attached.installed(model):
        assert advance(data, 1) == Code.NOT_CONVERGED
