"""Scenes shared by the physics tests."""

from pathlib import Path

import pytest

from finrft.scene import Scene, preset


def face(scene) -> float:
    """A chain segment's face area x mean depth (m^3), written out: the segment's length x the chain's height
    (medium.height), at the depth of its middle (medium.depth + height / 2). A segment's law coefficients (N) are
    the scene's (N/m^3) times it."""
    chain = getattr(scene, "plate", None) or scene.fin
    m = scene.medium
    return chain.segment_length * m.height * (m.depth + m.height / 2)


@pytest.fixture(scope="session")
def paper() -> Scene:
    return preset("paper")


@pytest.fixture(scope="session")
def responsive(paper: Scene) -> Scene:
    """A plate that bends and recovers within a fraction of a stroke (light inertia, little damping), with the
    penalty stop, at a time step where its results have converged (estimated error 0.005 deg; the MuJoCo limit
    stop 0.016 deg, see test_limit_stop_holds)."""
    return paper.replace(**{"plate.segment_inertia": 1e-2, "plate.rod_inertia": 1e-2, "plate.damping": 0.2,
                            "sim.dt": 2.5e-4})


@pytest.fixture(scope="session", autouse=True)
def _energy_warning_given():
    """The presets' law feeds energy in (f_par < 0), which a run says once per process: say it before any test, so
    that no test's stderr depends on which ran first (tests of the warning give it a fresh process state)."""
    from finrft import laws
    laws._warned.append("the presets' f_par < 0")


@pytest.fixture(scope="session", autouse=True)
def _help_cache(tmp_path_factory):
    """`finrft --help` keeps the help texts it printed in the user's cache folder (finrft.cli.helps): the tests'
    go to a folder of their own, for their processes too."""
    import os
    before = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("cache"))
    yield
    if before is None:
        del os.environ["XDG_CACHE_HOME"]
    else:
        os.environ["XDG_CACHE_HOME"] = before


@pytest.fixture
def errors_only():
    """A subprocess's stderr without that once-per-process warning, for tests of other messages."""
    return lambda err: "".join(line for line in err.splitlines(keepends=True) if "feeds energy in" not in line)


def law_cases(name: str):
    """The cases of a segment law for the tests every law goes through: its test module tests/test_law_NAME.py
    defines ``twin(tmp_path)`` (scene overrides), ``DISSIPATIVE`` and ``FEEDING`` (parameters of its force)."""
    import importlib

    try:
        return importlib.import_module(f"test_law_{name}")
    except ModuleNotFoundError:
        raise AssertionError(f"segment law {name!r} has no tests/test_law_{name}.py defining twin, DISSIPATIVE "
                             f"and FEEDING") from None



def logged_generations(log) -> int:
    """Generations in a search log that another process may be replacing; 0 while it has none."""
    import h5py
    try:
        with h5py.File(log, "r") as f:
            return len(f["state/sigma"])
    except (OSError, KeyError):
        return 0


def default_ctrl_c() -> None:
    """A child's preexec_fn where a test sends it SIGINT: the signal's default disposition, which a shell that runs
    the tests in the background leaves ignored (Python then raises no KeyboardInterrupt, and Ctrl-C does nothing)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def physics_run(scene, control=None):
    """A robot run (`finrft.run_robot`) without the companion run of its error estimate: for the tests of its
    physics, at steps fine enough that the estimate would tell nothing, at a third of the cost."""
    from finrft.experiment import run
    from finrft.experiments.user_model import UserModel
    return run(UserModel.of(scene, control), scene, max_error=None, estimate_error=False)


def dragged_plate_scene(stroke: float, *, drive: str = "", **sim: object) -> str:
    """The TOML scene of a plate (the body "plate" of plate.xml, beside the scene) dragged on its slide "drag" at
    0.1 m/s for ``stroke`` (m) through li2013's generic medium (zeta 1); ``drive``: more lines of the drive, ``sim``:
    keys of the sim beside a 1 ms step."""
    lines = [f"{key} = {value!r}" if isinstance(value, str) else f"{key} = {value}" for key, value in sim.items()]
    lines = [line.replace("'", '"') for line in lines]
    return "\n".join(['[model]', 'path = "plate.xml"', 'bodies = ["plate"]', '', '[medium]', 'zeta = 1.0', '',
                      '[drive]', 'joint = "drag"', 'speed = 0.1', f'stroke = {stroke}', *([drive] if drive else []),
                      '', '[sim]', 'dt = 1e-3', *lines]) + "\n"


def settling_box(folder: Path, method: str) -> Path:
    """A 50 g box 40 x 40 x 10 mm (the body "box" of box.xml), its top at the surface of li2013's medium (zeta 1),
    settling for 0.1 s at ``method`` and a 1 ms step: the scene written into ``folder`` (box.toml) and its path."""
    (folder / "box.xml").write_text("""<mujoco model="box">
  <option integrator="implicitfast"><flag contact="disable"/></option>
  <worldbody>
    <body name="box" pos="0 0 -0.005">
      <freejoint/>
      <geom type="box" size="0.02 0.02 0.005" mass="0.05" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
""")
    scene = folder / "box.toml"
    scene.write_text(f"""[model]
path = "box.xml"
bodies = ["box"]
[medium]
law = "li2013"
zeta = 1.0
element_size = 0.005
[sim]
dt = 0.001
method = "{method}"
duration = 0.1
settle = 0.05
""")
    return scene
