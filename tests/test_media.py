"""The media catalogue (every value with a unit and a source, nothing made up), `finrft medium`, and `finrft law`:
the stress map equal to the law at its grid points, its figure, and bad input; a named medium in attach and in
scenes."""

import dataclasses
import json
import math

import h5py
import mujoco
import numpy as np
import pytest

from finrft import geometry, laws, media
from finrft.attach import attach
from finrft.cli import main
from finrft.experiments.intrusion import intrude
from finrft.laws import li2013, rft3d, sandswim
from finrft.experiments.intrusion import IntrusionScene
from finrft.experiments.swim import RobotScene
from finrft.scene import Scene, SceneError, UserScene, load_scene, preset, scene_from_dict, to_toml

CM3 = li2013.N_PER_CM3
# alpha_z(0, 90 deg) of the poppy-seed sets: the sum of their A and B coefficients (Li 2013's zeta of a medium)
POPPY_ZETA = {"poppy_seeds_lp": 0.051 + 0.047 + 0.053 + 0.083 + 0.020,
              "poppy_seeds_cp": 0.094 + 0.092 + 0.092 + 0.151 + 0.035}


def _last_json(out: str):
    return json.loads(out.strip().splitlines()[-1])


def test_the_catalogue_names_the_asked_media_each_value_with_its_source():
    assert {"generic", "poppy_seeds_lp", "poppy_seeds_cp", "glass_beads_3mm", "glass_beads_4mm"} <= set(media.names())
    for m in media.media():
        assert m.description
        for key, value in m.values.items():
            assert value.source.strip() and value.status in ("", media.UNVERIFIED), (m.name, key)
        if m.missing:
            assert m.note or m.name.startswith("poppy"), m.name  # where it was looked for
    assert media.medium("generic").get("zeta").value == 1.0
    # no li2013 values were found for glass beads: none is made up, and the law refuses them
    for name in ("glass_beads_3mm", "glass_beads_4mm"):
        assert {"zeta", "li2013_coefficients"} <= set(media.medium(name).missing)
        with pytest.raises(SceneError, match="neither zeta nor li2013_coefficients"):
            li2013.medium_parameters(media.medium(name))


@pytest.mark.parametrize("name", sorted(POPPY_ZETA))
def test_poppy_seed_sets_are_absolute_and_unverified(name):
    m = media.medium(name)
    assert m.get("li2013_coefficients").status == media.UNVERIFIED
    zeta, coefficients = li2013.medium_parameters(m)
    assert zeta == 1.0
    assert li2013.alpha(0.0, math.pi / 2, zeta, coefficients)[1] / CM3 == pytest.approx(POPPY_ZETA[name], abs=1e-12)


def test_an_unknown_medium_names_the_known_ones():
    with pytest.raises(SceneError, match="unknown medium 'sand'.*generic, poppy_seeds_lp"):
        media.medium("sand")


@pytest.mark.parametrize("entry, message", [
    ({"description": "d", "zeta": {"value": 1.0}}, "names its source"),
    ({"description": "d", "zeta": {"value": 1.0, "source": " "}}, "names its source"),
    ({"description": "d", "zeta": {"value": 1.0, "source": "s", "status": "guessed"}}, "status must be"),
    ({"description": "d", "zeta": {"value": "1", "source": "s"}}, "finite number"),
    ({"description": "d", "zeta": {"value": float("nan"), "source": "s"}}, "finite number"),
    ({"description": "d", "colour": {"value": 1.0, "source": "s"}}, "unknown quantity 'colour'"),
    ({"description": "d", "missing": ["zeta"], "zeta": {"value": 1.0, "source": "s"}}, "both given and missing"),
    ({"zeta": {"value": 1.0, "source": "s"}}, "needs a description"),
])
def test_a_bad_catalogue_is_refused(entry, message):
    with pytest.raises(SceneError, match=message):
        media.parse({"units": {"zeta": "N/cm^3"}, "media": {"m": entry}})


def test_medium_list_json_shows_units_and_sources(capsys):
    assert main(["medium", "--list", "--json"]) == 0
    out, text = capsys.readouterr()
    listed = json.loads(out)
    assert [m["name"] for m in listed] == list(media.names())
    beads = next(m for m in listed if m["name"] == "glass_beads_3mm")
    assert beads["values"]["grain_diameter"] == {"value": pytest.approx(3.0), "unit": "mm",
                                                 "source": media.medium("glass_beads_3mm").get("grain_diameter").source,
                                                 "status": ""}
    assert "zeta = 1 N/cm^3" in text and "(unverified)" in text and "not found: zeta" in text
    assert main(["medium", "--json"]) == 0  # --list is the default, as its help says
    assert _last_json(capsys.readouterr().out) == listed


def test_law_li2013_json_is_the_law_on_its_grid(capsys):
    assert main(["law", "li2013", "--json", "--quiet"]) == 0
    data = _last_json(capsys.readouterr().out)
    assert list(data) == ["law", "units", "beta_deg", "gamma_deg", "alpha_x", "alpha_z"] and data["law"] == "li2013"
    assert data["units"] == {"alpha_x": "N/cm^3", "alpha_z": "N/cm^3"}  # not SI: the JSON says so
    beta, gamma = np.array(data["beta_deg"]), np.array(data["gamma_deg"])
    assert all(len(data[k]) == 37 * 37 for k in ("beta_deg", "gamma_deg", "alpha_x", "alpha_z"))
    # every (beta, gamma) pair of [-90, 90] deg at 5 deg, once
    assert {(b, g) for b, g in zip(beta, gamma)} == {(b, g) for b in range(-90, 91, 5) for g in range(-90, 91, 5)}
    for i in np.random.default_rng(5).choice(len(beta), 40, replace=False):
        x, z = li2013.alpha(math.radians(beta[i]), math.radians(gamma[i]))
        assert (data["alpha_x"][i], data["alpha_z"][i]) == pytest.approx((x / CM3, z / CM3), abs=1e-12)
    at = {(b, g): (x, z) for b, g, x, z in zip(beta, gamma, data["alpha_x"], data["alpha_z"])}
    assert at[(0, 90)][1] == pytest.approx(1.000, abs=1e-12)   # zeta of the generic medium
    assert at[(0, -90)][1] == pytest.approx(-0.250, abs=1e-12)  # Li 2013's extraction
    assert at[(90, 0)][0] == pytest.approx(0.370, abs=1e-12)


def test_law_li2013_in_a_named_medium(capsys):
    assert main(["law", "li2013", "--medium", "poppy_seeds_cp", "--json", "--quiet"]) == 0
    data = _last_json(capsys.readouterr().out)
    i = next(i for i, (b, g) in enumerate(zip(data["beta_deg"], data["gamma_deg"])) if (b, g) == (0, 90))
    assert data["alpha_z"][i] == pytest.approx(POPPY_ZETA["poppy_seeds_cp"], abs=1e-12)


def test_law_plot_is_written_and_not_overwritten(tmp_path, capsys):
    png = tmp_path / "map.png"
    assert main(["law", "li2013", "--plot", str(png), "--quiet"]) == 0
    import matplotlib.image
    height, width, _ = matplotlib.image.imread(png).shape
    assert width > 800 and height > 300  # two panels side by side
    assert main(["law", "li2013", "--plot", str(png)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["law", "li2013", "--plot", str(png), "--force", "--quiet"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["map.png"]  # no temporary file left


@pytest.mark.parametrize("argv, named", [
    (["law", "nope", "--plot", "m.png"], "unknown law 'nope'"),
    (["law", "li2013", "--medium", "sand", "--plot", "m.png"], "unknown medium 'sand'"),
    (["law", "li2013", "--medium", "glass_beads_3mm", "--plot", "m.png"], "glass_beads_3mm"),
    (["law", "li2013", "--plot", "m.pdf"], "must end in .png"),
    (["medium", "sand"], "unknown medium 'sand'"),
    (["medium", "poppy_seeds_lp", "--list"], "not both"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(argv, named, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert len(captured.err.strip().splitlines()) == 1 and named in captured.err and not captured.out
    assert not list(tmp_path.iterdir())


BOX = """<mujoco><worldbody><body name="plate" pos="0 0 -0.05"><freejoint/>
<geom type="box" size="0.02 0.03 0.001"/></body></worldbody></mujoco>"""


def test_attach_takes_a_named_medium():
    attached = attach(mujoco.MjSpec.from_string(BOX), "plate", medium="poppy_seeds_lp", backend="python")
    assert attached.parameters == {"zeta": 1.0}
    assert attached.coefficients == li2013.medium_parameters(media.medium("poppy_seeds_lp"))[1]
    assert attach(mujoco.MjSpec.from_string(BOX), "plate", backend="python").coefficients == li2013.GENERIC
    with pytest.raises(SceneError, match="one or the other"):
        attach(mujoco.MjSpec.from_string(BOX), "plate", medium="generic", zeta=0.5)
    with pytest.raises(SceneError, match="unknown medium"):
        attach(mujoco.MjSpec.from_string(BOX), "plate", medium="sand")


def test_a_scene_names_its_medium():
    scene = scene_from_dict({"medium": {"name": "poppy_seeds_cp"}, "plate": {"depth": 0.03}}, IntrusionScene)
    run = intrude(scene, [0.0])[0]
    p = scene.plate
    deep = run.depth > 0.01
    # a horizontal plate pushed straight down: alpha_z(0, 90 deg) of the medium x w L d
    assert run.force_z[deep] == pytest.approx(POPPY_ZETA["poppy_seeds_cp"] * CM3 * p.width * p.length
                                              * run.depth[deep], rel=1e-6)
    for medium, message in [({"name": "sand"}, "unknown medium"), ({"name": "generic", "zeta": 0.5}, "leave"),
                            ({"name": "glass_beads_4mm"}, "neither zeta")]:
        with pytest.raises(SceneError, match=message):
            scene_from_dict({"medium": medium}, IntrusionScene)


# A vertical 33 mm x 30 mm plate, 1 mm thick, its top 20 mm deep, in a medium given by its values (the catalogue
# has none): the sand-swimming law derived from 3D-RFT against the plate attached to MuJoCo with 3D-RFT.
PLATE_SIZE = {"length": 0.033, "height": 0.030, "depth": 0.020, "thickness": 0.001}
GRANULAR = {"bulk_density": 1500.0, "internal_friction": 0.4}


def _attached_plate_force(psi: float, mu_surf: float) -> np.ndarray:
    """The horizontal force (N) on the plate, moving at psi to its axis x, from `attach` (3D-RFT on surface
    elements), read after one explicit MuJoCo step."""
    p = PLATE_SIZE
    spec = mujoco.MjSpec.from_string(f"""<mujoco><option gravity="0 0 0" integrator="Euler" timestep="1e-6"/>
      <worldbody><body name="plate"><joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 1 0"/>
      <geom type="box" size="{p['length'] / 2} {p['thickness'] / 2} {p['height'] / 2}"
            pos="0 0 {-p['depth'] - p['height'] / 2}" mass="1000"/></body></worldbody></mujoco>""")
    attach(spec, ["plate"], law="rft3d", rho_c=GRANULAR["bulk_density"], mu_int=GRANULAR["internal_friction"],
           mu_surf=mu_surf, element_size=0.003, v_reg=0.0)  # the bare law, as plate_forces
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qvel[:] = 0.05 * np.array([math.cos(psi), math.sin(psi)])
    mujoco.mj_step(model, data)
    return data.qfrc_passive.copy()


@pytest.mark.parametrize("mu_surf", [0.0, 0.4])
def test_the_derived_sandswim_law_gives_the_attached_plates_force(mu_surf):
    # What the law was fitted to is the force on the attached plate (its faces' depth is linear: exact) ...
    found = media.sandswim_coefficients(**PLATE_SIZE, **GRANULAR, surface_friction=mu_surf)
    assert found.c_s > 0 and 0 < found.gamma0 <= math.pi / 2 and found.c_f >= 0
    psi = np.radians([0.0, 30.0, 60.0, 90.0])
    perp, par = media.plate_forces(psi, **PLATE_SIZE, **GRANULAR, surface_friction=mu_surf)
    attached = np.array([_attached_plate_force(p, mu_surf) for p in psi])
    np.testing.assert_allclose(-attached, np.stack([par, perp], axis=-1), rtol=1e-9, atol=1e-12)
    # ... and the law gives it within its fit's largest error
    for psi in np.radians([0.0, 45.0, 90.0]):
        v = 0.05 * np.array([[math.cos(psi), math.sin(psi), 0.0]])
        law = sandswim.force(v, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), 1e-9, found.c_s, found.c_f,
                             found.gamma0)[0, :2]
        np.testing.assert_allclose(law, _attached_plate_force(psi, mu_surf), rtol=0,
                                   atol=found.max_error * (1 + 1e-9))


MEDIUM_SET = {"medium.height": 0.03, "medium.depth": 0.02, "medium.bulk_density": 1500.0,
              "medium.internal_friction": 0.4, "medium.surface_friction": 0.4}


def test_the_physical_preset_names_its_medium_and_dissipates():
    scene = preset("physical")
    assert scene.medium.name == "glass_beads_4mm" and scene.rft.law == "sandswim"
    assert laws.feeds_energy(geometry.segment_law(scene)) == ""
    assert laws.feeds_energy(geometry.segment_law(preset("paper")))


@pytest.mark.parametrize("cls, chain", [(Scene, "plate"), (RobotScene, "fin")])
def test_a_sandswim_law_left_at_zero_takes_its_coefficients_from_the_medium(cls, chain):
    scene = preset("physical", cls).replace(**{"rft.law": "sandswim", "rft.c_s": 0.0, "rft.c_f": 0.0,
                                               "rft.gamma0": 0.0, **MEDIUM_SET})
    found = media.sandswim_coefficients(getattr(scene, chain).segment_length, 0.02, 0.03, 1500.0, 0.4, 0.4)
    law = geometry.resolve(scene).chain
    assert (law.law, law.parameters) == ("sandswim", {"c_s": found.c_s, "c_f": found.c_f, "gamma0": found.gamma0})
    # the scene says what its user gave: the coefficients stay left to the medium
    assert (scene.rft.c_s, scene.rft.c_f, scene.rft.gamma0) == (0.0, 0.0, 0.0)
    # deeper: 3D-RFT's stress grows with depth, so C_S and C_F with the plate's mean depth, and gamma0 stays
    deeper = geometry.resolve(scene.replace(**{"medium.depth": 0.05})).chain.parameters
    ratio = (0.05 + 0.015) / (0.02 + 0.015)
    assert deeper["c_s"] == pytest.approx(ratio * found.c_s, rel=1e-5)
    assert deeper["c_f"] == pytest.approx(ratio * found.c_f, rel=1e-5)
    assert deeper["gamma0"] == pytest.approx(found.gamma0, rel=1e-5)
    # coefficients set explicitly are kept, per unit area and depth (a plate's medium then gives nothing: its values
    # are refused beside them, tests/test_audit.py; a robot's still gives its arms and body)
    unread = {key: 0.0 for key in MEDIUM_SET if key.endswith("_density") or key.endswith("_friction")}
    explicit = scene.replace(**{"rft.c_s": 1000.0, "rft.c_f": 500.0, "rft.gamma0": 0.3,
                                **(unread if cls is Scene else {})})
    size = getattr(scene, chain).segment_length * 0.03 * (0.02 + 0.015)
    assert geometry.resolve(explicit).chain.parameters["c_s"] == pytest.approx(1000.0 * size, rel=1e-12)


@pytest.mark.parametrize("cls", [Scene, RobotScene])
def test_a_scene_whose_law_comes_from_its_medium_reads_back_the_same(cls, tmp_path):
    """Saved and read back (TOML: --write-scene, scene --dump; JSON: result files), a scene whose sandswim law comes
    from its [medium] is the same scene, and a changed medium changes both alike."""
    scene = preset("physical", cls).replace(**{"rft.law": "sandswim", "rft.c_s": 0.0, "rft.c_f": 0.0,
                                               "rft.gamma0": 0.0, **MEDIUM_SET})
    path = tmp_path / "scene.toml"
    path.write_text(to_toml(scene))
    for back in (load_scene(path, cls=cls), scene_from_dict(json.loads(json.dumps(scene.to_dict())), cls)):
        assert back == scene
        for changed in ({"medium.depth": 0.04}, {"medium.height": 0.05}, {"medium.bulk_density": 1600.0}):
            ours, theirs = scene.replace(**changed), back.replace(**changed)
            assert ours == theirs
            assert geometry.resolve(ours) == geometry.resolve(theirs)
            assert geometry.resolve(ours).chain != geometry.resolve(scene).chain  # the change did reach the law


def test_a_sandswim_law_without_coefficients_or_medium_values_is_refused():
    scene = preset("physical")
    with pytest.raises(SceneError, match=r"sandswim' needs rft.c_s > 0.*\[medium\] bulk_density"):
        scene.replace(**{"rft.c_s": 0.0, "rft.c_f": 0.0, "rft.gamma0": 0.0, **MEDIUM_SET,
                         "medium.name": "", "medium.bulk_density": 0.0})
    with pytest.raises(SceneError, match="unknown medium 'sand'"):
        scene.replace(**{"medium.name": "sand"})


def test_result_files_record_the_medium(tmp_path, capsys):
    out = tmp_path / "drag.h5"
    assert main(["drag", "--preset", "physical", "--distance", "10", "--quiet", "--out", str(out)]) == 0
    with h5py.File(out) as f:
        stored = json.loads(f.attrs["scene_json"])
        assert stored["medium"]["name"] == "glass_beads_4mm" and f.attrs["law_feeds_energy"] == ""
        assert 'name = "glass_beads_4mm"' in f.attrs["scene_toml"]
    assert main(["drag", "--set", "medium.name=sand", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown medium 'sand'" in err[0]


def test_surface_friction_left_at_0_is_the_named_mediums_everywhere():
    # rft3d in sand_3d_rft_code ran at mu_surf = 0 (the reference's "0: frictionless") where media.md said "0: the
    # named medium's": one meaning now, in scenes and in attach; a value given is the intruder's own
    catalogued = media.medium("sand_3d_rft_code").get("surface_friction").value
    scene = scene_from_dict({"medium": {"law": "rft3d", "name": "sand_3d_rft_code"}}, UserScene)
    resolved, _ = laws.surface_parameters("rft3d", rft3d.given(scene.medium), media.medium("sand_3d_rft_code"), "m")
    assert resolved["mu_surf"] == catalogued == 0.1806
    mine = scene.replace(**{"medium.surface_friction": 0.4})
    assert laws.surface_parameters("rft3d", rft3d.given(mine.medium), media.medium("sand_3d_rft_code"),
                                   "m")[0]["mu_surf"] == 0.4
    spec = mujoco.MjSpec.from_string(BOX)
    assert attach(spec, "plate", law="rft3d", medium="sand_3d_rft_code",
                  backend="python").parameters["mu_surf"] == catalogued
    # without a named medium, 0 is frictionless (nothing to take it from)
    plain = scene_from_dict({"medium": {"law": "rft3d", "bulk_density": 1500, "internal_friction": 0.5}},
                            UserScene)
    assert laws.surface_parameters("rft3d", rft3d.given(plain.medium), None, "m")[0]["mu_surf"] == 0.0
    # a chain's [medium] reads it the same way
    chain = preset("physical").medium
    assert media.immersion_properties(dataclasses.replace(chain, name="", bulk_density=1500.0,
                                                          internal_friction=0.5))[2] == 0.0


def test_attach_takes_the_scene_files_names_too():
    def parameters(**given):
        return attach(mujoco.MjSpec.from_string(BOX), "plate", law="rft3d", backend="python", **given).parameters
    assert parameters(bulk_density=1500.0, internal_friction=0.5, surface_friction=0.3) == parameters(
        rho_c=1500.0, mu_int=0.5, mu_surf=0.3) == {"rho_c": 1500.0, "mu_int": 0.5, "mu_surf": 0.3}
    with pytest.raises(SceneError, match="internal_friction is mu_int by the scene files' name: give one of them"):
        parameters(rho_c=1500.0, mu_int=0.5, internal_friction=0.5, mu_surf=0.3)
