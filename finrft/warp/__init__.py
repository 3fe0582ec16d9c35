"""finrft's surface laws on MuJoCo Warp: many worlds of one model stepped together, on a GPU or on Warp's CPU
device. Imported only when asked (``import finrft.warp``; ``pip install 'finrft[warp]'`` brings mujoco-warp and
warp-lang): the rest of finrft runs without it.

`WarpWorlds` holds N worlds of a model whose bodies `finrft.attach` cut into surface elements with
``backend="warp"`` (MuJoCo Warp takes no body plugins, so the spec carries no finrft.surface instance; on MuJoCo's
own CPU step the model runs with the Python backend's callback, the same laws in numpy). Every step, MuJoCo Warp's
passive-force callback (``Model.callback.passive``, run right after its own passive forces in each forward pass)
launches three kernels (`finrft.warp.kernels`):

1. ``body_states``, worlds x bodies: each attached body's pose and twist from MuJoCo Warp's float32 state,
   widened to float64;
2. ``element_wrenches``, worlds x elements: each element's depth, velocity and force (the law, DRFT's term, the
   ramp, as plugins/finrft_surface.c computes them, in float64), summed by atomic adds into each body's wrench;
3. ``apply_wrenches``, worlds x dofs: J^T of each wrench (mj_applyFT's) added to ``qfrc_passive``, the one
   narrowing back to float32.

The elements are those `attach` cut, culling included; per world, the medium's parameters (`set_medium`) and the
free surface's height. Runs the flat free surface under gravity along -z.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from ..attach import Attached
from ..errors import SceneError
from ..laws import rft3d

try:
    import warp as wp
except ImportError as error:  # pragma: no cover - the extra is absent
    raise ImportError("finrft.warp needs the warp extra: pip install 'finrft[warp]' (mujoco-warp and warp-lang)"
                      ) from error

wp.config.log_level = wp.LOG_WARNING  # no line per module loaded
wp.init()
import mujoco_warp as mjw  # noqa: E402  (after wp.init)

from mujoco_warp._src import derivative  # noqa: E402
from mujoco_warp._src.forward import _advance as advance  # noqa: E402

from . import kernels  # noqa: E402

LAWS = {"li2013": kernels.LI2013, "rft3d": kernels.RFT3D}
# The time-stepping methods, by finrft's names (`finrft.methods`): MuJoCo's step with the medium's force as it
# is, implicitfast with it linearised in velocity, and backward Euler in it.
METHODS = ("explicit", "implicit", "newton")
# The most evaluations of the medium's force a newton step makes: finrft.integrate's 50 iterations, each with a
# few of its line search's
NEWTON_ROUNDS = 200
CHECK_EVERY = 4     # rounds between looks at whether every world's Newton iteration has converged
# What `set_medium` takes per world, by law: the law's parameters (`finrft.attach`'s names), DRFT's and the
# surface's height.
SHARED = ("drft_lambda", "bulk_density", "surface_z")


def device_name(device: str | None = None) -> str:
    """The Warp device in words: "cpu (x86_64 ...)" or the GPU's name."""
    d = wp.get_device(device)
    return f"{d.alias} ({d.name})"


class WarpWorlds:
    """``worlds`` copies of a compiled model with RFT attached (``attach(..., backend="warp")``), stepped together
    on MuJoCo Warp with the surface laws in Warp kernels. Every getter and setter speaks numpy, one row per world.

    ``device``: a Warp device ("cpu", "cuda:0"; None: Warp's default, the GPU where there is one). The worlds start
    at ``data``'s state (None: the model's qpos0 at rest) with its ctrl.
    """

    def __init__(self, model: mujoco.MjModel, attached: Attached, worlds: int = 1, *, device: str | None = None,
                 data: mujoco.MjData | None = None, method: str = "explicit") -> None:
        if not isinstance(attached, Attached):
            raise SceneError(f"WarpWorlds: attached must be what finrft.attach returned, got "
                             f"{type(attached).__name__}")
        if attached.backend != "warp":
            raise SceneError(f"WarpWorlds: the model was attached with backend={attached.backend!r}: attach with "
                             f"backend='warp' (MuJoCo Warp takes no body plugins)")
        if attached.law not in LAWS:
            raise SceneError(f"WarpWorlds: law {attached.law!r} does not run on Warp yet: use "
                             f"{' or '.join(LAWS)}")
        g = model.opt.gravity
        if attached.free_surface.kind != "flat" or not (g[0] == 0 and g[1] == 0 and g[2] <= 0):
            raise SceneError("WarpWorlds: runs the flat free surface under gravity along -z only (surface "
                             f"{attached.free_surface.kind!r}, gravity {tuple(float(x) for x in g)})")
        if method not in METHODS:
            raise SceneError(f"WarpWorlds: method must be one of {', '.join(METHODS)}, got {method!r}")
        if not (isinstance(worlds, int) and worlds >= 1):
            raise SceneError(f"WarpWorlds: worlds must be a whole number >= 1, got {worlds!r}")
        attached.check_compiled(model)
        self.model, self.attached, self.worlds, self.method = model, attached, worlds, method
        self.device = wp.get_device(device)
        if data is None:
            data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        with wp.ScopedDevice(self.device):
            self.m = mjw.put_model(model)
            self.d = mjw.put_data(model, data, nworld=worlds)
            self._elements()
            self._medium = {key: wp.array(np.full(worlds, value), dtype=wp.float64)
                            for key, value in self._defaults().items()}
            self._scale = wp.zeros(worlds, dtype=wp.float64)  # the law's scale: li2013's zeta, rft3d's xi_n
            self._zeros = wp.zeros(worlds, dtype=wp.float64)
            self._rescale()
            self._origin = wp.zeros((worlds, self.nbody), dtype=wp.vec3d)
            self._rotation = wp.zeros((worlds, self.nbody), dtype=wp.mat33d)
            self._twist = wp.zeros((worlds, self.nbody), dtype=wp.spatial_vectord)
            self._wrench = wp.zeros((worlds, self.nbody), dtype=wp.spatial_vectord)
            if method != "explicit":
                self._com = wp.zeros((worlds, self.nbody), dtype=wp.vec3d)
                self._damping = wp.zeros((worlds, self.nbody), dtype=wp.spatial_matrixd)
                self._smooth = wp.zeros((worlds, self.m.nC), dtype=float)
                self._work = wp.zeros((worlds, model.nv, model.nv + 1), dtype=wp.float64)
                self._qacc = wp.zeros((worlds, model.nv), dtype=float)
                self._fullm = (self.m.M_fullm_i, self.m.M_fullm_j)
            if method == "newton":
                nv = model.nv
                self._gen = wp.zeros((worlds, nv), dtype=wp.float64)
                self._rest, self._v0, self._dv, self._accepted, self._direction = (
                    wp.zeros((worlds, nv), dtype=wp.float64) for _ in range(5))
                self._search = wp.zeros((worlds, 4), dtype=wp.float64)
                self._trial = wp.zeros((worlds, self.nbody), dtype=wp.spatial_vectord)
                self._trial_wrench = wp.zeros((worlds, self.nbody), dtype=wp.spatial_vectord)
        self.m.callback = dataclasses.replace(self.m.callback, passive=self._passive)

    # --- set up ------------------------------------------------------------------------------------------------
    def _elements(self) -> None:
        a = self.attached
        self.bodies = tuple(s.body for s in a.surfaces)
        self.nbody = len(self.bodies)
        ids = np.array([self.model.body(b).id for b in self.bodies], dtype=np.int32)
        self._body = wp.array(ids, dtype=int)
        self._rootid = wp.array(self.model.body_rootid.astype(np.int32), dtype=int)
        owner = np.concatenate([np.full(len(s.area), b, dtype=np.int32) for b, s in enumerate(a.surfaces)])
        self.nelement = len(owner)
        self._element_body = wp.array(owner, dtype=int)
        self._centre = wp.array(np.concatenate([s.centre for s in a.surfaces]), dtype=wp.vec3d)
        self._normal = wp.array(np.concatenate([s.normal for s in a.surfaces]), dtype=wp.vec3d)
        self._area = wp.array(np.concatenate([s.area for s in a.surfaces]), dtype=wp.float64)
        self._coef = wp.array(np.asarray(a.coefficients.values(), dtype=float), dtype=wp.float64)
        self._law = LAWS[a.law]

    def _defaults(self) -> dict[str, float]:
        a = self.attached
        out = {**a.parameters, "drft_lambda": a.drft_lambda}
        if self._law == kernels.LI2013:
            out["bulk_density"] = a.bulk_density  # rft3d's DRFT density is its own rho_c
        return {**out, "surface_z": a.surface_z}

    def _rescale(self) -> None:
        med = self._medium
        if self._law == kernels.LI2013:
            wp.copy(self._scale, med["zeta"])
        else:
            self._scale.assign(rft3d.xi(med["rho_c"].numpy(), med["mu_int"].numpy()))

    def medium_keys(self) -> tuple[str, ...]:
        """The per-world parameters `set_medium` takes: the law's (li2013: zeta; rft3d: rho_c, mu_int, mu_surf),
        drft_lambda, bulk_density (kg/m^3, DRFT's density for li2013; rft3d's is its rho_c) and surface_z (m)."""
        return tuple(self._medium)

    def set_medium(self, **values: float | Sequence[float] | np.ndarray) -> None:
        """Set medium parameters, each one number for every world or one per world (`medium_keys`; SI, zeta
        dimensionless as `finrft.attach` takes it). SceneError for an unknown key or a bad value."""
        for key, value in values.items():
            if key not in self._medium:
                raise SceneError(f"WarpWorlds.set_medium: {key!r} is not a parameter of law "
                                 f"{self.attached.law!r} (its: {', '.join(self._medium)})")
            column = np.broadcast_to(np.asarray(value, dtype=float), (self.worlds,)) if np.ndim(value) == 0 else \
                np.asarray(value, dtype=float)
            if column.shape != (self.worlds,) or not np.all(np.isfinite(column)):
                raise SceneError(f"WarpWorlds.set_medium: {key} must be one finite number or {self.worlds} of "
                                 f"them, got shape {np.shape(value)}")
            if key != "surface_z" and np.any(column < 0):
                raise SceneError(f"WarpWorlds.set_medium: {key} must be >= 0")
            self._medium[key].assign(np.ascontiguousarray(column))
        self._rescale()

    def medium(self) -> dict[str, np.ndarray]:
        """Each per-world parameter (`medium_keys`), one value per world."""
        return {key: array.numpy().copy() for key, array in self._medium.items()}

    # --- state ------------------------------------------------------------------------------------------------
    def _rows(self, value: Any, width: int, key: str) -> np.ndarray:
        rows = np.asarray(value, dtype=np.float32)
        if rows.ndim == 1:
            rows = np.broadcast_to(rows, (self.worlds, len(rows)))
        if rows.shape != (self.worlds, width) or not np.all(np.isfinite(rows)):
            raise SceneError(f"WarpWorlds: {key} must be ({width},) or ({self.worlds}, {width}) finite numbers, got "
                             f"shape {np.shape(value)}")
        return np.ascontiguousarray(rows)

    def set_ctrl(self, ctrl: np.ndarray) -> None:
        """Every world's ctrl: (nu,) for all or (worlds, nu)."""
        self.d.ctrl.assign(self._rows(ctrl, self.model.nu, "ctrl"))

    def set_state(self, qpos: np.ndarray | None = None, qvel: np.ndarray | None = None) -> None:
        """Every world's positions (nq,) or (worlds, nq) and velocities (nv,) or (worlds, nv); None: unchanged."""
        if qpos is not None:
            self.d.qpos.assign(self._rows(qpos, self.model.nq, "qpos"))
        if qvel is not None:
            self.d.qvel.assign(self._rows(qvel, self.model.nv, "qvel"))

    @property
    def qpos(self) -> np.ndarray:
        """(worlds, nq) positions."""
        return self.d.qpos.numpy().copy()

    @property
    def qvel(self) -> np.ndarray:
        """(worlds, nv) velocities."""
        return self.d.qvel.numpy().copy()

    @property
    def time(self) -> np.ndarray:
        """(worlds,) each world's time, s."""
        return self.d.time.numpy().astype(float)

    # --- stepping ---------------------------------------------------------------------------------------------
    def _passive(self, m: Any, d: Any) -> None:
        wp.launch(kernels.body_states, dim=(self.worlds, self.nbody),
                  inputs=[self._body, self._rootid, d.xpos, d.xmat, d.cvel, d.subtree_com],
                  outputs=[self._origin, self._rotation, self._twist])
        self._sum_wrenches()
        wp.launch(kernels.apply_wrenches, dim=(self.worlds, self.model.nv),
                  inputs=[self.nbody, self._body, self._rootid, m.body_isdofancestor, d.subtree_com, d.cdof,
                          self._origin, self._wrench], outputs=[d.qfrc_passive])

    def _sum_wrenches(self) -> None:
        self._per_element(kernels.element_wrenches, self._twist, self._wrench)

    def _per_element(self, kernel: Any, twist: Any, out: Any, *more: Any) -> None:
        """Launch a kernel over worlds x elements at the forward pass's positions and the twists given, the
        medium's parameters of each world, into ``out`` (zeroed first)."""
        out.zero_()
        med = self._medium
        rft = self._law == kernels.RFT3D
        wp.launch(kernel, dim=(self.worlds, self.nelement),
                  inputs=[self._law, self._coef, wp.float64(self.attached.v_reg), self._element_body, self._centre,
                          self._normal, self._area, self._scale, med["mu_surf"] if rft else self._zeros,
                          med["drft_lambda"], med["rho_c"] if rft else med["bulk_density"], med["surface_z"],
                          self._origin, self._rotation, twist, *more], outputs=[out])

    def step(self, steps: int = 1) -> None:
        """Advance every world ``steps`` steps of the model's timestep. ``method`` explicit: MuJoCo Warp's step of
        the model's integrator, the medium's force an explicit passive force (light bodies need dt < 2 m v_reg /
        F). implicit: the forward pass, then MuJoCo's implicitfast solve with each body's RFT damping, linearised
        at the step's start, added to MuJoCo's own (`_implicit`). newton: backward Euler in the medium's force,
        solved by Newton's method (`_newton`): stable on light links at 1 ms."""
        with wp.ScopedDevice(self.device):
            for _ in range(steps):
                if self.method == "explicit":
                    mjw.step(self.m, self.d)
                else:
                    mjw.forward(self.m, self.d)
                    if self.method == "implicit":
                        self._implicit()
                    else:
                        self._newton()

    def _implicit(self) -> None:
        """v' = v + dt (M - dt D - dt K)^-1 f: finrft's implicit method (implicitfast with the RFT force linearised
        in velocity) on MuJoCo Warp. f is the forward pass's force (the medium's included), D MuJoCo Warp's
        derivative of its smooth forces (dampers, actuators: its implicitfast's), K = sum over bodies J^T G J the
        medium's, from every submerged element's dF/dv (central differences of the same law; the trailing
        elements' secant as the native step takes it). Dense, one world per thread, in float64: robots have tens
        of dofs. Free bodies go without MuJoCo Warp's gyroscopic term of implicitfast."""
        m, d = self.m, self.d
        wp.launch(kernels.tree_centres, dim=(self.worlds, self.nbody), inputs=[self._body, self._rootid,
                  d.subtree_com], outputs=[self._com])
        self._per_element(kernels.element_damping, self._twist, self._damping, self._com, 1)
        derivative.deriv_smooth_vel(m, d, self._smooth)
        wp.launch(kernels.implicit_solve, dim=self.worlds,
                  inputs=[self.model.nv, self.nbody, self._body, m.body_isdofancestor, d.cdof, *self._fullm,
                          m.M_elemid, self._smooth, wp.float64(self.model.opt.timestep), self._damping, d.efc.Ma,
                          self._work], outputs=[self._qacc])
        advance(m, d, self._qacc)

    def _newton(self) -> None:
        """finrft's newton method on MuJoCo Warp: the velocity change dv solves (M - dt D) dv = dt (f - F(v) +
        F(v + dv)) at the forward pass's positions (F the medium's generalized force, f every force of the forward
        pass), by Newton's method per world with the Jacobian M - dt D - dt K(v + dv) and a backtracking line
        search on the residual's norm (halving, down to 1e-6 of the step), to the native step's root: a residual of at
        most 1e-3 of dt times the step's largest force with a change below 1e-7 (1 + |qvel|) (the native 1e-10 is
        below the rounding of MuJoCo Warp's float32 qvel), or a residual a million times smaller; else, when a
        search finds no descent or after NEWTON_ROUNDS evaluations, the last accepted dv (where the native step
        would halve itself). Every world iterates in the same launches, the finished ones idle."""
        m, d, nv = self.m, self.d, self.model.nv
        dt = wp.float64(self.model.opt.timestep)
        wp.launch(kernels.tree_centres, dim=(self.worlds, self.nbody), inputs=[self._body, self._rootid,
                  d.subtree_com], outputs=[self._com])
        moving = [nv, self._body, m.body_isdofancestor, d.cdof, self._origin, self._com]
        wp.launch(kernels.generalized_forces, dim=(self.worlds, nv), inputs=[self.nbody, *moving[1:], self._wrench],
                  outputs=[self._gen])
        wp.launch(kernels.newton_start, dim=(self.worlds, nv), inputs=[self._gen, d.efc.Ma, d.qvel],
                  outputs=[self._rest, self._v0, self._dv, self._search])
        derivative.deriv_smooth_vel(m, d, self._smooth)
        for round in range(NEWTON_ROUNDS):
            wp.launch(kernels.trial_twists, dim=(self.worlds, self.nbody), inputs=[*moving, self._v0, self._dv],
                      outputs=[self._trial])
            self._per_element(kernels.element_wrenches, self._trial, self._trial_wrench)
            self._per_element(kernels.element_damping, self._trial, self._damping, self._com, 0)
            wp.launch(kernels.generalized_forces, dim=(self.worlds, nv),
                      inputs=[self.nbody, *moving[1:], self._trial_wrench], outputs=[self._gen])
            wp.launch(kernels.newton_update, dim=self.worlds,
                      inputs=[nv, self.nbody, self._body, m.body_isdofancestor, d.cdof, *self._fullm, m.M_elemid,
                              self._smooth, dt, self._damping, self._rest, self._gen, self._v0, self._work],
                      outputs=[self._dv, self._accepted, self._direction, self._search])
            if round % CHECK_EVERY == CHECK_EVERY - 1 and (self._search.numpy()[:, 2] > 0).all():
                break
        wp.launch(kernels.newton_finish, dim=(self.worlds, nv), inputs=[dt, self._dv, self._accepted, self._search],
                  outputs=[self._qacc])
        advance(m, d, self._qacc)

    def forward(self) -> None:
        """MuJoCo Warp's forward pass at the current state (applies the medium's force into qfrc_passive)."""
        with wp.ScopedDevice(self.device):
            mjw.forward(self.m, self.d)

    # --- the medium's wrench ----------------------------------------------------------------------------------
    def wrenches(self) -> np.ndarray:
        """(worlds, B, 6): the medium's wrench on each attached body (the torque about its origin, N m, then the
        force, N; world frame; bodies in the order of ``attached.surfaces``), as the last forward pass applied it
        (float64, from the float32 state)."""
        return self._wrench.numpy().astype(float)

    def forces(self) -> np.ndarray:
        """(worlds, B, 3): each attached body's medium force, N (`wrenches`' force part)."""
        return self.wrenches()[:, :, 3:]

    def wrenches_at(self, origin: np.ndarray, rotation: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """The laws alone, in float64: (worlds, B, 6) wrenches as `wrenches`, of bodies at the origins (worlds, B,
        3), rotation matrices (worlds, B, 3, 3) and twists (worlds, B, 6: angular velocity, velocity of the origin,
        as mj_objectVelocity gives them) given, under each world's medium. What tests the kernels against the
        native plugin at its own float64 states."""
        shapes = {"origin": (3,), "rotation": (3, 3), "twist": (6,)}
        given = {"origin": origin, "rotation": rotation, "twist": twist}
        for key, tail in shapes.items():
            if np.shape(given[key]) != (self.worlds, self.nbody, *tail):
                raise SceneError(f"WarpWorlds.wrenches_at: {key} must have shape "
                                 f"{(self.worlds, self.nbody, *tail)}, got {np.shape(given[key])}")
        with wp.ScopedDevice(self.device):
            self._origin.assign(np.ascontiguousarray(origin, dtype=float))
            self._rotation.assign(np.ascontiguousarray(rotation, dtype=float))
            self._twist.assign(np.ascontiguousarray(twist, dtype=float))
            self._sum_wrenches()
        return self.wrenches()


def body_state(model: mujoco.MjModel, data: mujoco.MjData, bodies: Sequence[str]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The origins (B, 3), rotations (B, 3, 3) and twists (B, 6) of the named bodies in an MjData after
    mj_forward, as `WarpWorlds.wrenches_at` takes them: from MuJoCo's own float64 state."""
    origin, rotation, twist = np.zeros((len(bodies), 3)), np.zeros((len(bodies), 3, 3)), np.zeros((len(bodies), 6))
    for k, name in enumerate(bodies):
        i = model.body(name).id
        origin[k], rotation[k] = data.xpos[i], data.xmat[i].reshape(3, 3)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_XBODY, i, twist[k], 0)
    return origin, rotation, twist


def scene_worlds(scene: Any, worlds: int = 1, *, device: str | None = None,
                 overrides: Mapping[str, Any] | None = None, method: str = "explicit") -> WarpWorlds:
    """`WarpWorlds` of a robot scene (a `finrft.scene.UserScene`, or the path of its TOML file): its model with its
    medium attached (backend warp), at its keyframe if it names one, stepped by ``method``."""
    from ..experiments.attached_model import build_attached, scene_spec
    from ..scene import UserScene, load_scene
    if not isinstance(scene, UserScene):
        scene = load_scene(str(scene), overrides=dict(overrides or {}), cls=UserScene)
    sim = dataclasses.replace(scene.sim, backend="warp")
    built = build_attached(scene_spec(scene), [j.joint for j in scene.drive], scene.model.bodies, scene.medium, sim,
                           scene.model.geoms)
    data = mujoco.MjData(built.model)
    if scene.model.keyframe:
        mujoco.mj_resetDataKeyframe(built.model, data, built.model.key(scene.model.keyframe).id)
    return WarpWorlds(built.model, built.attached, worlds, device=device, data=data, method=method)
