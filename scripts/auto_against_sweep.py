"""`auto` against the runs of a sweep it competes with, timed alternately (in this process, or each as its own).

    python scripts/auto_against_sweep.py [--process | --bound] DIR [ROBOT ...]
        (DIR: a `finrft bench robots --battery --out DIR`)

For each robot (default: every one with DIR/NAME.csv), from its sweep: the fastest run within 2 % of the converged
run (or the default's own error, as `finrft bench robots` says) and the fastest run whose own estimate keeps its
headline figures within the default limits (the fastest a chooser can know is within them). Then `auto` (the
code installed now, under the default limits) and those runs, each whole with its companion, in turn, twice, best
of two: wall and CPU time (`time.process_time`, which other processes on the machine inflate less). Prints a
Markdown table, one row per robot.

With --bound, no run of `auto`: the least a chooser that verifies its choice by pilots would spend, from the sweep
alone (`bound`), in one process and as whole processes (the fastest run as a process, and the pilots added to it).

With --process, each run is a whole process, as a user starts it: ``finrft run --scene FILE --json --quiet --set
sim.method=M --set sim.dt=DT`` (M auto, DT the scene's step, for `auto`), its wall time and its CPU time (the
child's user and system time), imports, the scene's load and the model's build included.
"""

import csv
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

from finrft.studies.frontier import ACCURACY, BATTERY, battery_scene, measure

HEADLINE = ("com_speed_m_s", "cost_of_transport")
ROUNDS = 2


def _number(text: str) -> float | None:
    return float(text) if text not in ("", "nan") else None


def picks(rows: list[dict[str, str]]) -> dict[str, tuple[str, float] | None]:
    """The sweep's fastest run within the accuracy (the default's own error where that is larger) and the fastest
    its own estimate passes (every headline estimate within ACCURACY of its figure), as (method, dt)."""
    swept = _swept(rows)
    default = next(r for r in rows if r["default"] == "1")
    target = max(ACCURACY, _number(default["headline_error"]) or 0.0)

    def fastest(ok: Callable[[dict[str, str]], bool]) -> tuple[str, float] | None:
        found = [r for r in swept if ok(r)]
        best = min(found, key=lambda r: float(r["wall_s"]), default=None)
        return None if best is None else (best["method"], float(best["dt_s"]))

    def within(r: dict[str, str]) -> bool:
        error = _number(r["headline_error"])
        return error is not None and error <= target

    return {"within 2 %": fastest(within), "its estimate passes": fastest(passes)}


def _swept(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """A sweep's runs of a fixed method that ran through."""
    return [r for r in rows if r["method"] != "auto" and not r["failed"]]


def passes(r: dict[str, str]) -> bool:
    """A swept run whose own estimate keeps every headline figure within ACCURACY of it."""
    estimates = [_number(r[f"{k}_estimate"]) for k in HEADLINE]
    return any(e is not None for e in estimates) and all(e is None or e <= ACCURACY for e in estimates)


def bound(rows: list[dict[str, str]], scene: Any, pick: tuple[str, float]) -> tuple[float, float, list[str]]:
    """The least a chooser that verifies its choice by pilots would spend (s), the fastest run whose own estimate
    passes (F, ``pick``: its cost s, with its companion) and the candidates it would have to rule out first, from a
    robot's sweep: a chooser that knows every run's cost, not its error, and, as `auto`, measures a candidate only
    where it would cost less than SAVING of F. It makes F's run and its companion, and for each Newton candidate on
    `auto`'s ladder (at most START x sim.dt) that would cost less and misses the limits by its own estimate, its
    pilot and its pilot at half the step as far as the first instant a figure can tell them apart (the settle and
    one period of the gait, or the settle alone: `choice.period`), each pilot counted once, at its sweep's cost. The
    explicit step and the runs that failed (chatter) are left out, as if ruled out for nothing: a bound below."""
    from finrft.choice import FINER, IMPLICIT, SAVING, START, period
    swept = _swept(rows)
    fastest = next(r for r in swept if (r["method"], float(r["dt_s"])) == pick)
    whole = float(fastest["wall_s"])
    q = min(1.0, (scene.sim.settle + period(scene)) / scene.sim.duration)
    companion = float(fastest["companion_wall_s"])
    spent = {pick: whole - companion, (pick[0], pick[1] * FINER): companion}
    ruled: list[str] = []
    for r in swept:
        dt = float(r["dt_s"])
        if (r["method"] not in IMPLICIT or passes(r) or dt > START * scene.sim.dt * (1 + 1e-9)
                or not float(r["wall_s"]) < SAVING * whole):
            continue
        ruled.append(f"{r['method']}, {1e3 * dt:g} ms")
        half = float(r["companion_wall_s"])
        for pilot, cost in (((r["method"], dt), float(r["wall_s"]) - half), ((r["method"], dt * FINER), half)):
            spent[pilot] = max(spent.get(pilot, 0.0), q * cost)
    return sum(spent.values()), whole, ruled


def timed(scene: Any, method: str, dt: float) -> tuple[float, float, str]:
    """One whole run (`measure`): its wall and CPU time (s), and what `auto` chose or why it failed."""
    cpu = time.process_time()
    row = measure(scene, method, dt)
    return row.wall_s, time.process_time() - cpu, row.failed or row.chosen


def in_process(path: str, method: str, dt: float) -> tuple[float, float, str]:
    """One whole run (`measure`): its wall and CPU time (s), and what `auto` chose or why it failed."""
    from finrft.scene import UserScene, load_scene
    return timed(load_scene(path, cls=UserScene), method, dt)


def as_process(path: str, method: str, dt: float) -> tuple[float, float, str]:
    """One whole run as ``finrft run``: its wall and CPU time (s, the child's user and system time), and what `auto`
    chose or why it failed."""
    import json
    command = [sys.executable, "-m", "finrft", "run", "--scene", path, "--json", "--quiet",
               "--set", f"sim.method={method}", "--set", f"sim.dt={dt!r}"]
    before, start = os.times(), time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall, after = time.perf_counter() - start, os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    if done.returncode != 0:
        return wall, cpu, f"exit {done.returncode}: {(done.stderr.strip().splitlines() or [''])[-1]}"
    choice = json.loads(done.stdout).get("method_choice")
    return wall, cpu, f"{choice['method']}, {1e3 * choice['dt']:g} ms" if choice else ""


def bounds(folder: str, names: list[str]) -> None:
    """The `bound` of each robot as a Markdown table, in one process and as whole processes: the fastest run as a
    process (its CPU time, the best of two) and the pilots the bound adds to it, at the sweep's cost."""
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    print("| robot | fastest its estimate passes (s) | to rule out first | bound (s) | bound / it, one process | "
          "it as a process (CPU s) | bound / it, whole processes |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for name in names:
        with open(Path(folder) / f"{name}.csv") as f:
            rows = list(csv.DictReader(f))
        path = str(battery_scene(name) if name in BATTERY else example(name))
        pick = picks(rows)["its estimate passes"]
        least, whole, ruled = bound(rows, load_scene(path, cls=UserScene), pick)
        process = min(as_process(path, *pick)[1] for _ in range(ROUNDS))
        print(f"| {name} | {pick[0]}, {1e3 * pick[1]:g} ms ({whole:.2f}) | {', '.join(ruled) or 'none'} | "
              f"{least:.2f} | {least / whole:.2f} | {process:.2f} | {(process + least - whole) / process:.2f} |",
              flush=True)


def main(folder: str, names: list[str], process: bool = False) -> None:
    from finrft.experiments.user_model import example
    from finrft.scene import UserScene, load_scene
    one = as_process if process else in_process
    print("| robot | auto's choice | auto CPU s (wall s) | fastest within 2 % | CPU s (wall s) | auto / it, CPU "
          "(wall) | fastest its estimate passes | CPU s (wall s) | auto / it, CPU (wall) |")
    print("|---|---|---:|---|---:|---:|---|---:|---:|")
    for name in names:
        with open(Path(folder) / f"{name}.csv") as f:
            chosen = picks(list(csv.DictReader(f)))
        path = str(battery_scene(name) if name in BATTERY else example(name))
        scene = load_scene(path, cls=UserScene)
        runs = [("auto", scene.sim.dt)] + [p for p in dict.fromkeys(chosen.values()) if p is not None]
        best: dict[tuple[str, float], tuple[float, float, str]] = {}
        for _ in range(ROUNDS):
            for method, dt in runs:
                wall, cpu, said = one(path, method, dt)
                old = best.get((method, dt))
                best[(method, dt)] = (min(wall, old[0]), min(cpu, old[1]), said) if old else (wall, cpu, said)
        auto = best[("auto", scene.sim.dt)]
        cells = [name, auto[2], f"{auto[1]:.2f} ({auto[0]:.2f})"]
        for pick in chosen.values():
            if pick is None:
                cells += ["none", "—", "—"]
                continue
            wall, cpu, _ = best[pick]
            cells += [f"{pick[0]}, {1e3 * pick[1]:g} ms", f"{cpu:.2f} ({wall:.2f})",
                      f"{auto[1] / cpu:.2f} ({auto[0] / wall:.2f})"]
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a not in ("--process", "--bound")]
    robots = args[1:] or [p.stem for p in sorted(Path(args[0]).glob("*.csv")) if not p.stem.endswith("_all_methods")]
    if "--bound" in sys.argv[1:]:
        bounds(args[0], robots)
    else:
        main(args[0], robots, "--process" in sys.argv[1:])
