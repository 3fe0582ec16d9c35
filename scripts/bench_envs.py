"""Throughput of the Gymnasium environments (finrft.envs) on this machine, the robot playing its scene's own gait
as actions (`World.scene_action`; a robot standing still steps several times faster): one world's bare stepping
(the C stepper alone, the ctrl set once an interval), `RobotEnv.step`'s overhead over it, and `RobotVectorEnv`'s
control intervals per second by number of worlds, on one thread per core. Prints a Markdown table
(docs/guide/envs.md).

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
    gait = [world.scene_action(k * world.control_dt) for k in range(steps)]
    action = gait[0]

    env.reset(seed=0)
    bare_step = world.stepper()
    d = env.data

    def bare() -> None:
        for a in gait:  # the same steps and ctrl as the environment's, nothing else
            start = d.ctrl.copy()
            world.act(d, a)
            world.advance(d, bare_step, start)

    def wrapped() -> None:
        for a in gait:
            env.step(a)

    def python_parts() -> None:
        # what RobotEnv.step adds to the C stepper, timed alone: the whole step's timing carries the machine's load
        for _ in range(steps):
            start = d.ctrl.copy()
            world.act(d, action)
            world.advance(d, lambda d, n: 0, start)  # its pieces' Python, without their steps
            env.reward(world.figures(d, world.com(d), world.com(d)))
            world.observe(d)

    def timed(fn) -> float:
        def again() -> None:
            env.reset(seed=0)  # each timing from the start: the same steps
            fn()
        return best(again, args.repeats)

    one, added, full = timed(bare), timed(python_parts), timed(wrapped)
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

        def play() -> None:
            vec.reset(seed=0)  # each timing from the start (a reset is one forward pass a world)
            for a in gait:
                vec.step(np.repeat(a[None], n, axis=0))
        took = best(play, args.repeats)
        total = n * steps / took
        print(f"| {n} | {vec.threads} | {total:.1f} | {total / rate:.2f} | "
              f"{100 * total / (min(n, cores) * rate):.0f} % |")
        vec.close()


if __name__ == "__main__":
    main()
