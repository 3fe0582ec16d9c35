"""The schema engine knows no section: the sections of the laws' keys are built from what each law declares."""

import argparse
import dataclasses
import math
import re
import tomllib

import pytest

from finrft import laws, schema
from finrft.errors import Error, SceneError, UsageError
from finrft.experiments.flags import preset_name
from finrft.laws import li2013, table
from finrft.experiments.intrusion import IntrusionScene
from finrft.experiments.swim import RobotScene
from finrft.scene import (RFT, Control, JointDrive, Medium, RobotSim, Scene, UserScene, field_of, preset, presets,
                          scene_from_dict, scene_kinds)


class Recorder:
    """A stand-in for a section that records which keys a law reads."""

    def __init__(self, section):
        self._section, self.read = section, set()

    def __getattr__(self, name):
        self.read.add(name)
        return getattr(self._section, name)


def test_each_law_declares_its_own_keys_and_reads_only_them(tmp_path):
    # [rft] is the union of the segment laws' declarations (and the law's name and v_reg, which every law shares);
    # each law's parameters come from its own keys alone.
    shared = {"law", "v_reg"}
    declared = {name: {key for key, _, _ in laws.module(name).KEYS} for name in laws.names()}
    assert {f.name for f in dataclasses.fields(RFT)} == shared | set().union(*declared.values())
    table.write_table(tmp_path / "table.csv", table.paper_table(1.2, 0.2))
    for name in laws.names():
        rft = Recorder(RFT(law=name, table=str(tmp_path / "table.csv")))
        laws.module(name).parameters(rft)
        assert rft.read == declared[name], name
    # a law's own check of its section (through the registry, as every scene calls it) reads its own keys alone
    for name in laws.names():
        for medium in (None, (1500.0, 0.6, 0.3)):
            rft = Recorder(RFT(law=name))
            try:
                laws.check(rft, medium)
            except SceneError as error:
                assert f"rft.law = '{name}' needs" in str(error)
            assert rft.read <= declared[name] | shared, name
    assert field_of(Scene, "rft.c_s").metadata["unit"] == "N/m^3" and field_of(Scene, "rft.gamma0").metadata["unit"] == "rad"
    # the surface laws' keys of [medium], likewise
    for name in laws.names(laws.SURFACE):
        module = laws.module(name, laws.SURFACE)
        own = {key for key, _, _ in module.KEYS}
        assert own <= {f.name for f in dataclasses.fields(Medium)}
        assert set(module.given(Medium(law=name))) == set(module.PARAMETERS)
        assert set(module.SECTION_KEYS) == set(module.PARAMETERS)
        assert set(module.SECTION_KEYS.values()) <= {f.name for f in dataclasses.fields(Medium)}
    assert laws.names(laws.SURFACE) == ("li2013", "li2013-planar", "rft3d")


def test_a_key_declared_twice_must_agree():
    key = ("c", float, schema.field(1.0, "N", "a coefficient"))
    assert [f.name for f in dataclasses.fields(schema.section("S", (key, key), __name__, "doc"))] == ["c"]
    with pytest.raises(TypeError, match="'c' is declared twice, differently"):
        schema.section("S", (key, ("c", float, schema.field(2.0, "N", "a coefficient"))), __name__, "doc")


def test_every_scene_round_trips_through_its_toml():
    import tomllib
    kinds = scene_kinds()
    assert {Scene, RobotScene, UserScene, IntrusionScene} <= {kind.cls for kind in kinds}
    for kind in kinds:
        for scene in [preset(name, kind.cls) for name in kind.presets] or [kind.cls()]:
            assert scene_from_dict(tomllib.loads(schema.to_toml(scene)), kind.cls) == scene


def test_scene_kinds_are_a_registry():
    # preset and load_scene read the registry: a kind's presets, from its files; an unregistered class is refused
    assert presets(Scene) == presets(RobotScene) == ("paper", "physical")
    assert presets(UserScene) == presets(IntrusionScene) == ()
    with pytest.raises(SceneError, match="unknown preset 'nothing': use one of paper, physical"):
        preset("nothing", RobotScene)
    with pytest.raises(SceneError, match="not a registered scene kind"):
        preset("paper", dict)


def test_bad_input_is_one_error_family():
    with pytest.raises(SceneError, match="unknown scene key 'rft.nothing': \\[rft\\] has law, v_reg") as caught:
        preset("paper").replace(**{"rft.nothing": 1.0})
    assert isinstance(caught.value, Error) and isinstance(caught.value, ValueError)
    with pytest.raises(SceneError, match="rft.gamma0 must be <= 1.5708 rad"):
        preset("paper").replace(**{"rft.gamma0": 2.0})
    # a command line's own bad flags are of the same family: one line, exit status 2
    with pytest.raises(UsageError, match="give --scene s.toml or --preset paper, not both") as caught:
        preset_name(argparse.Namespace(scene="s.toml", preset="paper"))
    assert isinstance(caught.value, SceneError)


@pytest.mark.parametrize("make, message", [
    (lambda: Scene(sim=dataclasses.replace(Scene().sim, dt=-1.0)), r"sim.dt must be > 0 s, got -1.0"),
    (lambda: Scene(sim=dataclasses.replace(Scene().sim, dt=float("nan"))), "sim.dt must be finite"),
    (lambda: Scene(plate=dataclasses.replace(Scene().plate, segments=0)), "plate.segments must be >= 1"),
    (lambda: Scene(plate="x"), r"\[plate\] must be a Plate section, got str 'x'"),
    (lambda: UserScene(sim=Scene().sim), r"\[sim\] must be a RobotSim section, got Sim"),
    (lambda: UserScene(drive="x"), r"\[\[drive\]\] must be a tuple of JointDrive entries"),
    (lambda: RobotScene(sim=dataclasses.replace(RobotScene().sim, method="nope")), "sim.method = 'nope' is not"),
    (lambda: IntrusionScene(sim=dataclasses.replace(IntrusionScene().sim, record_dt=0.0)), "sim.record_dt must be >")])
def test_a_scene_built_directly_is_checked_as_one_read_from_toml(make, message):
    # The sections are plain dataclasses: Scene(sim=Sim(dt=-1.0)) once ran (a plate of 0 segments ran to exit 0)
    with pytest.raises(SceneError, match=message):
        make()


def test_a_scene_built_directly_takes_the_canonical_values():
    scene = Scene(sim=dataclasses.replace(Scene().sim, dt=1, integrator="Euler", method="explicit"))
    assert type(scene.sim.dt) is float and scene.sim.integrator == "euler"
    assert scene == scene_from_dict({"sim": {"dt": 1, "integrator": "Euler", "method": "explicit"}})


@pytest.mark.parametrize("build, named", [
    # a key the entry's kind (profile, law) does not use was accepted and ignored
    (lambda: UserScene(control=(Control(actuator="a", amplitude=1.0, frequency=2.0),)),
     "control.0.amplitude is used by kind = 'sine' or 'pd' or 'sensor' only, and this entry's kind is 'constant' (its default"),
    (lambda: UserScene(control=(Control(actuator="a", kind="sine", value=3.0),)), "control.0.value is used by kind"),
    (lambda: UserScene(control=(Control(actuator="a", kind="sine", table="t.csv"),)), "control.0.table"),
    (lambda: UserScene(drive=(JointDrive(joint="j", profile="sine", stroke=0.1),)), "drive.0.stroke is used by"),
    (lambda: scene_from_dict({"medium": {"law": "rft3d", "zeta": 0.5, "bulk_density": 1500,
                                         "internal_friction": 0.5}}, UserScene), "medium.zeta is used by law"),
    (lambda: scene_from_dict({"medium": {"internal_friction": 0.5}}, UserScene),
     "medium.internal_friction is used by law = 'rft3d' only"),
    (lambda: preset("physical").replace(**{"rft.law": "sandswim", "rft.c_s": 0, "rft.c_f": 0, "rft.gamma0": 0,
                                           "rft.table": "forces.csv"}), "rft.table is used by law = 'table'"),
    # the origami stop on a plate or fin that has none; an adaptive method's tolerance under a fixed step
    (lambda: scene_from_dict({"plate": {"kind": "soft", "stop": "limit"}}), "plate.stop is used by kind = 'origami'"),
    (lambda: scene_from_dict({"plate": {"kind": "rigid", "stop_stiffness": 1e5}}),
     "plate.stop_stiffness is used by kind = 'origami' only, and this entry's kind is 'rigid'"),
    (lambda: scene_from_dict({"fin": {"kind": "soft", "stop_stiffness": 1e3}}, RobotScene),
     "fin.stop_stiffness is used by kind = 'origami'"),
    (lambda: scene_from_dict({"plate": {"rigid_as": "welds"}}), "plate.rigid_as is used by kind = 'rigid' only"),
    (lambda: scene_from_dict({"sim": {"method": "newton", "tolerance": 1e-3}}),
     "sim.tolerance is used by method = 'adaptive' or 'adaptive-newton' only, and this entry's method is 'newton'"),
    (lambda: scene_from_dict({"sim": {"max_step": 0.01}}, UserScene), "sim.max_step is used by method = 'adaptive'"),
])
def test_a_key_the_entrys_kind_does_not_use_is_refused(build, named):
    with pytest.raises(SceneError, match=re.escape(named)):
        build()


def test_defaults_and_keys_set_back_to_them_are_no_unused_keys():
    # the rule refuses what a user gave: a dump (every key at its value) reads back, whatever the kinds
    for kind in scene_kinds():
        for name in kind.presets or ("",):
            scene = preset(name, kind.cls) if name else kind.cls()
            assert scene_from_dict(tomllib.loads(schema.to_toml(scene)), kind.cls) == scene
    sine = UserScene(control=(Control(actuator="a", kind="sine", amplitude=1.0),))
    assert sine.replace(**{"control.0.value": 0.0}) == sine
    # the robot's own default [rft] (the paper law's coefficients) under another law is no key the user gave
    assert preset("physical", RobotScene).rft.law == "sandswim"


def test_a_unit_suffix_is_read_in_the_keys_unit_and_refused_where_it_does_not_fit():
    assert schema.quantity("90deg", "rad", "k") == pytest.approx(math.pi / 2)
    assert schema.quantity("6e5 N/m3", "N/cm^3", "k") == pytest.approx(0.6)
    assert schema.quantity("5 mm", "m or rad", "k") == pytest.approx(0.005)
    assert scene_from_dict({"sim": {"dt": "0.5ms"}}, Scene).sim.dt == pytest.approx(5e-4)
    with pytest.raises(SceneError, match="mm is no unit of plate.damping"):
        scene_from_dict({"plate": {"damping": "5mm"}}, Scene)
    with pytest.raises(SceneError, match="sim.dt must be a number"):
        scene_from_dict({"sim": {"dt": "fast"}}, Scene)
    # --bounds reads the same table: any suffix the key's unit allows
    from finrft.studies.bounds import parse_bounds
    assert parse_bounds(["sim.dt=0.1:1ms"], Scene)["sim.dt"] == pytest.approx((1e-4, 1e-3))


def test_zeta_declares_its_unit_the_literatures():
    # scene files are SI but for zeta, which every source gives in N/cm^3: the schema says so plainly
    assert field_of(UserScene, "medium.zeta").metadata["unit"] == "N/cm^3"
    assert "N/cm^3" in schema.to_toml(UserScene()).splitlines()[0]


def test_per_segment_coefficients_are_refused_as_a_slip_of_units():
    # rft.f_perp = 2.0 meant 2 N per segment before coefficients were N/m^3: read as 2 N/m^3, forces 1e-4 of it
    with pytest.raises(SceneError, match=r"rft.f_perp = 2 N/m\^3 is implausibly small .* N per segment"):
        preset("paper").replace(**{"rft.f_perp": 2.0})
    with pytest.raises(SceneError, match="rft.c_s = 0.6 N/m"):
        preset("physical").replace(**{"rft.c_s": 0.6, "rft.c_f": 0.05, "rft.gamma0": 0.5})
    # the floor lies far below every medium: 1e-3 of the weakest catalogued zeta, and below the paper's weak fit
    from finrft import media
    weakest = min(m.get("zeta").value for m in media.media() if m.get("zeta")) * li2013.N_PER_CM3
    assert laws.LEAST_COEFFICIENT <= 1e-3 * weakest
    assert laws.LEAST_COEFFICIENT < preset("paper").rft.f_perp / 100


def test_the_least_v_reg_is_far_above_newtons_tolerance():
    from finrft.integrate import NEWTON_TOLERANCE
    assert laws.LEAST_V_REG / NEWTON_TOLERANCE >= 1e3 * (1 - 1e-9)
    assert laws.LEAST_V_REG <= laws.SURFACE_V_REG / 100
    with pytest.raises(SceneError, match="medium.v_reg = 3e-10 m/s is implausibly small"):
        scene_from_dict({"medium": {"v_reg": 3e-10}}, UserScene)
    assert scene_from_dict({"medium": {"v_reg": 0}}, UserScene).medium.v_reg == 0  # none: the law as published


@pytest.mark.parametrize("frequency, ok", [(125.0, True), (126.0, False)])
def test_a_sine_needs_eight_steps_per_period(frequency, ok):
    def build():
        return UserScene(control=(Control(actuator="a", kind="sine", frequency=frequency),),
                         sim=RobotSim(dt=1e-3, duration=1.0))
    if ok:
        build()
    else:
        with pytest.raises(SceneError, match=r"control.0.frequency = 126 Hz has 7.94 steps per period at sim.dt = "
                                             r"0.001 s, fewer than 8: set sim.dt <= 0.000992 s"):
            build()


def test_a_selector_set_drops_the_keys_of_the_choice_it_replaces():
    # --set rft.law=table on a preset of the sandswim law: the preset's c_s, c_f, gamma0 were no keys the user gave
    switched = preset("physical").replace(**{"rft.law": "table", "rft.table": "forces.csv"})
    assert (switched.rft.law, switched.rft.c_s, switched.rft.table) == ("table", 0.0, "forces.csv")
    # a key given beside the selector is still refused when the new choice does not use it
    with pytest.raises(SceneError, match="rft.c_s is used by law = 'sandswim' only"):
        preset("physical").replace(**{"rft.law": "table", "rft.table": "forces.csv", "rft.c_s": 1e4})
    sine = UserScene(control=(Control(actuator="a", kind="sine", amplitude=1.0),))
    assert sine.replace(**{"control.0.kind": "constant"}).control[0].amplitude == 0.0



def test_a_switch_of_plate_kind_drops_the_origami_stop():
    stopped = preset("paper").replace(**{"plate.stop": "limit", "plate.stop_stiffness": 2e4})
    rigid = stopped.replace(**{"plate.kind": "rigid", "plate.rigid_as": "welds"})
    assert (rigid.plate.stop, rigid.plate.stop_stiffness) == (Scene().plate.stop, Scene().plate.stop_stiffness)
    assert rigid.replace(**{"plate.kind": "origami"}).plate.rigid_as == "body"
    with pytest.raises(SceneError, match="plate.stop is used by kind = 'origami'"):
        preset("paper").replace(**{"plate.kind": "soft", "plate.stop": "limit"})


def test_a_switch_to_a_fixed_step_drops_the_adaptive_methods_keys():
    # the robot presets' tolerance and largest step are the preset's, not keys the user gave
    for name in presets(RobotScene):
        fixed = preset(name, RobotScene).replace(**{"sim.method": "newton"})
        assert (fixed.sim.tolerance, fixed.sim.max_step) == (RobotScene().sim.tolerance, RobotScene().sim.max_step)
    assert preset("physical").replace(**{"sim.method": "adaptive", "sim.tolerance": 1e-3}).sim.tolerance == 1e-3
    with pytest.raises(SceneError, match="sim.tolerance is used by method"):
        preset("paper", RobotScene).replace(**{"sim.method": "newton", "sim.tolerance": 1e-3})
