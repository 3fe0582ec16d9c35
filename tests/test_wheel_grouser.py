"""The grousered wheel of the wheel group's experiments (`finrft wheel --wheel grouser`): its elements against the
closed-form areas of its dimensions, its forces against the experimenters' own RFT predictions for it (their mesh,
their code; finrft/data/wheel/grouser_wheel_by_condition.csv), grousers against the smooth wheel as the measurements
order them, and the flags' bad input."""

import csv
import math

import numpy as np
import pytest

from finrft.cli import main
from finrft.data import wheel_dir
from finrft.experiment import run
from finrft.experiments.wheel import GROUSERED, Wheel, default_scene, outer_radius, read_conditions, wheel_model

RIM, HEIGHT, THICKNESS, WIDTH, COUNT = 0.0575, 0.005, 0.0079, 0.06, 24


def held(slip: float, beta_deg: float, sinkage: float, wheel: dict) -> dict:
    scene = default_scene(**wheel, **{"wheel.slip": slip, "wheel.slip_angle": math.radians(beta_deg),
                                      "wheel.sinkage": sinkage, "sim.duration": 0.3, "sim.settle": 0.1})
    return run(Wheel.of(scene), scene, estimate_error=False).summary()


def rows(wheel: str) -> list[dict[str, str]]:
    with open(wheel_dir() / f"{wheel}_wheel_by_condition.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_the_grousered_wheels_elements_have_its_closed_form_areas():
    """At the default 4 mm elements: the grousers' tips, flanks and ends and the wheel's two sides carry exactly
    the areas of a 57.5 mm rim with 24 boxes 7.9 mm thick rising 5 mm above it (their inner edges on the rim), the
    tips cut into ceil(t/h) x ceil(w/h) elements each; the rim between them is the rim less what the grousers cover,
    to within one element per grouser (the rim's elements under a grouser are dropped whole); the outer radius,
    found by rays, is the tips' 62.5 mm, the radius the slip is taken at."""
    scene = default_scene(**GROUSERED)
    h = scene.medium.element_size
    wheel = Wheel.of(scene)
    built = wheel.build(scene)
    surface, = built.attached.surfaces
    c, n, a = surface.centre, surface.normal, surface.area  # the wheel's frame: the axle along y
    r = np.hypot(c[:, 0], c[:, 2])
    radial = (n[:, 0] * c[:, 0] + n[:, 2] * c[:, 2]) / r
    side = np.abs(n[:, 1]) > 0.999
    base = math.sqrt(RIM ** 2 - (THICKNESS / 2) ** 2)
    stand = RIM + HEIGHT - base  # a grouser's extent from its inner face to its tip
    tips = (radial > 0.999) & (r > RIM + HEIGHT / 2)
    rim = (radial > 0.999) & (r < RIM + 1e-9) & ~side
    flanks = ~side & (np.abs(radial) < 0.2)
    ends = side & (r > RIM)
    assert tips.sum() == COUNT * math.ceil(THICKNESS / h) * math.ceil(WIDTH / h)
    assert a[tips].sum() == pytest.approx(COUNT * THICKNESS * WIDTH, rel=1e-12)
    assert a[flanks].sum() == pytest.approx(2 * COUNT * stand * WIDTH, rel=1e-12)
    assert a[ends].sum() == pytest.approx(2 * COUNT * THICKNESS * stand, rel=1e-12)
    assert a[side & ~ends].sum() == pytest.approx(2 * math.pi * RIM ** 2, rel=1e-12)
    assert (tips | rim | flanks | side).all()
    assert abs(a[rim].sum() - (2 * math.pi * RIM - COUNT * THICKNESS) * WIDTH) <= COUNT * h * WIDTH
    model = wheel_model(scene.wheel).spec.compile()
    assert outer_radius(model, model.body("wheel").id) == pytest.approx(RIM + HEIGHT, abs=2e-4)
    assert wheel.radius == wheel.outer == pytest.approx(RIM + HEIGHT)


# (beta, rim speed label): a driven, a braked and a rolling wheel at slip angles where the experimenters' side faces
# are exactly leading or trailing (at beta = 0 their rounded normals count an edge-on side: the data's README)
@pytest.mark.parametrize("beta, rim", [(30, 20), (45, 5), (60, 10)])
def test_the_grousered_wheel_gives_the_experimenters_own_rft_predictions(beta, rim):
    """Held at a condition's measured sinkage with the rig's medium (the experimenters' zeta = 0.6 on Li's generic
    coefficients), the grousered wheel's forces are those the wheel group computed with their own code on their own
    mesh of it (its sector-shaped grousers and root fillets, which the boxes leave out): within 5 % of the
    force's size and 0.5 N."""
    row = next(r for r in rows("grouser") if float(r["beta_deg"]) == beta and float(r["Vry_label_mm_s"]) == rim)
    s = held(float(row["slip_model"]), beta, 1e-3 * float(row["sinkage_mm"]), GROUSERED)
    found = np.array([s[k] for k in ("Fx_N", "Fy_N", "Fz_N")])
    theirs = np.array([float(row[f"F{k}_rft_N"]) for k in "xyz"])
    assert np.abs(found - theirs).max() < 0.05 * np.linalg.norm(theirs) + 0.5, (found, theirs)
    # the slip at the tips' radius: the data's omega (rim speed / 62.5 mm)
    assert s["omega_rad_s"] == pytest.approx(float(row["omega_model_rad_s"]), rel=1e-9)


def test_grousers_raise_the_driven_wheels_pull_and_straight_wheels_feel_no_side_force():
    """Driven (s = 0.5) straight ahead, held 25 mm deep at the tips: the grousers' faces across the rim push back on
    the sand they shear, so the grousered wheel pulls harder than the smooth one of the same outer radius (as the
    measurements have it at every driven slip straight ahead, in the two shipped files), and a wheel symmetric
    about its mid-plane, moving in that plane, feels no force along its axle."""
    measured = {w: {float(r["Vry_label_mm_s"]): float(r["Fx_meas_N"]) for r in rows(w) if float(r["beta_deg"]) == 0}
                for w in ("grouser", "smooth")}
    assert all(measured["grouser"][rim] > measured["smooth"][rim] for rim in (20, 40, 100))
    grousered, smooth = held(0.5, 0, 0.025, GROUSERED), held(0.5, 0, 0.025, {})
    assert grousered["Fx_N"] > smooth["Fx_N"] + 1.0
    for s in (grousered, smooth):
        assert abs(s["Fy_N"]) < 1e-6 * s["Fz_N"]


def test_the_grousered_wheels_conditions_file_has_the_smooth_ones_conditions():
    conditions = read_conditions(str(wheel_dir() / "grouser_wheel_by_condition.csv"))
    smooth = read_conditions(str(wheel_dir() / "smooth_wheel_by_condition.csv"))
    # the same 63 conditions: slip angles, and the slips each rig measured (within 0.02 of each other)
    assert [c.slip_angle for c in conditions] == [c.slip_angle for c in smooth]
    assert np.allclose([c.slip for c in conditions], [c.slip for c in smooth], atol=0.02)


@pytest.mark.parametrize("argv, named", [
    (["--wheel", "tracked"], "--wheel"),
    (["--wheel", "grouser", "--model", "w.xml"], "--model"),
    (["--grousers", "1", "--grouser-height", "5", "--grouser-thickness", "200"], "wider than the rim"),
    (["--grousers", "4", "--grouser-height", "5", "--grouser-thickness", "-1"], "--grouser-thickness"),
])
def test_the_wheels_bad_input_is_one_line_exit_2(capsys, argv, named):
    assert main(["wheel", "--slip", "0.5", "--sinkage", "20", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and named in err, err
