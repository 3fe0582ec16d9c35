"""An independent solution of the plate's equations of motion, without MuJoCo.

The plate is written in absolute segment angles phi_k and integrated with scipy at tight tolerance. The equations
come from the principle of virtual work, derived by hand: with segment midpoints
``r_i = P(t) + sum_j c_ij l e(phi_j)`` (c_ij = 1 for j < i, 1/2 for j = i), P the rod's tip,

    sum_j A_kj phi''_j = Q_k - sum_i m_i c_ik l e_perp(phi_k) . (P'' - sum_j c_ij l e(phi_j) phi'_j^2)
    A_kj = I_k delta_kj + l^2 cos(phi_k - phi_j) sum_i m_i c_ik c_ij
    Q_k  = sum_i F_i . c_ik l e_perp(phi_k) + tau_k - tau_(k+1)

with F_i the RFT force (the paper or the sand-swimming law) and tau_k the torque of hinge k on segment k. A
reversal of the drive changes P' at once; the segments then take the impulse
``A dphi' = -sum_i m_i c_ik l e_perp . dP'``.
It serves as the test oracle for the MuJoCo model (hinged plates; the origami stop as the penalty spring).
The half robot is solved the same way, in the body's slide and the fin's absolute angles (`solve_robot`).

It shares no code with what it checks: from finrft it takes only plain data, a scene and a drive, and writes
out on its own the law, the penalty stop and the robot's parts (its arm's and body's drag, its gait).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from scipy.integrate import solve_ivp

from .drive import Drive

if TYPE_CHECKING:
    from .scene import RFT, Scene


def _paper_law(f_perp: float, f_par: float, v_reg: float) -> Callable[[np.ndarray, np.ndarray, np.ndarray],
                                                                      np.ndarray]:
    """The paper's law on points moving at v (k, 3), axis e and normal n (k, 3): normal and tangential parts
    f_perp sin(attack), f_par cos(attack) against the motion, faded in over tanh(|v| / v_reg)."""
    def law(v, e, n):
        speed = np.sqrt(np.sum(v * v, axis=1))
        unit = v / np.maximum(speed, 1e-300)[:, None]
        normal = np.sum(unit * n, axis=1)
        along = np.sum(unit * e, axis=1)
        return -np.tanh(speed / v_reg)[:, None] * (f_perp * normal[:, None] * n + f_par * along[:, None] * e)
    return law


def _sandswim_law(c_s: float, c_f: float, gamma0: float, v_reg: float) -> Callable[..., np.ndarray]:
    """The sand-swimming law as Maladen et al. 2009 write it, with psi the angle between the velocity and the axis
    e: F_par = C_F cos psi, F_perp = C_S sin beta0 + C_F sin psi, tan beta0 = cot gamma0 sin psi, each against
    its part of the motion, faded in over tanh(|v| / v_reg)."""
    def law(v, e, n):
        speed = np.sqrt(np.sum(v * v, axis=1))
        unit = v / np.maximum(speed, 1e-300)[:, None]
        along, normal = np.sum(unit * e, axis=1), np.sum(unit * n, axis=1)
        psi = np.arctan2(np.abs(normal), np.abs(along))
        beta0 = np.arctan(np.sin(psi) / np.tan(gamma0))
        f_perp = c_s * np.sin(beta0) + c_f * np.sin(psi)
        f_par = c_f * np.cos(psi)
        return -np.tanh(speed / v_reg)[:, None] * ((f_perp * np.sign(normal))[:, None] * n
                                                   + (f_par * np.sign(along))[:, None] * e)
    return law


def _scene_law(rft: RFT, length: float, medium: Any, given: Any = None):
    """A segment's law: the scene's coefficients, per unit area and depth, times the segment's face area (length x
    medium.height) and its mean depth (medium.depth + height / 2); or a law ``given`` per segment (N), as a
    [medium] gives it (`finrft.laws.SegmentLaw`: its law's name, v_reg and parameters)."""
    if given is not None:
        return _given_law(given)
    size = length * medium.height * (medium.depth + medium.height / 2)
    if rft.law == "paper":
        return _paper_law(size * rft.f_perp, size * rft.f_par, rft.v_reg)
    if rft.law == "sandswim" and rft.c_s:
        return _sandswim_law(size * rft.c_s, size * rft.c_f, rft.gamma0, rft.v_reg)
    raise ValueError(f"the reference solves the paper and sandswim laws with given coefficients, not "
                     f"rft.law = {rft.law!r} (a law from [medium] must be given)")


def _given_law(law: Any):
    p = law.parameters
    if law.law == "paper":
        return _paper_law(p["f_perp"], p["f_par"], law.v_reg)
    if law.law == "sandswim":
        return _sandswim_law(p["c_s"], p["c_f"], p["gamma0"], law.v_reg)
    raise ValueError(f"the reference solves the paper and sandswim laws, not {law.law!r}")


def _stop(deflection, stiffness: float):
    """The penalty stop's torque on hinge deflections from the rest angle: k d^2 pushing back when d > 0."""
    return np.where(deflection > 0, -2 * stiffness * deflection ** 2, 0.0)


@dataclass(frozen=True)
class Solution:
    time: np.ndarray           # (T,) s
    segment_angle: np.ndarray  # (T, N) rad, change of absolute orientation since t = 0
    hinge_angle: np.ndarray    # (T, N) rad
    drive_force: np.ndarray    # (T,) N along +y (drag) or N m about +z (rotate), applied by the drive


def _e(phi):
    return np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=-1)


def _e_perp(phi):
    return np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=-1)


class _Chain:
    def __init__(self, scene: Scene, drive: Drive, law: Any = None) -> None:
        p = scene.plate
        if p.kind == "rigid":
            raise ValueError("the reference solves hinged plates; a rigid plate has no dynamics of its own")
        if p.kind == "origami" and p.stop != "penalty":
            raise ValueError("the reference models the origami stop as the penalty spring (plate.stop = 'penalty')")
        n = p.segments
        self.n, self.l, self.drive, self.p = n, p.segment_length, drive, p
        self.c = np.tril(np.ones((n, n)), -1) + 0.5 * np.eye(n)      # c[i, j]
        self.m = np.full(n, p.segment_mass)
        self.inertia = np.full(n, p.segment_inertia)
        self.mcc = np.einsum("i,ik,ij->kj", self.m, self.c, self.c)  # sum_i m_i c_ik c_ij
        self.mc = self.m[:, None] * self.c                            # m_i c_ik
        self.law = _scene_law(scene.rft, p.segment_length, scene.medium, law)
        self.penalty = p.kind == "origami"
        # a drag at angle of attack theta to +y starts with the plate at 90 deg - theta
        self.heading = np.radians(90.0 - drive.attack_deg) if drive.kind == "drag" else 0.0

    def rod(self, t: float, omega_sign: float):
        """Rod angle psi, tip velocity and tip acceleration at t (constant speed within a stroke)."""
        d, L = self.drive, self.p.rod_length
        if d.kind == "drag":
            return self.heading, np.array([0.0, omega_sign * d.speed, 0.0]), np.zeros(3)
        psi = self.heading + d.position(t)
        w = omega_sign * d.speed
        return psi, L * w * _e_perp(psi), -L * w * w * _e(psi)

    def hinge_torque(self, phi, dphi, psi, dpsi):
        q = np.diff(np.r_[psi, phi])
        dq = np.diff(np.r_[dpsi, dphi])
        deflection = q - self.p.springref
        tau = -self.p.stiffness * deflection - self.p.damping * dq
        if self.penalty:
            tau += _stop(deflection, self.p.stop_stiffness)
        return tau

    def accelerations(self, t: float, phi, dphi, sign: float):
        psi, v0, a0 = self.rod(t, sign)
        dpsi = sign * self.drive.speed if self.drive.kind == "rotate" else 0.0
        e, ep = _e(phi), _e_perp(phi)
        velocity = v0 + self.l * np.einsum("ij,j,jk->ik", self.c, dphi, ep)
        force = self.law(velocity, e, ep)
        tau = self.hinge_torque(phi, dphi, psi, dpsi)
        q_gen = self.l * np.einsum("ik,ia,ka->k", self.c, force, ep) + tau - np.r_[tau[1:], 0.0]
        centripetal = self.l * np.einsum("ij,j,ja->ia", self.c, dphi ** 2, e)   # sum_j c_ij l e_j phi'_j^2
        q_gen -= self.l * np.einsum("ik,ka,ia->k", self.mc, ep, a0[None, :] - centripetal)
        a = self.l ** 2 * self.mcc * np.cos(phi[:, None] - phi[None, :]) + np.diag(self.inertia)
        ddphi = np.linalg.solve(a, q_gen)
        accel = a0 + self.l * np.einsum("ij,ja->ia", self.c, ddphi[:, None] * ep - dphi[:, None] ** 2 * e)
        return ddphi, force, accel, psi

    def drive_load(self, t, phi, dphi, sign):
        """What the drive applies: along +y (drag), or the torque about the base (rotate)."""
        ddphi, force, accel, psi = self.accelerations(t, phi, dphi, sign)
        net = self.m[:, None] * accel - force        # force each segment needs from the chain
        if self.drive.kind == "drag":
            return net[:, 1].sum()
        p = self.p
        origin = self.l * np.einsum("ij,ja->ia", self.c, _e(phi)) + p.rod_length * _e(psi)
        torque = np.cross(origin, net)[:, 2].sum() + (self.inertia * ddphi).sum()
        return torque  # the rod itself turns at constant speed: no torque for its own inertia

    def reversal(self, phi, psi, jump: np.ndarray):
        ep = _e_perp(phi)
        a = self.l ** 2 * self.mcc * np.cos(phi[:, None] - phi[None, :]) + np.diag(self.inertia)
        rhs = -self.l * np.einsum("ik,ka,a->k", self.mc, ep, jump)
        return np.linalg.solve(a, rhs)


def solve(scene: Scene, drive: Drive, times: np.ndarray, *, rtol: float = 1e-10, atol: float = 1e-12,
          law: Any = None) -> Solution:
    """Integrate the plate test stroke by stroke (Radau) and sample it at ``times`` (s, increasing); ``law``: a
    segment's law (N) when the scene's [medium] gives it."""
    chain = _Chain(scene, drive, law)
    n, ts = chain.n, drive.stroke_time
    phi = np.full(n, chain.heading)
    # At t = 0 the plate moves rigidly with the drive: hinge rates are zero.
    dphi = np.full(n, drive.speed if drive.kind == "rotate" else 0.0)
    times = np.asarray(times, dtype=float)
    states = np.zeros((len(times), 2 * n))
    signs = np.zeros(len(times))
    for k in range(drive.strokes):
        sign = 1.0 if k % 2 == 0 else -1.0
        last = k == drive.strokes - 1
        # A run's last sample may overshoot the nominal end by part of a step; the last stroke carries on.
        t0, t1 = k * ts, max((k + 1) * ts, times[-1]) if last else (k + 1) * ts
        if k:
            psi, v_new, _ = chain.rod(t0, sign)
            _, v_old, _ = chain.rod(t0, -sign)
            dphi = dphi + chain.reversal(phi, psi, v_new - v_old)
        pick = (times >= t0 - 1e-12) & ((times <= t1) if last else (times < t1 - 1e-12))

        def rhs(t, y, sign=sign):
            return np.r_[y[n:], chain.accelerations(t, y[:n], y[n:], sign)[0]]

        # Sample the stroke's own times and its end, from which the next stroke starts.
        wanted = np.clip(times[pick], t0, t1)
        t_eval = np.unique(np.r_[wanted, t1])
        sol = solve_ivp(rhs, (t0, t1), np.r_[phi, dphi], method="Radau", rtol=rtol, atol=atol, t_eval=t_eval)
        if not sol.success:
            raise RuntimeError(f"reference integration failed in stroke {k}: {sol.message}")
        states[pick] = sol.y[:, np.searchsorted(t_eval, wanted)].T
        signs[pick] = sign
        phi, dphi = sol.y[:n, -1], sol.y[n:, -1]
    phi_t = states[:, :n]
    rotation = np.array([drive.position(t) for t in times]) if drive.kind == "rotate" else np.zeros(len(times))
    psi_t = chain.heading + rotation
    hinge = np.diff(np.c_[psi_t, phi_t], axis=1)
    load = np.array([chain.drive_load(t, y[:n], y[n:], s) for t, y, s in zip(times, states, signs)])
    return Solution(times, phi_t - chain.heading, hinge, load)


@dataclass(frozen=True)
class RobotSolution:
    time: np.ndarray           # (T,) s
    body_y: np.ndarray         # (T,) m
    hinge_angle: np.ndarray    # (T, N) rad, right fin
    stroke_y: np.ndarray       # (strokes + 1,) m, body position at each stroke start and at the end


class _HalfRobot:
    """The half robot in coordinates (y, phi_1..phi_N): body slide and absolute fin angles; the arm angle psi(t)
    is prescribed. Point masses j (body, arm centre, segment midpoints) at r_j(q, psi), with J_j = dr_j/dq and
    w_j = dr_j/dpsi:  M q'' = Q - sum_j m_j J_j^T (J_j' q' + w_j' psi'),  M = sum_j m_j J_j^T J_j + diag(I)."""

    def __init__(self, scene: Any, drive: Drive, arm: Any, body_drag: float | None, fin: Any) -> None:
        f, a = scene.fin, scene.arm
        if scene.robot.model != "half" or scene.robot.servo != "prescribed":
            raise ValueError("the reference solves the half robot with a prescribed servo")
        m = scene.medium
        if (arm is None or body_drag is None) and (m.name or m.bulk_density or m.internal_friction or
                                                   m.surface_friction):
            raise ValueError("a robot in a [medium] takes its arm's law and body drag from it: give them to the "
                             "reference as arm and body_drag")
        if f.kind == "origami" and f.stop != "penalty":
            raise ValueError("the reference models the origami stop as the penalty spring (fin.stop = 'penalty')")
        self.scene, self.drive, self.n, self.l, self.L = scene, drive, f.segments, f.segment_length, a.length
        self.c = np.tril(np.ones((self.n, self.n)), -1) + 0.5 * np.eye(self.n)
        share = 0.5  # the half robot carries half the body's mass and drag
        self.m_body = share * scene.body.mass
        self.m_arm = a.mass_base + a.linear_density * a.length
        self.m_seg = f.segment_mass
        self.inertia = np.full(self.n, f.segment_inertia)
        self.fin_law = _scene_law(scene.rft, f.segment_length, m, fin)
        # the arm: the given law, or the paper law with a normal coefficient growing with the arm's length; the
        # body: isotropic drag, the given one or the scene's
        self.arm_law = _given_law(arm) if arm else _paper_law(a.f_perp_base + a.f_perp_per_length * a.length,
                                                             a.f_par, scene.rft.v_reg)
        drag = share * (scene.body.drag if body_drag is None else body_drag)
        self.body_law = _paper_law(drag, drag, scene.body.v_reg)
        self.stroke_drag = drag
        self.rigid = f.kind == "rigid"
        self.penalty = f.stop_stiffness if f.kind == "origami" else 0.0

    def kinematics(self, phi, psi):
        """J (points x 3 x (N+1)), w (points x 3) for body, arm centre and each segment midpoint."""
        n, l, L = self.n, self.l, self.L
        y_hat = np.array([0.0, 1.0, 0.0])
        J = np.zeros((n + 2, 3, n + 1))
        J[:, :, 0] = y_hat
        w = np.zeros((n + 2, 3))
        w[1] = 0.5 * L * _e_perp(psi)
        w[2:] = L * _e_perp(psi)
        J[2:, :, 1:] = l * np.einsum("ij,ja->iaj", self.c, _e_perp(phi))
        return J, w

    def accelerations(self, t, y, sign):
        n, l, L = self.n, self.l, self.L
        phi, dy, dphi = y[1:n + 1], y[n + 1], y[n + 2:]
        psi = self.drive.position(t)
        dpsi = sign * self.drive.speed
        J, w = self.kinematics(phi, psi)
        qd = np.r_[dy, dphi]
        vel = J @ qd + w * dpsi
        mass = np.r_[self.m_body, self.m_arm, np.full(n, self.m_seg)]
        # J' q' + w' psi': centripetal terms of the arm (psi'^2) and of the segments (phi_j'^2)
        bias = np.zeros((n + 2, 3))
        bias[1] = -0.5 * L * _e(psi) * dpsi ** 2
        bias[2:] = -L * _e(psi) * dpsi ** 2 - l * np.einsum("ij,j,ja->ia", self.c, dphi ** 2, _e(phi))
        force = np.zeros((n + 2, 3))
        force[1] = self.arm_law(vel[1:2], _e(np.array([psi])), _e_perp(np.array([psi])))[0]
        force[2:] = self.fin_law(vel[2:], _e(phi), _e_perp(phi))
        if self.scene.body.drag_law == "velocity":
            force[0] = self.body_law(vel[0:1], np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))[0]
        else:
            force[0, 1] = -sign * self.stroke_drag
        q = np.diff(np.r_[psi, phi])
        dq = np.diff(np.r_[dpsi, dphi])
        f = self.scene.fin
        tau = -f.stiffness * (q - f.springref) - f.damping * dq
        if self.penalty:
            tau += _stop(q - f.springref, self.penalty)
        gen = np.einsum("jak,ja->k", J, force - mass[:, None] * bias)
        gen[1:] += tau - np.r_[tau[1:], 0.0]
        M = np.einsum("j,jak,jal->kl", mass, J, J)
        M[1:, 1:] += np.diag(self.inertia)
        return np.linalg.solve(M, gen), M, J, w, mass

    def reversal(self, y, t, jump):
        _, M, J, w, mass = self.accelerations(t, y, 1.0)
        return np.linalg.solve(M, -np.einsum("j,jak,ja->k", mass, J, w * jump))


def solve_robot(scene: Any, cycles: int, times: np.ndarray, *, rtol: float = 1e-9, atol: float = 1e-12,
                arm: Any = None, body_drag: float | None = None, fin: Any = None) -> RobotSolution:
    """Integrate the half robot's flap cycles with Radau; the same start and reversals as finrft.swim. A scene
    whose [medium] gives the arm's law and the body's drag (N, the whole robot's) needs them given, as numbers:
    ``arm`` and ``body_drag`` (and ``fin``, a fin segment's law, when the medium gives it)."""
    g = scene.gait  # the arm swings from theta2 up to theta1 and back at omega
    drive = Drive(kind="rotate", speed=g.omega, stroke=g.theta1 - g.theta2, cycles=cycles, start=g.theta2)
    robot = _HalfRobot(scene, drive, arm, body_drag, fin)
    n, ts = robot.n, drive.stroke_time
    if robot.rigid:
        raise ValueError("the reference solves hinged fins")
    state = np.r_[0.0, np.full(n, drive.start), 0.0, np.zeros(n)]
    times = np.asarray(times, dtype=float)
    states = np.zeros((len(times), len(state)))
    stroke_y = np.zeros(drive.strokes + 1)
    for k in range(drive.strokes):
        sign = 1.0 if k % 2 == 0 else -1.0
        last = k == drive.strokes - 1
        t0, t1 = k * ts, max((k + 1) * ts, times[-1]) if last else (k + 1) * ts
        if k:
            state[n + 1:] += robot.reversal(state, t0, 2 * sign * drive.speed)
        stroke_y[k] = state[0]
        pick = (times >= t0 - 1e-12) & ((times <= t1) if last else (times < t1 - 1e-12))

        def rhs(t, y, sign=sign):
            return np.r_[y[n + 1:], robot.accelerations(t, y, sign)[0]]

        wanted = np.clip(times[pick], t0, t1)
        t_eval = np.unique(np.r_[wanted, t1])
        # The anchored arm makes this stiff enough that scipy's finite-difference Jacobian grows its step
        # factors past overflow; harmless, and silenced.
        with np.errstate(over="ignore"):
            sol = solve_ivp(rhs, (t0, t1), state, method="Radau", rtol=rtol, atol=atol, t_eval=t_eval)
        if not sol.success:
            raise RuntimeError(f"reference integration failed in stroke {k}: {sol.message}")
        states[pick] = sol.y[:, np.searchsorted(t_eval, wanted)].T
        state = sol.y[:, -1].copy()
    stroke_y[-1] = state[0]
    psi = np.array([drive.position(t) for t in times])
    hinge = np.diff(np.c_[psi, states[:, 1:n + 1]], axis=1)
    return RobotSolution(times, states[:, 0], hinge, stroke_y)
