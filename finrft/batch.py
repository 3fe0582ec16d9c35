"""Many runs at once on all cores: a pool of worker processes, each running `finrft.experiment.run` of any
experiment (`run_experiments`; `run_many` for plate tests), and MuJoCo's threaded rollout of plate tests' states
(`rollout_plates`).

Whole runs go to processes: a run reads, checks and estimates its error in Python at every recorded instant,
which threads would serialise. Where only the states are wanted, rollout steps them with no Python between the
drive's reversals, which it applies between strokes (an impulse computed in Python, once per stroke). Every worker
loads the native plugin when it imports MuJoCo; a result is the same, bit for bit, as the single run of the same
job.

Workers are spawned, and a spawned worker imports the main module again: in a script, call `run_experiments`,
`run_many` and `map_jobs` under ``if __name__ == "__main__":`` (notebooks and the interactive prompt need nothing).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.context
import os
import signal
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterator, Sequence, TypeVar

import mujoco
import numpy as np

from . import laws
from .convergence import ErrorLimits
from .drive import Drive
from .experiment import Experiment, Result, run
from .scene import Scene
from .simulate import PlateTest

T = TypeVar("T")
R = TypeVar("R")


def _run(job: tuple[Experiment, Any, ErrorLimits | None]) -> Result:
    experiment, scene, max_error = job
    return run(experiment, scene, max_error=max_error)


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class _QuietProcess(multiprocessing.context.SpawnProcess):
    """A spawned worker deaf to Ctrl-C from its first instruction. Ctrl-C reaches every process in the terminal's
    group: the parent handles it and shuts the pool down, a worker would only print a traceback. The pool spawns
    workers as jobs arrive, so one may be starting when Ctrl-C comes, before any initializer runs: the worker is
    started with SIGINT blocked, which it inherits and keeps, while the parent receives a Ctrl-C of that moment as
    soon as the worker is started."""

    def start(self) -> None:
        if not hasattr(signal, "pthread_sigmask"):  # Windows delivers Ctrl-C otherwise
            return super().start()
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            super().start()
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


class _QuietSpawn(multiprocessing.context.SpawnContext):
    Process = _QuietProcess


def _ignore_interrupt() -> None:
    # Where SIGINT cannot be blocked from the start (`_QuietProcess`), from here on. The parent says that a law
    # feeds energy in (`map_jobs`), the workers do not.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warnings.simplefilter("ignore", laws.FeedsEnergy)


def local_executor(workers: int | None = None) -> ProcessPoolExecutor:
    """A process pool for `map_jobs`; spawned workers, so nothing of the parent's MuJoCo state is inherited, that
    leave Ctrl-C to the parent."""
    return ProcessPoolExecutor(max_workers=workers or default_workers(), mp_context=_QuietSpawn(),
                               initializer=_ignore_interrupt)


def map_jobs(fn: Callable[[T], R], jobs: Sequence[T], *, workers: int | None = None,
             executor: Executor | None = None, progress: Callable[[int, int], None] | None = None) -> list[R]:
    """``[fn(job) for job in jobs]`` on all cores, in order; ``fn`` must be a module-level function.

    ``executor``: any concurrent.futures executor to reuse across calls (one `local_executor` for all
    generations of an optimisation, or a Dask client's executor); without it a local pool of ``workers``
    processes (default: all cores) is made for this call, or the jobs run in this process when ``workers`` is 1.
    """
    jobs = list(jobs)
    results: list[R] = []
    with pool_for(executor, 1 if len(jobs) <= 1 else workers) as pool:
        if pool is not None:
            for job in jobs:
                for part in job if isinstance(job, tuple) else (job,):
                    laws.warn_if_feeds_energy(part)
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
    return map_jobs(_run, [(experiment, scene, max_error) for experiment, scene in jobs], **options)


def run_many(jobs: Sequence[tuple[Scene, Drive]], **options) -> list[Result]:
    """Simulate every (scene, drive) plate test and return the runs in order (options as `run_experiments`)."""
    return run_experiments([(PlateTest(drive), scene) for scene, drive in jobs], **options)


def rollout_plates(jobs: Sequence[tuple[Scene, Drive]], *, workers: int | None = None) -> list[np.ndarray]:
    """The states (mjSTATE_FULLPHYSICS) at the recorded instants of every (scene, drive) plate test, stepped by
    MuJoCo's threaded rollout on ``workers`` threads: no Python runs between the drive's reversals, which are
    applied between strokes as `stepping.Prescribed` applies them. The same steps as `simulate`'s, so the same
    states, bit for bit (a model with constraints, limit stops or welds, restarts its solver's warm start at each
    reversal: the same to the solver's tolerance); but no readings, chatter probe or error estimate (`run_many`
    gives those): for sweeps that need the states only, at the cores' full rate.

    Every job must share its drive, ``sim.dt`` and ``sim.record_dt``, and step explicitly with the native backend
    (a Python force callback cannot run on rollout's threads); ValueError otherwise. Jobs whose laws or chains
    differ are rolled out in turn, each group on all the threads."""
    from mujoco import rollout

    from .stepping import schedule
    jobs = list(jobs)
    if not jobs:
        return []
    scene0, drive = jobs[0]
    for scene, other in jobs:
        if other != drive or (scene.sim.dt, scene.sim.record_dt) != (scene0.sim.dt, scene0.sim.record_dt):
            raise ValueError("rollout_plates: every job needs the same drive, sim.dt and sim.record_dt")
        if scene.sim.method != "explicit" or scene.sim.backend != "native":
            raise ValueError("rollout_plates: every job needs sim.method 'explicit' and sim.backend 'native'")
    test = PlateTest(drive)
    built = [test.build(scene) for scene, _ in jobs]
    models = [b.model for b in built]
    steps, starts, samples = schedule(drive, scene0.sim.dt, scene0.sim.record_dt)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    datas = [mujoco.MjData(m) for m in models]
    trials = [test.start(scene, b, d, True) for (scene, _), b, d in zip(jobs, built, datas)]
    bounds = np.r_[starts, steps]
    threads = workers or default_workers()
    # Rollout steps every job on its threads' own MjData, whose plugin instances hold the law and the segments of
    # the model they were made for: jobs run together only with an identical plugin config and structure.
    groups: dict[tuple, list[int]] = {}
    for j, m in enumerate(models):
        groups.setdefault((m.plugin_attr.tobytes(), m.nbody, m.njnt, m.nsite, m.nq, m.nv), []).append(j)
    out: list[np.ndarray] = [np.empty(0)] * len(jobs)
    with rollout.Rollout(nthread=threads) as pool:
        for members in groups.values():
            group = [models[j] for j in members]
            scratch = [mujoco.MjData(group[0]) for _ in range(threads)]
            states = np.zeros((len(members), len(samples), mujoco.mj_stateSize(group[0], spec)))
            for k, (first, last) in enumerate(zip(bounds[:-1], bounds[1:])):
                initial = np.zeros((len(members), states.shape[2]))
                for i, j in enumerate(members):
                    trials[j].on_stroke(k)
                    mujoco.mj_getState(models[j], datas[j], initial[i], spec)
                state, _ = pool.rollout(group, scratch, initial, nstep=int(last - first))
                inside = (samples >= first) & (samples <= last) if k == len(starts) - 1 else \
                    (samples >= first) & (samples < last)
                index = samples[inside] - first
                states[:, inside] = np.where((index == 0)[None, :, None], initial[:, None], state[:, index - 1])
                for j, final in zip(members, state[:, -1]):
                    mujoco.mj_setState(models[j], datas[j], final, spec)
            for i, j in enumerate(members):
                out[j] = states[i]
    return out
