"""The two-fin robot swimming: flap cycles of the gait and the swimming efficiency.

A flap cycle starts at arm angle theta2 with the recovery stroke (the arm swings forward to theta1 at omega,
the fin folds) and ends with the power stroke (back to theta2, the fin flat against its stops). The body moves
back by D2 in the recovery stroke and forward by D1 in the power stroke; the paper's swimming efficiency is
eta = (D1 - D2) / D1. The robot starts at rest, arm and fin at theta2, the arm turning at omega.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import mujoco
import numpy as np

from .convergence import ErrorLimits, Estimated, SimulationFailed, checked, max_difference, paired, require_finite
from .coupling import PythonCoupling, installed
from .drive import Drive
from .integrate import stepper
from .models import RobotModel, body_share, build_robot
from .scene import RobotScene
from .simulate import Prescribed, schedule, step_through


@dataclass
class SwimRun(Estimated):
    """Results of a swim, SI units; arm and fin quantities are the right side's."""

    scene: RobotScene
    cycles: int
    time: np.ndarray           # (T,) s
    body_y: np.ndarray         # (T,) m, body position along the travel axis (+y forward)
    arm_angle: np.ndarray      # (T,) rad, right arm (0 sideways, +pi/2 forward)
    hinge_angle: np.ndarray    # (T, N) rad, right fin hinges (zeros for a rigid fin)
    servo_torque: np.ndarray   # (T,) N m, what the right servo applies to its arm
    stroke_y: np.ndarray       # (2 cycles + 1,) m, body position at the start of each stroke and at the end
    steps: int                 # steps taken (the adaptive method's accepted steps)
    wall_s: float
    backend: str
    steps_rejected: int = 0    # the adaptive method's rejected steps, and newton's halved ones

    @property
    def cycle_time(self) -> float:
        g = self.scene.gait
        return 2 * (g.theta1 - g.theta2) / g.omega

    @property
    def stroke_time(self) -> float:
        return self.cycle_time / 2

    def differences(self, other: SwimRun) -> dict[str, float]:
        """Largest differences from a swim at another resolution: arm and fin hinge angles (deg) at the same
        instants, eta per cycle (points) and the body's position at the stroke ends (mm)."""
        i, j = paired(self.time, other.time)
        angles = max(max_difference(self.arm_angle[i], other.arm_angle[j]),
                     max_difference(self.hinge_angle[i], other.hinge_angle[j]))
        eta = [max_difference(np.array([a["eta"]]), np.array([b["eta"]]))
               for a, b in zip(self.cycle_table(), other.cycle_table())]
        return {"angle_deg": float(np.degrees(angles)), "eta_points": 100 * max(eta),
                "body_mm": 1e3 * max_difference(self.stroke_y, other.stroke_y)}

    def cycle_table(self) -> list[dict[str, float]]:
        """Per flap cycle: D2 (back in recovery), D1 (forward in the power stroke), eta, net distance and speed."""
        rows = []
        for c in range(self.cycles):
            y0, y1, y2 = (float(y) for y in self.stroke_y[2 * c: 2 * c + 3])
            back, forward = y0 - y1, y2 - y1
            rows.append({"D1_mm": 1e3 * forward, "D2_mm": 1e3 * back,
                         "eta": (forward - back) / forward if forward > 0 else float("nan"),
                         "net_mm": 1e3 * (y2 - y0), "net_speed_mm_s": 1e3 * (y2 - y0) / self.cycle_time})
        return rows

    def summary(self) -> dict[str, Any]:
        """The figures `finrft swim --json` prints: the last cycle's, and per-cycle lists; plain Python numbers."""
        rows = self.cycle_table()
        g = self.scene.gait
        out: dict[str, Any] = dict(rows[-1])
        out.update({f"{key}_per_cycle": [row[key] for row in rows] for key in rows[-1]})
        out.update(theta1_deg=float(np.degrees(g.theta1)), theta2_deg=float(np.degrees(g.theta2)),
                   arm_length_mm=1e3 * self.scene.arm.length, omega_deg_s=float(np.degrees(g.omega)),
                   fin=self.scene.fin.kind, model=self.scene.robot.model, cycles=int(self.cycles),
                   steps=int(self.steps), steps_rejected=int(self.steps_rejected), sim_time_s=float(self.time[-1]),
                   wall_s=float(self.wall_s), backend=self.backend, integrator=self.scene.sim.integrator,
                   dt=float(self.scene.sim.dt))
        if self.error_estimate is not None:
            out.update(error_estimate=dict(self.error_estimate), error_companion=self.error_companion)
        return out


def gait_drive(scene: RobotScene, cycles: int) -> Drive:
    """The servo's motion: from theta2 up to theta1 and back at omega, ``cycles`` times."""
    g = scene.gait
    return Drive(kind="rotate", speed=g.omega, stroke=g.theta1 - g.theta2, cycles=cycles, start=g.theta2)


def _stroke_drag(robot: RobotModel, scene: RobotScene, d: mujoco.MjData, k: int) -> None:
    """The paper's body drag: a constant force against the fin's sweep in the current stroke, -y while the fin
    swings forward (recovery), +y while it swings back (power). It pushes the body the way the fin drives it."""
    drag = body_share(scene) * scene.body.drag
    d.xfrc_applied[robot.body, 1] = -drag if k % 2 == 0 else drag


def swim(scene: RobotScene, cycles: int = 1, *, progress: Callable[[float], None] | None = None,
         max_error: ErrorLimits | None = ErrorLimits(), estimate_error: bool = True) -> SwimRun:
    """Simulate ``cycles`` flap cycles from rest, with an estimate of the discretisation error
    (``run.error_estimate``, from a companion run: see finrft.convergence). Raises SimulationUnstable rather than
    return a diverged run, SimulationFailed when eta is undefined (a power stroke that does not move the body
    forward), and InaccurateResult when the estimate exceeds ``max_error`` (None: report it only).
    ``estimate_error=False`` skips the estimate, for studies that measure the error themselves."""
    return checked(build_robot, lambda s, robot, p, companion: _swim(s, cycles, robot, p, companion), scene,
                   progress, max_error, estimate_error)


def _swim(scene: RobotScene, cycles: int, robot: RobotModel, progress: Callable[[float], None] | None,
          companion: bool) -> SwimRun:
    start = time.perf_counter()
    m = robot.model
    d = mujoco.MjData(m)
    drive = gait_drive(scene, cycles)
    steps, starts, samples = schedule(drive, scene.sim.dt, scene.sim.record_dt)
    prescribed = scene.robot.servo == "prescribed"
    servos = Prescribed(robot.servo_dof, robot.servo_qpos, robot.armature, drive)
    callback = PythonCoupling(robot.groups) if robot.backend == "python" else None

    # The paper's start: body at rest, arm and fin at theta2, the arm turning at omega, the fin still at rest
    # in the world (its first hinge turns back at omega).
    d.qpos[robot.servo_qpos] = scene.gait.theta2
    d.qvel[robot.servo_dof] = scene.gait.omega
    if robot.fin_hinge_dof.shape[1]:
        d.qvel[robot.fin_hinge_dof[:, 0]] = -scene.gait.omega
    if not prescribed:
        d.act[:] = scene.gait.theta2
    stroke_y = np.zeros(drive.strokes + 1)
    n = scene.fin.segments
    rec = {"y": np.zeros(len(samples)), "arm": np.zeros(len(samples)), "hinge": np.zeros((len(samples), n)),
           "torque": np.zeros(len(samples))}
    hinges = robot.fin_hinge_qpos[0]

    def on_stroke(k: int) -> None:
        stroke_y[k] = d.qpos[robot.travel_qpos]
        if prescribed:
            servos.start_stroke(m, d, k)
        else:
            d.ctrl[robot.actuators] = drive.stroke_velocity(k)
        if scene.body.drag_law == "stroke":
            _stroke_drag(robot, scene, d, k)

    def on_sample(i: int) -> None:
        rec["y"][i] = d.qpos[robot.travel_qpos]
        rec["arm"][i] = d.qpos[robot.servo_qpos[0]]
        rec["hinge"][i, :len(hinges)] = d.qpos[hinges]
        if not companion:
            rec["torque"][i] = servos.load(d)[0] if prescribed else d.actuator_force[robot.actuators[0]]

    advance = stepper(m, scene.sim, robot.backend, robot.groups)
    with installed(callback):
        free = [] if companion else [robot.travel_dof, *robot.fin_hinge_dof.ravel(),
                                     *([] if prescribed else robot.servo_dof)]
        step_through(m, d, scene, advance, steps, starts, samples, on_stroke, on_sample, progress, free,
                     forward=not companion)
    stroke_y[-1] = d.qpos[robot.travel_qpos]
    run = SwimRun(scene=scene, cycles=cycles, time=samples * scene.sim.dt, body_y=rec["y"], arm_angle=rec["arm"],
                  hinge_angle=rec["hinge"], servo_torque=rec["torque"], stroke_y=stroke_y, steps=advance.taken,
                  wall_s=time.perf_counter() - start, backend=robot.backend, steps_rejected=advance.rejected)
    what = f"swim at dt {scene.sim.dt:g} s"
    require_finite({**rec, "stroke_y": stroke_y}, what)
    for c, row in enumerate(run.cycle_table(), start=1):
        if not row["D1_mm"] > 0:
            raise SimulationFailed(f"{what}: eta is undefined in cycle {c}: its power stroke moved the body "
                                   f"{row['D1_mm']:+.3g} mm, not forward")
    return run


# The paper's Table I: (name, theta1 deg, theta2 deg, L_a mm, fin, eta_exp %, eta_sim %, net speed mm/s exp).
PAPER_TABLE = (
    ("Optimized", 60, -90, 65, "origami", 8.61, 8.95, 1.69),
    ("Symmetry 1", 30, -30, 65, "origami", 1.22, 0.06, 0.48),
    ("Symmetry 2", 30, -30, 75, "origami", 1.08, 0.05, 0.59),
    ("Asymmetry 1", 90, 0, 65, "origami", 3.12, 3.71, 0.34),
    ("Asymmetry 2", 90, 0, 75, "origami", 3.57, 3.65, 0.43),
    ("Rigid fin", 60, -90, 65, "rigid", 0.11, 1.02, 0.02),
)


def table_scenes(scene: RobotScene) -> list[RobotScene]:
    """The scene of each gait of the paper's Table I."""
    return [scene.replace(**{"gait.theta1": np.radians(t1), "gait.theta2": np.radians(t2),
                             "arm.length": la / 1000, "fin.kind": fin})
            for _, t1, t2, la, fin, *_ in PAPER_TABLE]


def table_rows(runs: list[SwimRun]) -> list[dict[str, Any]]:
    """Table I rows: finrft's eta (the paper's definition), the authors' script measure |net| / D1, the
    distances and the net speed, beside the paper's figures."""
    rows = []
    for (name, t1, t2, la, fin, eta_exp, eta_sim, speed_exp), run in zip(PAPER_TABLE, runs):
        s = run.summary()
        rows.append({"gait": name, "theta1_deg": t1, "theta2_deg": t2, "arm_length_mm": la, "fin": fin,
                     "eta": s["eta"], "eta_script": abs(s["net_mm"]) / s["D1_mm"], "D1_mm": s["D1_mm"],
                     "D2_mm": s["D2_mm"], "net_speed_mm_s": s["net_speed_mm_s"], "paper_eta_sim": eta_sim / 100,
                     "paper_eta_exp": eta_exp / 100, "paper_net_speed_exp_mm_s": speed_exp,
                     "error_estimate": s.get("error_estimate")})
    return rows


def table_markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| gait | Θ1 ° | Θ2 ° | L_a mm | fin | η % | \\|net\\|/D1 % | paper η_sim % | paper η_exp % | D1 mm | "
             "D2 mm | net speed mm/s | paper speed mm/s |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['gait']} | {r['theta1_deg']} | {r['theta2_deg']} | {r['arm_length_mm']} | {r['fin']} | "
                     f"{100 * r['eta']:.2f} | {100 * r['eta_script']:.2f} | {100 * r['paper_eta_sim']:.2f} | "
                     f"{100 * r['paper_eta_exp']:.2f} | {r['D1_mm']:.1f} | {r['D2_mm']:.1f} | "
                     f"{r['net_speed_mm_s']:.2f} | {r['paper_net_speed_exp_mm_s']:.2f} |")
    return "\n".join(lines)


def swim_job(job: tuple[RobotScene, int, ErrorLimits | None]) -> SwimRun:
    """`swim` of a (scene, cycles, max_error) job: the module-level function a process pool can send to its
    workers."""
    scene, cycles, max_error = job
    return swim(scene, cycles, max_error=max_error)
