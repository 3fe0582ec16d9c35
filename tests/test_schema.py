"""The schema engine knows no section: the sections of the laws' keys are built from what each law declares."""

import argparse
import dataclasses

import pytest

from finrft import laws, schema
from finrft.errors import Error, SceneError, UsageError
from finrft.experiments.flags import preset_name
from finrft.laws import table
from finrft.experiments.intrusion import IntrusionScene
from finrft.experiments.swim import RobotScene
from finrft.scene import RFT, Medium, Scene, UserScene, field_of, preset, presets, scene_from_dict, scene_kinds


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
