"""The implicit methods on attached surfaces (`finrft.attach`): each body's wrench taken at the step's new velocity,
in both twins; a light box resting on the medium at 1 ms against the closed forms of li2013; convergence in dt;
and the chatter probe, which tells a body at rest from a step that chatters."""

import types

import mujoco
import numpy as np
import pytest

from conftest import physics_run, settling_box
from finrft import integrate, methods
from finrft.attach import attach
from finrft.errors import Chatter
from finrft.laws import li2013
from finrft.scene import Sim
from finrft.stepping import chatter_speeds, step_through

# A 10 x 10 x 2 cm box of 0.5 kg on a free joint, its lower face at height z.
BOX = """<mujoco><option timestep="{dt}" integrator="implicitfast"/><worldbody>
  <body name="box" pos="0 0 {z}"><freejoint/><geom type="box" size="0.05 0.05 0.01" mass="0.5"/></body>
</worldbody></mujoco>"""
MASS, AREA, HALF = 0.5, 0.1 * 0.1, 0.01

# A block dragged sideways at 5 cm/s, 4 cm deep: the carriage on a stiff velocity servo, the block free to rise and
# pitch under it (a light body whose lift and pitch the stiff medium sets).
DRAG = """<mujoco><option timestep="{dt}" integrator="implicitfast"/><worldbody>
  <body name="carriage"><joint name="x" type="slide" axis="1 0 0"/><geom type="sphere" size="0.001" mass="1"/>
    <body name="block" pos="0 0 -0.04"><joint name="z" type="slide" axis="0 0 1"/>
      <joint name="pitch" type="hinge" axis="0 1 0"/><geom type="box" size="0.02 0.0125 0.01" mass="0.05"/></body>
  </body></worldbody><actuator><velocity joint="x" kv="1000"/></actuator></mujoco>"""
DRAG_SPEED = 0.05


def _box(backend: str, dt: float, z: float = HALF, **medium):
    spec = mujoco.MjSpec.from_string(BOX.format(dt=dt, z=z))
    attached = attach(spec, "box", backend=backend, element_size=0.01, **medium)
    return spec.compile(), attached


def _steps(m, attached, backend: str, method: str, d, n: int) -> np.ndarray:
    """The positions after each of n steps (stopping the test on a failure code)."""
    advance = integrate.stepper(m, Sim(method=method, dt=m.opt.timestep), backend, [], attached)
    out = np.empty((n, m.nq))
    with attached.installed(m):
        for i in range(n):
            assert advance(d, 1) == 0
            out[i] = d.qpos
    return out


MEDIA = {"li2013": dict(law="li2013", v_reg=1e-3),
         "rft3d": dict(law="rft3d", rho_c=1617.0, mu_int=1.07, mu_surf=0.1806, v_reg=1e-3)}


@pytest.mark.parametrize("law", MEDIA)
@pytest.mark.parametrize("method", [
    # the adaptive methods' many small steps on the stiff medium, in the Python twin too, take minutes; the
    # linearly implicit and midpoint steps share newton's code: all three with the slow studies
    name if name == "newton" else pytest.param(name, marks=pytest.mark.slow)
    for name, m in methods.METHODS.items() if m.implicit])
def test_native_and_python_steppers_agree_on_a_free_body(law, method):
    # A box half in the medium, thrown sideways, down and spinning: every row of its twist and wrench is in play.
    # Adaptive steps are sized by each twin's own estimate, equal only to rounding (as test_methods says).
    # The linearly implicit step (one Newton iterate) on li2013's box amplifies a rounding difference of its
    # differenced Jacobian about 15-fold a step (1e-16 -> 1e-10 in 5 steps, measured): the twins are compared over
    # the first 10 steps there, where that growth stays below the tolerance.
    n = 10 if (method, law) == ("implicit", "li2013") else 150
    runs = {}
    for backend in ("native", "python"):
        m, attached = _box(backend, 1e-3, z=0.005, **MEDIA[law])
        d = mujoco.MjData(m)
        d.qvel[:] = [0.05, 0.02, -0.05, 0.5, -0.3, 1.0]
        runs[backend] = _steps(m, attached, backend, method, d, n)
    atol = 1e-6 if methods.get(method).adaptive else 1e-9
    np.testing.assert_allclose(runs["native"], runs["python"], atol=atol, rtol=0)
    # the medium did act: without it the box would have kept its speed
    assert abs(runs["native"][-1, 0] - 0.05 * n * 1e-3) > 1e-4


@pytest.mark.parametrize("law", [*MEDIA, "li2013-planar"])
def test_the_surface_laws_are_rate_independent_and_their_leading_slope_is_the_derivative(law):
    # Newton's slope on an element leading at v takes the law to depend on v's direction alone (L(c v) = L(v),
    # c > 0, so dL/dv v = 0) and probes it across v only: it is the derivative of the ramped force, as central
    # differences along every axis give it, on leading elements of every orientation, on the ramp and off it.
    medium = dict(MEDIA.get(law, dict(law=law, v_reg=1e-3)))
    _, attached = _box("python", 1e-3, **medium)
    rng = np.random.default_rng(23)
    normal = rng.normal(size=(400, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    v = rng.normal(scale=0.02, size=(400, 3))
    v *= np.where(np.einsum("ei,ei->e", normal, v) < 0, -1, 1)[:, None]   # leading
    v[:100] -= (np.einsum("ei,ei->e", normal[:100], v[:100]) - 3e-4)[:, None] * normal[:100]  # on the ramp
    depth, area = np.full(400, 0.02), np.full(400, 1e-4)
    bare = attached.law_forces(normal, v, depth, area)
    for c in (1e-3, 0.7, 40.0):
        np.testing.assert_allclose(attached.law_forces(normal, c * v, depth, area), bare, rtol=1e-9, atol=1e-12)
    f = attached.element_forces(normal, v, depth, area)
    h = 1e-6 * (np.linalg.norm(v, axis=1) + integrate.SURFACE_SPEED)
    slope = integrate._leading_slope(attached, normal, v, f, depth, area, h)
    step = 1e-8
    central = np.stack([(attached.element_forces(normal, v + step * e, depth, area)
                         - attached.element_forces(normal, v - step * e, depth, area)) / (2 * step)
                        for e in np.eye(3)], axis=2)
    smooth = np.all(np.abs(central) < 1e6, axis=(1, 2))  # not across a kink of the law (a face's edge-on switch)
    assert smooth.sum() > 300
    scale = np.abs(central[smooth]).max(axis=(1, 2))[:, None, None]
    assert np.all(np.abs(slope[smooth] - central[smooth]) <= 1e-3 * scale)


def _alpha_z_flat() -> float:
    """li2013's alpha_z of a horizontal plate pushed straight down: alpha_z(beta = 0, gamma = pi/2), N/m^3."""
    return float(li2013.alpha(np.array(0.0), np.array(np.pi / 2), 1.0, li2013.GENERIC)[1])


def test_dropped_box_settles_at_the_closed_form_depth_and_stays():
    # li2013 (planar form, generic medium, zeta 1): the lower face resists sinking with alpha_z A depth, so the
    # static depth is m g / (alpha_z A) (0.49 mm). Released at rest with its lower face on the surface, the box
    # sinks until the work of that force equals its weight's, alpha_z A x^2 / 2 = m g x: x = 2 m g / (alpha_z A);
    # rising meets no leading face below the surface, so it stays there. Regularised over v_reg it creeps on at the
    # speed where the weighted force carries the weight: v_reg atanh(m g / (alpha_z A x)).
    v_reg = 1e-5
    m, attached = _box("native", 1e-3, v_reg=v_reg)
    d = mujoco.MjData(m)
    z = _steps(m, attached, "native", "newton", d, 3000)[:, 2]
    depth = HALF - z
    weight = MASS * -m.opt.gravity[2]
    static = weight / (_alpha_z_flat() * AREA)
    assert depth[-1] == pytest.approx(2 * static, rel=0.03)
    creep = (depth[-1] - depth[-1001]) / 1.0
    assert creep == pytest.approx(v_reg * np.arctanh(weight / (_alpha_z_flat() * AREA * depth[-1])), rel=0.1)
    assert creep < 1e-4  # < 0.1 mm/s
    velocity = np.diff(z[-1001:]) / 1e-3
    assert np.all(np.diff(velocity) <= 0) or np.all(np.diff(velocity) >= 0)  # no step reverses: no chatter


def _flips(z: np.ndarray) -> float:
    """The share of steps whose velocity change reverses the previous one's."""
    change = np.sign(np.diff(z, n=2))
    return float(np.mean(change[1:] != change[:-1]))


def test_newton_midpoint_is_second_order_where_the_motion_is_quasi_static():
    # A box on the medium under its weight, its lower face deep enough that the regularised law carries it while it
    # creeps: m dv/dt = m g - alpha_z A d tanh(v / v_reg), dd/dt = v, solved independently by scipy (Radau). Its
    # velocity settles within m v_reg / (alpha_z A d) = 1e-5 s, so the depth follows a quasi-static creep: newton,
    # the force at the step's start, is first order in dt; newton-midpoint, the force half a step ahead, cancels
    # that error and keeps only the unresolved 1e-5 s transient (6e-10 m, the same for both).
    from scipy.integrate import solve_ivp
    v_reg, duration = 1e-4, 0.5
    k = _alpha_z_flat() * AREA
    weight = MASS * 9.81
    d0 = weight / k / 0.8

    def rhs(_, y):
        return [y[1], (weight - k * y[0] * np.tanh(max(y[1], 0.0) / v_reg)) / MASS]
    exact = solve_ivp(rhs, (0, duration), [d0, 0.0], method="Radau", rtol=1e-12, atol=[1e-16, 1e-14]).y[0, -1]
    assert exact - d0 == pytest.approx(5.08e-5, rel=0.01)  # it creeps 51 um
    error = {}
    for method in ("newton", "newton-midpoint"):
        for dt in (4e-3, 2e-3, 1e-3):
            m, attached = _box("native", dt, z=HALF - d0, v_reg=v_reg)
            assert -m.opt.gravity[2] == 9.81
            z = _steps(m, attached, "native", method, mujoco.MjData(m), round(duration / dt))[-1, 2]
            error[method, dt] = HALF - z - exact
    assert 0.4 < error["newton", 2e-3] / error["newton", 4e-3] < 0.6  # first order
    assert 0.4 < error["newton", 1e-3] / error["newton", 2e-3] < 0.6
    assert abs(error["newton-midpoint", 4e-3]) < abs(error["newton", 4e-3]) / 20
    assert max(abs(error["newton-midpoint", dt]) for dt in (4e-3, 2e-3, 1e-3)) < abs(error["newton", 1e-3]) / 5


def test_newton_midpoint_damps_an_inertial_drop_and_converges():
    # The box dropped onto the medium (as above) swings down against a force that grows with depth: the midpoint
    # positions lie ahead along the velocity, so the force is taken deeper than where the box is, a damping of about
    # k dt / 2 that stops it short, by an amount first order in dt, towards newton's depth.
    final = {}
    for method, dt in (("newton", 5e-4), ("newton-midpoint", 1e-3), ("newton-midpoint", 5e-4)):
        m, attached = _box("native", dt, v_reg=1e-5)
        final[method, dt] = HALF - _steps(m, attached, "native", method, mujoco.MjData(m), round(0.2 / dt))[-1, 2]
    short = {dt: 1 - final["newton-midpoint", dt] / final["newton", 5e-4] for dt in (1e-3, 5e-4)}
    assert 0.02 < short[1e-3] < 0.08
    assert 0.35 < short[5e-4] / short[1e-3] < 0.65


def test_explicit_step_chatters_on_the_resting_box():
    # Same box, MuJoCo's step at 1 ms: the medium's force, stiff on the scale v_reg, overshoots every step
    # (dt >> 2 m v_reg / F, about 1e-6 s here), where newton's velocity changes keep one sign (above).
    m, attached = _box("native", 1e-3, v_reg=1e-5)
    d = mujoco.MjData(m)
    z = _steps(m, attached, "native", "explicit", d, 3000)[:, 2]
    assert _flips(z[-1000:]) > 0.9


def _drag(method: str, dt: float, backend: str = "native") -> np.ndarray:
    spec = mujoco.MjSpec.from_string(DRAG.format(dt=dt))
    attached = attach(spec, "block", backend=backend, element_size=0.005, v_reg=1e-3)
    m = spec.compile()
    d = mujoco.MjData(m)
    d.ctrl[0] = d.qvel[0] = DRAG_SPEED
    return _steps(m, attached, backend, method, d, round(0.2 / dt))[-1]


def test_dragged_block_converges_in_dt():
    # Newton steps at 2, 1 and 0.5 ms against 25 µs: the error falls with the step (first order: halves or
    # better), and at 1 ms the block's rise and pitch are within 0.02 mm and 0.02 mrad.
    reference = _drag("newton", 2.5e-5)
    errors = [np.abs(_drag("newton", dt) - reference).max() for dt in (2e-3, 1e-3, 5e-4)]
    assert errors[1] < 0.6 * errors[0] and errors[2] < 0.6 * errors[1]
    assert errors[1] < 2e-5
    # the medium lifts and pitches the block (Ding et al. 2011's drag-induced lift), far beyond that error
    assert reference[1] > 2e-3 and abs(reference[2]) > 0.05


def test_newton_from_the_last_steps_change_halves_the_law_passes_and_keeps_the_root(monkeypatch):
    # The dragged block at 1 ms in the numpy twin, one step a call: Newton's method started from the last step's
    # velocity change (the stepper's history) against the same steps each started from rest (the history
    # cleared), which stop only at the fixed tolerance. The passes of the law over the elements, counted, beyond
    # the start's: at most 0.6 times as many, and the block within a thousandth of the step's own error (1 ms
    # against 0.5 ms) of where it is then.
    passes = {True: 0, False: 0}
    forces = integrate.PythonImplicit._forces

    def counted(*args, **kwargs):
        passes[args[3]] += 1
        return forces(*args, **kwargs)
    monkeypatch.setattr(integrate.PythonImplicit, "_forces", staticmethod(counted))

    def drag(dt: float, predicted: bool) -> tuple[np.ndarray, float]:
        spec = mujoco.MjSpec.from_string(DRAG.format(dt=dt))
        attached = attach(spec, "block", backend="python", element_size=0.005, v_reg=1e-4)
        m = spec.compile()
        d = mujoco.MjData(m)
        d.ctrl[0] = DRAG_SPEED
        advance = integrate.stepper(m, Sim(method="newton", dt=dt), "python", [], attached)
        passes[True] = passes[False] = 0
        n = round(0.1 / dt)
        with attached.installed(m):
            for _ in range(n):
                if not predicted:
                    advance.history[:] = np.nan
                assert advance(d, 1) == 0
        # per step: one pass takes the force as MuJoCo applied it, one (with the slope) starts Newton's method
        return d.qpos.copy(), (passes[False] - n) / n

    predicted, lean = drag(1e-3, True)
    afresh, full = drag(1e-3, False)
    finer, _ = drag(5e-4, False)
    assert lean <= 0.6 * full
    assert np.abs(predicted - afresh).max() < 1e-3 * np.abs(afresh - finer).max()


def test_chatter_speeds_are_the_regularisation_over_the_lever():
    # A free body's translations move every element one to one; its rotations move the farthest by its arm: on
    # 1 cm elements, the centre of a side face's corner element, (5, 4.5, 0.5) cm from the box's centre.
    v_reg = 1e-3
    m, attached = _box("native", 1e-3, v_reg=v_reg)
    d = mujoco.MjData(m)
    speeds = chatter_speeds(m, d, [], attached, range(6))
    arm = np.linalg.norm([0.05, 0.045, 0.005])
    np.testing.assert_allclose(speeds, v_reg / np.r_[np.ones(3), np.full(3, arm)])


@pytest.mark.parametrize("method", ["newton", "explicit"])
def test_chatter_probe_passes_a_body_at_rest_and_stops_a_chattering_step(method):
    # The box placed at rest at twice its static depth, where it stays (above): with newton at 1 ms its velocity
    # settles to the creep and the probe passes; MuJoCo's step at 1 ms flips it every step, and the run stops.
    v_reg = 1e-5
    static = MASS * 9.81 / (_alpha_z_flat() * AREA)
    m, attached = _box("native", 1e-3, z=HALF - 2 * static, v_reg=v_reg)
    d = mujoco.MjData(m)
    scene = types.SimpleNamespace(sim=Sim(method=method, dt=1e-3))
    advance = integrate.stepper(m, scene.sim, "native", [], attached)
    watch = list(range(6))
    steps, samples = 1000, np.arange(0, 1001, 10)

    def run() -> None:
        step_through(m, d, scene, advance, steps, np.array([0]), samples, lambda k: None, lambda i: None,
                     watch=watch, speeds=chatter_speeds(m, d, [], attached, watch))
    if method == "explicit":
        with pytest.raises(Chatter, match="use sim.method = 'newton'"):
            run()
    else:
        run()
        assert abs(d.qvel[2]) < 1e-4


def test_the_linearly_implicit_step_holds_a_light_plate_settling(tmp_path):
    # The exact slope of an element that trails is 0, so the linearly implicit step saw nothing of the force it
    # takes as it leads again: the 50 g plate at 1 ms chattered (Chatter at 0.04 s) where central differences had
    # held it. Across the ramp's kink its slope is a secant (finrft_surface_trailing_slope): it rests, the
    # medium carrying its weight, in both twins.
    from finrft.scene import UserScene, load_scene
    path = settling_box(tmp_path, "implicit")
    weight = 0.05 * 9.81
    forces = []
    for backend in ("native", "python"):
        scene = load_scene(str(path), cls=UserScene, overrides={"sim.backend": backend})
        summary = physics_run(scene).summary()
        assert summary["chatter"] is None
        assert summary["medium_force_N"][2] == pytest.approx(weight, rel=1e-3)
        assert abs(summary["com_velocity_m_s"][2]) < 1e-4  # at rest: creep at about li2013's v_reg
        forces.append(np.array(summary["medium_force_N"]))
    np.testing.assert_allclose(forces[0], forces[1], rtol=1e-9, atol=1e-12)
