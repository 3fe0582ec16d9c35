"""Plate tests on MuJoCo against closed forms, force balances, symmetry and convergence in dt."""

import mujoco
import numpy as np
import pytest
from scipy.optimize import brentq

from conftest import face
from finrft import integrate
from finrft.drive import Drive
from finrft.convergence import SimulationUnstable
from finrft.scene import preset
from finrft.experiments.plate import build_plate, simulate


@pytest.mark.parametrize("attack_deg", [90.0, 60.0, 30.0, 0.0])
def test_rigid_drag_is_the_sum_of_the_segment_law(paper, attack_deg):
    # A rigid plate at angle of attack theta: every segment sees the same v, so the drive must supply
    # N (f_perp sin^2 theta + f_par cos^2 theta) tanh(v / v_reg) along +y, at every instant.
    scene = paper.replace(**{"plate.kind": "rigid"})
    drive = Drive(speed=0.03, stroke=0.03, attack_deg=attack_deg)
    run = simulate(scene, drive)
    theta, r, size = np.radians(attack_deg), scene.rft, face(scene)
    expected = scene.plate.segments * size * (r.f_perp * np.sin(theta) ** 2 + r.f_par * np.cos(theta) ** 2) \
        * np.tanh(drive.speed / r.v_reg)
    np.testing.assert_allclose(run.drive_force, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(run.rft_force.sum(axis=1)[:, 1], -expected, rtol=1e-9, atol=1e-12)
    assert np.all(run.segment_angle == 0.0)


def test_rigid_rotation_torque_closed_form(paper):
    # Turning about the base at omega, segment i (midpoint radius r_i) moves normal to itself at omega r_i.
    scene = paper.replace(**{"plate.kind": "rigid"})
    drive = Drive(kind="rotate", speed=1.0, stroke=0.5)
    run = simulate(scene, drive)
    p, r = scene.plate, scene.rft
    radius = p.rod_length + (np.arange(p.segments) + 0.5) * p.segment_length
    expected = np.sum(face(scene) * r.f_perp * np.tanh(drive.speed * radius / r.v_reg) * radius)
    # The drive slows under the load by load / armature, which the plate's inertia feels: 1.6e-8 of the load here,
    # where the armature is what resolves the load in each step (plate.drive_armature)
    np.testing.assert_allclose(run.drive_force, expected, rtol=1e-7)
    np.testing.assert_allclose(run.segment_angle[:, 0], run.displacement, atol=1e-12)


@pytest.mark.parametrize("dt", [1e-3, 1e-5])
def test_rigid_rotation_per_stroke_means_are_the_closed_form(paper, dt):
    # The per-stroke mean torque is the drive's impulse over the stroke, read from its speed: the authors' plate
    # (segments of 1 kg m^2) made the drive so heavy that at dt = 1e-5 s its 0.2 N m changed the speed by less
    # than the speed's rounding each step, and both means came out -0.0 with an error estimate of 0.
    scene = paper.replace(**{"plate.kind": "rigid", "sim.dt": dt})
    drive = Drive(kind="rotate", speed=np.radians(60), stroke=np.radians(120), cycles=1)
    run = simulate(scene, drive)
    p, r = scene.plate, scene.rft
    radius = p.rod_length + (np.arange(p.segments) + 0.5) * p.segment_length
    expected = np.sum(face(scene) * r.f_perp * np.tanh(drive.speed * radius / r.v_reg) * radius)
    row, = run.cycle_table()
    assert row["mean_recovery_torque_Nm"] == pytest.approx(expected, rel=1e-4)
    assert row["mean_power_torque_Nm"] == pytest.approx(-expected, rel=1e-4)
    # a rigid plate turning steadily loads the drive with that torque at every step, reversals included
    assert run.summary()["peak_drive_torque_Nm"] == pytest.approx(expected, rel=1e-4)


def test_peak_is_taken_from_every_step_and_estimated(paper):
    # The authors' origami plate peaks where its stop engages after the reversal (t = 2.09 s), a spike a few ms
    # wide: taken from the recorded samples the peak was 81.6 or 80.2 N m as sim.record_dt was 1 or 20 ms. From
    # every step it is one number whatever the samples, and its estimate bounds its change when dt falls 4 times,
    # which Richardson's comparison with the coarse companion alone (7.5e-3 N m) does not: the peak converges
    # unevenly in dt (81.536, 81.510, 81.521, 81.553 N m at 5, 2, 1, 0.5 ms).
    drive = Drive(kind="rotate", speed=np.radians(60), stroke=np.radians(120), cycles=1)
    runs = {(dt, record): simulate(paper.replace(**{"sim.dt": dt, "sim.record_dt": record}), drive, max_error=None)
            for dt, record in [(1e-3, 1e-3), (1e-3, 2e-2), (2.5e-4, 2e-2)]}
    coarse, sampled, fine = runs.values()
    assert coarse.peak_drive_force == sampled.peak_drive_force
    assert np.abs(sampled.drive_force).max() < coarse.peak_drive_force - 1.0  # the samples miss the spike's top
    change = abs(coarse.peak_drive_force - fine.peak_drive_force)
    assert change > 0.02
    assert coarse.error_estimate["peak_torque_Nm"] >= change
    assert coarse.summary()["error_estimate"]["peak_torque_Nm"] == coarse.error_estimate["peak_torque_Nm"]


def _peak_by_hand(scene, drive):
    """The largest drive load of a one-stroke drag at any step's state, stepped here one mj_step at a time with the
    native plugin's forces, the load -armature * qacc read after mj_forward at each state."""
    plate = build_plate(scene)
    m, d = plate.model, mujoco.MjData(plate.model)
    d.qvel[plate.drive_dof] = drive.stroke_velocity(0)
    loads = []
    for _ in range(round(drive.duration / scene.sim.dt) + 1):
        mujoco.mj_forward(m, d)
        loads.append(plate.armature * abs(d.qacc[plate.drive_dof]))
        mujoco.mj_step(m, d)
    return max(loads)


@pytest.mark.parametrize("integrator", ["implicitfast", "euler", "rk4"])
def test_native_explicit_steps_take_the_peak_at_every_step_without_python(paper, monkeypatch, integrator):
    # The native steppers keep the peak themselves (plugins/peaks.c): Python steps and runs forward passes only at
    # the recorded samples and the stroke's ends, not after every step (which cost the paper drag half its time),
    # and the peak is still the largest load of every step's state, the stop engaging between samples included.
    scene = paper.replace(**{"sim.integrator": integrator, "sim.record_dt": 0.05})
    drive = Drive(speed=0.03, stroke=0.02)
    steps = round(drive.duration / scene.sim.dt)
    calls = {"mj_step": 0, "mj_forward": 0}

    def counted(name):
        call = getattr(mujoco, name)

        def counting(*args):
            calls[name] += 1
            return call(*args)
        return counting
    for name in calls:
        monkeypatch.setattr(mujoco, name, counted(name))
    run = simulate(scene, drive, estimate_error=False)
    monkeypatch.undo()
    assert calls["mj_step"] == 0 and calls["mj_forward"] < steps / 10
    assert run.peak_drive_force == pytest.approx(_peak_by_hand(scene, drive), rel=1e-12)
    assert np.abs(run.drive_force).max() < run.peak_drive_force


def _untraced(monkeypatch):
    """Steppers that keep no trace of the probe's velocities: the run stops at each of the probe's steps."""
    monkeypatch.setattr(integrate._Counted, "traced", lambda self, watch, steps: None)


@pytest.mark.parametrize("method", ["explicit", "newton"])
def test_the_chatter_probe_reads_the_native_steppers_trace(monkeypatch, method):
    # The native steppers trace the probe's velocities (plugins/peaks.c), so a plate run steps from one recorded
    # sample to the next in one call: it stopped at each of the probe's 8 steps every 20 ms, 3000 calls of Python
    # in the paper drag's 6667 steps, which took 10 times the bare steps. The probe judges the same velocities:
    # the same largest swing over a turned-out-and-back plate (a reversal between probes), and a chattering light
    # plate stops at the same onset.
    calls = []
    for cls in (integrate.Explicit, integrate.Implicit):
        monkeypatch.setattr(cls, "__call__", lambda self, d, n, call=cls.__call__: calls.append(n) or call(self, d, n))
    scene = preset("paper").replace(**{"sim.method": method, "sim.dt": 4e-3})
    drive = Drive(kind="rotate", speed=np.radians(60), stroke=np.radians(120), cycles=1)
    traced = simulate(scene, drive, estimate_error=False)
    assert len(calls) <= len(traced.time) + 2  # a call from each recorded sample to the next, a reversal between
    _untraced(monkeypatch)
    untraced = simulate(scene, drive, estimate_error=False)
    assert traced.chattering.worst > 0 and traced.chattering == untraced.chattering
    monkeypatch.undo()
    light = preset("physical").replace(**{"sim.method": "explicit"})
    with pytest.raises(SimulationUnstable) as fast:
        simulate(light, Drive(speed=0.03, stroke=0.2), estimate_error=False)
    _untraced(monkeypatch)
    with pytest.raises(SimulationUnstable) as slow:
        simulate(light, Drive(speed=0.03, stroke=0.2), estimate_error=False)
    assert "chatters at t =" in str(fast.value) and str(fast.value) == str(slow.value)


# the adaptive methods' Python twin takes the longest: with the slow studies
@pytest.mark.parametrize("method", ["explicit", "newton", pytest.param("adaptive-newton", marks=pytest.mark.slow)])
def test_native_and_numpy_steppers_take_the_same_peak(method):
    # The authors' plate turned out and back (a reversal, its stop engaging after it): each stroke's peak and its
    # change to the neighbouring steps, kept in C by the native steppers and in Python by their numpy twins.
    scene = preset("paper").replace(**{"sim.method": method, "plate.segment_inertia": 1e-3, "sim.dt": 1e-3})
    drive = Drive(kind="rotate", speed=np.radians(60), stroke=np.radians(60), cycles=1)
    native, python = (simulate(scene.replace(**{"sim.backend": b}), drive, estimate_error=False)
                      for b in ("native", "python"))
    assert np.all(native.stroke_peak > 0)
    np.testing.assert_allclose(native.stroke_peak, python.stroke_peak, rtol=1e-9)
    assert native.values["peak_resolution"] == pytest.approx(python.values["peak_resolution"], rel=1e-6, abs=1e-9)


@pytest.mark.parametrize("kind", ["origami", "soft"])
def test_drive_reaction_balances_rft_in_steady_state(responsive, kind):
    # Once the plate's shape has settled, nothing accelerates: the drive holds exactly the summed RFT force.
    run = simulate(responsive.replace(**{"plate.kind": kind}), Drive(stroke=0.15))
    late = run.time > 0.8 * run.time[-1]
    np.testing.assert_allclose(run.drive_force[late], -run.rft_force[late].sum(axis=1)[:, 1], rtol=1e-4)


def test_single_hinge_settles_where_spring_balances_rft(paper):
    # One segment on a soft hinge dragged along +y at 90 deg: at rest in its own frame the RFT torque about the
    # hinge is -(l/2) f_perp cos(q) (the tangential part passes through the hinge), so k q = -(l/2) f_perp cos q.
    scene = paper.replace(**{"plate.kind": "soft", "plate.segments": 1, "plate.stiffness": 0.05,
                             "plate.damping": 0.01, "plate.segment_inertia": 1e-3, "sim.dt": 2.5e-4})
    run = simulate(scene, Drive(stroke=0.15))
    p, r = scene.plate, scene.rft
    f_perp = face(scene) * r.f_perp  # N, on the one segment
    q_eq = brentq(lambda q: p.stiffness * q + 0.5 * p.segment_length * f_perp * np.cos(q), -np.pi / 2, 0.0)
    assert np.degrees(run.hinge_angle[-1, 0]) == pytest.approx(np.degrees(q_eq), abs=1e-3)
    assert -40.0 < np.degrees(q_eq) < -10.0  # a real bend, not a trivial case


@pytest.fixture(scope="module")
def loops(responsive):
    """Two back-and-forth cycles of each plate kind."""
    drive = Drive(speed=0.03, stroke=0.2, cycles=2)
    return {kind: simulate(responsive.replace(**{"plate.kind": kind}), drive)
            for kind in ("rigid", "soft", "origami")}


def _stroke_force(run, stroke, part=(0.0, 1.0)):
    """Mean drive force over a fraction of one stroke."""
    ts = run.drive.stroke_time
    lo, hi = (stroke + part[0]) * ts, (stroke + part[1]) * ts
    pick = (run.time > lo + 1e-9) & (run.time < hi - 1e-9)
    return run.drive_force[pick].mean()


def test_soft_loop_is_symmetric_origami_is_not(loops):
    rigid, soft, origami = loops["rigid"], loops["soft"], loops["origami"]
    stroke_impulse = abs(rigid.stroke_impulse[0])
    # Rigid and soft: the second cycle's power and recovery strokes mirror each other.
    for run in (rigid, soft):
        assert abs(run.cycle_table()[1]["net_impulse_Ns"]) < 2e-3 * stroke_impulse
        assert _stroke_force(run, 3) == pytest.approx(-_stroke_force(run, 2), rel=2e-3)
    # Origami: a net thrust of more than a quarter of a stroke's impulse, toward +y (against the power stroke).
    assert origami.cycle_table()[1]["net_impulse_Ns"] > 0.25 * stroke_impulse
    # Once flat against its stop, the origami plate is the rigid plate. Its recovery starts from flat, as the
    # soft plate's first stroke does, and follows it: well below the rigid plate's force.
    assert _stroke_force(origami, 3, (0.5, 1.0)) == pytest.approx(_stroke_force(rigid, 3, (0.5, 1.0)), rel=2e-3)
    assert _stroke_force(origami, 2, (0.0, 0.3)) == pytest.approx(_stroke_force(soft, 0, (0.0, 0.3)), rel=0.02)
    assert _stroke_force(origami, 2, (0.0, 0.3)) < 0.7 * _stroke_force(rigid, 2, (0.0, 0.3))


def test_limit_stop_holds(responsive):
    # The stated penetration of the limit stop: below 0.02 deg while the power stroke presses the plate into it.
    # At this step its slams are resolved too (estimated error 0.016 deg, 0.005 deg against dt 10 us), now that
    # the constraint solver iterates to convergence (see finrft.models.new_spec).
    scene = responsive.replace(**{"plate.stop": "limit"})
    origami = simulate(scene, Drive(speed=0.03, stroke=0.2, cycles=2))
    assert origami.error_estimate["angle_deg"] < 0.05
    assert np.degrees(origami.hinge_angle.max()) < 0.02
    assert np.degrees(origami.hinge_angle.min()) < -20.0  # and it did bend the other way


def test_penalty_stop_settles_at_its_static_balance(responsive):
    # Pressed flat in the power stroke, hinge j carries the RFT torque of the segments beyond it,
    # tau_j = f_perp l sum_(i >= j) (i - j + 1/2), against k q + 2 k_stop q^2 (the penalty's q + |q| term).
    scene = responsive
    run = simulate(scene, Drive(stroke=0.2, cycles=1))
    p, r = scene.plate, scene.rft
    n = p.segments
    tau = [face(scene) * r.f_perp * p.segment_length * sum(i - j + 0.5 for i in range(j, n)) for j in range(n)]
    static = [brentq(lambda q, t=t: p.stiffness * q + 2 * p.stop_stiffness * q * q - t, 0.0, 1.0) for t in tau]
    np.testing.assert_allclose(run.hinge_angle[-1], static, rtol=0.01)
    assert np.all(run.hinge_angle.max(axis=0) < 3 * np.array(static))  # the impact overshoots, boundedly


def test_results_converge_in_dt(paper, responsive):
    # Halving dt changes the paper drag's final angles by less than 0.01 deg, and the responsive origami
    # cycle's impulse per stroke (exact, from the drive's momentum) by less than 0.2 %.
    coarse = simulate(paper, Drive())
    fine = simulate(paper.replace(**{"sim.dt": paper.sim.dt / 2}), Drive())
    assert np.degrees(np.abs(coarse.segment_angle[-1] - fine.segment_angle[-1])).max() < 0.01
    drive = Drive(stroke=0.08, cycles=1)
    coarse = simulate(responsive, drive)
    fine = simulate(responsive.replace(**{"sim.dt": responsive.sim.dt / 2}), drive)
    np.testing.assert_allclose(coarse.stroke_impulse, fine.stroke_impulse, rtol=2e-3)


def test_instability_stops_loudly(paper):
    # Physical inertia, a stiff penalty stop integrated explicitly and a large step: this must blow up, and
    # the error must say when and what to change instead of returning a reset state.
    scene = paper.replace(**{"plate.segment_inertia": 2.6e-7, "plate.rod_inertia": 4e-8, "plate.damping": 0.0,
                             "sim.integrator": "euler", "sim.dt": 1e-3})
    with pytest.raises(SimulationUnstable, match=r"unstable at t = .* reduce sim.dt"):
        simulate(scene, Drive(cycles=1))


def test_spatial_chain_stays_in_the_plane(paper):
    # A chain free to turn about each segment's own x and y axes too: the in-plane loads leave those six extra
    # degrees of freedom at rest, so the motion is the planar chain's.
    spatial = paper.replace(**{"plate.chain": "spatial"})
    assert build_plate(spatial).model.nv == build_plate(paper).model.nv + 2 * paper.plate.segments
    planar, free = simulate(paper, Drive()), simulate(spatial, Drive())
    np.testing.assert_allclose(free.segment_angle, planar.segment_angle, atol=1e-12)
    np.testing.assert_allclose(free.drive_force, planar.drive_force, atol=1e-9)


@pytest.mark.parametrize("name,f_perp", [("paper", None), ("physical", None), ("physical", 0.6)])
def test_welded_segments_behave_as_one_rigid_body(name, f_perp):
    # The drive's load of a welded plate is -armature qacc through the constraint solver, which once accepted its
    # warm start (qacc = 0, a load of 0) on the physical plate with the paper law at f_perp = 0.6 N per segment.
    scene = preset(name)
    rigid = scene.replace(**{"plate.kind": "rigid", **({"rft.law": "paper", "rft.f_perp": f_perp / face(scene),
                                                        "rft.f_par": 0.1 / face(scene)} if f_perp else {})})
    body, welded = simulate(rigid, Drive()), simulate(rigid.replace(**{"plate.rigid_as": "welds"}), Drive())
    assert np.degrees(np.abs(welded.hinge_angle)).max() < 1e-3  # the welds hold
    assert body.peak_drive_force > 0.5
    np.testing.assert_allclose(welded.drive_force, body.drive_force, rtol=1e-3)
