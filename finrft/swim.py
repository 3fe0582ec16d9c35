"""The two-fin robot swimming: flap cycles of the gait and the swimming efficiency.

A flap cycle starts at arm angle theta2 with the recovery stroke (the arm swings forward to theta1 at omega,
the fin folds) and ends with the power stroke (back to theta2, the fin flat against its stops). The body moves
back by D2 in the recovery stroke and forward by D1 in the power stroke; the paper's swimming efficiency is
eta = (D1 - D2) / D1. The robot starts at rest, arm and fin at theta2, the arm turning at omega.

The experiment measures a robot already swimming, so a gait's eta (`steady`) is taken over the cycles after the
first: eta = (sum D1 - sum D2) / sum D1 over cycles 2..N, the net distance over the distance forward (a mean of the
per-cycle eta would weigh a short cycle as much as a long one); with N = 1 it is the first cycle's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import mujoco
import numpy as np

from . import geometry
from .convergence import ErrorLimits, SimulationFailed
from .drive import Drive
from .experiment import Compared, Plot, Quantity, Result, run
from .models import RobotModel, body_share, build_robot
from .scene import RobotScene
from .stepping import Prescribed


SIGN_CONVENTION = (
    "Forward is +y, along the body's slide. The right arm's angle is 0 pointing sideways (+x) and +90 deg pointing "
    "forward; fin hinge angles are negative when the fin folds. The servo torque is what the servo applies to its "
    "arm about +z.")


@dataclass(frozen=True)
class Swim:
    """``cycles`` flap cycles of the robot from rest, as an experiment (finrft.experiment). Its result's series,
    SI units, arm and fin quantities the right side's: ``body_y`` (T,), ``arm_angle`` (T,), ``hinge_angle``
    (T, N), ``servo_torque`` (T,), ``stroke_y`` per stroke and at the end, ``eta`` per cycle; ``run.cycle_time``."""

    cycles: int = 1
    name = "swim"
    schema = "finrft.swim/1"
    sign_convention = SIGN_CONVENTION
    shape = "hinge_angle"  # the series whose angles give the fin's shape
    load = "servo_torque"  # the series of the drive's load

    def build(self, scene: RobotScene) -> RobotModel:
        return build_robot(scene)

    def drive_for(self, scene: RobotScene) -> Drive:
        return gait_drive(scene, self.cycles)

    def quantities(self, scene: RobotScene) -> dict[str, Quantity]:
        return {
            "body_y": Quantity("m", "body position along the travel axis (+y forward)",
                               plot=Plot("motion/body_y", "Body position (mm)", "body y", "mm")),
            "arm_angle": Quantity("rad", "right arm angle (0 sideways, +pi/2 forward)",
                                  plot=Plot("motion/arm", "Arm angle (deg)", "arm angle", "deg")),
            "hinge_angle": Quantity("rad", "right fin hinge angles",
                                    plot=Plot("hinges", "Fin hinges (deg)", "hinge", "deg", "hinge")),
            "servo_torque": Quantity("N m", "torque the right servo applies to its arm",
                                     plot=Plot("servo/torque", "Servo torque (N m)", "servo torque")),
            "stroke_y": Quantity("m", "body position at the start of each stroke, and at the end", per="stroke"),
            "eta": Quantity("1", "swimming efficiency (D1 - D2) / D1 of each flap cycle", per="cycle"),
        }

    def compared(self, scene: RobotScene) -> tuple[Compared, ...]:
        """Arm and fin hinge angles (deg) at the same instants, eta per cycle (points) and the body's position at
        the stroke ends (mm)."""
        return (Compared("angle_deg", ("arm_angle", "hinge_angle"), float(np.degrees(1.0))),
                Compared("eta_points", ("eta",), 100.0), Compared("body_mm", ("stroke_y",), 1e3))

    def start(self, scene: RobotScene, robot: RobotModel, d: mujoco.MjData, companion: bool) -> _SwimTrial:
        return _SwimTrial(self, scene, robot, d, companion)

    def check(self, run: Result) -> None:
        if not np.all(np.isfinite(run.stroke_y)):
            return  # the finite check names it
        for c, row in enumerate(self.cycle_table(run), start=1):
            if not row["D1_mm"] > 0:
                raise SimulationFailed(f"swim at dt {run.scene.sim.dt:g} s: eta is undefined in cycle {c}: its "
                                       f"power stroke moved the body {row['D1_mm']:+.3g} mm, not forward")

    def attrs(self) -> dict[str, Any]:
        return {"cycles": self.cycles}

    def independent(self, scene: RobotScene, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray:
        """The right fin's hinge angles (rad) of the independent solution (finrft.reference) at ``times``."""
        from .reference import solve_robot  # scipy's integrators load only when asked for
        # the forces a [medium] gives, as numbers: the reference writes out the laws, not their derivation
        resolved = geometry.resolve(scene)
        given = {"arm": resolved.arm, "body_drag": resolved.body_drag} if geometry.properties(scene) else {}
        if geometry.from_medium(scene):
            given["fin"] = resolved.chain
        return solve_robot(scene, self.cycles, times, rtol=rtol, atol=atol, **given).hinge_angle

    def cycle_table(self, run: Result) -> list[dict[str, float]]:
        """Per flap cycle: D2 (back in recovery), D1 (forward in the power stroke), eta, net distance and speed."""
        return _cycle_rows(run.stroke_y, self.cycles, run.cycle_time)

    def summary(self, run: Result) -> dict[str, Any]:
        """The last cycle's figures, per-cycle lists, the first cycle's eta and the steady figures (`steady`)."""
        rows = self.cycle_table(run)
        scene = run.scene
        g = scene.gait
        out: dict[str, Any] = dict(rows[-1])
        out.update({f"{key}_per_cycle": [row[key] for row in rows] for key in rows[-1]})
        out.update(eta_first_cycle=rows[0]["eta"], **{f"{key}_steady": value for key, value in steady(rows).items()})
        out.update(theta1_deg=float(np.degrees(g.theta1)), theta2_deg=float(np.degrees(g.theta2)),
                   arm_length_mm=1e3 * scene.arm.length, omega_deg_s=float(np.degrees(g.omega)),
                   fin=scene.fin.kind, model=scene.robot.model, cycles=int(self.cycles))
        out.update(geometry.resolve(scene).figures())
        return out

    def draw(self, rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
        from .views import draw_robot
        return draw_robot(rec, run, times, prefix)


def _cycle_rows(stroke_y: np.ndarray, cycles: int, cycle_time: float) -> list[dict[str, float]]:
    rows = []
    for c in range(cycles):
        y0, y1, y2 = (float(y) for y in stroke_y[2 * c: 2 * c + 3])
        back, forward = y0 - y1, y2 - y1
        rows.append({"D1_mm": 1e3 * forward, "D2_mm": 1e3 * back,
                     "eta": (forward - back) / forward if forward > 0 else float("nan"),
                     "net_mm": 1e3 * (y2 - y0), "net_speed_mm_s": 1e3 * (y2 - y0) / cycle_time})
    return rows


def steady(rows: list[dict[str, float]]) -> dict[str, float]:
    """eta, the mean D1 and D2 (mm) and the net speed (mm/s) over cycles 2..N of per-cycle rows (`_cycle_rows`),
    eta = (sum D1 - sum D2) / sum D1; the first cycle's with one row."""
    kept = rows[1:] or rows
    forward, back = sum(r["D1_mm"] for r in kept), sum(r["D2_mm"] for r in kept)
    return {"eta": (forward - back) / forward if forward > 0 else float("nan"), "D1_mm": forward / len(kept),
            "D2_mm": back / len(kept), "net_speed_mm_s": sum(r["net_speed_mm_s"] for r in kept) / len(kept)}


def steady_cycles(cycles: int) -> str:
    """The cycles `steady` takes, in words."""
    return "cycle 1" if cycles == 1 else "cycle 2" if cycles == 2 else f"cycles 2..{cycles}"


def gait_drive(scene: RobotScene, cycles: int) -> Drive:
    """The servo's motion: from theta2 up to theta1 and back at omega, ``cycles`` times."""
    g = scene.gait
    return Drive(kind="rotate", speed=g.omega, stroke=g.theta1 - g.theta2, cycles=cycles, start=g.theta2)


def _stroke_drag(robot: RobotModel, scene: RobotScene, d: mujoco.MjData, k: int) -> None:
    """The paper's body drag: a constant force against the fin's sweep in the current stroke, -y while the fin
    swings forward (recovery), +y while it swings back (power). It pushes the body the way the fin drives it."""
    drag = body_share(scene) * scene.body.drag
    d.xfrc_applied[robot.body, 1] = -drag if k % 2 == 0 else drag


class _SwimTrial:
    """One swim on one MjData. The paper's start: body at rest, arm and fin at theta2, the arm turning at omega,
    the fin still at rest in the world (its first hinge turns back at omega)."""

    def __init__(self, swim: Swim, scene: RobotScene, robot: RobotModel, d: mujoco.MjData, companion: bool) -> None:
        self.swim, self.scene, self.robot, self.d = swim, scene, robot, d
        self.drive = gait_drive(scene, swim.cycles)
        self.prescribed = scene.robot.servo == "prescribed"
        self.servos = Prescribed(robot.servo_dof, robot.servo_qpos, robot.armature, self.drive)
        d.qpos[robot.servo_qpos] = scene.gait.theta2
        d.qvel[robot.servo_dof] = scene.gait.omega
        if robot.fin_hinge_dof.shape[1]:
            d.qvel[robot.fin_hinge_dof[:, 0]] = -scene.gait.omega
        if not self.prescribed:
            d.act[:] = scene.gait.theta2
        self.stroke_y = np.zeros(self.drive.strokes + 1)
        n, hinges = scene.fin.segments, robot.fin_hinge_qpos[0]

        def hinge(d: mujoco.MjData) -> np.ndarray:
            q = np.zeros(n)
            q[:len(hinges)] = d.qpos[hinges]
            return q

        def torque(d: mujoco.MjData) -> float:
            return self.servos.load(d)[0] if self.prescribed else d.actuator_force[robot.actuators[0]]

        self.reads = {"body_y": lambda d: d.qpos[robot.travel_qpos], "arm_angle": lambda d: d.qpos[robot.servo_qpos[0]],
                      "hinge_angle": hinge}
        if not companion:
            self.reads["servo_torque"] = torque
        self.watch = [robot.travel_dof, *robot.fin_hinge_dof.ravel(), *([] if self.prescribed else robot.servo_dof)]

    def on_stroke(self, k: int) -> None:
        robot, d = self.robot, self.d
        self.stroke_y[k] = d.qpos[robot.travel_qpos]
        if self.prescribed:
            self.servos.start_stroke(robot.model, d, k)
        else:
            d.ctrl[robot.actuators] = self.drive.stroke_velocity(k)
        if self.scene.body.drag_law == "stroke":
            _stroke_drag(robot, self.scene, d, k)

    def finish(self, d: mujoco.MjData, readings: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                    dict[str, float]]:
        self.stroke_y[-1] = d.qpos[self.robot.travel_qpos]
        cycle_time = 2 * self.drive.stroke_time
        eta = np.array([row["eta"] for row in _cycle_rows(self.stroke_y, self.swim.cycles, cycle_time)])
        torque = readings.get("servo_torque", np.zeros(len(readings["body_y"])))
        return ({**readings, "servo_torque": torque, "stroke_y": self.stroke_y, "eta": eta},
                {"cycle_time": cycle_time})


def swim(scene: RobotScene, cycles: int = 1, *, progress: Callable[[float], None] | None = None,
         max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> Result:
    """Simulate ``cycles`` flap cycles from rest: `experiment.run` of `Swim(cycles)`, with an estimate of the
    discretisation error (``run.error_estimate``, from a companion run: see finrft.convergence). Raises
    SimulationUnstable rather than return a diverged run, SimulationFailed when eta is undefined (a power stroke
    that does not move the body forward), and InaccurateResult when the estimate exceeds ``max_error`` (None:
    report it only). ``estimate_error=False`` skips the estimate, for studies that measure the error themselves."""
    return run(Swim(cycles), scene, progress=progress, max_error=max_error, estimate_error=estimate_error)


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

