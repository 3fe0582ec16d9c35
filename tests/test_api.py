"""The package's Python API: what `import finrft` gives, what it loads, and summaries made of plain numbers."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

import finrft


def _python(code: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, capture_output=True, text=True,
                          timeout=120)


def test_import_loads_neither_rerun_nor_matplotlib(tmp_path):
    done = _python("""
        import sys
        import finrft
        print(sorted(m for m in ("rerun", "matplotlib", "h5py", "cma") if m in sys.modules))
        finrft.write_rrd
        print("rerun" in sys.modules)
        """, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:2] == ["[]", "True"]


HEAVY = ("scipy", "matplotlib", "h5py", "rerun", "cma", "tqdm", "dask")


def test_version_imports_neither_the_engine_nor_the_studies(tmp_path):
    # `finrft --version` answers before the commands' parsers, whose imports took it 0.6 s of CPU
    done = _python(f"""
        import sys
        from finrft.cli import main
        try:
            main(["--version"])
        except SystemExit as exit:
            print("exit", exit.code)
        print(sorted(m for m in {HEAVY + ("mujoco", "numpy")} if m in sys.modules))
        """, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:3] == [f"finrft {finrft.__version__}", "exit 0", "[]"]


def _help(argv: list[str], cache, columns: int = 100) -> subprocess.CompletedProcess:
    """finrft's help in a process of its own, what it printed and then the heavy modules it imported."""
    code = f"""
        import sys
        from finrft.cli import main
        try:
            main({argv!r})
        except SystemExit as exit:
            assert exit.code == 0, exit.code
        print(sorted(m for m in {HEAVY + ("mujoco", "numpy")} if m in sys.modules))
        """
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cache.parent, capture_output=True,
                          text=True, timeout=120, env={**os.environ, "XDG_CACHE_HOME": str(cache),
                                                       "COLUMNS": str(columns)})


@pytest.mark.parametrize("argv", [["--help"], ["drag", "-h"], ["bench", "robots", "--help"]])
def test_help_imports_neither_the_engine_nor_the_studies(tmp_path, argv):
    # The commands' imports (MuJoCo, numpy, every experiment) took `finrft --help` 0.6-0.9 s; the help the full
    # parser printed once is printed again, as long as the package and the terminal's width are the same.
    first = _help(argv, tmp_path / "cache")
    assert first.returncode == 0, first.stderr
    assert first.stdout.splitlines()[-1] != "[]"  # the full parser, nothing kept yet
    again = _help(argv, tmp_path / "cache")
    assert again.returncode == 0, again.stderr
    assert again.stdout.splitlines()[-1] == "[]"
    assert again.stdout == first.stdout.replace(first.stdout.splitlines()[-1], "[]")


def test_a_help_kept_for_another_width_or_package_is_not_printed(tmp_path):
    wide = _help(["drag", "--help"], tmp_path / "cache", columns=140)
    narrow = _help(["drag", "--help"], tmp_path / "cache", columns=60)
    assert narrow.stdout.splitlines()[-1] != "[]" and max(map(len, narrow.stdout.splitlines())) <= 60
    assert max(map(len, wide.stdout.splitlines())) > 60
    # A kept text whose package differs (a flag added since) is not printed: its key is the package's files'.
    kept = tmp_path / "cache" / "finrft" / "helps.json"
    text = json.loads(kept.read_text())
    kept.write_text(json.dumps({"key": "an older package", "helps": {k: "stale" for k in text["helps"]}}))
    again = _help(["drag", "--help"], tmp_path / "cache", columns=60)
    assert again.stdout == narrow.stdout


@pytest.mark.parametrize("cache", ["file", "relative"])
def test_a_cache_folder_that_cannot_be_used_still_prints_the_help(tmp_path, cache):
    # XDG_CACHE_HOME at a regular file: NotADirectoryError escaped as a traceback; a relative one is to be ignored
    (tmp_path / "a_file").write_text("")
    home = str(tmp_path / "a_file") if cache == "file" else "relative_cache"
    done = subprocess.run([sys.executable, "-m", "finrft", "--help"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "XDG_CACHE_HOME": home, "HOME": str(tmp_path / "home")})
    assert done.returncode == 0 and "usage: finrft" in done.stdout and not done.stderr, done.stderr
    assert not (tmp_path / "relative_cache").exists()
    assert (tmp_path / "home" / ".cache" / "finrft" / "helps.json").exists() == (cache == "relative")


def test_the_command_lines_parser_imports_no_study_package(tmp_path):
    # Every command's flags, without what only some commands use (scipy.optimize, half the start, is the media's fit)
    done = _python(f"""
        import sys
        from finrft.cli import build_parser
        build_parser()
        print(sorted(m for m in {HEAVY} if m in sys.modules))
        """, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0] == "[]"


def test_every_export_is_documented_and_is_the_modules_own():
    import finrft.studies.fit  # importing a module of the same name must not replace the function
    from finrft.experiments.plate import simulate
    for name in finrft.__all__:
        value = getattr(finrft, name)
        assert value.__doc__ and value.__doc__.strip(), name
        assert value.__module__.startswith("finrft."), name
        assert getattr(sys.modules[value.__module__], name) is value, name
    assert finrft.simulate is simulate and callable(finrft.fit) and callable(finrft.optimize)
    assert set(finrft.__all__) <= set(dir(finrft))
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        finrft.nothing


def test_the_package_docstring_example_runs(tmp_path):
    example = finrft.__doc__.split("::\n\n", 1)[1].split("\n\n", 1)[0]
    assert "finrft.simulate(" in example
    done = _python(example, tmp_path)
    assert done.returncode == 0, done.stderr
    assert "'steps': " in done.stdout


def _plain(value) -> bool:
    if isinstance(value, dict):
        return all(type(k) is str and _plain(v) for k, v in value.items())
    if isinstance(value, list):
        return all(_plain(v) for v in value)
    return type(value) in (str, int, float, bool)


def test_summaries_and_table_rows_are_plain_numbers():
    run = finrft.simulate(finrft.preset("paper"), finrft.Drive(stroke=0.01, cycles=2))
    robot = finrft.preset("paper", finrft.RobotScene).replace(**{"gait.theta1": 0.3, "gait.theta2": -0.3})
    swims = [finrft.swim(robot, 2)]
    for value in (run.summary(), swims[0].summary(), finrft.table_rows(swims)[0]):
        assert _plain(value), value
        assert "np." not in repr(value)
        assert json.loads(json.dumps(value, allow_nan=True)).keys() == value.keys()
    assert run.summary()["steps"] == round(4 * 0.01 / 0.03 / 1e-3) and run.summary()["steps_rejected"] == 0


def test_run_many_from_a_script_without_the_main_guard_says_what_to_do(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text("import finrft\n"
                      "finrft.run_many([(finrft.preset('paper'), finrft.Drive(stroke=0.001))] * 2, workers=2)\n")
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert 'call it under `if __name__ == "__main__":` (each worker imports the script again).' in done.stderr


def test_load_scene_defaults_to_what_every_command_runs():
    # The API and the command line start from the same scene: the physical presets (the paper's one flag away).
    import argparse
    from finrft.experiments.flags import preset_name
    command = preset_name(argparse.Namespace(scene=None, preset=None))
    for cls in (finrft.Scene, finrft.RobotScene):
        assert finrft.load_scene(cls=cls) == finrft.preset(command, cls) == finrft.preset("physical", cls)
        assert finrft.load_scene(cls=cls) != finrft.load_scene(preset_name="paper", cls=cls)
    # a scene without presets takes its schema's defaults, as `finrft intrude` without --scene does
    assert finrft.load_scene(cls=finrft.IntrusionScene) == finrft.scene.scene_from_dict({}, finrft.IntrusionScene)


# One contract: the API checks what it is given as the command line does, and raises the documented family.

@pytest.mark.parametrize("kwargs, message", [
    ({"start": float("nan")}, "drive start must be finite"), ({"start": float("inf")}, "drive start must be finite"),
    ({"speed": "3"}, r"drive speed must be a number \(m/s\), got '3'"), ({"speed": True}, "must be a number"),
    ({"stroke": -1.0}, "drive stroke must be > 0"), ({"cycles": 1.5}, "drive cycles must be a whole number"),
    ({"cycles": 0}, "drive cycles must be >= 1"), ({"attack_deg": float("nan")}, "attack_deg must be finite"),
    ({"kind": "spin"}, "drive kind must be one of drag, rotate")])
def test_a_drive_refuses_what_the_cli_would(kwargs, message):
    with pytest.raises(finrft.SceneError, match=message):
        finrft.Drive(**kwargs)


def test_numpy_scalars_are_numbers_to_the_drive_and_the_scene():
    import numpy as np
    drive = finrft.Drive(speed=np.float32(0.05), stroke=np.float64(0.1), cycles=np.int64(2))
    assert type(drive.speed) is float and type(drive.cycles) is int and drive.duration == pytest.approx(8.0)
    json.dumps(vars(drive))  # written out with every result file
    scene = finrft.Scene().replace(**{"sim.dt": np.float64(2e-4), "plate.segments": np.int64(4)})
    assert (scene.sim.dt, scene.plate.segments) == (2e-4, 4) and type(scene.plate.segments) is int
    with pytest.raises(finrft.SceneError, match="plate.segments must be a whole number"):
        finrft.Scene().replace(**{"plate.segments": np.float64(4.0)})


def test_experiments_refuse_the_wrong_scene_or_arguments_before_running():
    with pytest.raises(finrft.SceneError, match=r"the scene must be a finrft.Scene .*got str 'paper'"):
        finrft.simulate("paper", finrft.Drive())
    with pytest.raises(finrft.SceneError, match="the scene must be a finrft.RobotScene"):
        finrft.swim(finrft.Scene())
    with pytest.raises(finrft.SceneError, match="swim cycles must be a whole number >= 1, got 1.5"):
        finrft.swim(finrft.RobotScene(), 1.5)
    with pytest.raises(finrft.SceneError, match="drive must be a finrft.Drive"):
        finrft.simulate(finrft.Scene(), "drag")


def test_write_h5_refuses_an_existing_file_as_the_cli_does(tmp_path):
    run = finrft.simulate(finrft.preset("physical"), finrft.Drive(stroke=0.01), estimate_error=False)
    path = tmp_path / "run.h5"
    path.write_text("keep")
    (tmp_path / "link.h5").symlink_to(tmp_path / "missing.h5")
    for target in (path, tmp_path / "link.h5"):
        with pytest.raises(finrft.SceneError, match="exists: choose a new file, or pass force=True"):
            finrft.write_h5(run, target)
    assert path.read_text() == "keep" and not (tmp_path / "missing.h5").exists()
    finrft.write_h5(run, path, force=True)
    assert path.read_bytes()[:4] == b"\x89HDF"
    with pytest.raises(finrft.SceneError, match="written from a finrft.Result"):
        finrft.write_h5("run", tmp_path / "new.h5")


def test_python_backend_runs_in_threads_as_they_run_alone():
    """Each run's callback is served for its own model: runs in threads give, bit for bit, what they give one after
    another, and MuJoCo's callbacks are back as they were afterwards."""
    from concurrent.futures import ThreadPoolExecutor

    import mujoco
    import numpy as np
    base = finrft.preset("physical").replace(**{"sim.backend": "python"})
    # three runs on three threads at once, each short: the stroke bends the plate enough to tell them apart
    jobs = [(base.replace(**{"plate.stiffness": 0.3 + 0.2 * i}), finrft.Drive(stroke=0.005)) for i in range(3)]
    alone = [finrft.simulate(s, d, estimate_error=False).segment_angle for s, d in jobs]
    with ThreadPoolExecutor(3) as pool:
        threaded = list(pool.map(lambda job: finrft.simulate(*job, estimate_error=False).segment_angle, jobs))
    assert all(np.array_equal(a, b) for a, b in zip(alone, threaded))
    assert len({a[-1, -1] for a in alone}) == len(jobs)  # the stiffness shows: each run had its own forces
    assert mujoco.get_mjcb_passive() is None and mujoco.get_mjcb_control() is None


@pytest.mark.parametrize("call, message", [
    (lambda: finrft.run(None, finrft.Scene()), "the experiment must be a finrft.Experiment"),
    (lambda: finrft.load_scene(overrides="sim.dt=1"), "overrides must map dotted keys to values"),
    (lambda: finrft.to_toml(3), "to_toml: a scene is written"),
    (lambda: finrft.run_many("abc"), r"every job is a \(finrft.Scene, finrft.Drive\) pair"),
    (lambda: finrft.run_experiments([finrft.PlateTest(finrft.Drive())]), "every job is an .experiment, scene. pair"),
    (lambda: finrft.map_jobs(abs, [1, 2], workers="2"), "workers: from 1 to 1024 processes"),
    (lambda: finrft.map_jobs(abs, [1, 2], workers=2.5), "workers: from 1 to 1024"),
    (lambda: finrft.map_jobs(abs, [1], workers=-1), "workers: from 1 to 1024"),
    (lambda: finrft.simulate(finrft.Scene(), finrft.Drive(stroke=0.01), max_error=0.5),
     "max_error must be a finrft.convergence.ErrorLimits"),
    (lambda: finrft.convergence.ErrorLimits(angle_deg=float("nan")), "max_error angle_deg must be finite"),
    (lambda: finrft.convergence.ErrorLimits.uniform(0), "max_error angle_deg must be > 0 degrees"),
    (lambda: finrft.convergence.ErrorLimits(eta_points="1"), "max_error eta_points must be a number"),
    (lambda: finrft.optimize(None), "the scene must be a finrft.RobotScene"),
    (lambda: finrft.optimize(finrft.RobotScene(), variables="gait.theta1"), "a list of finrft.Variable"),
    (lambda: finrft.optimize(finrft.RobotScene(), max_error=None), "max_error must be"),
    (lambda: finrft.optimize(finrft.RobotScene(), variables=[finrft.Variable("gait.theta1", "0", 1.0)]),
     "bounds of gait.theta1 must be numbers"),
    (lambda: finrft.resolve_params("b,k"), "the fitted parameters must be a list of names"),
])
def test_the_api_refuses_wrong_kinds_of_argument_in_the_family(call, message):
    # each of these once ended in a raw AttributeError, TypeError or ValueError from deep inside
    with pytest.raises(finrft.SceneError, match=message):
        call()


def test_fit_checks_its_data_and_variables_as_optimize_does(tmp_path):
    from finrft.studies.fit import simulated_drag
    scene = finrft.preset("physical")
    drag = simulated_drag(scene, 0.03, 0.005)
    four = simulated_drag(scene.replace(**{"plate.segments": 4}), 0.03, 0.005)
    damping = finrft.Variable("plate.damping", 0.01, 0.1)
    for data, variables, message in (
            ([], [damping], "at least one drag to fit"), (drag, [damping], "a list of drags"),
            ([drag, four], [damping], "has 4 segments, the scene 3"),
            ([drag], [finrft.Variable("plate.damping", 0.1, 0.01)], r"lower \(0.1\) must be below upper \(0.01\)"),
            ([drag], [finrft.Variable("plate.damping", 0.1, 0.1)], "must be below upper"),
            ([drag], [damping, damping], "plate.damping is listed twice"), ([drag], [], "at least one variable")):
        # the inverted bounds and the twice-listed key once ran a search to the end, exit 0
        with pytest.raises(finrft.SceneError, match=message):
            finrft.fit(scene, data, variables, budget=2, workers=1)
    with pytest.raises(finrft.SceneError, match="the scene must be a finrft.Scene"):
        finrft.fit(finrft.RobotScene(), [drag], [damping], budget=2, workers=1)
    with pytest.raises(finrft.SceneError, match="cannot lock search log .*No such file"):
        finrft.fit(scene, [drag], [damping], budget=2, workers=1, log=tmp_path / "none" / "fit.h5")
    assert not any(tmp_path.iterdir())
