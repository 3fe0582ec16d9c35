"""The package's Python API: what `import finrft` gives, what it loads, and summaries made of plain numbers."""

import json
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
