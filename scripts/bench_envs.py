"""Throughput of the Gymnasium environments (finrft.envs) on this machine: one world's bare stepping (the C stepper
alone, no Python between a control interval's steps), `RobotEnv.step`'s overhead over it, and `RobotVectorEnv`'s
worlds per second by number of worlds, on one thread per core. Prints a Markdown table (docs/guide/envs.md).

    python scripts/bench_envs.py [--scene sand_swimmer] [--worlds 1,2,4,8] [--steps 40] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import time

import mujoco
import numpy as np

import finrft.envs as envs


def best(fn, repeats: int) -> float:
    """The shortest of ``repeats`` timings of fn() (s): the machine's other load only ever adds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="sand_swimmer")
    p.add_argument("--worlds", default="1,2,4,8")
    p.add_argument("--steps", type=int, default=40, help="control intervals per timing")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    cores = len(os.sched_getaffinity(0))
    env = envs.make(args.scene)
    world, steps = env.world, args.steps
    action = np.zeros(env.action_space.shape, np.float32)

    env.reset(seed=0)
    bare_step = world.stepper()
    d = env.data

    def bare() -> None:
        for _ in range(steps):
            world.act(d, action)
            bare_step(d, world.substeps)

    def wrapped() -> None:
        for _ in range(steps):
            env.step(action)

    def python_parts() -> None:
        # what RobotEnv.step adds to the C stepper, timed alone: the whole step's timing carries the machine's load
        for _ in range(steps):
            world.act(d, action)
            env.reward(world.figures(d, world.com(d), world.com(d)))
            world.observe(d)

    env.reset(seed=0)
    one = best(bare, args.repeats)
    added = best(python_parts, args.repeats)
    env.reset(seed=0)
    full = best(wrapped, args.repeats)
    rate = steps / one
    print(f"{args.scene}: {world.substeps} steps of {world.dt:g} s a control interval; {cores} cores; "
          f"mujoco {mujoco.__version__}")
    print(f"one world, bare C stepper: {rate:.1f} intervals/s; RobotEnv.step: {steps / full:.1f} intervals/s "
          f"(overhead {100 * (full / one - 1):.1f} %, its Python parts timed alone "
          f"{1e6 * added / steps:.0f} us an interval: {100 * added / one:.1f} %)\n")
    print("| worlds | threads | intervals/s (all worlds) | x one world | share of cores x one world |")
    print("|---:|---:|---:|---:|---:|")
    for n in (int(w) for w in args.worlds.split(",")):
        vec = envs.make_vector(args.scene, n)
        vec.reset(seed=0)
        actions = np.zeros((n, *action.shape), np.float32)
        took = best(lambda: [vec.step(actions) for _ in range(steps)], args.repeats)
        total = n * steps / took
        print(f"| {n} | {vec.threads} | {total:.1f} | {total / rate:.2f} | "
              f"{100 * total / (min(n, cores) * rate):.0f} % |")
        vec.close()


if __name__ == "__main__":
    main()
