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

import argparse
import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable

import mujoco
import numpy as np

from .. import geometry, media, native
from ..convergence import ErrorLimits
from ..errors import SimulationFailed, UndefinedResult
from ..drive import Drive
from ..experiment import Compared, Plot, Quantity, Result, run
from ..geometry import Resolved, resolve
from ..laws import SegmentLaw
from ..models import (ARMATURE_RATIO, AttachedChain, ForceGroup, addresses, attach_chain, bind_plugin, compile_spec,
                      force_group, new_spec, penalty_stiffness)
from ..scene import (IN_MM, RFT, Chain, Immersion, SceneError, Sections, Sim, check_chain_law, check_sim,
                     load_scene, parse_override, register_scene, resolution)
from ..schema import field as _f
from ..stepping import Prescribed
from ..views import centre_line
from .command import Command, authors_model_line, error_line, register, steps_line
from .flags import add_max_error, add_result_files, add_scene_flags, number, preset_name


SIGN_CONVENTION = (
    "Forward is +y, along the body's slide. The right arm's angle is 0 pointing sideways (+x) and +90 deg pointing "
    "forward; fin hinge angles are negative when the fin folds. The servo torque is what the servo applies to its "
    "arm about +z.")


# The robot's scene: its sections, beside the shared ones of finrft.scene (the fin is a `Chain`).

@dataclass(frozen=True)
class Robot:
    model: str = _f("half", "", "full: body and both arms; half: body and the right arm, with half the body's mass "
                    "and drag (the paper's shortcut for symmetric gaits)", choices=("half", "full"))
    servo: str = _f("prescribed", "", "prescribed: the arm follows the gait exactly; position: a stiff servo "
                    "tracks it", choices=("prescribed", "position"))
    servo_kp: float = _f(50.0, "N m/rad", "position servo stiffness (servo = position); critically damped",
                         minimum=0.0)


@dataclass(frozen=True)
class Body:
    mass: float = _f(0.309, "kg", "mass of the whole robot's body (the half model carries half)", minimum=0.0)
    drag: float = _f(2.4612, "N", "body drag of the whole robot (the half model carries half)", minimum=0.0,
                     exclusive=False)
    drag_law: str = _f("velocity", "", "velocity: rate-independent, against the body's velocity (tanh below "
                       "v_reg); stroke: the paper's shortcut, a constant force against the fin's sweep in the current "
                       "stroke",
                       choices=("velocity", "stroke"))
    v_reg: float = _f(0.001, "m/s", "regularisation speed of the velocity body drag", minimum=0.0)
    height: float = _f(0.045, "m", "with [medium]: body height H_r, its top edge at medium.depth",
                       minimum=0.0)
    width: float = _f(0.055, "m", "with [medium]: body width W_r, the front face", minimum=0.0)
    length: float = _f(0.075, "m", "with [medium]: body length L_r, along its axis", minimum=0.0)
    cart: float = _f(0.0, "N", "with [medium]: the cart's rolling resistance, against the body's motion (whole "
                     "robot)", minimum=0.0, exclusive=False)


@dataclass(frozen=True)
class Arm:
    length: float = _f(0.065, "m", "arm length L_a, pivot to the fin's first hinge", minimum=0.0, maximum=1.0,
                       why_maximum=IN_MM)
    pivot: float = _f(0.0275, "m", "distance of the arm's pivot from the body's axis", minimum=0.0,
                      exclusive=False)
    mass_base: float = _f(0.001158, "kg", "arm mass at zero length (servo horn)", minimum=0.0, exclusive=False)
    linear_density: float = _f(0.1445, "kg/m", "arm mass per length", minimum=0.0, exclusive=False)
    inertia: float = _f(1e-6, "kg m^2", "arm inertia about z through its centre", minimum=0.0)
    f_perp_base: float = _f(2.0, "N", "arm RFT normal coefficient: f_perp_base + f_perp_per_length * length",
                            minimum=0.0, exclusive=False)
    f_perp_per_length: float = _f(17940.0, "N/m", "arm RFT normal coefficient per arm length", minimum=0.0,
                                  exclusive=False)
    f_par: float = _f(-0.3, "N", "arm RFT tangential coefficient")
    height: float = _f(0.010, "m", "with [medium]: the arm's height, its top edge at medium.depth", minimum=0.0)


@dataclass(frozen=True)
class Gait:
    theta1: float = _f(1.0471975511965976, "rad", "arm angle at the end of the recovery stroke (0 = sideways, "
                       "+90 deg = forward)")
    theta2: float = _f(-1.5707963267948966, "rad", "arm angle at the end of the power stroke; the gait starts here")
    omega: float = _f(1.1519173063162575, "rad/s", "arm angular speed", minimum=0.0)
    cycles: int = _f(1, "", "flap cycles a gait is evaluated over (table, optimize): 1, the first cycle from rest; "
                     "N >= 2, eta over the steady cycles 2..N", minimum=1, exclusive=False)


@dataclass(frozen=True)
class RobotScene(Sections):
    """The two-fin robot: body, arms, fins, the RFT law on the fin segments, the gait and the numerics."""

    robot: Robot = field(default_factory=Robot)
    body: Body = field(default_factory=Body)
    arm: Arm = field(default_factory=Arm)
    fin: Chain = field(default_factory=lambda: Chain(segments=3, segment_length=0.02, segment_mass=0.00795,
                                                     segment_inertia=2.65e-7, stiffness=0.5879, damping=0.4399,
                                                     stop_stiffness=100.0))
    # the authors' 6.779 N and -1 N per 20 mm fin segment, over its face 20 x 55 mm at 37.5 mm mean depth
    rft: RFT = field(default_factory=lambda: RFT(f_perp=164339.39393939395, f_par=-24242.424242424244))
    medium: Immersion = field(default_factory=Immersion)
    gait: Gait = field(default_factory=Gait)
    sim: Sim = field(default_factory=Sim)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_chain_law(self)
        check_sim(self.sim)
        g = self.gait
        for key in ("theta1", "theta2"):
            if abs(getattr(g, key)) > math.pi / 2 + 1e-12:
                raise SceneError(f"gait.{key} = {math.degrees(getattr(g, key)):g} deg is outside the servo's range "
                                 f"-90..90 deg")
        if g.theta1 <= g.theta2:
            raise SceneError(f"gait.theta1 ({math.degrees(g.theta1):g} deg) must be greater than gait.theta2 "
                             f"({math.degrees(g.theta2):g} deg)")
        if self.body.drag_law != "velocity" and media.immersion_properties(self.medium) is not None:
            raise SceneError("a robot in a [medium] is resisted against its body's velocity (its faces and the "
                             "cart): set body.drag_law = 'velocity'")


PRESETS = ("paper", "physical")
register_scene(RobotScene, presets=PRESETS, prefix="robot",
               title="The two-fin robot: `finrft swim`, `table`, `optimize`; `finrft.RobotScene`")


# The robot's model, built from mjcf/robot.xml and the chain builder (finrft.models).

@dataclass(frozen=True)
class RobotModel:
    """A compiled robot model and the indices the simulation needs."""

    model: mujoco.MjModel
    backend: str
    sides: tuple[str, ...]     # ("r",) for the half robot, ("r", "l") for the full one
    travel_qpos: int           # the body's slide along +y
    travel_dof: int
    body: int
    servo_qpos: np.ndarray     # (S,) per side
    servo_dof: np.ndarray
    armature: float            # prescribed servos: their armature; 0 with position servos
    actuators: np.ndarray      # position servos' actuator ids (empty when prescribed)
    fin_hinge_qpos: np.ndarray  # (S, H) fin hinges per side (H = 0 for a rigid fin)
    fin_hinge_dof: np.ndarray   # (S, H)
    fin_sites: np.ndarray      # (S, N) fin segment midpoints per side
    groups: tuple[ForceGroup, ...]
    resolved: Resolved         # the forces the scene's medium and geometry give (finrft.geometry.resolve)


# The largest distance a position servo's arm may be off its gait, at any recorded sample, as a share of the stroke:
# beyond it the run measures another gait, as a prescribed drive's DRIVE_LAG. Measured: the physical robot's servo
# misses by 1.1 % (1.7 deg of 150) at kp 50 N m/rad and by 11 % at kp 5; the authors' robot with real inertias by
# 0.8 % at kp 200, with its arm and fin of 1 kg m^2 by 16 % at kp 50 (refused).
SERVO_MISS = 0.05
# eta = (D1 - D2) / D1 is undefined when the power stroke moves the body forward by less than this share of the fin
# tip's sweep: a D1 of rounding errors (a servo that never moved: 2e-12 mm) gave eta = +355 %.
MIN_FORWARD = 1e-3


def sweep_length(scene: RobotScene) -> float:
    """The arc the fin's tip sweeps in one stroke, the arm and fin laid straight (m)."""
    g = scene.gait
    return (scene.arm.length + scene.fin.segments * scene.fin.segment_length) * (g.theta1 - g.theta2)


def body_share(scene: RobotScene) -> float:
    """The share of the body's mass and drag a model carries: all of it, or half for the half robot."""
    return 0.5 if scene.robot.model == "half" else 1.0


def body_law(scene: RobotScene, resolved: Resolved) -> SegmentLaw:
    """The velocity body drag as an isotropic law: F = -tanh(|v|/v_reg) drag v/|v|, the model's share of the whole
    robot's resolved body drag."""
    drag = body_share(scene) * resolved.body_drag
    return SegmentLaw("paper", scene.body.v_reg, {"f_perp": drag, "f_par": drag})


@dataclass(frozen=True)
class _Robot:
    spec: mujoco.MjSpec
    travel: mujoco.MjsJoint
    body: mujoco.MjsBody
    arms: list[mujoco.MjsBody]            # per side
    servos: list[mujoco.MjsJoint]
    actuators: list[mujoco.MjsActuator]   # position servos, per side (empty when prescribed)
    fins: list[AttachedChain]


def _robot(scene: RobotScene, backend: str, resolved: Resolved) -> _Robot:
    spec = new_spec("robot.xml", scene.sim)
    r, a, fin = scene.robot, scene.arm, scene.fin
    sides = ("r",) if r.model == "half" else ("r", "l")
    if r.model == "half":
        spec.delete(spec.body("l_arm"))
    body = spec.body("body")
    body.mass = body_share(scene) * scene.body.mass
    arm_mass = a.mass_base + a.linear_density * a.length
    # What a servo turns, about its pivot: the arm and the fin laid straight out.
    moved = a.inertia + arm_mass * (a.length / 2) ** 2 + sum(
        fin.segment_inertia + fin.segment_mass * (a.length + (i + 0.5) * fin.segment_length) ** 2
        for i in range(fin.segments))
    robot = _Robot(spec, spec.joint("travel"), body, [], [], [], [])
    for side in sides:
        arm = spec.body(f"{side}_arm")
        arm.pos = [a.pivot if side == "r" else -a.pivot, 0, 0]
        arm.mass, arm.ipos, arm.inertia = arm_mass, [a.length / 2, 0, 0], [a.inertia] * 3
        spec.geom(f"{side}_arm").fromto = [0, 0, 0, a.length, 0, 0]
        spec.site(f"{side}_arm").pos = [a.length / 2, 0, 0]
        mount = spec.frame(f"{side}_fin")
        mount.pos = [a.length, 0, 0]
        robot.fins.append(attach_chain(spec, mount, fin, scene.sim.dt, f"{side}_"))
        robot.arms.append(arm)
        servo = spec.joint(f"{side}_servo")
        robot.servos.append(servo)
        if r.servo == "prescribed":
            servo.armature = ARMATURE_RATIO * moved
        else:
            actuator = spec.add_actuator(name=f"{side}_servo", target=servo.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            actuator.set_to_intvelocity(kp=r.servo_kp, dampratio=1.0)
            actuator.actlimited = mujoco.mjtLimited.mjLIMITED_TRUE
            actuator.actrange = [scene.gait.theta2, scene.gait.theta1]
            robot.actuators.append(actuator)
    if backend == "native":
        bind_plugin(spec, "fin_sand", resolved.chain, penalty_stiffness(fin), _fin_bodies(robot))
        bind_plugin(spec, "arm_sand", resolved.arm, 0.0, robot.arms)
        if scene.body.drag_law == "velocity":
            bind_plugin(spec, "body_sand", body_law(scene, resolved), 0.0, [body])
    spec.modelname = f"finrft robot ({r.model}, {fin.kind} fins)"
    return robot


def _fin_bodies(robot: _Robot) -> list[mujoco.MjsBody]:
    return [b for fin in robot.fins for b in fin.bodies]


def robot_spec(scene: RobotScene, backend: str = "python") -> mujoco.MjSpec:
    """The robot's MjSpec for a scene (see mjcf/robot.xml)."""
    return _robot(scene, backend, resolve(scene)).spec


def build_robot(scene: RobotScene) -> RobotModel:
    """Compile the robot model for a scene and collect its indices."""
    backend = native.resolve_backend(scene.sim.backend)
    resolved = resolve(scene)
    robot = _robot(scene, backend, resolved)
    model = compile_spec(robot.spec)
    fin = scene.fin
    sides = ("r",) if scene.robot.model == "half" else ("r", "l")
    groups = [force_group(model, "fin_sand", resolved.chain, penalty_stiffness(fin), _fin_bodies(robot)),
              force_group(model, "arm_sand", resolved.arm, 0.0, robot.arms)]
    if scene.body.drag_law == "velocity":
        groups.append(force_group(model, "body_sand", body_law(scene, resolved), 0.0, [robot.body]))
    (travel_qpos,), (travel_dof,) = addresses(model, [robot.travel])
    servo_qpos, servo_dof = addresses(model, robot.servos)
    hinges = [addresses(model, chain.hinges) for chain in robot.fins]
    prescribed = scene.robot.servo == "prescribed"
    return RobotModel(
        model=model,
        backend=backend,
        sides=sides,
        travel_qpos=int(travel_qpos),
        travel_dof=int(travel_dof),
        body=robot.body.id,
        servo_qpos=servo_qpos,
        servo_dof=servo_dof,
        armature=float(model.dof_armature[servo_dof[0]]) if prescribed else 0.0,
        actuators=np.array([u.id for u in robot.actuators], dtype=int),
        fin_hinge_qpos=np.array([q for q, _ in hinges], dtype=int).reshape(len(sides), -1),
        fin_hinge_dof=np.array([d for _, d in hinges], dtype=int).reshape(len(sides), -1),
        fin_sites=np.array([[b.sites[0].id for b in chain.bodies] for chain in robot.fins]),
        groups=tuple(groups),
        resolved=resolved,
    )


@dataclass(frozen=True)
class Swim:
    """``cycles`` flap cycles of the robot from rest, as an experiment (finrft.experiment). Its result's series,
    SI units, arm and fin quantities the right side's: ``body_y`` (T,), ``arm_angle`` (T,), ``hinge_angle``
    (T, N), ``servo_torque`` (T,), ``stroke_y`` per stroke and at the end, ``eta`` per cycle; ``run.cycle_time``."""

    cycles: int = 1
    name = "swim"
    scene_type = RobotScene
    schema = "finrft.swim/1"
    sign_convention = SIGN_CONVENTION
    shape = "hinge_angle"  # the series whose angles give the fin's shape
    load = "servo_torque"  # the series of the drive's load

    def __post_init__(self) -> None:
        if isinstance(self.cycles, bool) or not isinstance(self.cycles, numbers.Integral) or self.cycles < 1:
            raise SceneError(f"swim cycles must be a whole number >= 1, got {self.cycles!r}")
        object.__setattr__(self, "cycles", int(self.cycles))

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
        if not (np.all(np.isfinite(run.stroke_y)) and np.all(np.isfinite(run.arm_angle))):
            return  # the finite check names it
        scene = run.scene
        drive = self.drive_for(scene)
        if scene.robot.servo == "position":
            miss = np.abs(run.arm_angle - drive.positions(run.time))
            worst = int(np.argmax(miss))
            if miss[worst] > SERVO_MISS * drive.stroke:
                raise SimulationFailed(
                    f"the position servo missed its gait by {np.degrees(miss[worst]):.3g} deg at t = "
                    f"{run.time[worst]:.4g} s ({100 * miss[worst] / drive.stroke:.3g} % of the stroke; at most "
                    f"{100 * SERVO_MISS:g} %): the figures would be another gait's: raise robot.servo_kp (now "
                    f"{scene.robot.servo_kp:g} N m/rad), or use robot.servo = 'prescribed'")
        sweep = sweep_length(scene)
        for c, row in enumerate(self.cycle_table(run), start=1):
            if not row["D1_mm"] > 1e3 * MIN_FORWARD * sweep:
                raise UndefinedResult(f"swim at dt {scene.sim.dt:g} s: eta is undefined in cycle {c}: its power "
                                      f"stroke moved the body {row['D1_mm']:+.3g} mm, not forward by more than "
                                      f"{100 * MIN_FORWARD:g} % of the fin tip's sweep ({1e3 * sweep:.3g} mm)")

    def attrs(self) -> dict[str, Any]:
        return {"cycles": self.cycles}

    def independent(self, scene: RobotScene, times: np.ndarray, *, rtol: float, atol: float) -> np.ndarray:
        """The right fin's hinge angles (rad) of the independent solution (finrft.reference) at ``times``."""
        from ..reference import solve_robot  # scipy's integrators load only when asked for
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
        return draw_robot(rec, run, times, prefix)


def robot_points(run: Result) -> np.ndarray:
    """The right arm and fin's centre line, (T, N + 2, 3) m: pivot, arm tip (first hinge), hinges, fin tip."""
    a, f = run.scene.arm, run.scene.fin
    count = len(run.time)
    pivot = np.zeros((count, 3))
    pivot[:, 0], pivot[:, 1] = a.pivot, run.body_y
    angles = np.column_stack([run.arm_angle, run.arm_angle[:, None] + np.cumsum(run.hinge_angle, axis=1)])
    return centre_line(pivot, angles, a.length, f)


def draw_robot(rec: Any, run: Result, times: Any, prefix: str) -> list[Any]:
    """The robot's right half from above: the body as a box outline, arm and fin as a line."""
    import rerun as rr  # loads only when a recording is written
    import rerun.blueprint as rrb
    points = robot_points(run)
    half_width, half_length = run.scene.arm.pivot, 0.0375
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]) * [half_width, half_length]
    outline = np.zeros((len(run.time), 5, 3))
    outline[..., :2] = corners
    outline[..., 1] += run.body_y[:, None]
    rec.log(f"{prefix}robot", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(f"{prefix}robot/body", rr.LineStrips3D.from_fields(colors=[[90, 110, 160]], radii=[0.0008]),
            static=True)
    rec.send_columns(f"{prefix}robot/body", indexes=[times], columns=rr.LineStrips3D.columns(strips=outline))
    rec.log(f"{prefix}robot/fin", rr.LineStrips3D.from_fields(colors=[[60, 60, 70]], radii=[0.0008]), static=True)
    rec.send_columns(f"{prefix}robot/fin", indexes=[times], columns=rr.LineStrips3D.columns(strips=points))
    eye = rrb.EyeControls3D(position=[0.0, 0.0, 0.6], look_target=[0.0, 0.0, 0.0], eye_up=[0.0, 1.0, 0.0])
    return [rrb.Spatial3DView(name="Robot (top view)", origin=f"{prefix}robot", eye_controls=eye,
                              line_grid=rrb.LineGrid3D(spacing=0.01))]


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


# ---------------------------------------------------------------------------------------------------------
# The command: finrft swim

PRESETS_HELP = ("built-in robot scene when no --scene is given (default: physical): physical = real inertias, "
                "penalty stops, velocity body drag (against the body's velocity), adaptive-newton method; paper = "
                "the authors' model with its quirks: inertias of 1 kg m^2, a law that feeds energy in, penalty "
                "stops, stroke body drag (a constant force against the fin's sweep), adaptive method")


def add_robot(p: argparse.ArgumentParser) -> None:
    """The robot scene's flags (also those of the studies on the robot: optimize, table)."""
    g = add_scene_flags(p, "robot", "fin.stiffness=0.4", presets=PRESETS, presets_help=PRESETS_HELP,
                        title="robot scene", backend="")
    g.add_argument("--fin", choices=("origami", "soft", "rigid"), help="fin kind (overrides fin.kind)")
    g.add_argument("--model", choices=("full", "half"), help="full robot, or its right half with half the body's "
                   "mass and drag (overrides robot.model)")
    g.add_argument("--backend", choices=("native", "python"), help="where the RFT force is computed")


# Flags that set a scene key, with the factor from the CLI's units to SI.
_GAIT_FLAGS = (("theta1", "gait.theta1", math.pi / 180), ("theta2", "gait.theta2", math.pi / 180),
               ("arm_length", "arm.length", 1e-3), ("omega", "gait.omega", math.pi / 180))


def resolve_robot(args: argparse.Namespace) -> RobotScene:
    """The robot scene of --scene or --preset, --set, the kind flags and (for swim) the gait flags."""
    overrides = dict(parse_override(item, RobotScene) for item in args.set)
    for flag, key in (("fin", "fin.kind"), ("model", "robot.model"), ("backend", "sim.backend")):
        if getattr(args, flag, None):
            overrides[key] = getattr(args, flag)
    for flag, key, scale in _GAIT_FLAGS:
        if getattr(args, flag, None) is not None:
            overrides[key] = getattr(args, flag) * scale
    return load_scene(args.scene, preset_name=preset_name(args), overrides=overrides, cls=RobotScene)


@register
class SwimCommand(Command):
    name = "swim"
    help = "the two-fin robot swimming: flap cycles and the swimming efficiency"
    description = ("Simulate the robot's flap cycles from rest, the arm at theta2: recovery stroke up to theta1, "
                   "power stroke back. Reports eta = (D1 - D2) / D1 with D1 the distance forward in the power stroke "
                   "and D2 the distance back in the recovery stroke.")

    def add_flags(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("--theta1", type=number("degrees", minimum=-math.inf), metavar="DEG",
                       help="arm angle at the end of the recovery stroke, degrees in -90..90 (0 sideways, 90 "
                            "forward; default: the scene's, 60 in the presets)")
        p.add_argument("--theta2", type=number("degrees", minimum=-math.inf), metavar="DEG",
                       help="arm angle at the end of the power stroke, degrees (default: the scene's, -90 in the "
                            "presets)")
        p.add_argument("--arm-length", type=number("mm"), metavar="MM",
                       help="arm length L_a in mm (default: the scene's, 65 in the presets)")
        p.add_argument("--omega", type=number("deg/s"), metavar="DEG_S",
                       help="arm angular speed in degrees/s (default: the scene's, 66 in the presets)")
        p.add_argument("--cycles", type=number("cycles", minimum=1, inclusive=True, integer=True),
                       metavar="N", help="flap cycles (default: the scene's gait.cycles: 1 in the paper preset, 2 "
                       "in the physical one); figures are the last cycle's, and eta over cycles 2..N")
        add_robot(p)
        add_max_error(p)
        add_result_files(p)

    def scene(self, args: argparse.Namespace) -> RobotScene:
        return resolve_robot(args)

    def jobs(self, args: argparse.Namespace, scene: RobotScene) -> list[tuple[Swim, RobotScene]]:
        return [(Swim(args.cycles or scene.gait.cycles), scene)]

    def describe(self, args: argparse.Namespace, runs: list[Result]) -> str:
        run, = runs
        scene, summary = run.scene, run.summary()
        lines = [*authors_model_line(args, scene),
                 f"{scene.robot.model} robot, {scene.fin.kind} fin, theta1 {summary['theta1_deg']:g} deg, theta2 "
                 f"{summary['theta2_deg']:g} deg, arm {summary['arm_length_mm']:g} mm, omega "
                 f"{summary['omega_deg_s']:g} deg/s, {resolution(scene.sim)} ({run.backend}): {steps_line(summary)} "
                 f"in {run.wall_s:.2f} s"]
        for i, row in enumerate(run.cycle_table(), start=1):
            lines.append(f"cycle {i}: eta {100 * row['eta']:+.2f} %, forward D1 {row['D1_mm']:.2f} mm, back D2 "
                         f"{row['D2_mm']:.2f} mm, net {row['net_mm']:+.2f} mm ({row['net_speed_mm_s']:+.3f} mm/s)")
        lines.append(error_line(run))
        return "\n".join(lines)
