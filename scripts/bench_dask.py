"""The Dask executor's overhead per evaluation on a local cluster: the same gait evaluations (the optimiser's
job, each with its error estimate) through a Dask LocalCluster and through finrft's local process pool of as many
workers, and the round trip of an empty task. Needs finrft[cluster].

    python scripts/bench_dask.py [--evaluations N] [--workers W]
"""

import argparse
import json
import math
import time

from finrft import batch
from finrft.studies.optimize import evaluate
from finrft.experiments.swim import RobotScene
from finrft.scene import preset


def _gait(scene: RobotScene) -> dict[str, float]:
    return evaluate(scene)


def _empty(job: int) -> int:
    return job


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def main() -> None:
    from dask.distributed import Client, LocalCluster
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evaluations", type=int, default=64)
    parser.add_argument("--workers", type=int, default=batch.default_workers())
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    # distinct gaits (theta1 from 55 to 65 degrees), as an optimiser's generation: Dask would reuse equal tasks
    scene = preset("paper", RobotScene)
    jobs = [scene.replace(**{"gait.theta1": math.radians(55 + 10 * i / args.evaluations)})
            for i in range(args.evaluations)]
    run = lambda pool, fn, items: batch.map_jobs(fn, items, executor=pool)  # noqa: E731
    out = {"evaluations": args.evaluations, "workers": args.workers}
    with batch.local_executor(args.workers) as pool, \
            LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None) as \
            cluster, Client(cluster) as client:
        dask = client.get_executor()
        walls: dict[str, list[float]] = {"pool": [], "dask": [], "pool_empty": [], "dask_empty": []}
        for executor, name in ((pool, "pool"), (dask, "dask")):
            run(executor, _gait, jobs[:args.workers])  # warm the workers
        for _ in range(args.repeat):  # interleaved: the machine's load weighs on both alike
            for executor, name in ((pool, "pool"), (dask, "dask")):
                walls[name].append(_timed(lambda: run(executor, _gait, jobs)))
                walls[f"{name}_empty"].append(_timed(lambda: run(executor, _empty, range(args.evaluations))))
    for name, times in walls.items():
        out[f"{name}_ms_per_evaluation"] = 1e3 * min(times) / args.evaluations
    out["dask_overhead_ms_per_evaluation"] = out["dask_ms_per_evaluation"] - out["pool_ms_per_evaluation"]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":  # the workers import this module again
    main()
