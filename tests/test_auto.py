"""sim.method = "auto", a robot's default: the light-linked sand-swimmer gets an implicit method, a heavy, slow sled
MuJoCo's explicit step, each says what it chose and why, and the choice's figures are within their limits of a run
at 1/8 of its step."""

import json
import math

import pytest

from finrft import experiment, methods
from finrft.cli import main
from finrft.convergence import ErrorLimits, FigureLimit, figure_difference, magnitude
from finrft.experiments.user_model import UserModel, example, run_robot
from finrft.scene import SceneError, UserScene, load_scene

from conftest import settling_box

# A 2 kg sled on the sand (a 10 x 10 x 2 cm box, 9 mm deep, free to sink) pushed at 20 mm/s: its explicit step holds
# where dt < 2 m v_reg / F: its bottom face, sinking at a creep, switches its full force (about 90 N, the 20 N weight
# on a partial ramp) on over v_reg = 25 mm/s: 1.1 ms. An implicit step costs several explicit ones.
SLED = """<mujoco><option gravity="0 0 -9.81"/><worldbody><body name="carriage">
  <joint name="push" type="slide" axis="1 0 0"/><geom type="sphere" size="0.005" mass="0.1"/>
  <body name="sled" pos="0 0 0.0008"><joint name="lift" type="slide" axis="0 0 1"/>
  <geom type="box" size="0.05 0.05 0.01" mass="2.0"/></body></body></worldbody></mujoco>"""
SLED_SCENE = """[model]\npath = "sled.xml"\nbodies = ["sled"]
[medium]\nlaw = "li2013"\nelement_size = 0.005\nv_reg = 0.025
[[drive]]\njoint = "push"\nspeed = 0.02\nstroke = 0.0
[sim]\nduration = 0.6\nsettle = 0.3\n"""
SPEED = ErrorLimits(figures=(FigureLimit("com_speed_m_s", 2.0, floor=1e-4),))


def _sled(tmp_path) -> str:
    (tmp_path / "sled.xml").write_text(SLED)
    (tmp_path / "sled.toml").write_text(SLED_SCENE)
    return str(tmp_path / "sled.toml")


def _chooser(tmp_path, prices: dict | None = None):
    """A chooser of the sled's 0.6 s run with no pilot of its own, its candidates priced at ``prices`` (CPU s a
    simulated second, by (method, dt)), none run whole yet."""
    from finrft import choice as choosing
    chooser = choosing.Chooser(load_scene(_sled(tmp_path), cls=UserScene), ErrorLimits(), None, lambda s: None,
                               0.6, 0.6, 1)
    chooser._priced.update(prices or {})
    chooser._rates.update(prices or {})
    return chooser


def _converged(run, limits: ErrorLimits) -> None:
    """The run's bounded figures are within their limits of the chosen method at 1/8 of the chosen step."""
    choice = run.method_choice
    scene = run.scene.replace(**{"sim.method": choice.method, "sim.dt": choice.dt / 8})
    fine = experiment.run(UserModel.of(scene), scene, estimate_error=False)
    ours, theirs = run.summary(), fine.summary()
    for limit in limits.figures or run.headline():
        if theirs[limit.key] is not None:
            off = magnitude(figure_difference(ours[limit.key], theirs[limit.key]))
            assert off <= limit.allowed(theirs[limit.key]), limit.key


@pytest.mark.slow  # its pilots, and the chosen method at an eighth of its step: about a minute
def test_the_sand_swimmers_choice_meets_its_limit_against_the_converged_run():
    # Which method wins depends on this machine's prices (the explicit step at an eighth of a millisecond or an
    # implicit one at the scene's): whichever it is, its speed is within 2 % of the same method at an eighth of its
    # step, and no explicit step as long as the scene's passes (its 10 g links chatter there).
    over = {"sim.method": "auto", "sim.duration": 0.6, "sim.settle": 0.3,
            **{f"control.{i}.{key}": value for i in range(6) for key, value in (("ramp", 0.1), ("frequency", 2.0))}}
    run = run_robot(load_scene(example("sand_swimmer"), cls=UserScene, overrides=over), max_error=SPEED)
    choice = run.method_choice
    assert run.scene.sim.method == choice.method
    assert not any(c.passed for c in choice.candidates if c.method == "explicit" and c.dt >= 1e-3)
    assert run.error_estimate["com_speed_m_s"] <= SPEED.figures[0].allowed(run.summary()["com_speed_m_s"])
    _converged(run, SPEED)


def test_a_run_that_starts_at_once_is_judged_past_its_start():
    # The wheel rig has no ramp-in: its drive starts at once from its steady depth and rings its 2.1 kg axis on the
    # sand for about half a second, where its implicit step's error at 125 ms was estimated 29 % over the pilots'
    # first second, and auto took the explicit step at 1 ms (16 times the cost). Judged over the window's second
    # half, newton at 125 ms meets the limits, and its whole run holds the medium's mean force within 2 % of the run
    # at 1/8 of the step (its steady state: the run averages from 4 s).
    run = run_robot(load_scene(example("wheel_rig"), cls=UserScene, overrides={"sim.method": "auto"}))
    choice = run.method_choice
    assert choice.method in ("newton", "newton-midpoint") and choice.dt >= 0.0625, choice.line()
    _converged(run, ErrorLimits(figures=(FigureLimit("medium_force_N", 2.0),)))


@pytest.fixture
def dear_implicit(monkeypatch):
    """The implicit methods' measured costs tripled: the sled's explicit step at 1 ms and newton at 4 ms cost
    within the timing noise of a loaded machine (newton was chosen in 2 of 24 runs of this file on two cores, and
    its explicit step not piloted in 2 of 24 of the slow ones), and these tests are of the choice, not of the
    machine."""
    from finrft import choice as choosing
    cost = choosing.Chooser.cost
    monkeypatch.setattr(choosing.Chooser, "cost", lambda self, method, dt:
                        cost(self, method, dt) * (1 if method == "explicit" else 3))


def test_a_heavy_slow_sled_gets_the_explicit_step_and_says_why(tmp_path, capsys, dear_implicit):
    assert main(["run", "--scene", _sled(tmp_path), "--json"]) == 0
    out, err = capsys.readouterr()
    s = json.loads(out)
    choice = s["method_choice"]
    assert choice["method"] == "explicit" and s["dt"] == choice["dt"]
    assert "method auto: explicit" in err and choice["reason"]
    weighed = {c["method"] for c in choice["candidates"]}
    assert {"explicit", "newton-midpoint"} <= weighed
    chosen, = [c for c in choice["candidates"] if c["method"] == "explicit" and c["dt"] == choice["dt"]]
    implicit = [c for c in choice["candidates"] if c["method"] != "explicit"]
    # every implicit candidate either missed the limits or costs more (its measured cost may be the lower one)
    assert implicit and all(c["predicted_cost_s"] > chosen["predicted_cost_s"] for c in implicit if c["within_limits"])
    assert all(c["why_not"] for c in choice["candidates"] if c is not chosen)
    assert s["wall_s"] >= choice["pilot_wall_s"] > 0


@pytest.mark.slow  # the chosen method at an eighth of its step: a convergence check
def test_the_sleds_choice_is_within_its_limits_of_a_converged_run(tmp_path, dear_implicit):
    run = run_robot(load_scene(_sled(tmp_path), cls=UserScene))
    assert run.method_choice.method == "explicit"
    _converged(run, ErrorLimits())


def test_a_method_named_runs_as_named_and_auto_is_a_robots_default_only(tmp_path):
    run = run_robot(load_scene(_sled(tmp_path), cls=UserScene, overrides={"sim.method": "newton"}))
    assert run.method_choice is None and run.scene.sim.method == "newton" and "method_choice" not in run.summary()
    assert UserScene().sim.method == "auto"
    with pytest.raises(SceneError):
        load_scene(preset_name="physical", overrides={"sim.method": "auto"})


def test_an_explicit_choice_its_whole_run_refuses_falls_back_to_an_implicit_step(monkeypatch):
    # The wheel rig free under 21 N at 10 ms: the explicit step runs through the pilots' 0.16 s and chatters on its
    # vertical axis from 0.09 s on, which the whole run's probe sees; the implicit steps are searched then (a finer
    # explicit step would chatter after the window too, as the sand-swimmer's do down to 0.25 ms). Here the
    # explicit step is priced at nothing, as on a machine where it is the cheaper one (with the analytic Jacobian
    # the implicit step costs the less on the wheel: newton is chosen at once).
    from finrft import choice as choosing
    from finrft.experiments import wheel
    cost = choosing.Chooser.cost
    monkeypatch.setattr(choosing.Chooser, "cost", lambda self, method, dt:
                        0.0 if method == "explicit" else cost(self, method, dt))
    # and its explicit limit not taken (its steps down to 0.16 ms are beyond it, and would not be piloted)
    monkeypatch.setattr(choosing, "EXPLICIT_ROOM", float("inf"))
    scene = wheel.default_scene(**{"sim.method": "auto", "sim.duration": 1.0, "sim.settle": 0.5, "wheel.slip": 0.3,
                                   "wheel.load": 21.0})
    run = experiment.run(wheel.Wheel.of(scene), scene)
    choice = run.method_choice
    assert methods.get(choice.method).implicit and "run whole, was refused" in choice.reason
    assert any(c.method == "explicit" and c.failed.startswith("run whole") for c in choice.candidates)
    # the refused run's time is the run's too
    assert choice.refused_wall_s > 0 and run.wall_s > choice.pilot_wall_s + choice.refused_wall_s
    assert run.summary()["Fz_N"] == pytest.approx(21.0, rel=1e-3)  # the medium carries the load


@pytest.mark.slow  # its pilots, three whole runs and the chosen method at an eighth of its step: about 20 s
def test_an_implicit_choice_its_whole_run_refuses_goes_on_down_the_ladder(tmp_path, monkeypatch):
    # A pilot over the window can pass where the whole run chatters (the whegs' newton at 2 ms: in 40 % of its
    # probes over its 0.75 s window, in over half of them in its second). Once every candidate that met the limits
    # was refused so, the run stopped; the search goes on past them instead. Here the first two whole runs (newton
    # at 0.5 and 0.25 ms, both of which met the limits) are made to chatter, the explicit step is priced out and
    # newton is the one implicit method.
    from finrft import choice as choosing
    from finrft.errors import Chatter
    cost, chosen, refused = choosing.Chooser.cost, choosing._chosen, []
    monkeypatch.setattr(choosing, "IMPLICIT", ("newton",))
    monkeypatch.setattr(choosing.Chooser, "cost", lambda self, method, dt:
                        float("inf") if method == "explicit" else cost(self, method, dt))

    def chatters(full, scene, candidate, chooser, fell_back):
        if len(refused) < 2:
            refused.append(candidate.dt)
            raise Chatter("the RFT force chatters at t = 0.06 s (it reverses within a few steps)")
        return chosen(full, scene, candidate, chooser, fell_back)
    monkeypatch.setattr(choosing, "_chosen", chatters)
    run = run_robot(load_scene(_sled(tmp_path), cls=UserScene))
    choice = run.method_choice
    assert len(refused) == 2 and choice.method == "newton" and choice.dt < min(refused)
    assert all(f"newton at {dt:g} s, run whole, was refused" in choice.reason for dt in refused)
    _converged(run, ErrorLimits())


def test_pilots_that_span_the_run_are_the_run_and_its_companion(tmp_path, monkeypatch):
    # Where the pilots' window would span most of the run they run whole, and the chosen candidate's pilots are
    # its run and its companion: no run is made twice, and the result is the run of the method named. The first
    # candidate that meets the limits is chosen, as made: none is measured after it, none at a longer step.
    from finrft import choice as choosing
    monkeypatch.setattr(choosing, "WHOLE_SHARE", 0.05)  # the sled's 0.06 s window of its 0.6 s: whole
    made = []  # the runs made through (a short pilot that prices a candidate stops early)
    once = experiment._once

    def counted(exp, s, *rest):
        result = once(exp, s, *rest)
        made.append((s.sim.method, s.sim.dt, s.sim.duration))
        return result
    monkeypatch.setattr(experiment, "_once", counted)
    run = run_robot(load_scene(_sled(tmp_path), cls=UserScene))
    choice = run.method_choice
    assert choice.window_s == run.scene.sim.duration and len(made) == len(set(made))
    measured = [c for c in choice.candidates if c.measured]
    assert measured[-1].passed and not any(c.passed for c in measured[:-1])
    assert (choice.method, choice.dt) == (measured[-1].method, measured[-1].dt)
    named = run_robot(run.scene)  # the chosen method and step, named: no pilots
    assert named.method_choice is None and named.summary()["com_velocity_m_s"] == run.summary()["com_velocity_m_s"]
    # the means over every step estimated alike (the centre of mass's figures interpolate its start between the
    # companion's samples, which the named run's records every fourth instant), every figure estimated
    assert set(run.error_estimate) == set(named.error_estimate)
    for key in ("medium_force_N", "drive_load", "positive_power_W"):
        assert run.error_estimate[key] == pytest.approx(named.error_estimate[key], rel=1e-6, abs=1e-12), key
    assert run.error_companion == named.error_companion


def test_a_step_with_room_to_spare_is_lengthened(tmp_path):
    # The sled at 0.25 ms: its explicit step meets the limits at 0.5 ms, which costs half as much.
    run = run_robot(load_scene(_sled(tmp_path), cls=UserScene, overrides={"sim.dt": 0.00025}))
    assert run.method_choice.dt > 0.00025 and run.scene.sim.dt == run.method_choice.dt
    _converged(run, ErrorLimits())


def test_a_resting_box_is_not_run_at_a_step_that_lifts_it_out_of_the_sand(tmp_path):
    # Its speed is 0 and it reports no cost of transport: at twice its step the explicit step hops it out of the
    # sand while those pass. A step longer than the scene's own keeps the medium's mean force too: the weight.
    run = run_robot(load_scene(str(settling_box(tmp_path, "auto")), cls=UserScene))
    assert run.summary()["medium_force_N"][2] == pytest.approx(0.05 * 9.81, rel=0.02)


def test_a_pilot_stops_once_it_costs_more_than_it_may(tmp_path):
    # A pilot that spends 20 ms of CPU between its samples, under a budget of 50 ms: it stops, as the step's
    # failure, and its cost per simulated second is measured as far as it got.
    import time

    from finrft import choice as choosing
    scene = load_scene(_sled(tmp_path), cls=UserScene)

    def pilot(s, companion, progress):
        for i in range(11):
            end = time.process_time() + 0.02
            while time.process_time() < end:
                pass
            progress(i / 10)
        return "the run"
    chooser = choosing.Chooser(scene, ErrorLimits(), pilot, lambda s: None, 0.6, 0.6, 1)
    run, rate = chooser._timed(scene, 0.6)
    assert run == "the run" and rate == pytest.approx(0.02 * 10 / 0.6, rel=0.5)
    chooser.budget = 0.05
    run, _ = chooser._timed(scene, 0.6)
    assert isinstance(run, Exception) and "cost more than" in str(run)


def _searched(errors: dict, prices: dict, limit: float = float("inf"), whole: bool = False,
              costs: dict | None = None, asked: list | None = None) -> tuple[list, tuple]:
    """The candidates a search of the methods of ``errors`` measures, in turn, and the one it chose, where each
    method's error (of its limit) and cost go with its step as ``errors`` and ``prices`` say (s at 2 ms, as 1 / dt;
    once a pilot of it ran, as ``costs`` say where they do; an error None: its pilot fails), the bodies' explicit
    limit ``limit`` s; its pilots ``whole`` runs or windows of a tenth of the run. Each cost it asks for goes to
    ``asked``: (method, step, the cost past which its price may stop, how many candidates it had measured)."""
    from finrft import choice as choosing
    tried = []

    class Fake(choosing.Chooser):
        def __init__(self):
            self.top, self.candidates, self.budget, self.whole = 2e-3, [], float("inf"), whole
            self._whole = set()  # the pilots that ran through
            self._runs, self.window, self.duration = {}, 1.0 if whole else 0.1, 1.0

        def predicted(self, method, dt, dearer_than=float("inf")):
            if asked is not None:
                asked.append((method, dt, dearer_than, len(tried)))
            return self.cost(method, dt)

        def cost(self, method, dt):
            ran = any(m == method for m, _ in tried)
            return (costs or {}).get(method, prices[method]) * 2e-3 / dt if ran else prices[method] * 2e-3 / dt

        def explicit_limit(self):
            return limit

        def try_step(self, method, dt, *_):
            tried.append((method, dt))
            self._runs[(method, dt)] = self._runs[(method, dt / 2)] = None
            excess = errors[method](dt)
            c = choosing.Candidate(method, dt, cost_s=self.cost(method, dt), measured=excess is not None,
                                   excess=math.inf if excess is None else excess)
            c.over = ["over"] if c.measured and c.excess > 1 else []
            c.failed = "" if c.measured else "chatters"
            if c.measured:
                self._whole.add((method, dt))
            self.candidates.append(c)
            return c
    passed = Fake().search(tuple(errors))
    return tried, (passed[0].method, passed[0].dt)


def test_a_method_is_walked_down_by_halvings_and_one_far_off_not_at_all():
    # The sandfish's pilots over its 2 s run (estimates as measured): newton 19 % off at 2 ms (first order: 0.125 ms
    # would do), newton-midpoint 3.3 % at 2 ms and 0.33 % at 1 ms. Each pilot costs as 1 / dt. newton-midpoint is
    # judged at 1 ms, whose pilot at half the step is all it takes, not sent to 0.5 ms as its first-order error
    # asks (pilots at 0.5 and 0.25 ms); newton's next steps are ranked by the 0.125 ms it would need, and not run.
    errors = {"newton-midpoint": lambda dt: 3.3 * (dt / 2e-3) ** 3.3 / 2.0, "newton": lambda dt: 18.9 * dt / 2e-3 / 2.0}
    tried, chosen = _searched(errors, {"newton": 2.0, "newton-midpoint": 4.5})  # s, at 2 ms: newton the cheaper
    assert tried == [("newton", 2e-3), ("newton-midpoint", 2e-3), ("newton-midpoint", 1e-3)]
    assert chosen == ("newton-midpoint", 1e-3)


def test_a_method_aimed_far_down_is_ranked_by_the_pilots_of_its_walk_there():
    # Whole pilots: newton 19 % off at 2 ms, aimed at 0.125 ms, where its run and companion would cost 32 s and
    # the pilots still to run on the way there (0.5 ms to 62.5 us) 40 s; newton-midpoint priced at 36 s at 2 ms (the
    # sandfish's, priced over a burst of Newton's iterations at four times its cost, 9 s). It is measured before
    # newton's walk, and meets the limits at 1 ms.
    errors = {"newton-midpoint": lambda dt: 3.3 * (dt / 2e-3) ** 3.3 / 2.0, "newton": lambda dt: 18.9 * dt / 2e-3 / 2.0}
    tried, chosen = _searched(errors, {"newton": 2.0, "newton-midpoint": 36.0}, whole=True,
                              costs={"newton-midpoint": 9.0})
    assert tried == [("newton", 2e-3), ("newton-midpoint", 2e-3), ("newton-midpoint", 1e-3)]
    assert chosen == ("newton-midpoint", 1e-3)


def test_newton_is_piloted_before_newton_midpoint_priced_alike_within_the_noise_of_cpu_time():
    # Whole pilots, both methods within the limits at 2 ms: newton-midpoint's pilot goes first only where it is
    # priced cheaper than newton's by more than NEWTON_FIRST (1.5) times, and the first that meets the limits is run.
    from finrft import choice as choosing
    both = {"newton-midpoint": lambda dt: 0.5, "newton": lambda dt: 0.5}
    for midpoint, first in ((2.0 / 1.25, "newton"), (2.0 / (1.01 * choosing.NEWTON_FIRST), "newton-midpoint")):
        tried, chosen = _searched(both, {"newton": 2.0, "newton-midpoint": midpoint}, whole=True)
        assert tried == [(first, 2e-3)] and chosen == (first, 2e-3)
    # the whegs': both fail at 2 ms (they chatter), both known by their prices alone still, and at 1 ms alike again
    chatter = {m: lambda dt: None if dt > 1.5e-3 else 0.5 for m in both}
    tried, chosen = _searched(chatter, {"newton": 2.0, "newton-midpoint": 2.0 / 1.25}, whole=True)
    assert tried == [("newton", 2e-3), ("newton-midpoint", 2e-3), ("newton", 1e-3)] and chosen == ("newton", 1e-3)


def test_every_price_stops_where_it_shows_its_candidate_dearer_than_one_priced_or_one_that_met_the_limits():
    # Each price is bounded by the cheapest option priced before it, and once one candidate met the limits, by what
    # another may cost and still be measured (SAVING of it): none runs unbounded after a candidate met the limits
    # (newton-midpoint's, where newton at its step met them and its own ladder ended).
    from finrft import choice as choosing
    asked = []
    order = ("explicit", *choosing.IMPLICIT)  # as a search is given them
    prices = {"newton": 2.0, "newton-midpoint": 2.2, "explicit": 3.0}
    tried, chosen = _searched({m: lambda dt: 0.5 for m in order}, {m: prices[m] for m in order}, asked=asked)
    first = list(dict.fromkeys(a[:3] for a in asked if a[1] == 2e-3 and a[3] == 0))  # before any pilot ran
    assert sorted(a[0] for a in first) == sorted(order)
    assert [a[2] for a in first] == [min((prices[b[0]] for b in first[:i]), default=float("inf"))
                                     for i in range(len(first))]
    assert tried[0] == ("newton", 2e-3) and chosen == ("newton", 2e-3)
    after = [a for a in asked if a[3] > 0]  # newton met the limits at 2 s: the others' prices stop past SAVING of it
    assert after and all(a[2] <= choosing.SAVING * 2.0 * (1 + 1e-9) for a in after)


def test_an_explicit_step_is_walked_down_step_by_step():
    # A sled that hops out of the sand at 2 and 1 ms (75 and 79 % off its cost of transport) and settles at 0.5 ms:
    # the explicit step's error need not fall with the step, and can collapse at the next halving (the quadruped's:
    # 6.5 % off at 2 ms, 0.95 % at 1 ms). Ranked by the step a first-order error would ask for (0.03 ms), it would
    # lose to newton.
    hops = {"explicit": lambda dt: 0.01 if dt < 1e-3 else 37.0 + 2e3 * (2e-3 - dt), "newton": lambda dt: 0.3}
    tried, chosen = _searched(hops, {"explicit": 0.1, "newton": 0.5}, 3.8e-3)
    assert tried == [("explicit", 2e-3), ("explicit", 1e-3), ("explicit", 5e-4)]
    assert chosen == ("explicit", 5e-4)


def test_a_step_is_priced_by_the_cost_per_step_its_method_showed_at_two_steps(tmp_path):
    # Whole pilots at 2 and 1 ms whose cost per step goes as the square root of the step (Newton's iterations fewer
    # at shorter steps): the step at 0.5 ms costs c sqrt(0.5 ms) per step, not the 1 ms step's per step; one at
    # 0.25 ms no less (a step costs at least one iteration: the power is taken one halving on, no further).
    from finrft import choice as choosing
    chooser = _chooser(tmp_path)
    per_step = lambda h: 1e-4 * math.sqrt(h)  # noqa: E731  CPU s a step
    for h in (2e-3, 1e-3):
        chooser._rates[("newton", h)] = per_step(h) / h
        chooser._whole.add(("newton", h))
    assert chooser.predicted("newton", 5e-4) == pytest.approx(
        per_step(5e-4) / 5e-4 * 0.6 * choosing.COMPANION_COST, rel=1e-9)
    assert chooser.predicted("newton", 2.5e-4) == pytest.approx(
        per_step(5e-4) / 2.5e-4 * 0.6 * choosing.COMPANION_COST, rel=1e-9)
    chooser._whole.clear()  # a price's stretch, not a whole pilot: the nearest step's cost per step
    assert chooser.predicted("newton", 2.5e-4) == pytest.approx(
        per_step(1e-3) / 2.5e-4 * 0.6 * choosing.COMPANION_COST, rel=1e-9)


def test_a_failed_pilot_counts_by_its_price_or_not_at_all_in_predicting_other_steps(tmp_path):
    # The explicit step priced at 2 ms at 1 s of CPU a simulated second; its pilots at 2 and 1 ms fail at their
    # start, where they ran at 0.6 and 1.2 (a robot not yet bearing on the sand). The step at 0.5 ms is predicted
    # from the price at 2 ms, per step alike (4 times its rate), not from the failed pilot at 1 ms (twice 1.2).
    from finrft import choice as choosing
    from finrft.errors import SimulationUnstable
    chooser = _chooser(tmp_path, {("explicit", 2e-3): 1.0})
    rates = {2e-3: 0.6, 1e-3: 1.2}
    chooser._timed = lambda scene, span, sample=False, watch=None: (SimulationUnstable("it chatters"),
                                                                    rates[scene.sim.dt])
    for dt in rates:
        assert isinstance(chooser._run("explicit", dt), SimulationUnstable)
    assert chooser._rates[("explicit", 2e-3)] == 1.0 and not chooser._whole
    assert chooser.predicted("explicit", 5e-4) == pytest.approx(4 * 1.0 * 0.6 * choosing.COMPANION_COST, rel=1e-12)


def test_a_price_stops_where_it_shows_its_candidate_dearer_and_goes_on_where_it_comes_to_rank_first(tmp_path):
    # A candidate whose run costs 40 s of CPU a simulated second against another's 0.5 s: its price stops once its
    # timed stretch (the second half of PRICE_SHARE of the run) has cost what the other's would at the other's cost
    # (its cost then a bound below that, never a failure), and is taken further, from its start again, once the
    # other costs more.
    from finrft import choice as choosing
    chooser = _chooser(tmp_path)
    spent = []

    def timed(scene, span, share=1.0, skip=0.0, sample=False, watch=None, early=False):  # 40 s a second, timed
        reached = min((share - skip) * span, chooser.budget / 40.0)              # held to the budget
        spent.append(40.0 * reached)
        stopped = reached < (share - skip) * span * (1 - 1e-9)
        return (choosing._Enough("dearer") if stopped else None), 40.0
    chooser._timed = timed
    other = 0.5 * 0.6 * choosing.COMPANION_COST  # the other candidate's run and companion, CPU s
    assert chooser.price("explicit", 1e-5, other) >= other
    assert spent[0] == pytest.approx(other * choosing.PRICE_SHARE / 2 / choosing.COMPANION_COST, rel=1e-9)
    assert ("explicit", 1e-5) not in chooser._runs  # no failure stored for it: it may yet run
    assert chooser.price("explicit", 1e-5, other) >= other and len(spent) == 1  # not priced again while dearer
    chooser.price("explicit", 1e-5, 1e3)  # the other now dearer than its bound: priced over its whole stretch
    assert spent[1] == pytest.approx(40.0 * choosing.PRICE_SHARE / 2 * 0.6, rel=1e-9)
    assert ("explicit", 1e-5) not in chooser._bounds


def _whole(rate: float) -> float:
    """A rate's run of the sled's 0.6 s with its companion (CPU s)."""
    from finrft import choice as choosing
    return rate * 0.6 * choosing.COMPANION_COST


def test_a_price_is_scaled_by_what_its_kinds_whole_pilots_cost_over_their_prices(tmp_path):
    # Newton priced at 0.2 s a simulated second, run whole at 0.44 (2.2 times: the eel's start, its gait ramping in,
    # costs less than the rest); newton-midpoint, priced alike at 0.21, is then predicted at 0.21 x 2.2, not 0.21.
    # A second pair at 1.8 times: the geometric mean of the two, 1.99. The explicit step's price, of another kind
    # (no Newton iterations to follow the gait), stays as priced; a whole pilot's cost is its own.
    chooser = _chooser(tmp_path, {("newton", 2e-3): 0.2, ("newton-midpoint", 2e-3): 0.21, ("explicit", 1e-4): 3.0})
    chooser._rates[("newton", 2e-3)] = 0.44
    chooser._whole.add(("newton", 2e-3))  # ran whole
    assert chooser.cost("newton", 2e-3) == pytest.approx(_whole(0.44), rel=1e-12)
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.21 * 2.2), rel=1e-12)
    assert chooser.cost("explicit", 1e-4) == pytest.approx(_whole(3.0), rel=1e-12)
    chooser._priced[("newton", 1e-3)] = 0.5
    chooser._rates[("newton", 1e-3)] = 0.9
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.21 * 2.2), rel=1e-12)  # not run whole
    chooser._whole.add(("newton", 1e-3))
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.21 * math.sqrt(2.2 * 1.8)), rel=1e-12)


def test_a_newton_methods_price_is_held_within_alike_times_the_others_whole_pilot_at_its_step(tmp_path):
    # Newton priced at 0.1 s a simulated second and run whole at 0.12; newton-midpoint priced at 0.8, eight times
    # newton's price (the sandfish's, over its landing): calibrated, 0.96, but held at ALIKE x 0.12. At 1.5 times
    # newton's price it stays as calibrated; at another step, or before newton ran whole, as calibrated too.
    from finrft import choice as choosing
    chooser = _chooser(tmp_path, {("newton", 2e-3): 0.1, ("newton-midpoint", 2e-3): 0.8,
                                  ("newton-midpoint", 1e-3): 0.8})
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.8), rel=1e-12)  # newton not run whole
    chooser._rates[("newton", 2e-3)] = 0.12
    chooser._whole.add(("newton", 2e-3))
    assert chooser.calibration("newton-midpoint") == pytest.approx(1.2)
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(choosing.ALIKE * 0.12), rel=1e-12)
    assert chooser.cost("newton-midpoint", 1e-3) == pytest.approx(_whole(0.8 * 1.2), rel=1e-12)  # another step
    chooser._rates[("newton-midpoint", 2e-3)] = chooser._priced[("newton-midpoint", 2e-3)] = 0.15
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.15 * 1.2), rel=1e-12)
    chooser._rates[("newton-midpoint", 2e-3)] = chooser._priced[("newton-midpoint", 2e-3)] = 0.01
    assert chooser.cost("newton-midpoint", 2e-3) == pytest.approx(_whole(0.12 / choosing.ALIKE), rel=1e-12)


def test_an_explicit_price_stops_before_the_half_it_times_where_its_pace_shows_it_dearer(tmp_path, monkeypatch):
    # A fake CPU clock: a pilot set up in 50 s, then every 1 % of its run costs 1 s. Budget 0.1 s for the stretch it
    # times (5 % to 10 %, 5 s at its pace): held EARLY times over from the start, the explicit step's price stops at
    # its first sample past 0, its rate its pace since its first sample; a Newton method's (a landing may cost it
    # several times its gait) runs to its timed half, and stops there at its budget. With a budget of 2 s, 8 s at
    # EARLY times, its pace runs it to its timed half: the set-up is not its pace.
    from finrft import choice as choosing
    chooser = _chooser(tmp_path)
    now = [0.0]
    monkeypatch.setattr(choosing.time, "process_time", lambda: now[0])
    reached = []

    def pilot(scene, companion, progress):
        for i in range(101):
            now[0] = 50.0 + i
            reached.append(i / 100)
            progress(i / 100)
    chooser.pilot, chooser.budget = pilot, 0.1
    run, rate = chooser._timed(None, 0.6, 0.1, 0.05, early=True)
    assert isinstance(run, choosing._Enough) and run.args and reached[-1] == 0.01
    assert rate == pytest.approx(1.0 / (0.01 * 0.6), rel=1e-9)
    for early, budget, stop in ((False, 0.1, 0.06), (True, 2.0, 0.08)):
        reached.clear()
        now[0], chooser.budget = 0.0, budget
        run, _ = chooser._timed(None, 0.6, 0.1, 0.05, early=early)
        assert isinstance(run, choosing._Enough) and run.args and reached[-1] == stop


SWAY = SLED_SCENE.replace('speed = 0.02\nstroke = 0.0', 'profile = "sine"\namplitude = 0.01\nfrequency = 5.0')


def test_a_pilot_at_half_the_step_stops_where_its_speed_over_whole_periods_is_far_off_its_runs(tmp_path):
    # The sled swayed at 5 Hz (its gait's period 0.2 s; the pilots are its whole 0.6 s run, settled at 0.3 s). The
    # robot of the pilot at the step moves along x at 50 mm/s; that at half the step as far plus an offset from the
    # settling on. The companion would estimate the speed's error SAFETY / (1 - 1/2) times the difference of their
    # speeds since the settling: where that is above OFF_LIMIT times its 2 % limit (3 mm/s estimated, 0.75 mm/s
    # apart) after a whole period, the pilot stops there; at 0.5 mm/s apart, or far ahead within the period only (a
    # lurch, then back), it runs through.
    from types import SimpleNamespace

    import numpy as np

    from finrft import choice as choosing
    (tmp_path / "sled.xml").write_text(SLED)
    (tmp_path / "sway.toml").write_text(SWAY)
    d = SimpleNamespace(time=0.0, subtree_com=np.zeros((1, 3)))
    chooser = choosing.Chooser(load_scene(str(tmp_path / "sway.toml"), cls=UserScene), ErrorLimits(), None,
                               lambda s: None, 0.6, 0.6, 1, state=lambda scene: (None, d, None, None))
    scene = chooser.at("newton", 1e-3)
    assert chooser.whole and choosing.period(scene) == pytest.approx(0.2)
    times = np.linspace(0.0, 0.6, 601)
    run = SimpleNamespace(figure_values=lambda: {"com_speed_m_s": 0.05},
                          headline=lambda: (FigureLimit("com_speed_m_s", 2.0),))
    chooser._runs[("newton", 2e-3)] = run
    chooser._tracks[("newton", 2e-3)] = [(t, 0.05 * t, 0.0) for t in times]

    def stopped(offset) -> float | None:  # where the pilot at half the step stops (s), None where it runs through
        watch = chooser._off(scene, [], ("newton", 2e-3))
        for t in times:
            d.time, d.subtree_com[0, 0] = t, 0.05 * t + offset(t - 0.3)
            try:
                watch()
            except choosing.Off as off:
                assert off.off == pytest.approx(4 * abs(offset(t - 0.3)) / (t - 0.3), rel=1e-6)
                assert off.excess == pytest.approx(off.off / 1e-3, rel=1e-6)
                return t
        return None
    assert stopped(lambda s: 0.001 * max(s, 0.0)) == pytest.approx(0.5, abs=1.5e-3)
    assert stopped(lambda s: -0.0005 * max(s, 0.0)) is None
    assert stopped(lambda s: 0.01 * s if 0 < s < 0.15 else 0.0) is None


def test_a_candidate_whose_pilot_at_half_the_step_stopped_misses_and_that_pilot_runs_again_when_wanted(tmp_path):
    # The pilot at half the step stops far off (`Off`): the candidate is measured and misses the limits by its
    # estimate, and the stopped pilot is not kept: the next candidate of the method, at that step, runs it whole.
    from types import SimpleNamespace

    from finrft import choice as choosing
    chooser = _chooser(tmp_path)
    runs = []

    def timed(scene, span, share=1.0, skip=0.0, sample=False, watch=None):
        runs.append(scene.sim.dt)
        if scene.sim.dt == 1e-3 and runs.count(1e-3) == 1:
            return choosing.Off("com_speed_m_s: off", "com_speed_m_s", 0.004, 4.0), 1.0
        return SimpleNamespace(), 1.0
    chooser._timed = timed
    candidate = chooser.try_step("newton", 2e-3)
    assert candidate.measured and not candidate.passed and candidate.excess == 4.0
    assert candidate.error == {"com_speed_m_s": 0.004} and candidate.over == ["com_speed_m_s: off"]
    assert ("newton", 1e-3) not in chooser._runs and runs == [2e-3, 1e-3]
    assert not isinstance(chooser._run("newton", 1e-3), Exception) and runs == [2e-3, 1e-3, 1e-3]


BOX = """<mujoco><worldbody><body name="box" pos="0 0 -0.02"><joint type="slide" axis="{axis}"/>
  <geom type="box" size="0.02 0.01 0.015" mass="0.2"/></body></worldbody></mujoco>"""


def _box(axis: str):
    """A 0.2 kg box 40 x 20 x 30 mm, its top 5 mm below the surface, on a slide along ``axis``: its model, data and
    attached surface (li2013, v_reg 0.1 mm/s)."""
    import mujoco

    from finrft import attach
    spec = mujoco.MjSpec.from_string(BOX.format(axis=axis))
    attached = attach(spec, ["box"], backend="python", element_size=0.005)
    m = spec.compile()
    return m, mujoco.MjData(m), attached


def test_the_explicit_limit_of_a_box_dragged_through_the_sand_is_2_m_v_over_its_force():
    # The box on a slide along x, moving at 0.1 m/s: only its leading face (depths 5-35 mm, 20 mm wide) takes a
    # force, li2013's (alpha_x, alpha_z)(pi/2, 0) |z| on each element. A rate-independent force turns with the
    # velocity, so its slope across it is |F| / v: dt < 2 m v / |F|. At rest its front and back faces graze the
    # sand, and a speed of v_reg along x switches either's whole force on: dt < 2 m v_reg / (2 |F|).
    from finrft.choice import explicit_limit
    from finrft.laws import li2013
    m, d, attached = _box("1 0 0")
    d.qvel[0] = 0.1
    alpha_x, alpha_z = li2013.alpha(math.pi / 2, 0.0)
    force = math.hypot(float(alpha_x), float(alpha_z)) * 0.02 * (0.035 ** 2 - 0.005 ** 2) / 2
    assert explicit_limit(m, d, (), attached) == pytest.approx(2 * 0.2 * 0.1 / force, rel=1e-6)
    d.qvel[0] = 0.0
    assert explicit_limit(m, d, (), attached) == pytest.approx(2 * 0.2 * attached.v_reg / (2 * force), rel=1e-6)


def test_the_explicit_limit_of_a_box_free_to_rise_or_sink_is_its_faces_switch():
    # The box on a vertical slide, at rest: its bottom face (35 mm deep) takes li2013's force moving down
    # (alpha(0, pi/2)), its top (5 mm) moving up (alpha(0, -pi/2)), each switched on over v_reg of vertical speed. An
    # explicit step longer than 2 m v_reg / (their sum) lets the box's vertical velocity flip each step, and the
    # deeper face pushes harder than the shallower: the box rises (the sandfish's 10 g links, free to, rose and swam
    # 25-27 % slow at explicit steps of 8 us to 0.25 ms, their cost of transport under half the converged one).
    from finrft.choice import explicit_limit
    from finrft.laws import li2013
    m, d, attached = _box("0 0 1")
    area = 0.04 * 0.02
    down = math.hypot(*(float(a) for a in li2013.alpha(0.0, math.pi / 2))) * 0.035 * area
    up = math.hypot(*(float(a) for a in li2013.alpha(0.0, -math.pi / 2))) * 0.005 * area
    assert explicit_limit(m, d, (), attached) == pytest.approx(2 * 0.2 * attached.v_reg / (down + up), rel=1e-6)


def test_the_explicit_limit_over_a_run_ignores_a_body_creeping_and_one_reversal_but_not_the_ramp_in():
    # Two such boxes (the test above), one dragged along +x, one creeping at 2 mm/s (a foot standing in the sand):
    # each takes the same rate-independent force F, so the creeping one's limit at one instant is 2 m 2 mm/s / F,
    # the run's limit the dragged box's, 2 m v / F: at its slowest stretch, its ramp-in at 30 mm/s, not at one
    # instant's reversal (25 mm/s) inside its gait at 0.1 m/s.

    import mujoco

    from finrft import attach
    from finrft.choice import body_limits, explicit_limit, window_limit
    from finrft.laws import li2013
    spec = mujoco.MjSpec.from_string("""<mujoco><worldbody>
      <body name="a" pos="0 0 -0.02"><joint type="slide" axis="1 0 0"/>
        <geom type="box" size="0.02 0.01 0.015" mass="0.2"/></body>
      <body name="b" pos="0 0.5 -0.02"><joint type="slide" axis="1 0 0"/>
        <geom type="box" size="0.02 0.01 0.015" mass="0.2"/></body>
      </worldbody></mujoco>""")
    attached = attach(spec, ["a", "b"], backend="python", element_size=0.005)
    m = spec.compile()
    d = mujoco.MjData(m)
    alpha_x, alpha_z = li2013.alpha(math.pi / 2, 0.0)
    force = math.hypot(float(alpha_x), float(alpha_z)) * 0.02 * (0.035 ** 2 - 0.005 ** 2) / 2

    def at(t: float, v: float) -> tuple:
        d.qvel[0], d.qvel[1] = v, 0.002
        return (t, *body_limits(m, d, (), attached))
    gait = [at(0.01 * i, 0.1 if i % 10 != 5 else 0.025) for i in range(10, 100)]
    assert explicit_limit(m, d, (), attached) == pytest.approx(2 * 0.2 * 0.002 / force, rel=1e-6)  # one instant's
    assert window_limit(gait, 1.0) == pytest.approx(2 * 0.2 * 0.1 / force, rel=1e-6)
    ramp = [at(0.01 * i, 0.03) for i in range(10)]
    assert window_limit(ramp + gait, 1.0) == pytest.approx(2 * 0.2 * 0.03 / force, rel=1e-6)
    assert window_limit([], 1.0) == math.inf
    assert window_limit([at(0.0, 0.005)], 1.0) == math.inf  # nothing moves: both slower than STILL


@pytest.mark.slow  # two robots' auto runs end to end; explicit_limit itself is checked above
def test_auto_pilots_no_explicit_step_beyond_a_light_robots_limit_and_does_below_a_heavy_ones(tmp_path,
                                                                                              dear_implicit):
    # The sandfish's 10 g links, free to rise and sink, have a limit of ~3 us (their top and bottom faces' switch):
    # its explicit step is 25-27 % off at 8 us to 0.25 ms, and is not piloted at any step of its ladder.
    # The 2 kg sled's limit is ~1.1 ms (SLED): its explicit step at the scene's 1 ms is still piloted.
    from finrft.studies.frontier import battery_scene
    fish = load_scene(battery_scene("sandfish"), cls=UserScene,
                      overrides={"sim.method": "auto", "sim.duration": 0.6, "sim.settle": 0.3})
    candidates = run_robot(fish).method_choice.candidates
    skipped = [c for c in candidates if c.method == "explicit" and c.skipped.startswith("skipped: explicit limit")]
    assert skipped
    limits = [float(c.skipped.split()[3]) for c in skipped]  # as the samples stood when each was skipped
    assert all(c.dt > limit for c, limit in zip(skipped, limits)) and max(limits) < 1e-5
    assert not any(c.method == "explicit" and (c.measured or c.failed) for c in candidates)
    sled = run_robot(load_scene(_sled(tmp_path), cls=UserScene)).method_choice.candidates
    assert any(c.method == "explicit" and c.measured for c in sled)
    assert not any(c.skipped.startswith("skipped: explicit limit") and c.dt <= 0.001 for c in sled)
