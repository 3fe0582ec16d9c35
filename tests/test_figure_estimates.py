"""A robot run's means over every step, whatever record_dt, and an error estimate and limit for every figure it
reports (finrft.convergence.FigureLimit, --max-error NAME=X%)."""

import numpy as np
import pytest

import finrft
from finrft.cli import main
from finrft.convergence import ROBOT_HEADLINE, ErrorLimits, FigureLimit
from finrft.experiment import run
from finrft.experiments.flags import limits
from finrft.experiments.user_model import UserModel, example, window_mean
from finrft.scene import SceneError, UserScene, load_scene

MEANS = ("medium_force_N", "drive_load", "actuator_power_W", "positive_power_W")


def _summaries(scene):
    """The summary at the scene's record_dt and at every step, and the every-step run itself."""
    every = scene.replace(**{"sim.record_dt": scene.sim.dt})
    sparse = run(UserModel.of(scene), scene, estimate_error=False)
    dense = run(UserModel.of(every), every, estimate_error=False)
    return sparse.summary(), dense.summary(), dense


@pytest.mark.parametrize("name, method, dt", [("sand_swimmer", "newton-midpoint", 1e-3),
                                               pytest.param("hexapod", "explicit", 1e-4, marks=pytest.mark.slow)])
def test_means_do_not_depend_on_record_dt_and_are_the_integral_over_every_step(name, method, dt, monkeypatch):
    # the explicit step's means are read without a forward pass of their own (`RobotTrial.after_step`); the chatter
    # probe, which a hexapod's feet resting in the sand trip at 0.1 ms, is not what is tested here
    monkeypatch.setattr("finrft.experiment.chatter_speeds", lambda m, d, groups, attached, watch:
                        np.full(len(watch), np.inf))
    # an example for 0.6 s: its actuators' power changes within a 10 ms sample interval
    scene = load_scene(example(name), cls=UserScene, overrides={
        "sim.duration": 0.6, "sim.settle": 0.3, "sim.method": method, "sim.dt": dt, "sim.record_dt": 0.01})
    sparse, dense, every = _summaries(scene)
    for key in MEANS:  # the means of the 10 ms samples differed by 5e-5 W of 0.70 W here, 9 % over 5 s
        assert np.allclose(sparse[key], dense[key], rtol=1e-9, atol=1e-12), key
    # an independent integration: the trapezoid rule over the samples of every step, each actuator's power the
    # force its step applied (the force read at the step's start, its damping kv at the new velocity: both
    # examples' servos have an affine bias, no force range and no gain in velocity) times its velocity
    t, settle = every.time, scene.sim.settle
    kv = -UserModel.of(scene).build(scene).model.actuator_biasprm[:, 2]
    force, velocity = every.actuator_force, every.actuator_velocity
    assert kv.min() > 0
    power = (force[:-1] - kv * (velocity[1:] - velocity[:-1])) * velocity[1:]
    assert dense["actuator_power_W"] == pytest.approx(window_mean(t[1:], power.sum(axis=1), settle), rel=1e-9)
    assert dense["positive_power_W"] == pytest.approx(
        window_mean(t[1:], np.maximum(power, 0).sum(axis=1), settle), rel=1e-9)
    assert dense["medium_force_N"] == pytest.approx(window_mean(t, every.medium_force, settle).sum(axis=0),
                                                    rel=1e-9, abs=1e-12)


@pytest.mark.slow
def test_a_stiff_servos_power_is_the_force_its_step_applied_and_converges_at_1_ms():
    # The sand-swimmer's 10 g links on servos of kp = 50 N m/rad: a force read at the state itself, kp (ctrl - q)
    # with q a step further on, put its positive power 12 % above the run at 1/8 of the step over this window (15 %
    # over the example's); the force each step applied (`StepPower`) 1.1 % (0.3 %), and its net power too.
    figures = {}
    for dt in (1e-3, 1.25e-4):
        scene = load_scene(example("sand_swimmer"), cls=UserScene, overrides={
            "sim.duration": 2.0, "sim.settle": 1.0, "sim.method": "newton-midpoint", "sim.dt": dt})
        figures[dt] = run(UserModel.of(scene), scene, estimate_error=False).summary()
    coarse, fine = figures[1e-3], figures[1.25e-4]
    assert coarse["positive_power_W"] == pytest.approx(fine["positive_power_W"], rel=0.02)
    assert coarse["actuator_power_W"] == pytest.approx(fine["actuator_power_W"], rel=0.02)
    assert coarse["cost_of_transport"] == pytest.approx(fine["cost_of_transport"], rel=0.02)
    # and the step's power is not the state's: positive power clips a power that changes sign within a stroke
    assert fine["positive_power_W"] > 1.05 * fine["actuator_power_W"]


def test_the_mean_velocity_does_not_depend_on_the_instants_recorded():
    # the window opens at 0.305 s, between two 10 ms samples: the centre of mass is taken where it opens, not
    # interpolated between samples (a companion records every fourth instant of its run)
    scene = load_scene(example("sand_swimmer"), cls=UserScene, overrides={
        "sim.duration": 0.6, "sim.settle": 0.305, "sim.method": "newton-midpoint", "sim.dt": 1e-3,
        "sim.record_dt": 0.01})
    sparse, dense, every = _summaries(scene)
    assert np.allclose(sparse["com_velocity_m_s"], dense["com_velocity_m_s"], rtol=1e-9, atol=1e-12)
    start = every.com_position[np.argmin(abs(every.time - scene.sim.settle))]  # a sample at every step: 0.305 s
    assert np.allclose(dense["com_velocity_m_s"], (every.com_position[-1] - start) / (0.6 - 0.305), rtol=1e-9)
    assert sparse["cost_of_transport"] == pytest.approx(dense["cost_of_transport"], rel=1e-9)


def test_a_figure_limit_is_relative_to_its_magnitude_with_a_floor():
    speed = FigureLimit("com_velocity_m_s", 2.0, floor=1e-4)
    assert speed.allowed([0.03, 0.04, 0.0]) == pytest.approx(0.02 * 0.05)  # 2 % of |v| = 50 mm/s
    assert speed.allowed([1e-6, 0, 0]) == 1e-4                             # a robot that hardly moves: the floor
    assert FigureLimit("cost_of_transport", 0.5, relative=False).allowed(10.0) == 0.5
    with pytest.raises(SceneError, match="no reported figure is named 'speed'"):
        FigureLimit("speed", 2.0)


def test_limits_bound_the_figures_named_or_the_headline_ones_and_only_those_a_run_reports():
    figures = {"com_velocity_m_s": [0.01, 0.0, 0.0], "cost_of_transport": None, "positive_power_W": 0.3}
    estimate = {"com_velocity_m_s": [3e-4, 0, 0], "cost_of_transport": None, "positive_power_W": 0.03,
                "position_percent": 7.0}
    headline = (FigureLimit("com_velocity_m_s", 2.0, floor=1e-4), FigureLimit("cost_of_transport", 2.0))
    assert {f.key for f in ROBOT_HEADLINE} == {"com_speed_m_s", "cost_of_transport"}
    # the default limits bound the headline figures (3 % > 2 % of the speed), not the positions, and not a cost
    # of transport the run does not report
    over = ErrorLimits().exceeded(estimate, figures, headline)
    assert len(over) == 1 and over[0].startswith("com_velocity_m_s = 0.0003 (3 %) > 0.0002"), over
    # named figures replace them: positive power within 10 %, the speed unbounded
    assert ErrorLimits(figures=(FigureLimit("positive_power_W", 10.0),)).exceeded(estimate, figures, headline) == []
    # an experiment without headline figures keeps the positions' 5 % of its scale
    assert ErrorLimits().exceeded(estimate, figures, ()) == ["position_percent = 7 > 5"]


class _Args:
    def __init__(self, *items):
        from finrft.experiments.flags import max_error_item
        self.max_error = [max_error_item(i) for i in items]


def test_max_error_takes_a_bare_number_or_named_figures():
    assert limits(_Args("1")) == ErrorLimits.uniform(1.0)  # as before: degrees, points, percent of the scale
    named = limits(_Args("com_velocity_m_s=1%", "cost_of_transport=0.2", "position_percent=8"))
    assert named.figures == (FigureLimit("com_velocity_m_s", 1.0), FigureLimit("cost_of_transport", 0.2, False))
    assert named.position_percent == 8 and named.angle_deg == ErrorLimits().angle_deg
    assert limits(_Args()) == ErrorLimits()


@pytest.mark.parametrize("item, named", [("speed=2%", "no bounded quantity or reported figure named 'speed'"),
                                         ("angle_deg=1%", "angle_deg is bounded in its own unit"),
                                         ("cost_of_transport=-1%", "must be > 0")])
def test_a_bad_max_error_is_one_line_and_exit_2(item, named, capsys):
    assert main(["run", "--example", "hexapod", "--max-error", item]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and named in err, err
