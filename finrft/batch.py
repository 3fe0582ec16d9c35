"""Many runs at once on all cores: a pool of worker processes, each running `finrft.experiment.run` of any
experiment (`run_experiments`; `run_many` for plate tests), and plate tests' states stepped in C on threads
(`PlateRollouts`, `rollout_plates`).

Whole runs go to processes: a run reads, checks and estimates its error in Python at every recorded instant,
which threads would serialise. Where only the states are wanted, threads step them in C with no Python between the
drive's reversals, which are applied between strokes (an impulse computed in Python, once per stroke). Every worker
loads the native plugin when it imports MuJoCo; a result is the same, bit for bit, as the single run of the same
job.

Workers are spawned, and a spawned worker imports the main module again: in a script, call `run_experiments`,
`run_many` and `map_jobs` under ``if __name__ == "__main__":`` (notebooks and the interactive prompt need nothing).
"""

from __future__ import annotations

import contextlib
import copy
import ctypes
import dataclasses
import multiprocessing
import multiprocessing.context
import os
import signal
import sys
import threading
import time
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterator, Sequence, TypeVar

import mujoco
import numpy as np

from . import geometry, laws, methods, native
from .convergence import ErrorLimits, SimulationUnstable, check_limits
from .drive import Drive
from .errors import SceneError
from .experiment import Experiment, Result, run
from .scene import Scene
from .experiments.plate import PlateModel, PlateTest, retune, retune_key
from .stepping import schedule

T = TypeVar("T")
R = TypeVar("R")


def _run(job: tuple[Experiment, Any, ErrorLimits | None]) -> Result:
    experiment, scene, max_error = job
    return run(experiment, scene, max_error=max_error)


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class _QuietProcess(multiprocessing.context.SpawnProcess):
    """A spawned worker deaf to Ctrl-C from its first instruction, that dies with its parent and never holds the
    caller's streams.

    Ctrl-C reaches every process in the terminal's group: the parent handles it and shuts the pool down, a worker
    would only print a traceback. The pool spawns workers as jobs arrive, so one may be starting when Ctrl-C comes,
    before any initializer runs: the worker is started with SIGINT blocked, which it inherits and keeps, while the
    parent receives a Ctrl-C of that moment as soon as the worker is started.

    A parent killed outright (SIGKILL: a scheduler's pre-emption, an out-of-memory kill) cannot shut its pool down:
    its workers would run on, each holding the pipe a caller reads the parent's output from, and with them
    multiprocessing's resource tracker, which ends only when every worker has. So a worker asks Linux to kill it
    when its parent dies (PR_SET_PDEATHSIG), or elsewhere watches its parent's pid, and points its standard streams
    at the null device: the caller's pipe closes with the parent. Linux sends that signal when the thread that
    started the worker ends: a pool is used from the thread that made it, or one that outlives it."""

    def start(self) -> None:
        self._owner = os.getpid()
        if not hasattr(signal, "pthread_sigmask"):  # Windows delivers Ctrl-C otherwise
            return super().start()
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            super().start()
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

    def run(self) -> None:
        die_with_parent(self._owner)
        detach_streams()
        super().run()


class _QuietSpawn(multiprocessing.context.SpawnContext):
    Process = _QuietProcess


_PR_SET_PDEATHSIG = 1  # linux/prctl.h
# How often a worker without PR_SET_PDEATHSIG looks for its parent (s): the delay before it notices a death.
PARENT_POLL = 0.5


def die_with_parent(parent: int) -> None:
    """End this process when process ``parent`` (its parent) ends: at once on Linux (the kernel sends SIGKILL),
    else within PARENT_POLL seconds (a thread watching the parent's pid). A parent already gone ends it now."""
    if not _parent_death_signal() and hasattr(os, "getppid"):
        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(PARENT_POLL)
            os._exit(1)
        threading.Thread(target=watch, name="finrft-parent-watch", daemon=True).start()
    # The signal is set from here on: a parent that died while this process started leaves it orphaned already.
    if hasattr(os, "getppid") and os.getppid() != parent:
        os._exit(1)


def _parent_death_signal() -> bool:
    """Ask Linux to send SIGKILL to this process when its parent ends; whether it was set."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def detach_streams() -> None:
    """Point this process's stdin, stdout and stderr at the null device. A worker reports through its pool, never
    on the streams it inherited: those may be a pipe a caller reads to its end, which must close with the parent."""
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.close(null)


def _ignore_interrupt() -> None:
    # Where SIGINT cannot be blocked from the start (`_QuietProcess`), from here on. The parent says that a law
    # feeds energy in (`map_jobs`), the workers do not.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warnings.simplefilter("ignore", laws.FeedsEnergy)


_tracker_lock = threading.Lock()
_tracker_detached = False


def _detached_resource_tracker() -> None:
    """Start multiprocessing's resource tracker, once, with its stderr on the null device. It outlives a parent
    killed outright until its last worker ends, and then warns of the semaphores the parent could not release: on
    the caller's stderr, after the caller's command has ended, unless started here first."""
    global _tracker_detached
    if sys.platform == "win32":  # no resource tracker there
        return
    from multiprocessing import resource_tracker
    with _tracker_lock:
        if _tracker_detached:
            return
        saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
        if sys.stderr is not None:
            sys.stderr.flush()
        try:
            os.dup2(null, 2)
            resource_tracker.ensure_running()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            os.close(null)
        _tracker_detached = True


# More worker processes than any machine has cores for; beyond it a pool fails deep inside multiprocessing.
MAX_WORKERS = 1024


def check_workers(workers: Any, what: str = "processes") -> None:
    """SceneError unless ``workers`` is None (all cores) or a whole number from 1 to MAX_WORKERS."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or not 1 <= workers <= MAX_WORKERS):
        raise SceneError(f"workers: from 1 to {MAX_WORKERS} {what} (a whole number, or None: all cores), got "
                         f"{workers!r}")


def local_executor(workers: int | None = None) -> ProcessPoolExecutor:
    """A process pool for `map_jobs`; spawned workers, so nothing of the parent's MuJoCo state is inherited, that
    leave Ctrl-C to the parent and end with it. SceneError for more than MAX_WORKERS workers."""
    check_workers(workers)
    _detached_resource_tracker()
    return ProcessPoolExecutor(max_workers=workers or default_workers(), mp_context=_QuietSpawn(),
                               initializer=_ignore_interrupt)


def map_jobs(fn: Callable[[T], R], jobs: Sequence[T], *, workers: int | None = None,
             executor: Executor | None = None, progress: Callable[[int, int], None] | None = None) -> list[R]:
    """``[fn(job) for job in jobs]`` on all cores, in order; ``fn`` must be a module-level function.

    ``executor``: any concurrent.futures executor to reuse across calls (one `local_executor` for all
    generations of an optimisation, or a Dask client's executor); without it a local pool of ``workers``
    processes (default: all cores) is made for this call, or the jobs run in this process when ``workers`` is 1.
    """
    check_workers(workers)  # also where the jobs are too few to need a pool
    jobs = list(jobs)
    results: list[R] = []
    with pool_for(executor, 1 if len(jobs) <= 1 else workers) as pool:
        if pool is not None:
            for job in jobs:
                for part in job if isinstance(job, tuple) else (job,):
                    laws.warn_if_feeds_energy(geometry.segment_law(part))
        pending = [pool.submit(fn, job) for job in jobs] if pool is not None else jobs
        try:
            for item in pending:
                results.append(item.result() if pool is not None else fn(item))
                if progress is not None:
                    progress(len(results), len(jobs))
        except BrokenProcessPool as exc:
            # The usual cause: a script without the main guard, whose workers run it again and stop at this call.
            raise BrokenProcessPool(f"{exc} If this runs from a script, call it under "
                                    f"`if __name__ == \"__main__\":` (each worker imports the script again).") from exc
    return results


@contextlib.contextmanager
def pool_for(executor: Executor | None = None, workers: int | None = None) -> Iterator[Executor | None]:
    """The executor a block should use: the given one; None (run in this process) when ``workers`` is 1; else a
    local pool of ``workers`` processes that the block owns and shuts down."""
    check_workers(workers)
    if executor is not None or workers == 1:
        yield executor
        return
    pool = local_executor(workers)
    try:
        yield pool
    except BaseException:
        # After an error or Ctrl-C, stop at once: drop the jobs not started and end the running ones (a gait can
        # take seconds; waiting for them also raced with the workers' pipes). ProcessPoolExecutor gains
        # terminate_workers only in Python 3.14.
        terminate = getattr(pool, "terminate_workers", None)
        if terminate is not None:
            terminate()
        else:
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                process.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def run_experiments(jobs: Sequence[tuple[Experiment, Any]], *, max_error: ErrorLimits | None = ErrorLimits(),
                    **options) -> list[Result]:
    """`experiment.run` of every (experiment, scene) job with ``max_error``; the runs in order (options as
    `map_jobs`)."""
    check_limits(max_error)
    if isinstance(jobs, (str, bytes)) or not all(isinstance(job, tuple) and len(job) == 2 for job in jobs):
        raise SceneError(f"run_experiments: every job is an (experiment, scene) pair, got {jobs!r:.60}")
    return map_jobs(_run, [(experiment, scene, max_error) for experiment, scene in jobs], **options)


def run_many(jobs: Sequence[tuple[Scene, Drive]], **options) -> list[Result]:
    """Simulate every (scene, drive) plate test and return the runs in order (options as `run_experiments`)."""
    if isinstance(jobs, (str, bytes)) or not all(isinstance(job, tuple) and len(job) == 2 for job in jobs):
        raise SceneError(f"run_many: every job is a (finrft.Scene, finrft.Drive) pair, got {jobs!r:.60}")
    return run_experiments([(PlateTest(drive), scene) for scene, drive in jobs], **options)


def rollout_plates(jobs: Sequence[tuple[Scene, Drive]], *, workers: int | None = None) -> list[np.ndarray]:
    """The states (mjSTATE_FULLPHYSICS) at the recorded instants of every (scene, drive) plate test, stepped on
    ``workers`` threads: one batch of a `PlateRollouts`, which a sweep of many batches should keep instead."""
    with PlateRollouts(workers) as rollouts:
        return rollouts(jobs)


class PlateRollouts:
    """Plate tests' states stepped on threads, batch after batch: the threads, and the models of the last batch
    for the next.

    A thread steps one job's stroke at a time in C (the native library's `finrft_explicit_record`: MuJoCo's step,
    the states kept at the recorded instants only), with no Python and no GIL between the drive's reversals, which
    are applied between strokes as `stepping.Prescribed` applies them: the same steps as `simulate`'s, so the same
    states, bit for bit. There are no readings, chatter probe or error estimate (`run_many` gives those): this is
    for sweeps that need the states only, at the cores' full rate. (MuJoCo's threaded rollout steps the same way
    but copies every step's state out, which cost it 5 % of a plate's steps.)

    Every job of a batch must share its drive, ``sim.dt`` and ``sim.record_dt``, and step explicitly with the native
    backend (a Python force callback would hold the GIL); SceneError otherwise. Jobs may differ in anything else:
    a thread steps jobs of any law on one MjData per size, as the plugin takes each job's law from its model. A job
    that differs from one of the last batch's only in the hinges' stiffness and damping (`RETUNABLE` of
    finrft.experiments.plate) reuses its compiled model. A run that goes unstable raises SimulationUnstable.

    ``with PlateRollouts(workers) as rollouts: states = rollouts(jobs)``, or `close` when done.
    """

    def __init__(self, workers: int | None = None) -> None:
        check_workers(workers, "threads")
        self.threads = workers or default_workers()
        self._pool = ThreadPoolExecutor(self.threads)
        self._plates: dict[tuple, list[PlateModel]] = {}  # the last batch's models, by retune key
        self._datas: dict[tuple, list[mujoco.MjData]] = {}       # by sizes: the drive's, then one per thread
        self._record = native.function("finrft_explicit_record", ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p,
                                       ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)

    def __enter__(self) -> PlateRollouts:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        self._pool.shutdown()
        self._plates, self._datas = {}, {}

    def __call__(self, jobs: Sequence[tuple[Scene, Drive]]) -> list[np.ndarray]:
        """The states (mjSTATE_FULLPHYSICS) at the recorded instants of every (scene, drive) plate test."""
        jobs = list(jobs)
        if not jobs:
            return []
        for job in jobs:
            if not (isinstance(job, tuple) and len(job) == 2 and isinstance(job[0], Scene)
                    and isinstance(job[1], Drive)):
                raise SceneError(f"rollout_plates: every job is a (finrft.Scene, finrft.Drive) pair, got {job!r:.60}")
        scene0, drive = jobs[0]
        for scene, other in jobs:
            if other != drive or (scene.sim.dt, scene.sim.record_dt) != (scene0.sim.dt, scene0.sim.record_dt):
                raise SceneError("rollout_plates: every job needs the same drive, sim.dt and sim.record_dt")
            if methods.get(scene.sim.method).stepper or scene.sim.backend != "native":
                raise SceneError("rollout_plates: every job needs sim.method 'explicit' and sim.backend 'native'")
        test = PlateTest(drive)
        plates = self._models(test, [scene for scene, _ in jobs])
        steps, starts, samples = schedule(drive, scene0.sim.dt, scene0.sim.record_dt)
        groups: dict[tuple, list[int]] = {}
        for j, plate in enumerate(plates):
            m = plate.model
            groups.setdefault((m.nq, m.nv, m.na, m.nu, m.nbody, m.njnt, m.nsite, m.neq, m.nplugin, m.npluginstate),
                              []).append(j)
        out: list[np.ndarray] = [np.empty(0)] * len(jobs)
        for sizes, members in groups.items():
            states = self._roll(test, members, [jobs[j][0] for j in members], [plates[j] for j in members], sizes,
                                steps, starts, samples)
            for j, state in zip(members, states):
                out[j] = state
        return out

    def _models(self, test: PlateTest, scenes: list[Scene]) -> list[PlateModel]:
        """A compiled plate for every scene: the last batch's of its retune key, retuned, while there are enough;
        then copies of one, or a compile."""
        kept, self._plates = self._plates, {}
        out = []
        for scene in scenes:
            key = (retune_key(scene), test.drive.kind, test.drive.attack_deg)
            mine = self._plates.setdefault(key, [])
            spare = kept.get(key, [])
            if len(spare) > len(mine):
                plate = spare[len(mine)]
            elif mine or spare:
                source = (mine or spare)[0]
                plate = dataclasses.replace(source, model=copy.copy(source.model))
            else:
                plate = test.build(scene)
            retune(plate, scene.plate)
            mine.append(plate)
            out.append(plate)
        return out

    def _roll(self, test: PlateTest, jobs: list[int], scenes: list[Scene], plates: list[PlateModel],
              sizes: tuple, steps: int, starts: np.ndarray, samples: np.ndarray) -> list[np.ndarray]:
        """The recorded states of jobs (their indices in the batch, their scenes and models) of one size."""
        # A job's state between strokes: the physics and the solver's warm start, as one MjData would carry them.
        carry, kept = mujoco.mjtState.mjSTATE_INTEGRATION, mujoco.mjtState.mjSTATE_FULLPHYSICS
        group = [plate.model for plate in plates]
        if sizes not in self._datas:
            self._datas[sizes] = [mujoco.MjData(group[0]) for _ in range(1 + self.threads)]
        d, *scratch = self._datas[sizes]
        # One MjData applies every job's reversals, each job's state put in and taken out again.
        trials = [test.start(scene, plate, d, True) for scene, plate in zip(scenes, plates)]
        nstate = mujoco.mj_stateSize(group[0], kept)
        states = np.zeros((len(plates), len(samples), nstate))
        current = np.zeros((len(plates), mujoco.mj_stateSize(group[0], carry)))
        bounds = np.r_[starts, steps]
        for k, (first, last) in enumerate(zip(bounds[:-1], bounds[1:])):
            recorded = np.flatnonzero(samples == first)  # the stroke's start, when it is a recorded instant
            for i, (m, trial) in enumerate(zip(group, trials)):
                if k:
                    mujoco.mj_setState(m, d, current[i], carry)
                else:
                    mujoco.mj_resetData(m, d)
                trial.on_stroke(k)
                mujoco.mj_getState(m, d, current[i], carry)
                if recorded.size:
                    mujoco.mj_getState(m, d, states[i, recorded[0]], kept)
            # The last step of a stroke that is not the run's last is the next one's start (after its reversal).
            inside = (samples > first) & ((samples < last) | (last == steps))
            at = np.ascontiguousarray(samples[inside] - first, dtype=np.int32)
            rows = np.flatnonzero(inside)
            queue = iter(range(len(plates)))  # shared: each job goes to the next thread free (next() holds the GIL)

            def stroke(t: int) -> int | None:
                """Jobs through the stroke on thread t's MjData; the first that went unstable, or None."""
                data, record = scratch[t], np.zeros((len(at), nstate))
                for i in queue:
                    mujoco.mj_setState(group[i], data, current[i], carry)
                    if self._record(group[i]._address, data._address, int(last - first), len(at), at.ctypes.data,
                                    record.ctypes.data):
                        return i
                    states[i, rows] = record
                    mujoco.mj_getState(group[i], data, current[i], carry)
                return None

            messages: list[str] = []
            with native.untimed(), native.captured_warnings(messages):
                failed = [i for i in self._pool.map(stroke, range(self.threads)) if i is not None]
            if failed:
                i, said = min(failed), f"; MuJoCo: {messages[0].strip()}" if messages else ""
                raise SimulationUnstable(
                    f"rollout_plates: job {jobs[i]} went unstable between t = {first * scenes[i].sim.dt:.4g} and "
                    f"{last * scenes[i].sim.dt:.4g} s (its state is not finite{said}) with dt = "
                    f"{scenes[i].sim.dt:g} s: reduce sim.dt, or run it with finrft.simulate for the newton method")
        return list(states)
