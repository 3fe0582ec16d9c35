"""The chatter probe (`stepping.ChatterProbe`) on whole robot runs: a run whose force chatters most of the time stops
as it happens, within a second of simulated time of the chatter's onset, whatever its duration; a body at rest on the
medium kicked into a hopping limit cycle (no flip every step) stops like it; chatter that comes and goes and leaves
the figures where finer steps put them is reported, not refused."""

import math
import re

import mujoco
import numpy as np
import pytest

import finrft
from finrft.errors import Chatter
from finrft.experiments.user_model import example
from finrft.scene import UserScene, load_scene
from conftest import physics_run

BLOCK = """<mujoco model="block">
  <option><flag contact="disable"/></option>
  <worldbody>
    <body name="block"><freejoint/><geom type="box" size="0.03 0.03 0.015" mass="0.5"/></body>
  </worldbody>
</mujoco>"""

BLOCK_SCENE = """[model]
path = "block.xml"
bodies = ["block"]
[medium]
law = "li2013"
surface_z = 0.0
element_size = 0.005
[sim]
duration = 2.0
settle = 1.0
record_dt = 0.01
"""


def reached(scene: UserScene) -> tuple[float, str]:
    """How far (s of simulated time, to its last recorded instant) a run got, and its Chatter's message ("" when it
    finished)."""
    done = [0.0]
    try:
        finrft.run(finrft.UserModel.of(scene), scene, progress=lambda f: done.__setitem__(0, f), estimate_error=False)
    except Chatter as exc:
        return done[0] * scene.sim.duration, str(exc)
    return scene.sim.duration, ""


def test_a_chattering_run_stops_within_a_second_of_its_onset():
    """The sand-swimmer's 10 g links at MuJoCo's explicit step of 0.5 ms, 100 times past their explicit limit
    (docs/guide/robots.md: they chatter down to 6.6 us), over 20 s: the run stops within a second of simulated time
    of the onset its message names, long before its end (the probe that judged the run after its end took all 20
    s)."""
    scene = load_scene(example("sand_swimmer"), cls=UserScene,
                       overrides={"sim.method": "explicit", "sim.dt": 5e-4, "sim.duration": 20.0})
    t, message = reached(scene)
    onset = float(re.search(r"chatters at t = ([0-9.e+-]+) s", message).group(1))
    assert "reduce sim.dt" in message
    assert onset <= t <= onset + 1.0 and t < 3.0


@pytest.fixture
def block(tmp_path):
    (tmp_path / "block.xml").write_text(BLOCK)
    (tmp_path / "block.toml").write_text(BLOCK_SCENE)
    return lambda method, dt: load_scene(str(tmp_path / "block.toml"), cls=UserScene,
                                         overrides={"sim.method": method, "sim.dt": dt})


def test_a_block_hopping_at_rest_is_caught_and_a_resolved_rest_carries_its_weight(block):
    """A 0.5 kg block (60 x 60 x 30 mm) put into the sand half its height deep. With MuJoCo's step at 0.1 ms it
    settles into a limit cycle: one step's force (~40 N, 8 times its weight) kicks it up by ~7 mm/s, and it falls
    back at g over the next 5-8 steps until it moves down again (mean |v_z| 2.4 mm/s, 24 times li2013's v_reg), so
    no flip every step: the probe that looked for those passed it, reporting a mean force of 6.07 N for its 4.905 N
    weight. It stops within a second. Newton's step at 1 ms rests it: the medium's mean force carries its weight to
    1 %, and nothing chatters."""
    t, message = reached(block("explicit", 1e-4))
    assert message and t < 1.0
    run = physics_run(block("newton", 1e-3))
    s = run.summary()
    weight = 0.5 * 9.81
    assert s["medium_force_N"][2] == pytest.approx(weight, rel=0.01)
    assert np.linalg.norm(s["com_velocity_m_s"]) < 1e-4     # at rest: creep at about li2013's v_reg, 0.1 mm/s
    assert s["chatter"] is None


@pytest.mark.slow  # two hexapod runs of 2 s, one at 0.2 ms
def test_chatter_that_leaves_the_figures_is_reported_not_refused():
    """The hexapod at MuJoCo's explicit step of 0.2 ms chatters as its legs land (the first 0.3 s) and at some strikes
    after (6 % of the probes): its speed lies within 1 % of the implicit run's at its default numerics, so it runs
    through, and reports the chatter it saw."""
    base = load_scene(example("hexapod"), cls=UserScene, overrides={"sim.duration": 2.0})
    explicit = physics_run(base.replace(**{"sim.method": "explicit", "sim.dt": 2e-4})).summary()
    implicit = physics_run(base).summary()
    speed = [math.hypot(*s["com_velocity_m_s"][:2]) for s in (explicit, implicit)]
    assert speed[0] == pytest.approx(speed[1], rel=0.01)
    assert 0 < explicit["chatter"]["share"] < 0.5 and explicit["chatter"]["first_s"] < 0.3
