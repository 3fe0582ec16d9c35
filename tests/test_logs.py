"""Optimisation and fit logs: resumed after a real SIGINT or SIGKILL they give the uninterrupted run bit for bit,
they hold only plain numbers and text, each command names the other's logs, a resumed run keeps its seed and may
extend its budget, and Ctrl-C exits 130 (SIGTERM 143) with one line."""

import ast
import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import default_ctrl_c, logged_generations

import finrft
import finrft.scene
from finrft.studies.fit import read_drag, simulated_drag, write_drag
from finrft.cli import main
from finrft.scene import preset

SEED, BUDGET = "3", "34"  # 7 gaits a generation; CMA-ES stops at 35
# The paper robot at a faster gait (~8 ms an evaluation).
OPTIMIZE = ["optimize", "--preset", "paper", "--seed", SEED, "--workers", "1", "--set", "gait.omega=3"]
FIT = ["fit", "--preset", "paper", "--params", "b", "--seed", "2", "--budget", "40", "--set", "sim.dt=0.002",
       "--workers", "1"]


def _interrupt(argv: list[str], log: Path, sig: int, workers_too: bool = False) -> subprocess.CompletedProcess:
    """Run ``finrft argv`` and send it ``sig`` once its log holds two generations (to its whole process group,
    as a terminal's Ctrl-C, with ``workers_too``)."""
    # Outside the repository: from its root `python -m finrft` would import the source tree, not the installed package.
    proc = subprocess.Popen([sys.executable, "-m", "finrft", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, cwd=log.parent, preexec_fn=default_ctrl_c)
    deadline = time.monotonic() + 60
    while logged_generations(log) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    (os.killpg if workers_too else os.kill)(proc.pid, sig)
    out, err = proc.communicate(timeout=60)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def _contents(log: Path) -> tuple[dict, dict]:
    """Every dataset (name -> (dtype, values)) and root attribute of a log but its creation time (and the digest,
    which covers it)."""
    datasets = {}
    with h5py.File(log, "r") as f:
        f.visititems(lambda name, obj: datasets.__setitem__(name, (obj.dtype, obj[()], dict(obj.attrs)))
                     if isinstance(obj, h5py.Dataset) else None)
        attrs = {k: v for k, v in f.attrs.items() if k not in ("created_utc", "digest")}
    return datasets, attrs


def _assert_same_log(log: Path, reference: Path) -> None:
    datasets, attrs = _contents(log)
    ref_datasets, ref_attrs = _contents(reference)
    assert datasets.keys() == ref_datasets.keys()
    for name, (dtype, values, ds_attrs) in ref_datasets.items():
        assert datasets[name][0] == dtype, name
        np.testing.assert_array_equal(datasets[name][1], values, err_msg=name, strict=True)
        assert datasets[name][2] == ds_attrs
    assert attrs.keys() == ref_attrs.keys()
    for key, value in ref_attrs.items():
        np.testing.assert_array_equal(attrs[key], value, err_msg=key)


def _json(capsys) -> dict:
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    summary.pop("wall_s")
    return summary


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Path, dict]:
    """The uninterrupted optimisation: its log and JSON summary."""
    log = tmp_path_factory.mktemp("reference") / "optimize.h5"
    with contextlib.redirect_stdout(io.StringIO()) as out:
        assert main([*OPTIMIZE, "--budget", BUDGET, "--out", str(log), "--json"]) == 0
    summary = json.loads(out.getvalue().strip().splitlines()[-1])
    summary.pop("wall_s")
    return log, summary


@pytest.fixture(scope="module")
def drag_data(tmp_path_factory) -> Path:
    """A short simulated drag of a plate with b = 0.8, to fit b to."""
    path = tmp_path_factory.mktemp("data") / "v20.csv"
    truth = preset("paper").replace(**{"plate.damping": 0.8, "sim.dt": 0.002})
    write_drag(path, simulated_drag(truth, 0.02, 0.03), "simulated, b = 0.8")
    return path


# Each is an optimisation in a process of its own: SIGTERM takes SIGINT's path (finrft.cli turns it into Ctrl-C) and
# a log cut by SIGKILL is the fit's below, so those two run with the slow studies.
@pytest.mark.parametrize("sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow),
                                 pytest.param(signal.SIGKILL, marks=pytest.mark.slow)])
def test_optimize_resumes_after_a_real_signal_bit_for_bit(tmp_path, capsys, reference, sig, errors_only):
    reference, expected = reference
    log = tmp_path / "run.h5"
    done = _interrupt([*OPTIMIZE, "--budget", BUDGET, "--out", str(log)], log, sig)
    generations = logged_generations(log)
    assert 2 <= generations < expected["generations"]
    if sig != signal.SIGKILL:  # SIGTERM as Ctrl-C, with its own status
        assert done.returncode == 128 + sig
        assert errors_only(done.stderr) == (f"finrft: interrupted after {generations} generations; continue with: "
                                            f"finrft optimize --resume {log}\n")
    else:
        assert done.returncode == -signal.SIGKILL
    assert main(["optimize", "--resume", str(log), "--json"]) == 0
    assert _json(capsys) == expected
    _assert_same_log(log, reference)


# a fit run twice, once cut by SIGKILL: with the slow studies
@pytest.mark.slow
def test_fit_resumes_after_sigkill_bit_for_bit(tmp_path, capsys, drag_data):
    reference = tmp_path / "reference.h5"
    assert main([*FIT, "--data", str(drag_data), "--out", str(reference), "--json"]) == 0
    expected = _json(capsys)
    assert expected["params"]["plate.damping"] == pytest.approx(0.8, rel=0.02)
    log = tmp_path / "run.h5"
    done = _interrupt([*FIT, "--data", str(drag_data), "--out", str(log)], log, signal.SIGKILL)
    assert done.returncode == -signal.SIGKILL and 2 <= logged_generations(log) < logged_generations(reference)
    drag_data.rename(drag_data.with_suffix(".moved"))  # the log holds the data: the file is not needed
    try:
        assert main(["fit", "--resume", str(log), "--json"]) == 0
    finally:
        drag_data.with_suffix(".moved").rename(drag_data)
    assert _json(capsys) == expected
    _assert_same_log(log, reference)
    with h5py.File(log) as f:
        assert f.attrs["objective_units"] == "deg^2" and f["cost"].attrs["units"] == "deg^2"
        np.testing.assert_array_equal(f["data/0/angles"][()], read_drag(drag_data).angles)


@pytest.mark.slow  # a search on two worker processes beside its parent: all cores for seconds
def test_ctrl_c_reaches_no_worker(tmp_path, errors_only):
    # Ctrl-C in a terminal signals the whole process group: the pool's workers stay quiet, the parent reports.
    log = tmp_path / "run.h5"
    done = _interrupt(["optimize", "--preset", "paper", "--workers", "2", "--out", str(log)], log, signal.SIGINT,
                      workers_too=True)
    assert done.returncode == 130
    err = errors_only(done.stderr)
    assert err.startswith("finrft: interrupted after ") and len(err.splitlines()) == 1
    assert done.stderr.count("feeds energy in") == 1  # the parent's warning, once: the workers say nothing
    assert logged_generations(log) >= 2


def test_ctrl_c_without_a_log(monkeypatch, capsys):
    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sys.modules["finrft.studies.optimize"], "swim", interrupt)  # finrft.optimize is the function
    assert main(["optimize", "--workers", "1"]) == 130
    assert capsys.readouterr().err == ("finrft: interrupted; nothing was logged (--out LOG.h5 makes a run "
                                       "resumable)\n")
    monkeypatch.setattr("finrft.cli.run.run_experiment", interrupt)
    assert main(["drag", "--distance", "5"]) == 130
    assert capsys.readouterr().err == "finrft: interrupted\n"


# three searches: with the slow studies
@pytest.mark.slow
def test_resumed_run_keeps_its_seed_and_extends_its_budget(tmp_path, capsys, reference):
    reference, expected = reference
    log = tmp_path / "run.h5"
    assert main([*OPTIMIZE, "--budget", "27", "--out", str(log), "--json"]) == 0
    assert _json(capsys)["evaluations"] == 28
    before = log.read_bytes()
    for argv, named in ((["--seed", "4"], f"seed 4 differs from the seed of {log}, 3"),
                        (["--set", "sim.dt=0.001"], "--set cannot be given with --resume")):
        assert main(["optimize", "--resume", str(log), *argv]) == 2
        err = capsys.readouterr().err
        assert named in err and len(err.splitlines()) == 1
        assert log.read_bytes() == before
    # Without --budget the logged budget stands: nothing is left to do.
    assert main(["optimize", "--resume", str(log), "--json"]) == 0
    summary = _json(capsys)
    assert (summary["seed"], summary["budget"], summary["evaluations"]) == (3, 27, 28)
    # The same seed may be given; --budget is the new total, and the run goes on as if it had had it from the start.
    assert main(["optimize", "--resume", str(log), "--seed", SEED, "--budget", BUDGET, "--json"]) == 0
    assert _json(capsys) == expected
    _assert_same_log(log, reference)


def test_each_command_names_the_other_logs(tmp_path, capsys, drag_data):
    fit_log, optimize_log, old = tmp_path / "fit.h5", tmp_path / "optimize.h5", tmp_path / "old.h5"
    assert main([*FIT, "--budget", "4", "--data", str(drag_data), "--out", str(fit_log)]) == 0
    assert main([*OPTIMIZE, "--budget", "7", "--out", str(optimize_log)]) == 0
    with h5py.File(old, "w") as f:
        f.attrs["schema"] = "finrft.optimize/1"
    capsys.readouterr()
    for argv, message in (
            (["optimize", "--resume", str(fit_log)],
             f"{fit_log} is a finrft fit log; continue it with finrft fit --resume {fit_log}"),
            (["fit", "--resume", str(optimize_log)],
             f"{optimize_log} is a finrft optimisation log; continue it with finrft optimize --resume {optimize_log}"),
            (["optimize", "--resume", str(old)], "older format (finrft.optimize/1)"),
            (["fit", "--resume", str(fit_log), "--data", str(drag_data)], "--data cannot be given with --resume"),
            (["fit", "--params", "b"], "--data is required")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("dataset,named", [("cost", "differs from its logged state after generation 0"),
                                           ("unit", "generation 0 asks other points than logged")])
def test_a_log_that_does_not_replay_is_refused(tmp_path, capsys, dataset, named):
    # What a log written by another pycma would look like: the rebuilt optimiser cannot reach the logged state.
    from finrft.studies import searchlog
    log = tmp_path / "run.h5"
    assert main([*OPTIMIZE, "--budget", "13", "--out", str(log)]) == 0
    with h5py.File(log, "a") as f:
        f[dataset][0] = -f[dataset][0]  # the best of its generation, or outside the bounds
        f.attrs["digest"] = searchlog.digest(f)  # as the other version would have written it
    capsys.readouterr()
    assert main(["optimize", "--resume", str(log)]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.splitlines()) == 1


def test_logs_hold_plain_numbers_and_text(tmp_path, drag_data):
    logs = [tmp_path / "optimize.h5", tmp_path / "fit.h5"]
    assert main([*OPTIMIZE, "--budget", "7", "--out", str(logs[0])]) == 0
    assert main([*FIT, "--budget", "4", "--data", str(drag_data), "--out", str(logs[1])]) == 0
    for log in logs:
        with h5py.File(log, "r") as f:
            for key in ("finrft_version", "mujoco_version", "numpy_version", "cma_version", "created_utc",
                        "objective", "objective_units", "scene_toml"):
                assert isinstance(f.attrs[key], str) and f.attrs[key], key
            assert isinstance(f.attrs["seed"], np.integer) and isinstance(f.attrs["budget"], np.integer)
            for value in f.attrs.values():
                assert isinstance(value, (str, np.integer, np.floating)) or all(isinstance(v, str) for v in value)
            datasets = []
            f.visititems(lambda name, obj: datasets.append(obj) if isinstance(obj, h5py.Dataset) else None)
            for ds in datasets:
                # numbers as numbers: no bytes, strings or opaque blobs among the data
                assert ds.dtype.kind in "iuf" and ds.dtype != np.uint8, ds.name
                assert ds.attrs["units"] and ds.attrs["description"], ds.name


def test_the_package_never_pickles():
    forbidden = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "shelve", "marshal", "joblib"}
    for path in Path(finrft.__file__).parent.glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                names = {(node.module or "").split(".")[0]}
            elif isinstance(node, ast.keyword):
                assert node.arg != "allow_pickle", path.name
                continue
            else:
                continue
            assert not names & forbidden, f"{path.name} imports {names & forbidden}"


def test_the_search_owns_its_random_numbers():
    # pycma's default draws from numpy's global generator; a caller drawing from it too must not change the search.
    from finrft.studies.optimize import Variable, optimize
    scene = preset("paper", finrft.RobotScene).replace(**{"gait.omega": 3.0})
    variables = [Variable("gait.theta1", 0.5, 1.5)]
    plain = optimize(scene, variables=variables, budget=12, seed=5, workers=1)
    np.random.seed(0)
    busy = optimize(scene, variables=variables, budget=12, seed=5, workers=1,
                    on_generation=lambda *_: np.random.standard_normal(3))
    assert busy.best == plain.best and busy.best_cost_per_generation == plain.best_cost_per_generation
