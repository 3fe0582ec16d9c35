"""Processes and files under pre-emption and concurrency: a multi-worker search killed by any signal leaves no
process and closes its caller's pipe, SIGTERM and SIGHUP act as Ctrl-C does (and the run resumes bit for bit),
logs are owned by one run, checked against their digest and refused in one line when damaged, outputs appear only
where nothing is, and every file read and number given is bounded before use."""

import contextlib
import io
import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import logged_generations

from finrft import files
from finrft.cli import main
from finrft.errors import SceneError, UsageError
from finrft.studies import searchlog
from finrft.studies.optimize import MAX_SEED, Variable, optimize
from finrft.scene import preset

# The paper robot at a faster gait (~8 ms an evaluation), as tests/test_logs.py.
OPTIMIZE = ["optimize", "--preset", "paper", "--seed", "3", "--set", "gait.omega=3"]
FIT = ["fit", "--preset", "paper", "--params", "b", "--seed", "2", "--set", "sim.dt=0.002"]
DATA = Path(__file__).resolve().parents[1] / "finrft" / "data" / "plate_drag" / "origami_v30.csv"


def _session(sid: int) -> list[int]:
    """The live processes of session ``sid`` (a run started in a session of its own, its workers and helpers)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                found.append(int(entry))
    return found


def _read_to_eof(stream, timeout: float) -> bytes | None:
    """All a pipe gives until its writers close it; None when it is still open after ``timeout`` s."""
    data, deadline = b"", time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([stream], [], [], 0.1)
        if ready:
            chunk = os.read(stream.fileno(), 65536)
            if not chunk:
                return data
            data += chunk
    return None


def _start(argv: list[str], cwd: Path) -> subprocess.Popen:
    # From outside the repository: there `python -m finrft` would import the source tree, not the installed package.
    return subprocess.Popen([sys.executable, "-m", "finrft", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, cwd=cwd)


def _signal_mid_run(argv: list[str], log: Path, sig: int, group: bool = False) -> tuple[subprocess.Popen, str]:
    """Start ``finrft argv`` (workers: 2), send ``sig`` once its log holds two generations (to its process group
    with ``group``, as a scheduler's pre-emption does), then check that no process of it outlives it by 5 s and
    that its pipes close; its stderr."""
    proc = _start([*argv, "--workers", "2", "--out", str(log)], log.parent)
    deadline = time.monotonic() + 120
    while logged_generations(log) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be signalled"
    assert len(_session(proc.pid)) >= 3  # the parent, its workers (and the resource tracker)
    (os.killpg if group else os.kill)(proc.pid, sig)
    proc.wait(timeout=60)
    deadline = time.monotonic() + 5
    while _session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = _session(proc.pid)
    for pid in left:  # nothing may outlive the test, whatever it finds
        os.kill(pid, signal.SIGKILL)
    assert not left, f"processes of the run outlived it: {left}"
    out, err = _read_to_eof(proc.stdout, 3), _read_to_eof(proc.stderr, 3)
    assert out is not None and err is not None, "the caller's pipe stayed open"
    return proc, err.decode()


# SIGTERM and SIGHUP take Ctrl-C's path, which test_logs sends to the whole group; each is a whole optimisation
# in processes of its own, so all four run with the slow studies (SIGKILL: no handler at all)
@pytest.mark.parametrize("sig,group", [pytest.param(signal.SIGKILL, False, marks=pytest.mark.slow),
                                       pytest.param(signal.SIGTERM, False, marks=pytest.mark.slow),
                                       pytest.param(signal.SIGHUP, False, marks=pytest.mark.slow),
                                       pytest.param(signal.SIGTERM, True, marks=pytest.mark.slow)])
def test_optimize_workers_end_with_their_parent(tmp_path, sig, group, errors_only):
    log = tmp_path / "run.h5"
    proc, err = _signal_mid_run([*OPTIMIZE, "--budget", "1000"], log, sig, group)
    if sig == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL and errors_only(err) == ""
    else:
        # as Ctrl-C: one line with the resume hint, exit status 128 + sig, and neither lock nor temporary file left
        assert proc.returncode == 128 + sig
        assert errors_only(err) == (f"finrft: interrupted after {logged_generations(log)} generations; continue with: "
                                    f"finrft optimize --resume {log}\n")
        assert [p.name for p in tmp_path.iterdir()] == ["run.h5"]
    searchlog.read(log, searchlog.OPTIMIZE)  # a complete log, its digest intact


@pytest.mark.slow  # the optimisation's workers end with their parent (above); the fit's pool is the same
def test_fit_workers_end_with_their_parent(tmp_path, errors_only):
    log = tmp_path / "fit.h5"
    proc, err = _signal_mid_run([*FIT, "--budget", "1000", "--data", str(DATA)], log, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL and errors_only(err) == ""


# two searches each; the fast suite resumes after SIGINT bit for bit (test_logs), and SIGTERM and SIGHUP take its path
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_resume_after_sigterm_and_sighup_is_bit_identical(tmp_path, capsys, sig):
    reference = tmp_path / "reference.h5"
    budget = ["--budget", "34", "--workers", "1"]
    assert main([*OPTIMIZE, *budget, "--out", str(reference), "--json"]) == 0
    expected = json.loads(capsys.readouterr().out.splitlines()[-1])
    log = tmp_path / "run.h5"
    proc = _start([*OPTIMIZE, *budget, "--out", str(log)], tmp_path)
    while logged_generations(log) < 2 and proc.poll() is None:
        time.sleep(0.01)
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == 128 + sig
    assert 2 <= logged_generations(log) < expected["generations"]
    assert main(["optimize", "--resume", str(log), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    for name, value in expected.items():
        assert name == "wall_s" or summary[name] == value, name
    with h5py.File(log) as a, h5py.File(reference) as b:
        for name in ("x", "cost", "eta", "state/C", "state/rng_key"):
            np.testing.assert_array_equal(a[name][()], b[name][()], strict=True)


@pytest.mark.slow  # two searches at once; a log in use is refused in the fast suite (below)
def test_two_runs_on_one_new_log_one_refuses(tmp_path):
    log = tmp_path / "l.h5"
    runs = [_start([*OPTIMIZE, "--budget", "21", "--workers", "1", "--out", str(log)], tmp_path) for _ in range(2)]
    done = [(run.wait(timeout=120), run.stderr.read().decode()) for run in runs]
    assert sorted(code for code, _ in done) == [0, 2]
    refused = next(err for code, err in done if code == 2)
    lines = [line for line in refused.splitlines() if "feeds energy in" not in line]
    assert len(lines) == 1 and ("is in use by another run" in lines[0] or "exists" in lines[0])
    assert searchlog.read(log, searchlog.OPTIMIZE)[1]["cost"].data.size >= 21


def test_a_log_in_use_is_refused_and_left_alone(tmp_path, capsys):
    log = tmp_path / "l.h5"
    assert main([*OPTIMIZE, "--budget", "7", "--workers", "1", "--out", str(log)]) == 0
    before = log.read_bytes()
    capsys.readouterr()
    with files.locked(log, "search log"):  # another run owns it
        for argv in (["optimize", "--resume", str(log), "--budget", "14"],
                     [*OPTIMIZE, "--budget", "7", "--out", str(log), "--force"]):
            assert main(argv) == 2
            err = capsys.readouterr().err
            assert f"search log {log} is in use by another run (process {os.getpid()})" in err
            assert len(err.splitlines()) == 1
    assert log.read_bytes() == before
    assert main(["optimize", "--resume", str(log), "--budget", "14"]) == 0  # free again
    assert not (tmp_path / ".l.h5.lock").exists()


def test_a_killed_writers_temporary_file_is_removed_by_the_next_run(tmp_path):
    gone = subprocess.Popen(["true"])  # a pid whose process is over
    gone.wait()
    dead = tmp_path / f".l.{gone.pid}-0123456789ab.tmp.h5"
    live = tmp_path / f".l.{os.getpid()}-0123456789ab.tmp.h5"
    other = tmp_path / f".m.{gone.pid}-0123456789ab.tmp.h5"
    for path in (dead, live, other):
        path.write_bytes(b"partial")
    assert main([*OPTIMIZE, "--budget", "7", "--workers", "1", "--out", str(tmp_path / "l.h5"), "--quiet"]) == 0
    assert not dead.exists() and live.exists() and other.exists()


def test_an_output_that_appears_meanwhile_is_kept(tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(UsageError, match="appeared while this ran"):
        with files.atomic_path(target, exclusive=True) as tmp:
            tmp.write_text("mine")
            target.write_text("theirs")
    assert target.read_text() == "theirs" and [p.name for p in tmp_path.iterdir()] == ["out.txt"]
    with files.keep_existing(), pytest.raises(UsageError):
        with files.atomic_path(target) as tmp:
            tmp.write_text("mine")
    with files.atomic_path(target) as tmp:  # outside keep_existing a writer replaces, as the API always has
        tmp.write_text("mine")
    assert target.read_text() == "mine"


@pytest.mark.parametrize("argv", [["drag", "--distance", "5", "--out", "{}"],
                                  [*OPTIMIZE, "--budget", "7", "--out", "{}"]])
def test_a_dangling_symlink_at_out_is_refused_without_force(tmp_path, capsys, argv):
    link = tmp_path / "x.h5"
    link.symlink_to(tmp_path / "nowhere.h5")
    assert main([a.format(link) for a in argv]) == 2
    err = capsys.readouterr().err
    assert f"--out {link} exists" in err and len(err.splitlines()) == 1
    assert link.is_symlink() and not (tmp_path / "nowhere.h5").exists()


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    log = tmp_path_factory.mktemp("log") / "l.h5"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main([*OPTIMIZE, "--budget", "14", "--workers", "1", "--out", str(log)]) == 0
    return log


def _edited(small_log: Path, tmp_path: Path, edit, seal: bool) -> Path:
    """A copy of the log edited by ``edit(file)``; with ``seal`` its digest made to match again (a log edited by
    someone who knows the format)."""
    log = tmp_path / "edited.h5"
    log.write_bytes(small_log.read_bytes())
    with h5py.File(log, "a") as f:
        edit(f)
        if seal and "digest" in f.attrs:
            f.attrs["digest"] = searchlog.digest(f)
    return log


@pytest.mark.parametrize("name,edit", [
    ("eta", lambda f: f["eta"].__setitem__(0, 0.9)),
    ("x", lambda f: f["x"].__setitem__((0, 0), 0.3)),
    ("D1", lambda f: f["D1"].__setitem__(1, 0.2)),
    ("seed", lambda f: f.attrs.__delitem__("seed")),
    ("scene", lambda f: f.attrs.__setitem__("scene_toml", "[[[")),
    ("unit attribute", lambda f: f["cost"].attrs.__setitem__("units", "mm"))])
def test_an_edited_log_is_refused_by_its_digest(small_log, tmp_path, capsys, name, edit):
    log = _edited(small_log, tmp_path, edit, seal=False)
    before = log.read_bytes()
    assert main(["optimize", "--resume", str(log), "--budget", "21"]) == 2
    err = capsys.readouterr().err
    assert "do not match the digest" in err and len(err.splitlines()) == 1
    assert log.read_bytes() == before


@pytest.mark.parametrize("edit,named", [
    (lambda f: f["x"].__setitem__((0, 0), 0.3), "generation 0 logs other values of the variables"),
    (lambda f: f.attrs.__delitem__("seed"), "its attribute seed is missing"),
    (lambda f: f.attrs.__setitem__("seed", 2**40), "its attribute seed is damaged"),
    (lambda f: f.attrs.__setitem__("variables", 3), "its attribute variables is damaged"),
    (lambda f: f.attrs.__setitem__("sigma0", "abc"), "its attribute sigma0 is damaged"),
    (lambda f: f.attrs.__setitem__("budget", -5), "its attribute budget is damaged"),
    (lambda f: f.attrs.__setitem__("scene_toml", "[[["), "its scene: malformed TOML"),
    (lambda f: f.attrs.__delitem__("digest"), "carries no digest of its contents"),
    (lambda f: f.__delitem__("bounds"), "lacks bounds")])
def test_a_log_with_damaged_attributes_is_one_line(small_log, tmp_path, capsys, edit, named):
    log = _edited(small_log, tmp_path, edit, seal=True)
    assert main(["optimize", "--resume", str(log), "--budget", "21"]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("make", ["device", "fifo", "huge"])
def test_a_file_read_is_bounded(tmp_path, capsys, make):
    if make == "device":
        path, said = "/dev/zero", "is not a regular file"
    elif make == "fifo":
        path, said = tmp_path / "table.csv", "is not a regular file"
        os.mkfifo(path)  # would block a plain open until a writer comes
    else:
        path, said = tmp_path / "table.csv", f"holds {files.MAX_TEXT_BYTES + 1} bytes, more than"
        with open(path, "wb") as handle:  # sparse: no disk used
            handle.truncate(files.MAX_TEXT_BYTES + 1)
    assert main(["drag", "--distance", "5", "--set", "rft.law=table", "--set", f"rft.table={path}"]) == 2
    err = capsys.readouterr().err
    assert f"RFT table {path} {said}" in err and len(err.splitlines()) == 1
    assert main(["optimize", "--resume", str(path)]) == 2
    assert len(capsys.readouterr().err.splitlines()) == 1


@pytest.mark.parametrize("override,named", [
    ("sim.dt=5e-324", "more than 1e+09"),
    ("sim.max_step=1e-300", "sim.max_step = 1e-300 s would take at least"),
    ("sim.max_step=1e-12", "more than 1e+09: raise sim.max_step")])
def test_a_step_budget_bounds_every_run(capsys, override, named):
    # 1e-300 s steps never end; 1e-12 s steps would take 5e9 steps over the 5 mm drag's 0.17 s.
    assert main(["drag", "--distance", "5", "--set", "sim.method=adaptive", "--set", override]) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("argv,named", [
    (["optimize", "--seed", "99999999999999999999"], "--seed: must be <= 4294967295"),
    (["optimize", "--seed", str(2**32)], "--seed: must be <= 4294967295"),
    (["fit", "--data", str(DATA), "--seed", "99999999999999999999"], "--seed: must be <= 4294967295"),
    ([*OPTIMIZE, "--budget", str(10**20)], "the budget must be a whole number of evaluations from 1 to"),
    (["fit", "--data", str(DATA), "--params", ""], "the fitted parameters must be named"),
    (["fit", "--data", str(DATA), "--params", "b,,k"], "the fitted parameters must be named"),
    ([*OPTIMIZE, "--bounds", "gait.theta1=0:1", "--bounds", "gait.theta1=0.2:1.2"],
     "gait.theta1 has bounds already (gait.theta1=0:1)"),
    (["fit", "--data", str(DATA), "--params", "b", "--bounds", "b=0.1:1", "--bounds", "plate.damping=0.2:2"],
     "plate.damping has bounds already (b=0.1:1)"),
    ([*OPTIMIZE, "--bounds", "gait.theta1=0:inf"], "bounds must be finite numbers"),
    ([*OPTIMIZE, "--workers", "99999999999999"], "workers: from 1 to 1024 processes")])
def test_numbers_from_the_user_are_checked_before_use(capsys, argv, named):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.splitlines()) == 1


def test_the_api_checks_seeds_too():
    scene = preset("paper", __import__("finrft").RobotScene)
    for seed in (0, MAX_SEED + 1, 2.5, True):
        with pytest.raises(SceneError, match="the seed must be a whole number from 1 to 4294967295"):
            optimize(scene, variables=[Variable("gait.theta1", 0.5, 1.5)], budget=7, seed=seed, workers=1)


@pytest.mark.parametrize("command", ["optimize", "fit"])
def test_preset_with_resume_is_refused(small_log, capsys, command):
    assert main([command, "--resume", str(small_log), "--preset", "paper"]) == 2
    err = capsys.readouterr().err
    assert "--preset cannot be given with --resume" in err and len(err.splitlines()) == 1


def test_a_new_log_over_an_existing_one_needs_replace(small_log, tmp_path):
    log = tmp_path / "l.h5"
    log.write_bytes(small_log.read_bytes())
    scene = preset("paper", __import__("finrft").RobotScene).replace(**{"gait.omega": 3.0})
    with pytest.raises(UsageError, match="exists: continue it"):
        optimize(scene, budget=7, seed=3, workers=1, log=log)
    assert log.read_bytes() == small_log.read_bytes()
    search = optimize(scene, budget=7, seed=3, workers=1, log=log, replace=True)
    assert searchlog.read(log, searchlog.OPTIMIZE)[1]["cost"].data.size == search.evaluations


def test_closed_stdout_at_start_is_one_line(tmp_path):
    done = subprocess.run(["sh", "-c", 'exec "$0" -m finrft drag --distance 5 --json >&-', sys.executable],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 2
    assert done.stderr == "finrft: error: standard output is closed: redirect it to a file or to /dev/null\n"
