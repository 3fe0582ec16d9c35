"""The paper's Table I: its six gaits, finrft's figures for each beside the paper's, and the Markdown table."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..batch import run_experiments
from ..convergence import ErrorLimits
from ..experiment import Result
from ..experiments.swim import Swim, steady_cycles
from ..experiments.swim import RobotScene


# The paper's Table I: (name, theta1 deg, theta2 deg, L_a mm, fin, eta_exp %, eta_sim %, net speed mm/s exp).
PAPER_TABLE = (
    ("Optimized", 60, -90, 65, "origami", 8.61, 8.95, 1.69),
    ("Symmetry 1", 30, -30, 65, "origami", 1.22, 0.06, 0.48),
    ("Symmetry 2", 30, -30, 75, "origami", 1.08, 0.05, 0.59),
    ("Asymmetry 1", 90, 0, 65, "origami", 3.12, 3.71, 0.34),
    ("Asymmetry 2", 90, 0, 75, "origami", 3.57, 3.65, 0.43),
    ("Rigid fin", 60, -90, 65, "rigid", 0.11, 1.02, 0.02),
)


# The gaits the physical preset's fitted parameter (fin.stiffness) was fitted on (scripts/fit_robot.py --shape preset).
PHYSICAL_FITTED = ("Optimized",)


def table_scenes(scene: RobotScene) -> list[RobotScene]:
    """The scene of each gait of the paper's Table I."""
    return [scene.replace(**{"gait.theta1": np.radians(t1), "gait.theta2": np.radians(t2),
                             "arm.length": la / 1000, "fin.kind": fin})
            for _, t1, t2, la, fin, *_ in PAPER_TABLE]


def table_rows(runs: list[Result], fitted: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """Table I rows: finrft's eta (steady, `steady`; the first cycle's when a run has one), the first cycle's, the
    authors' script measure |net| / D1, the distances and the net speed (steady), beside the paper's figures;
    ``fitted``: the gaits the scene's parameters were fitted on."""
    rows = []
    for (name, t1, t2, la, fin, eta_exp, eta_sim, speed_exp), result in zip(PAPER_TABLE, runs):
        s = result.summary()
        rows.append({"gait": name, "theta1_deg": t1, "theta2_deg": t2, "arm_length_mm": la, "fin": fin,
                     "cycles": s["cycles"], "eta": s["eta_steady"], "eta_first_cycle": s["eta_first_cycle"],
                     "eta_script": abs(s["D1_mm_steady"] - s["D2_mm_steady"]) / s["D1_mm_steady"],
                     "D1_mm": s["D1_mm_steady"], "D2_mm": s["D2_mm_steady"],
                     "net_speed_mm_s": s["net_speed_mm_s_steady"], "paper_eta_sim": eta_sim / 100,
                     "paper_eta_exp": eta_exp / 100, "paper_net_speed_exp_mm_s": speed_exp, "fitted": name in fitted,
                     "error_estimate": s.get("error_estimate")})
    return rows


def table(scene: RobotScene, *, preset: str | None = None, max_error: ErrorLimits = ErrorLimits(),
          workers: int | None = None, progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Table I's rows for ``scene``'s model, its six gaits run on all cores; ``preset``: the preset the scene came
    from (None: a scene file), which marks the gaits that preset was fitted on."""
    jobs = [(Swim(s.gait.cycles), s) for s in table_scenes(scene)]
    runs = run_experiments(jobs, max_error=max_error, workers=workers, progress=progress)
    return table_rows(runs, PHYSICAL_FITTED if preset == "physical" else ())


def table_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| gait | Θ1 ° | Θ2 ° | L_a mm | fin | η % | η cycle 1 % | \\|net\\|/D1 % | paper η_sim % | "
             "paper η_exp % | D1 mm | D2 mm | net speed mm/s | paper speed mm/s | fit |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['gait']} | {r['theta1_deg']} | {r['theta2_deg']} | {r['arm_length_mm']} | {r['fin']} | "
                     f"{100 * r['eta']:.2f} | {100 * r['eta_first_cycle']:.2f} | {100 * r['eta_script']:.2f} | "
                     f"{100 * r['paper_eta_sim']:.2f} | {100 * r['paper_eta_exp']:.2f} | {r['D1_mm']:.1f} | "
                     f"{r['D2_mm']:.1f} | {r['net_speed_mm_s']:.2f} | {r['paper_net_speed_exp_mm_s']:.2f} | "
                     f"{'fitted' if r['fitted'] else ''} |")
    cycles = rows[0]["cycles"] if rows else 1
    if cycles > 1:
        lines.append(f"\nη, D1, D2 and the net speed over the steady {steady_cycles(cycles)}; η cycle 1 from rest.")
    return "\n".join(lines)

