"""The time-stepping methods: the implicit step is MuJoCo's implicitfast plus the RFT Jacobian, in both twins;
the adaptive method follows its tolerance."""

import mujoco
import numpy as np
import pytest

from finrft import integrate, methods, native, reference
from finrft.studies import accuracy
from finrft.drive import Drive
from finrft.errors import Chatter, StepUnderflow
from finrft.scene import Scene, SceneError, field_of, preset
from finrft.experiments.plate import PlateTest, build_plate, plate_spec, simulate


def test_the_methods_table_says_what_each_method_does():
    # What the table says of a method is what its runs do: sim.method's choices are the table's; a method that takes
    # the law implicitly needs implicitfast (an explicit one runs on any integrator); an adaptive one takes steps
    # of its own size, a fixed one exactly the steps of dt; its native stepper is a function of the plugin.
    assert field_of(Scene, "sim.method").metadata["choices"] == methods.names()
    drive = Drive(speed=0.03, stroke=0.006, cycles=1)
    for name, method in methods.METHODS.items():
        adaptive = {"sim.max_step": 1e-2, "sim.tolerance": 1e-3} if method.adaptive else {}
        scene = preset("paper").replace(**{"sim.method": name, "sim.dt": 1e-4, **adaptive})
        if method.implicit:
            with pytest.raises(SceneError, match="implicitfast"):
                scene.replace(**{"sim.integrator": "euler"})
        else:
            scene.replace(**{"sim.integrator": "euler"})
        run = simulate(scene, drive, max_error=None, estimate_error=False)
        fixed = round(drive.duration / scene.sim.dt)
        if method.adaptive:
            assert run.steps < fixed / 2
        else:
            assert run.steps + run.steps_rejected >= fixed and (run.steps_rejected == 0 or method.newton)
        if method.stepper:
            native.load()
            assert native.function(method.stepper, None) is not None
    assert methods.explicit() == ("explicit",)


@pytest.mark.parametrize("backend", ["python", "native"])
def test_implicit_step_without_rft_is_implicitfast(backend):
    # A model with no RFT (python-backend model, no callback installed): only MuJoCo's own forces.
    scene = preset("paper").replace(**{"sim.backend": "python", "plate.stop": "limit", "plate.segment_inertia": 1e-3,
                                       "sim.dt": 5e-4, "sim.method": "implicit"})
    plate = build_plate(scene)
    m = plate.model
    ours, theirs = mujoco.MjData(m), mujoco.MjData(m)
    for d in (ours, theirs):
        d.qvel[:] = [0.03, 1.0, -2.0, 3.0]
        d.qpos[1:] = [0.2, -0.3, 0.1]
    mujoco.mj_step(m, theirs, 1000)
    step = integrate.stepper(m, scene.sim, backend, [])
    assert step(ours, 1000) == 0
    np.testing.assert_allclose(ours.qpos, theirs.qpos, atol=1e-12)
    np.testing.assert_allclose(ours.qvel, theirs.qvel, atol=1e-12)


@pytest.mark.parametrize("method", [
    # the adaptive methods' Python twin takes minutes here; the robot's twins agree on their steps below
    # and of the fixed steps, newton's and explicit coupling's here (the others share their code), the rest slow
    name if name in ("newton", "explicit") else pytest.param(name, marks=pytest.mark.slow) for name in methods.names()])
def test_native_and_numpy_methods_agree(method):
    scene = preset("paper").replace(**{"sim.method": method, "plate.segment_inertia": 1e-3, "sim.dt": 1e-3})
    drive = Drive(stroke=0.03, cycles=1)  # the hinges bend 6.6 deg, and the adaptive methods reject steps
    native = simulate(scene, drive, estimate_error=False)
    python = simulate(scene.replace(**{"sim.backend": "python"}), drive, estimate_error=False)
    np.testing.assert_allclose(native.segment_angle, python.segment_angle, rtol=0, atol=1e-9)
    assert np.degrees(np.abs(native.hinge_angle).max()) > 5
    assert (native.steps, native.steps_rejected) == (python.steps, python.steps_rejected)


@pytest.mark.parametrize("method", [name for name, m in methods.METHODS.items() if not m.adaptive])
def test_fixed_steps_take_the_nominal_count(method):
    scene = preset("paper").replace(**{"sim.method": method, "sim.dt": 1e-3})
    run = simulate(scene, Drive(stroke=0.02, cycles=1))
    nominal = round(run.drive.duration / 1e-3)
    assert (run.steps, run.steps_rejected) == (nominal, 0)
    assert run.summary()["sim_time_s"] == pytest.approx(nominal * 1e-3)


@pytest.mark.slow  # the paper robot's gait in both twins, the Python one adaptive: half a minute on two cores
def test_adaptive_counts_its_steps_on_the_paper_robot():
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import swim
    scene = preset("paper", RobotScene)
    runs = [swim(scene.replace(**{"sim.backend": backend})) for backend in ("native", "python")]
    duration = runs[0].cycle_time
    for run in runs:
        # at least the largest step's count, far fewer than the time grid's; rejections cost little
        assert duration / scene.sim.max_step <= run.steps < 0.01 * round(duration / scene.sim.dt)
        assert 0 < run.steps_rejected < 0.1 * run.steps
    # the twins' arithmetic rounds apart, their decisions do not
    assert (runs[0].steps, runs[0].steps_rejected) == (runs[1].steps, runs[1].steps_rejected)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_newton_halvings_count_as_rejected_and_taken(backend):
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import swim
    # At 10 ms the paper robot's f_par < 0 leaves Newton's method without a root twice: a halving replaces one
    # step by two.
    scene = preset("paper", RobotScene).replace(**{"sim.method": "newton", "sim.dt": 1e-2, "sim.backend": backend})
    run = swim(scene, max_error=None)  # the counts, not the (coarse) result, are tested
    nominal = round(run.cycle_time / 1e-2)
    assert run.steps_rejected == 2 and run.steps == nominal + run.steps_rejected


@pytest.mark.slow  # four drags, one at a tolerance of 1e-8 (the accuracy study sweeps the tolerances too)
def test_adaptive_error_falls_with_the_tolerance():
    scene = preset("paper").replace(**{"sim.method": "adaptive", "plate.segment_inertia": 1e-3, "sim.dt": 1e-3})
    drive = Drive(stroke=0.1)
    truth = simulate(scene.replace(**{"sim.tolerance": 1e-8}), drive, estimate_error=False).segment_angle
    errors = [np.abs(simulate(scene.replace(**{"sim.tolerance": tol}), drive, estimate_error=False).segment_angle
                     - truth).max()
              for tol in (1e-3, 1e-4, 1e-5)]
    assert errors[0] > errors[1] > errors[2]


def test_methods_need_implicitfast():
    with pytest.raises(SceneError, match="implicitfast"):
        preset("paper").replace(**{"sim.method": "adaptive", "sim.integrator": "rk4"})


def test_adaptive_step_underflow_stops_loudly():
    scene = preset("paper").replace(**{"sim.method": "adaptive", "sim.tolerance": 1e-6, "plate.stop": "limit",
                                       "plate.segment_inertia": 2.6e-7, "plate.rod_inertia": 4e-8})
    with pytest.raises(StepUnderflow, match="fell below 1e-9 s at t = .* raise sim.tolerance"):
        simulate(scene, Drive(cycles=1))


LIGHT_DRIVE = Drive(speed=0.03, stroke=0.045, cycles=1)


def _flips(scene, method: str, dt: float) -> float:
    """The share of steps, over 200 steps half a second into a 45 mm recovery stroke, in which some hinge's
    acceleration changes sign: near 1 when the segments chatter (the RFT force reverses every step)."""
    scene = scene.replace(**{"sim.method": method, "sim.dt": dt})
    plate = build_plate(scene)
    m, d = plate.model, mujoco.MjData(plate.model)
    d.qvel[plate.drive_dof] = LIGHT_DRIVE.speed
    advance = integrate.stepper(m, scene.sim, "native", plate.groups)
    assert advance(d, round(0.5 / dt)) == 0
    velocities = []
    for _ in range(200):
        assert advance(d, 1) == 0
        velocities.append(d.qvel[plate.hinge_qpos - 1].copy())  # hinge dofs follow the drive's
    change = np.sign(np.diff(velocities, axis=0))
    return float(np.mean(np.any(change[1:] != change[:-1], axis=1)))


def test_explicit_coupling_chatters_on_light_segments_and_newton_does_not():
    light = preset("physical")
    assert _flips(light, "explicit", 1e-4) > 0.9
    # the force linearised at the step's start overshoots too (at 3 ms on this plate's sand-swimming law; the
    # paper law of the earlier fit, twice the normal force, made it chatter at 1 ms already)
    assert _flips(light, "implicit", 3e-3) > 0.9
    assert _flips(light, "explicit", 1e-5) == 0
    assert _flips(light, "newton", 1e-3) == 0


# the Python twin gives the native trajectories (above); its run here is with the slow studies
@pytest.mark.parametrize("backend", ["native", pytest.param("python", marks=pytest.mark.slow)])
def test_newton_on_light_segments_matches_reference_at_large_steps(backend):
    # 15 mm out and back: Radau needs minutes for the longer drive's close against the stiff penalty stops.
    light, drive = preset("physical").replace(**{"sim.backend": backend}), Drive(speed=0.03, stroke=0.015, cycles=1)
    ref = None
    for dt, angle, force in ((1e-3, 0.01, 0.005), (1e-2, 0.05, 0.03)):
        run = simulate(light.replace(**{"sim.dt": dt}), drive, estimate_error=False)
        # Radau at rtol 1e-5 is within 2e-6 deg and 1e-6 of the peak force of its solution at 1e-7
        ref = ref or reference.solve(light, drive, run.time, rtol=1e-5, atol=1e-8)
        assert np.degrees(np.abs(run.segment_angle - ref.segment_angle)).max() < angle
        assert np.abs(run.drive_force - ref.drive_force).max() < force * run.peak_drive_force
    assert np.degrees(run.hinge_angle.min()) < -8  # the plate did fold


def test_chatter_stops_the_run_loudly():
    # The run that _flips shows chattering (explicit coupling, light segments, 0.1 ms) must not pass as a result.
    scene = preset("physical").replace(**{"sim.method": "explicit", "sim.dt": 1e-4})
    with pytest.raises(Chatter, match=r"chatters at t = .* dt = 0.0001 s: use sim.method = 'newton'"):
        simulate(scene, LIGHT_DRIVE)
    # the speed study names a failure by its kind, not by its wording
    trial = accuracy._trial((PlateTest(LIGHT_DRIVE), scene, False))
    assert trial["failure"] == "chatter" and "chatters" in trial["detail"]


LIMIT_STOP = preset("physical").replace(**{"sim.method": "adaptive-newton", "plate.stop": "limit"})


@pytest.mark.slow  # the Python twin over 4,700 adaptive steps: minutes
def test_adaptive_twins_agree_through_a_limit_stop():
    # The light plate out and back, folding and closing onto its origami stop modelled as a MuJoCo limit. Its samples
    # (20 ms) are a whole number of its largest steps (1 ms) apart, so a stretch at the largest step ends on each
    # sample at the step size to the last bits of the time, which the twins round apart: when the step carried over
    # hung on those bits, the twins took different steps from 2.7 s on (4692 and 4709) and ended 3.7e-4 rad apart.
    # Each twin's arithmetic is its own (numpy's sums, C's loops), so rounding is all that may part them.
    native, python = (simulate(LIMIT_STOP.replace(**{"sim.backend": b}), LIGHT_DRIVE, estimate_error=False)
                      for b in ("native", "python"))
    assert (native.steps, native.steps_rejected) == (python.steps, python.steps_rejected)
    for angle in ("segment_angle", "hinge_angle"):
        np.testing.assert_allclose(getattr(native, angle), getattr(python, angle), rtol=0, atol=1e-9)
    hinge = np.degrees(native.hinge_angle)
    assert hinge.min() < -8 and np.abs(hinge[-1]).max() < 0.5  # folded, then closed against the stop


def test_adaptive_steps_do_not_hang_on_the_last_bits_of_the_time():
    # The run above by hand (drive out, reversed at 1.5 s, back), stepping to every instant of its largest step's
    # grid, twice: the time nudged one bit down after each in one, one bit up in the other, as two twins' sums of the
    # steps may round. The same steps and, to rounding, the same trajectory (the test on those bits took 4563 steps in
    # one and 4613 in the other).
    plate = build_plate(LIMIT_STOP)
    m, runs = plate.model, []
    for direction in (-np.inf, np.inf):
        d = mujoco.MjData(m)
        advance = integrate.stepper(m, LIMIT_STOP.sim, "native", plate.groups)
        for k in range(3000):
            if k % 1500 == 0:
                d.qvel[plate.drive_dof] = LIGHT_DRIVE.speed * (-1) ** (k // 1500)
                advance.restart()
            assert advance.until(d, (k + 1) * LIMIT_STOP.sim.dt) == 0
            d.time = np.nextafter(d.time, direction)
        runs.append((advance.taken, advance.rejected, d.qpos.copy(), d.qvel.copy()))
    assert runs[0][:2] == runs[1][:2]
    np.testing.assert_allclose(runs[0][2], runs[1][2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][3], runs[1][3], rtol=0, atol=1e-9)
    assert np.all(np.degrees(runs[0][2][plate.hinge_qpos]) > -0.5)  # back against the stop


@pytest.mark.parametrize("method", ["newton", "adaptive"])
def test_native_step_too_big_for_the_arena_says_so_and_leaves_the_state(method):
    # The native step's workspace (3 nv x nv matrices and the segments' Jacobians, ~180 kB here) lives on the mjData
    # stack: an arena too small for it must give ARENA_FULL before anything moves, not a MuJoCo error.
    scene = preset("physical").replace(**{"plate.segments": 60, "sim.method": method})
    native.load()
    for memory, code in ((150_000, native.Code.ARENA_FULL), (400_000, 0)):
        spec = plate_spec(scene, backend="native")
        spec.memory = memory
        m = spec.compile()
        d = mujoco.MjData(m)
        assert integrate.stepper(m, scene.sim, "native", [])(d, 5) == code
        assert d.time == (0.0 if code else pytest.approx(5 * scene.sim.dt))


def test_adaptive_newton_converges_to_newton_on_the_light_plate():
    # The physical plate (light segments, stiff penalty stops): adaptive-newton against newton at 10 µs (itself
    # within 1e-4 deg of newton at 20 µs); the error stays small at loose tolerances and falls at tight ones.
    light = preset("physical").replace(**{"sim.dt": 1e-3})
    drive = Drive(speed=0.03, stroke=0.015, cycles=1)
    fine = simulate(light.replace(**{"sim.dt": 1e-5}), drive, estimate_error=False)
    errors = []
    for tolerance in (1e-1, 1e-2, 1e-5):
        run = simulate(light.replace(**{"sim.method": "adaptive-newton", "sim.max_step": 1e-2,
                                        "sim.tolerance": tolerance}), drive, estimate_error=False)
        assert np.allclose(run.time, fine.time)
        errors.append(np.degrees(np.abs(np.c_[run.segment_angle, run.hinge_angle]
                                        - np.c_[fine.segment_angle, fine.hinge_angle]).max()))
    assert errors[0] < 0.02 and errors[1] < 0.005 and errors[2] < min(5e-4, errors[0] / 10)
    assert np.degrees(fine.hinge_angle.min()) < -8  # the plate did fold


@pytest.mark.slow  # four swims of the physical robot, two at 1e5 steps a stroke: a convergence study
def test_adaptive_newton_converges_to_newton_on_the_physical_robot():
    # Newton at strokes of 5e4 and 1e5 steps (reversals on the grid), extrapolated to dt -> 0 as a first-order
    # method: adaptive-newton's eta and hinge angles at the preset's tolerance and at 1/10 of it.
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import gait_drive, swim
    scene = preset("physical", RobotScene)
    stroke = gait_drive(scene, 1).stroke_time
    coarse, fine = (swim(scene.replace(**{"sim.method": "newton", "sim.dt": stroke / n}), estimate_error=False)
                    for n in (50_000, 100_000))
    eta = 2 * fine.series["eta"][0] - coarse.series["eta"][0]
    assert abs(fine.series["eta"][0] - eta) < 1e-4  # the reference's own error, well under the check's
    # The first cycle from rest, eta's hardest: the fin slaps flat at the start and turns over at the reversal.
    for tolerance, eta_error in ((scene.sim.tolerance, 1e-3), (scene.sim.tolerance / 10, 2e-4)):
        run = swim(scene.replace(**{"sim.tolerance": tolerance}), estimate_error=False)
        assert abs(run.series["eta"][0] - eta) < eta_error
        i = np.searchsorted(np.round(fine.time, 9), np.round(run.time, 9))
        assert np.degrees(np.abs(run.series["hinge_angle"] - fine.series["hinge_angle"][i]).max()) < 0.02


def test_adaptive_reversals_fall_on_the_drive_not_the_grid():
    # The robot's stroke (25/11 s) is no whole number of these grids' steps: rounded to the grid it would be up to
    # 7 µs off, which moves eta by ~1e-4; on the drive's instants eta does not depend on the grid.
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import swim
    scene = preset("physical", RobotScene).replace(**{"sim.tolerance": 1e-5})
    etas = [swim(scene.replace(**{"sim.dt": dt}), estimate_error=False).series["eta"][0] for dt in (1e-5, 2e-5, 1e-3)]
    assert np.ptp(etas) < 1e-6


def test_physical_robot_error_estimate_follows_its_error():
    # Each Table I gait as the optimiser evaluates it (steady eta, the body recorded at the reversals), against
    # the same at 1/100 of the tolerance: within 0.05 points (0.02 at most; 0.12 on the symmetric gaits when the
    # steps did not restart at the reversals), and the companion at 25x the tolerance estimates eta's error within a
    # factor of 3 (the error comes from where the steps fall at the stops' engagement, not from a smooth truncation
    # error that Richardson's estimate would bound), far below the default limit.
    from finrft.studies.optimize import evaluation_scene
    from finrft.experiments.swim import RobotScene
    from finrft.experiments.swim import swim
    from finrft.studies.table import table_scenes
    for scene in map(evaluation_scene, table_scenes(preset("physical", RobotScene))):
        cycles = scene.gait.cycles
        run = swim(scene, cycles)
        converged = swim(scene.replace(**{"sim.tolerance": scene.sim.tolerance / 100}), cycles, estimate_error=False)
        error = 100 * abs(run.summary()["eta_steady"] - converged.summary()["eta_steady"])
        assert error <= 3 * run.error_estimate["eta_points"] <= 1.5 and error < 0.05, (error, run.error_estimate)
