"""RFT on any MuJoCo model: `attach` cuts the geoms of named bodies of a user's `mujoco.MjSpec` into surface
elements and gives them a granular resistive force law, before the spec is compiled.

Each element below the free surface (`finrft.surfaces`: the horizontal z = surface_z, a plane at any tilt or a
heightfield; depth measured along the model's gravity from the surface above the element) that leads the motion
(outward normal . velocity > 0) takes the law's stress times its depth and area (a surface law of the registry
`finrft.laws`, found by its name: `finrft.laws.li2013.element_forces` (Li 2013 in 3D, Treers et al. 2021),
`li2013-planar` or `finrft.laws.rft3d.element_forces`), plus, with ``drft_lambda`` > 0, DRFT's rate-dependent term
(`finrft.laws.drft`), all times the ramp tanh(max(n . v, 0) / v_reg) (`finrft.laws.regularised`). The laws take
their angles against gravity: they see normals and velocities in `finrft.surfaces.law_frame`, whose z is up (the
identity under gravity along -z). The force appears where MuJoCo's passive forces appear, ``data.qfrc_passive``:
from the native plugin ``finrft.surface`` (plugins/finrft_surface.c, one instance per body, the elements in its
config) or, with the Python backend, from a passive-force callback that `Attached.installed` sets for a block and
then restores.

Elements: a box's faces are cut into rectangles, a cylinder's side into rectangles and its caps into ring
sectors, spheres, ellipsoids and a capsule's ends into bands of equal polar angle split in azimuth, a mesh's
triangles into equal sub-triangles; all about ``element_size`` across, each with the exact area of its cell (on
an ellipsoid, the area at the cell's centre). Each element acts at its cell's centre, so the force on a flat face is
exact while the depth is linear over it; where the free surface cuts elements the error falls as the square of the
element size, and where the edge of a curved face's leading part cuts elements (the stress jumps there) between
first and second order.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
from dataclasses import dataclass, field
from typing import Callable, Iterator, Sequence

import mujoco
import numpy as np

from . import callbacks, laws, media, native, surfaces
from .errors import SceneError
from .laws import drft, li2013, rft3d

BACKENDS = ("native", "python", "warp")
PLUGIN = "finrft.surface"
# The Python backend's forces come from a callback installed for a block: a model given them carries an instance of
# the native plugin finrft.guard (plugins/finrft_guard.c), which MuJoCo runs right after the callback in every
# mj_passive and which raises unless the callback stamped its state, as `SurfaceForces` does.
GUARD, GUARD_PLUGIN = "finrft_guard", "finrft.guard"
# More elements than this make the plugin's config and every passive-force evaluation needlessly large.
MAX_ELEMENTS = 100_000

_G = mujoco.mjtGeom
SUPPORTED = {int(_G.mjGEOM_BOX): "box", int(_G.mjGEOM_CAPSULE): "capsule", int(_G.mjGEOM_CYLINDER): "cylinder",
             int(_G.mjGEOM_SPHERE): "sphere", int(_G.mjGEOM_ELLIPSOID): "ellipsoid", int(_G.mjGEOM_MESH): "mesh"}


@dataclass(frozen=True, eq=False)
class Surface:
    """The elements of one body, in its frame: centres (N, 3, m), outward unit normals (N, 3), areas (N, m^2)."""

    body: str
    centre: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    # Per geom cut: its place among the body's geoms, then the type, size, pos and quat it was cut at (G, 12): a
    # geom changed since (resized in the spec, or in model.geom_size for domain randomisation) has other elements.
    geoms: np.ndarray = field(default_factory=lambda: np.zeros((0, 12)))


@dataclass(frozen=True, eq=False)
class Attached:
    """What `attach` added to a spec: the law and medium, and each body's surface elements."""

    law: str
    parameters: dict[str, float]  # the law's parameters (its PARAMETERS): li2013's zeta, rft3d's rho_c, mu_int, mu_surf
    surface_z: float
    element_size: float
    backend: str               # the backend in use: "native" (plugin instances in the spec), "python" or "warp"
    coefficients: li2013.Coefficients | rft3d.Coefficients
    surfaces: tuple[Surface, ...] = field(repr=False)
    drft_lambda: float = 0.0   # DRFT's lambda; 0: the quasi-static law alone
    bulk_density: float = 0.0  # kg/m^3, DRFT's rho_c (0: none known)
    v_reg: float = laws.SURFACE_V_REG  # m/s, the ramp of `finrft.laws.regularised` (0: none)
    # the free surface; None: the horizontal one at surface_z
    surface: surfaces.Field | None = None

    @property
    def free_surface(self) -> surfaces.Field:
        """The free surface the depths are measured from."""
        return self.surface or surfaces.Field("flat", {"surface_z": self.surface_z})

    def law_forces(self, normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                   frame: np.ndarray | None = None) -> np.ndarray:
        """The law's own force on each element (world frame): no DRFT term, no ramp. Every surface law is
        rate-independent, a function of the direction of the velocity alone. ``frame``: the law's
        (`finrft.surfaces.law_frame` of the model's gravity; None: gravity along -z)."""
        law = laws.module(self.law, laws.SURFACE)
        if frame is None:
            return law.element_forces(normal, velocity, depth, area, coefficients=self.coefficients,
                                      **self.parameters)
        return law.element_forces(normal @ frame.T, velocity @ frame.T, depth, area, coefficients=self.coefficients,
                                  **self.parameters) @ frame

    def element_forces(self, normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                       frame: np.ndarray | None = None) -> np.ndarray:
        """The law's force on each element (world frame), regularised, as the native plugin computes it;
        ``frame`` as `law_forces`'."""
        force = self.law_forces(normal, velocity, depth, area, frame)
        if self.drft_lambda > 0:
            force = force + drft.element_forces(normal, velocity, depth, area, self.drft_lambda, self.bulk_density)
        return laws.regularised(force, normal, velocity, self.v_reg)

    def element_slopes(self, normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray,
                       frame: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """`element_forces` and their analytic derivatives in the velocity (N, 3, 3; row: the force's component),
        as finrft_surface_element_slope computes them; None for a law without its own (its ``element_slopes``),
        whose derivative the implicit steps take by differences. ``frame`` as `law_forces`'."""
        own = getattr(laws.module(self.law, laws.SURFACE), "element_slopes", None)
        if own is None:
            return None
        if frame is None:
            force, slope = own(normal, velocity, depth, area, coefficients=self.coefficients, **self.parameters)
        else:
            force, slope = own(normal @ frame.T, velocity @ frame.T, depth, area, coefficients=self.coefficients,
                               **self.parameters)
            force, slope = force @ frame, np.einsum("ki,ekl,lj->eij", frame, slope, frame)
        if self.drft_lambda > 0:
            force = force + drft.element_forces(normal, velocity, depth, area, self.drft_lambda, self.bulk_density)
            slope = slope + drft.element_slopes(normal, velocity, depth, area, self.drft_lambda, self.bulk_density)
        return laws.regularised_slopes(force, slope, normal, velocity, self.v_reg)

    def trailing_slopes(self, normal: np.ndarray, velocity: np.ndarray, depth: np.ndarray, area: np.ndarray
                        ) -> np.ndarray:
        """The linearly implicit step's slope of elements that trail by less than the ramp's width (-v_reg < n . v
        <= RAMP_FLOOR v_reg; N, 3, 3), as finrft_surface_trailing_slope: the secant to where the element leads by
        v_reg, F(v_s) n^T / (v_reg - n . v), v_s = v + (v_reg - n . v) n. Their force and exact slope are 0, so a
        step that linearises there sees nothing of the force the element takes as it leads again, and a light body
        settling (a 50 g plate at 1 ms) chattered; 0 for every other element, and without a ramp."""
        slope = np.zeros((len(area), 3, 3))
        if self.v_reg <= 0 or not len(area):
            return slope
        v_n = np.einsum("ei,ei->e", normal, velocity)
        near = (v_n > -self.v_reg) & (v_n <= laws.RAMP_FLOOR * self.v_reg)
        if near.any():
            gap = self.v_reg - v_n[near]
            ahead = velocity[near] + gap[:, None] * normal[near]
            force = self.element_forces(normal[near], ahead, depth[near], area[near])
            slope[near] = force[:, :, None] * normal[near][:, None, :] / gap[:, None, None]
        return slope

    @property
    def elements(self) -> dict[str, int]:
        """The number of elements per body."""
        return {s.body: len(s.area) for s in self.surfaces}

    def forces(self, model: mujoco.MjModel, data: mujoco.MjData) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The medium's force (N) and its torque about the body's origin (N m) on each attached body, world frame,
        at the state of ``data`` (after mj_forward, or at least mj_kinematics and mj_comVel), from the backend in
        use (`wrenches`)."""
        wrench = self.wrenches(model)(data)
        return {s.body: (w[3:], w[:3]) for s, w in zip(self.surfaces, wrench)}

    def check_data(self, model: mujoco.MjModel, data: mujoco.MjData, where: str = "Attached.forces",
                   geoms: bool = True) -> None:
        """SceneError unless ``model`` is an MjModel whose geoms are those `attach` cut (unless not ``geoms``) and
        ``data`` an MjData of it: another model's MjData gives another model's numbers, or none."""
        if not isinstance(model, mujoco.MjModel):
            raise SceneError(f"{where}: model must be a mujoco.MjModel, got {type(model).__name__}")
        if not isinstance(data, mujoco.MjData):
            raise SceneError(f"{where}: data must be a mujoco.MjData, got {type(data).__name__}")
        if data.model._address != model._address:
            raise SceneError(f"{where}: data is an MjData of another model: pass mujoco.MjData(model) of the model "
                             f"given")
        if geoms:
            self.check_geoms(model)

    def check_geoms(self, model: mujoco.MjModel) -> None:
        """SceneError when a geom `attach` cut into elements has another type, size, position or orientation in
        ``model`` than it had then: its elements, and so its force, would be those of the old geom."""
        for surface in self.surfaces:
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, surface.body)
            if body < 0 or not len(surface.geoms):
                continue
            message = _changed_geom(model, body, surface)
            if message:
                raise SceneError(message)

    def wrenches(self, model: mujoco.MjModel, applied: bool = False,
                 every_call: bool = True) -> Callable[[mujoco.MjData], np.ndarray]:
        """A reader of the medium's wrench on each attached body at the state of an MjData of ``model`` (after
        mj_forward): (B, 6), the torque about the body's origin (N m), then the force (N), world frame, in the order
        of ``surfaces``; from the native plugin's own sum with the native backend (a call per body, no law in
        Python), else from the Python backend's. With ``applied``, the native plugin's sum as its last forward pass
        of the MjData applied it, where it applied one (no element summed again: a recording after mj_forward).
        The geoms are checked (`check_geoms`) at every call, or, without ``every_call``, once, here: a run's own
        reader, called at every step of its model, which nothing changes while it runs (the check was two fifths
        of a sand-swimmer's run)."""
        if not every_call:
            self.check_geoms(model)
        if self.backend == "native":
            signature = (ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p)
            wrench = native.function("finrft_surface_body_wrench", *signature)
            last = native.function("finrft_surface_applied_wrench", *signature) if applied else None
            instances = [int(model.body_plugin[model.body(s.body).id]) for s in self.surfaces]

            def native_read(data: mujoco.MjData) -> np.ndarray:
                self.check_data(model, data, "Attached.wrenches", every_call)
                out = np.zeros((len(instances), 6))
                # the rows' addresses from the array's own (a row's .ctypes each was half of a read's time)
                rows, size, m_at, d_at = out.ctypes.data, out.strides[0], model._address, data._address
                for k, instance in enumerate(instances):
                    row = rows + k * size
                    found = -2 if last is None else last(m_at, d_at, instance, row)
                    if found == -2:
                        found = wrench(m_at, d_at, instance, row)
                    if found < 0:
                        raise SceneError("the model holds no finrft.surface instance for an attached body: "
                                         "compile the spec attach() was given")
                return out
            return native_read
        forces = SurfaceForces(self, model)

        def python_read(data: mujoco.MjData) -> np.ndarray:
            self.check_data(model, data, "Attached.wrenches", every_call)
            out = np.zeros((len(forces.bodies), 6))
            for row, (body, surface) in zip(out, forces.bodies):
                force, arm = forces.element_forces(model, data, body, surface)
                row[:3], row[3:] = np.cross(arm, force).sum(axis=0), force.sum(axis=0)
            return out
        return python_read

    def world_elements(self, model: mujoco.MjModel, data: mujoco.MjData
                       ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each attached body's elements at the state of ``data`` (after mj_kinematics): centres (N, 3, m) and
        outward unit normals (N, 3), world frame, and areas (N, m^2): to draw or inspect them."""
        self.check_data(model, data, "Attached.world_elements")
        out = {}
        for surface in self.surfaces:
            body = model.body(surface.body).id
            rotation = data.xmat[body].reshape(3, 3)
            out[surface.body] = (surface.centre @ rotation.T + data.xpos[body], surface.normal @ rotation.T,
                                 surface.area.copy())
        return out

    def check_compiled(self, model: mujoco.MjModel) -> None:
        """SceneError unless ``model`` was compiled from the spec after `attach`: one compiled before has no RFT."""
        if not isinstance(model, mujoco.MjModel):
            raise SceneError(f"Attached: model must be a mujoco.MjModel (spec.compile()), got {type(model).__name__}")
        text = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, callbacks.PYTHON_MARK)
        start = model.text_adr[text] if text >= 0 else 0
        marked = set() if text < 0 else set(bytes(model.text_data[start:start + model.text_size[text] - 1]).decode()
                                            .split()[1:])
        for surface in self.surfaces:
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, surface.body)
            if body < 0 or not (model.body_plugin[body] >= 0 if self.backend == "native" else surface.body in marked):
                raise SceneError(f"attach: the model has no RFT on body {surface.body!r}: it was compiled before "
                                 f"attach (or from another spec); compile the spec after attach")
        self.check_geoms(model)

    def callback(self, model: mujoco.MjModel) -> "SurfaceForces":
        """The Python backend's passive-force callback for the compiled model."""
        return SurfaceForces(self, model)

    @contextlib.contextmanager
    def installed(self, model: mujoco.MjModel) -> Iterator[None]:
        """A block in which MuJoCo applies the forces: with the Python backend, the callback is installed for
        the block (compile every model first: MuJoCo's compiler cannot run Python callbacks); with the native
        plugin, nothing needs installing. SceneError for a model compiled before `attach` (it has no RFT)."""
        self.check_compiled(model)
        if self.backend == "native":
            yield
            return
        with callbacks.installed(model, self.callback(model)):
            yield


# `SurfaceForces.limit_terms` takes a face's force moving into the medium at this many ramp widths along its
# normal (tanh(3) = 0.995 of the full force), divided by tanh of it.
FULL_RAMP = 3.0
# ... and only where the element's normal speed is within this many widths of the switch (1 - tanh^2(8) = 4.5e-7).
NEAR_SWITCH = 8.0


class SurfaceForces:
    """The Python backend: every element's force, summed per body into one force and one torque about the body's
    origin and added to ``qfrc_passive``, as the native plugin does."""

    def __init__(self, attached: Attached, model: mujoco.MjModel) -> None:
        self.attached = attached
        self.bodies = [(model.body(s.body).id, s) for s in attached.surfaces]
        self._twist = np.zeros(6)
        self._gravity = model.opt.gravity  # the model's, read at every use: it may be changed between steps
        guard = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_PLUGIN, GUARD)
        self._stamp = int(model.plugin_stateadr[guard]) if guard >= 0 else -1

    def element_forces(self, m: mujoco.MjModel, d: mujoco.MjData, body: int, surface: Surface
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Each element's force (N, 3) and its arm from the body's origin (N, 3), world frame."""
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_XBODY, body, self._twist, 0)
        return self.twist_forces(d, body, surface, self._twist)

    def twist_forces(self, d: mujoco.MjData, body: int, surface: Surface, twist: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """As `element_forces`, had the body the ``twist`` (angular velocity, velocity of its origin; world
        frame) at the positions of ``d``."""
        arm, normal, velocity, depth = self._moving(d, body, surface, twist)
        return self.attached.element_forces(normal, velocity, depth, surface.area, self.frame()), arm

    def limit_terms(self, d: mujoco.MjData, twists: Sequence[np.ndarray], width: float
                    ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """For each of `bodies`, had it the twist of ``twists`` (angular velocity, velocity of its origin; world
        frame) at the positions of ``d``: its elements' forces and velocities (world frame), their force slopes (N
        s/m) across the leading-face switch: the force an element would carry moving into the medium along its face,
        over the switch's ramp ``width`` (m/s; the laws' v_reg, `laws.regularised`), weighted by the ramp's slope at
        its normal speed, 1 - tanh^2(n.v / width), and their normals (world frame). A face grazing the medium (the
        top and bottom of a plate swimming level) carries no force and has the full slope: a velocity along its
        normal of ``width`` switches its whole force on. One call of the law for all of them: its cost is mostly per
        call."""
        moving = [self._moving(d, body, surface, twist) for (body, surface), twist in zip(self.bodies, twists)]
        if not moving:
            return []
        parts, near, into = [], [], []
        for (_, surface), (_, normal, velocity, depth) in zip(self.bodies, moving):
            along = np.einsum("ij,ij->i", normal, velocity)
            # those near the switch alone: the others' slopes are below 1e-6 of theirs
            close = (np.abs(along) < NEAR_SWITCH * width) & (depth > 0)
            leading = velocity[close] + (FULL_RAMP * width - along[close])[:, None] * normal[close]
            parts += [(normal, velocity, depth, surface.area),
                      (normal[close], leading, depth[close], surface.area[close])]
            near.append(close)
            into.append(along)
        force = self.attached.element_forces(*(np.concatenate(k) for k in zip(*parts)), self.frame())
        ends = np.cumsum([len(part[2]) for part in parts])[:-1]
        forces = np.split(force, ends)
        terms = []
        for i, (_, normal, velocity, _) in enumerate(moving):
            slopes = np.zeros(len(into[i]))
            slopes[near[i]] = (np.linalg.norm(forces[2 * i + 1], axis=1) / np.tanh(FULL_RAMP) / width
                               * (1 - np.tanh(into[i][near[i]] / width) ** 2))
            terms.append((forces[2 * i], velocity, slopes, normal))
        return terms

    def _moving(self, d: mujoco.MjData, body: int, surface: Surface, twist: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A body's elements at the positions of ``d``, had it the ``twist``: their arms from its origin, normals
        and velocities (world frame) and depths."""
        rotation = d.xmat[body].reshape(3, 3)
        arm = surface.centre @ rotation.T
        velocity = twist[3:] + np.cross(twist[:3], arm)
        return arm, surface.normal @ rotation.T, velocity, self.depths(d, body, arm)

    def level(self) -> bool:
        """Whether the surface is the flat one and gravity along -z (or none): today's depth, z's alone, and the
        laws' own frame (the native plugin's FinrftSurface.level)."""
        g = self._gravity
        return self.attached.free_surface.kind == "flat" and g[0] == 0 and g[1] == 0 and g[2] <= 0

    def frame(self) -> np.ndarray | None:
        """The laws' frame under the model's gravity now (`finrft.surfaces.law_frame`); None under gravity along -z
        (or none), where it is the identity (the native plugin's FinrftSurface.upright)."""
        g = self._gravity
        return None if g[0] == 0 and g[1] == 0 and g[2] <= 0 else surfaces.law_frame(surfaces.up(g))

    def depths(self, d: mujoco.MjData, body: int, arm: np.ndarray) -> np.ndarray:
        """The depths (N) of the elements at ``arm`` (N, 3, world frame) from the origin of ``body``, along the
        model's gravity below the free surface."""
        if self.level():
            return self.attached.surface_z - (d.xpos[body, 2] + arm[:, 2])
        return self.attached.free_surface.depth(d.xpos[body] + arm, self._gravity)

    def submerged(self, d: mujoco.MjData, body: int, surface: Surface
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The body's elements below the free surface at the positions of ``d``, world frame: arms from its origin
        (N, 3), outward unit normals (N, 3), depths (N), areas (N); the twin of finrft_surface_submerged. The
        implicit steps take them once per step: an element above the surface has no force at any velocity."""
        rotation = d.xmat[body].reshape(3, 3)
        arm = surface.centre @ rotation.T
        depth = self.depths(d, body, arm)
        below = depth > 0
        return arm[below], surface.normal[below] @ rotation.T, depth[below], surface.area[below]

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        self.attached.check_geoms(m)  # model.geom_size may change between steps (domain randomisation)
        for body, surface in self.bodies:
            force, arm = self.element_forces(m, d, body, surface)
            mujoco.mj_applyFT(m, d, force.sum(axis=0), np.cross(arm, force).sum(axis=0), d.xpos[body], body,
                              d.qfrc_passive)
        if self._stamp >= 0:
            d.plugin_state[self._stamp] = 1.0


def attach(spec: mujoco.MjSpec, bodies: Sequence[str] | str = (), law: str = "li2013", zeta: float | None = None,
           surface_z: float = 0.0, element_size: float = 0.005, backend: str = "native",
           coefficients: li2013.Coefficients | rft3d.Coefficients | None = None, medium: str | None = None,
           rho_c: float | None = None, mu_int: float | None = None, mu_surf: float | None = None,
           drft_lambda: float = 0.0, bulk_density: float | None = None,
           v_reg: float = laws.SURFACE_V_REG, geoms: Sequence[str] = (), cull: bool = True,
           internal_friction: float | None = None, surface_friction: float | None = None,
           surface: str | surfaces.Field = "flat", surface_point: Sequence[float] = (0.0, 0.0, 0.0),
           surface_normal: Sequence[float] = (0.0, 0.0, 1.0), hfield: str = "", bed_depth: float = 0.0) -> Attached:
    """Add granular RFT to the named bodies of ``spec`` (before it is compiled): all the geoms of each of
    ``bodies``, and the geoms named in ``geoms`` (their bodies' other geoms left out).

    ``law``, a surface law of `finrft.laws`: ``li2013`` (`finrft.laws.li2013`: Li 2013 in 3D as Treers, Cao &
    Stuart 2021 extend it) or ``li2013-planar`` (its planar form, which cannot swim: it warns) with
    ``coefficients`` (default: the generic medium) scaled by ``zeta`` (default 1), or instead of both a ``medium``
    of the catalogue (`finrft.media`, e.g. ``"poppy_seeds_lp"``); or ``rft3d`` (`finrft.laws.rft3d`) with
    ``coefficients`` (default: `rft3d.AGARWAL_2023`) and the medium's critical density ``rho_c`` (kg/m^3), internal friction ``mu_int`` and
    the bodies' surface friction ``mu_surf``, all three required (a catalogued ``medium`` gives those it has; a
    ``mu_surf`` given overrides its); the scene files' names are taken too: ``bulk_density`` for rft3d's rho_c,
    ``internal_friction`` for mu_int, ``surface_friction`` for mu_surf (one name or the other); ``drft_lambda`` (dimensionless, default 0: off):
    DRFT's rate-dependent term on top of either law (`finrft.laws.drft`), with the medium's density: rft3d's
    ``rho_c``, li2013's ``bulk_density`` (kg/m^3; else the catalogued ``medium``'s, if it has one);
    ``v_reg`` (m/s, default `finrft.laws.SURFACE_V_REG`, 1e-4; 0: none): every element's force times
    tanh(max(n . v, 0) / v_reg), the smooth onset of the leading-face switch and of the speed
    (`finrft.laws.regularised`);
    ``surface_z``: height of the free surface, m; ``surface``: its kind (`finrft.surfaces`): ``flat`` (the
    horizontal plane at ``surface_z``, gravity along -z), ``plane`` (through ``surface_point``, m, its
    ``surface_normal`` out of the sand), ``hfield`` (the model's ``<hfield>`` named ``hfield``, where its geom puts
    it, or at ``surface_point`` level with gravity when no geom shows it), or a `finrft.surfaces.Field` (a generated
    heightfield: `finrft.surfaces.hfield.generated`); depths are measured along the model's gravity
    (``spec.option.gravity``, read again at every step) and the laws' angles taken against it; ``bed_depth`` (m, 0:
    unbounded): the sand's thickness, a rigid floor added to the spec (`BED`, a plane geom whose contacts are
    MuJoCo's) that far below the surface along gravity, parallel to a flat or plane surface, level with gravity
    below a heightfield's lowest point; ``element_size``: the elements' size, m; ``backend``:
    ``native`` (falls back to ``python``, with a warning, when the plugin cannot be loaded) or ``python`` (then run
    the model inside ``Attached.installed``: a model stepped outside it stops with an exception at its second step,
    from the native guard the compiled model carries while the plugin library loads) or ``warp`` (the spec as with
    ``python``, which MuJoCo's own step runs; many worlds of the model run on MuJoCo Warp with `finrft.warp.WarpWorlds`,
    the ``warp`` extra); ``cull``: leave out the
    elements that face another geom of the same kinematic tree closely (`TOUCHING`), such as the end faces of
    neighbouring links of a chain, which the grains cannot reach. Raises `SceneError` on bad input.
    """
    _check_types(spec, bodies, geoms, {"law": law, "backend": backend, "medium": medium},
                 {"surface_z": surface_z, "element_size": element_size, "drft_lambda": drft_lambda, "v_reg": v_reg},
                 {"zeta": zeta, "rho_c": rho_c, "mu_int": mu_int, "mu_surf": mu_surf, "bulk_density": bulk_density},
                 cull)
    material = media.medium(medium) if medium is not None else None
    names = _names(bodies, "bodies")
    chosen = _chosen_geoms(spec, names, _names(geoms, "geoms"))
    names += list(chosen)
    _check(names, law, surface_z, element_size, backend)
    if not (math.isfinite(v_reg) and v_reg >= 0):
        raise SceneError(f"attach: v_reg must be >= 0 m/s, got {v_reg!r}")
    if v_reg > laws.LARGEST_V_REG:
        raise SceneError(f"attach: v_reg must be <= {laws.LARGEST_V_REG:g} m/s ({laws.WHY_LARGEST_V_REG}), got "
                         f"{v_reg!r}")
    module = laws.module(law, laws.SURFACE)
    # one vocabulary with the scene files: their names of rft3d's parameters are taken as its own
    rho_c = _either(rho_c, bulk_density if module.DENSITY else None, "rho_c", "bulk_density")
    bulk_density = None if module.DENSITY else bulk_density
    if bulk_density is not None and not drft_lambda:
        raise SceneError(f"attach: bulk_density is used by drft_lambda > 0 and a law with a density (rft3d) only, "
                         f"and law {law!r} has drft_lambda = 0: pass drft_lambda, or leave bulk_density out")
    mu_int = _either(mu_int, internal_friction, "mu_int", "internal_friction")
    mu_surf = _either(mu_surf, surface_friction, "mu_surf", "surface_friction")
    parameters, catalogued = laws.surface_parameters(
        law, {"zeta": zeta, "rho_c": rho_c, "mu_int": mu_int, "mu_surf": mu_surf}, material, "attach")
    if catalogued is not None and coefficients is not None:
        raise SceneError(f"attach: medium={medium!r} gives the coefficients: pass one or the other")
    known = material.get("bulk_density") if material is not None else None
    rho = drft.density(drft_lambda, parameters[module.DENSITY] if module.DENSITY else bulk_density,
                       None if known is None else known.value, "bulk_density", "attach")
    if coefficients is None:
        coefficients = module.DEFAULT if catalogued is None else catalogued
    elif not isinstance(coefficients, module.Coefficients):
        raise SceneError(f"attach: law {law!r} takes finrft.laws.{law}.Coefficients")
    backend = native.resolve_backend(backend)
    # The mark's first word is the spec's address: a spec read back from its XML (or a copy) holds no callback's
    # surfaces, and may take them anew.
    mark = spec.text(callbacks.PYTHON_MARK)
    marked = [] if mark is None else mark.data.split()
    python_bodies = marked[1:] if marked and marked[0] == str(spec._address) else []
    with callbacks.compiling():
        model = spec.copy().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    field = _field(model, data, surface, surface_z, surface_point, surface_normal, hfield)
    if not (_is_number(bed_depth) and math.isfinite(bed_depth) and bed_depth >= 0):
        raise SceneError(f"attach: bed_depth must be >= 0 m (0: unbounded), got {bed_depth!r}")
    parts = []
    for name in names:
        if spec.body(name) is None:
            raise SceneError(f"attach: the model has no body named {name!r}")
        body = model.body(name).id
        if model.body_plugin[body] >= 0 or name in python_bodies:
            raise SceneError(f"attach: body {name!r} already has a plugin (a body takes one)" if model.body_plugin[
                body] >= 0 else f"attach: body {name!r} has RFT attached already (a body takes it once)")
        parts.append(_surface(model, data, name, body, element_size, chosen.get(name), cull))
    total = sum(len(s.area) for s in parts)
    if total > MAX_ELEMENTS:
        raise SceneError(f"attach: element_size = {element_size:g} m gives {total} elements, more than "
                         f"{MAX_ELEMENTS}: use a larger element_size")
    attached = Attached(law, parameters, float(surface_z), float(element_size), backend, coefficients,
                        tuple(parts), float(drft_lambda), rho, float(v_reg), field)
    if bed_depth > 0:
        _add_bed(spec, field, float(bed_depth), model.opt.gravity)
    if backend == "native":
        spec.activate_plugin(PLUGIN)
        for part in parts:
            _bind(spec, attached, part)
    else:
        # The compiled model carries the bodies, so that stepping it without its callback is refused, as is a
        # second attach of one of them.
        if mark is None:
            mark = spec.add_text(name=callbacks.PYTHON_MARK)
        mark.data = " ".join([str(spec._address), *python_bodies, *names])
        # Stepped where no callback is installed at all, only a native guard can stop it (`GUARD`); MuJoCo Warp
        # takes a model with no plugin instance, so the warp backend's has none.
        if backend == "python" and native.available() and not any(p.name == GUARD for p in spec.plugins):
            spec.activate_plugin(GUARD_PLUGIN)
            spec.add_plugin(name=GUARD, plugin_name=GUARD_PLUGIN, active=True)
    laws.warn_feeds_energy(law, module.FEEDS_ENERGY, "kept as published")
    laws.warn_caveat(law)
    return attached


def _field(model: mujoco.MjModel, data: mujoco.MjData, surface: str | surfaces.Field, surface_z: float,
           surface_point: Sequence[float], surface_normal: Sequence[float], hfield: str) -> surfaces.Field:
    """The free surface `attach` was given, checked under the model's gravity; SceneError naming what is wrong."""
    if isinstance(surface, surfaces.Field):
        field = surface
    elif surface == "flat":
        field = surfaces.Field("flat", {"surface_z": float(surface_z)})
    elif surface == "plane":
        field = surfaces.Field("plane", {"surface_point": _vector(surface_point, "surface_point"),
                                         "surface_normal": _vector(surface_normal, "surface_normal")})
    elif surface == "hfield":
        field = surfaces.module("hfield").of_model(model, data, hfield, _vector(surface_point, "surface_point"))
    elif surface == "deforming":
        raise SceneError("attach: surface 'deforming' needs its grid: give a finrft.surfaces.Field('deforming', "
                         "...) (finrft.surfaces.deforming.field)")
    elif isinstance(surface, str) and surface in surfaces.names():
        field = surfaces.Field(surface, {})  # a kind runs do not take yet: refused below
    else:
        raise SceneError(f"attach: surface must be one of {', '.join(FIELD_KINDS)} or a finrft.surfaces.Field, got "
                         f"{surface!r:.60}")
    if field.kind not in FIELD_KINDS:
        raise SceneError(f"attach: surface {field.kind!r} is not yet run: use {', '.join(FIELD_KINDS)}")
    try:
        field.check(model.opt.gravity)
    except SceneError as error:
        raise SceneError(f"attach: {error}") from None
    return field


def _vector(value: object, key: str) -> tuple[float, float, float]:
    """Three finite numbers; SceneError naming ``key`` otherwise."""
    if not (isinstance(value, (list, tuple, np.ndarray)) and len(value) == 3 and all(_is_number(v) for v in value)
            and all(math.isfinite(v) for v in value)):
        raise SceneError(f"attach: {key} must be three finite numbers (x, y, z), got {value!r:.60}")
    return tuple(float(v) for v in value)


# The name of the floor under a bed of sand of finite depth (attach's bed_depth).
BED = "finrft_bed"


def _add_bed(spec: mujoco.MjSpec, field: surfaces.Field, depth: float, gravity: np.ndarray) -> None:
    """The rigid floor ``depth`` below the free surface along gravity: a plane geom of the world body."""
    if spec.geom(BED) is not None:
        raise SceneError(f"attach: the model has a geom named {BED!r} already: bed_depth adds the floor of that name")
    up = surfaces.up(gravity)
    p = field.parameters
    if field.kind == "hfield":
        frame = np.asarray(p["frame"], dtype=float)
        point = np.asarray(p["centre"], dtype=float) + frame[:, 2] * (np.min(p["heights"]) - depth)
        normal = up
    else:
        point = np.asarray(p.get("surface_point", (0.0, 0.0, p.get("surface_z", 0.0))), dtype=float)
        normal = np.asarray(p.get("surface_normal", (0.0, 0.0, 1.0)), dtype=float)
        normal = normal / np.linalg.norm(normal)
        point = point - depth * up
    quat = np.empty(4)
    mujoco.mju_quatZ2Vec(quat, normal)
    spec.worldbody.add_geom(name=BED, type=mujoco.mjtGeom.mjGEOM_PLANE, pos=point, quat=quat, size=[0, 0, 1])


# The kinds of free surface runs take (finrft.surfaces; the native plugin's kFields).
FIELD_KINDS = ("flat", "plane", "hfield", "deforming")


def _names(value: Sequence[str] | str, key: str) -> list[str]:
    """A name or a sequence of names as a list; SceneError naming ``key`` for anything else."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return list(value)
    raise SceneError(f"attach: {key} must be a name or a list of names (str), got {type(value).__name__} "
                     f"{value!r:.60}")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _check_types(spec: object, bodies: object, geoms: object, texts: dict[str, object], numbers: dict[str, object],
                 optional: dict[str, object], cull: object) -> None:
    """SceneError naming the first argument of `attach` of the wrong type (texts may be None only as ``medium``)."""
    if not isinstance(spec, mujoco.MjSpec):
        raise SceneError(f"attach: spec must be a mujoco.MjSpec (attach before compiling: mujoco.MjSpec.from_file"
                         f"(...)), got {type(spec).__name__}")
    _names(bodies, "bodies")
    _names(geoms, "geoms")
    for key, value in texts.items():
        if not (isinstance(value, str) or (key == "medium" and value is None)):
            raise SceneError(f"attach: {key} must be a str, got {type(value).__name__} {value!r:.60}")
    for key, value in {**numbers, **optional}.items():
        if not (_is_number(value) or (key in optional and value is None)):
            raise SceneError(f"attach: {key} must be a number{' or None' if key in optional else ''}, got "
                             f"{type(value).__name__} {value!r:.60}")
    if not isinstance(cull, (bool, np.bool_)):
        raise SceneError(f"attach: cull must be True or False, got {type(cull).__name__} {cull!r:.60}")


# The largest surface element, m: a body granular RFT acts on is centimetres to decimetres across, and a larger
# element is a size in mm (the command line's unit) written where metres belong (5 for 5 mm: one element per face).
MAX_ELEMENT_SIZE = 1.0


def _check(names: list[str], law: str, surface_z: float, element_size: float, backend: str) -> None:
    if law not in laws.names(laws.SURFACE):
        raise SceneError(f"attach: law must be one of {', '.join(laws.names(laws.SURFACE))}, got {law!r}")
    if backend not in BACKENDS:
        raise SceneError(f"attach: backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if not names:
        raise SceneError("attach: name at least one body")
    if len(set(names)) != len(names):
        raise SceneError("attach: a body is named twice")
    if not math.isfinite(surface_z):
        raise SceneError(f"attach: surface_z must be finite, got {surface_z!r}")
    if not (math.isfinite(element_size) and element_size > 0):
        raise SceneError(f"attach: element_size must be > 0 m, got {element_size!r}")
    if element_size > MAX_ELEMENT_SIZE:
        raise SceneError(f"attach: element_size = {element_size:g} m is more than {MAX_ELEMENT_SIZE:g} m: it is in "
                         f"metres (a value in mm is 1000 times larger): give 5 mm as 0.005")


def _bind(spec: mujoco.MjSpec, attached: Attached, surface: Surface) -> None:
    elements = np.column_stack([surface.centre, surface.normal, surface.area])
    instance = spec.add_plugin(name=f"finrft_surface_{surface.body}", plugin_name=PLUGIN, active=True)
    instance.config = {
        "law": attached.law,
        "coefficients": " ".join(map(repr, attached.coefficients.values())),
        **laws.module(attached.law, laws.SURFACE).config(attached.parameters),
        **({"drft_lambda": repr(attached.drft_lambda), "bulk_density": repr(attached.bulk_density)}
           if attached.drft_lambda > 0 else {}),
        "surface_z": repr(attached.surface_z),
        **_field_config(attached.free_surface),
        "v_reg": repr(attached.v_reg),
        "elements": " ".join(map(repr, elements.ravel().tolist())),  # repr: the Python backend's exact numbers
        "geoms": " ".join(map(repr, surface.geoms.ravel().tolist())),
    }
    body = spec.body(surface.body)
    body.plugin = instance
    body.plugin.name = instance.name
    body.plugin.active = True


def _field_config(field: surfaces.Field) -> dict[str, str]:
    """The native plugin's config of a free surface (flat: none beyond surface_z)."""
    if field.kind == "plane":
        return {"surface": "plane", "surface_point": _numbers(field.parameters["surface_point"]),
                "surface_normal": _numbers(field.parameters["surface_normal"])}
    if field.kind in ("hfield", "deforming"):
        p = field.parameters
        heights = np.asarray(p["heights"], dtype=float)
        frame = np.asarray(p.get("frame", np.eye(3)), dtype=float)
        config = {"surface": field.kind, "hfield": _numbers([*heights.shape, *p["size"], *p.get("centre", (0, 0, 0)),
                                                            *frame.ravel(), *heights.ravel()])}
        if field.kind == "deforming" and p.get("pile_factor"):
            config["pile_factor"] = repr(float(p["pile_factor"]))
        return config
    return {}


def _numbers(values: object) -> str:
    """Numbers as the plugin's config reads them: repr, the Python backend's exact numbers."""
    return " ".join(map(repr, np.asarray(values, dtype=float).ravel().tolist()))


def _either(value: float | None, alias: float | None, name: str, alias_name: str) -> float | None:
    """A parameter given by its own name or by the scene files' (``alias_name``), not both."""
    if value is not None and alias is not None:
        raise SceneError(f"attach: {alias_name} is {name} by the scene files' name: give one of them")
    return alias if value is None else value


def attached_bodies(spec: mujoco.MjSpec, bodies: Sequence[str], geoms: Sequence[str]) -> list[str]:
    """The bodies `attach` gives surfaces for ``bodies`` and ``geoms``: the bodies named, then those of the geoms
    named, in order; SceneError for a geom the model lacks (the bodies are checked as `attach` runs)."""
    return [*bodies, *_chosen_geoms(spec, list(bodies), list(geoms))]


def _chosen_geoms(spec: mujoco.MjSpec, bodies: list[str], geoms: list[str]) -> dict[str, list[str]]:
    """The geoms named, by body (in the order named), for the bodies not named whole; SceneError for a name the
    model lacks or a geom named twice."""
    if len(set(geoms)) != len(geoms):
        raise SceneError("attach: a geom is named twice")
    chosen: dict[str, list[str]] = {}
    for name in geoms:
        geom = spec.geom(name) if name else None
        if geom is None:
            raise SceneError(f"attach: the model has no geom named {name!r}")
        body = geom.parent.name
        if not body:
            raise SceneError(f"attach: geom {name!r} belongs to an unnamed body: name the body")
        if body not in bodies:
            chosen.setdefault(body, []).append(name)
    return chosen


# Elements whose centre, moved this share of the element size outward along its normal, lies inside another geom of
# the same kinematic tree face that geom closely (a link's end face against its neighbour's, a leg's capsules where
# they overlap): the grains cannot get between them, so they are left out. Judged once, in the model's reference
# pose (qpos0): a hinge that opens the gap later does not bring them back.
TOUCHING = 0.1


def _surface(model: mujoco.MjModel, data: mujoco.MjData, name: str, body: int, h: float,
             chosen: list[str] | None, cull: bool) -> Surface:
    geoms = np.flatnonzero(model.geom_bodyid == body)
    if chosen is not None:
        geoms = np.array([model.geom(g).id for g in chosen], dtype=int)
    if not len(geoms):
        raise SceneError(f"attach: body {name!r} has no geoms to cut into elements")
    for g in geoms:
        if int(model.geom_type[g]) not in SUPPORTED:
            kind = mujoco.mjtGeom(model.geom_type[g]).name.removeprefix("mjGEOM_").lower()
            raise SceneError(f"attach: geom {model.geom(g).name or int(g)!r} of body {name!r} is a {kind}; RFT takes "
                             f"{', '.join(SUPPORTED.values())}")
    estimate = sum(_area(model, g) for g in geoms) / h ** 2
    if estimate > MAX_ELEMENTS:
        raise SceneError(f"attach: element_size = {h:g} m gives about {estimate:.3g} elements on body {name!r}, "
                         f"more than {MAX_ELEMENTS}: use a larger element_size")
    tree = [int(g) for g in np.flatnonzero(model.body_rootid[model.geom_bodyid] == model.body_rootid[body])
            if int(model.geom_type[g]) in SUPPORTED] if cull and model.body_rootid[body] != 0 else []
    parts = []
    for g in geoms:
        centre, normal, area = _geom_elements(model, g, h)
        rotation = np.empty(9)
        mujoco.mju_quat2Mat(rotation, model.geom_quat[g])
        rotation = rotation.reshape(3, 3)
        centre, normal = centre @ rotation.T + model.geom_pos[g], normal @ rotation.T
        if tree:
            frame = data.xmat[body].reshape(3, 3)
            probe = (centre + TOUCHING * h * normal) @ frame.T + data.xpos[body]
            inside = np.zeros(len(area), dtype=bool)
            for other in tree:
                if other != g:
                    inside |= _inside(model, data, other, probe)
            centre, normal, area = centre[~inside], normal[~inside], area[~inside]
        parts.append((centre, normal, area))
    centre, normal, area = (np.concatenate(p) for p in zip(*parts))
    if not len(area):
        raise SceneError(f"attach: every element of body {name!r} faces another geom of its tree closely (culled): "
                         f"pass cull=False, or attach the geoms the medium reaches")
    cut = np.column_stack([geoms - model.body_geomadr[body], _geometry(model, geoms)])
    return Surface(name, centre, normal, area, cut)


def _geometry(model: mujoco.MjModel, geoms: np.ndarray) -> np.ndarray:
    """What a geom's elements are cut from, per geom (G, 11): type, size, pos, quat."""
    return np.column_stack([model.geom_type[geoms], model.geom_size[geoms], model.geom_pos[geoms],
                            model.geom_quat[geoms]]).astype(float)


def _changed_geom(model: mujoco.MjModel, body: int, surface: Surface) -> str:
    """Why the geoms of ``surface`` in ``model`` are not those `attach` cut (the first one changed), or ""; the twin
    of the native plugin's check (geoms_changed in plugins/finrft_surface.c)."""
    place = surface.geoms[:, 0].astype(int)
    geoms = model.body_geomadr[body] + place
    if np.all(place < model.body_geomnum[body]) and np.array_equal(_geometry(model, geoms), surface.geoms[:, 1:]):
        return ""
    for row, k, g in zip(surface.geoms, place, geoms):
        there = k < model.body_geomnum[body]
        if not there or not np.array_equal(_geometry(model, np.array([g]))[0], row[1:]):
            return geom_changed((model.geom(g).name if there else "") or f"#{k}", surface.body)
    return ""


def geom_changed(geom: str, body: str) -> str:
    """The message for a geom changed since `attach` cut it (the native plugin's says the same)."""
    return (f"geom {geom!r} of body {body!r} changed its type, size, position or orientation since finrft.attach cut "
            f"it into elements, which keep the old geom's force: call attach on a spec that has the geoms' final "
            f"sizes (one spec per size when randomising), then compile it")


def _inside(model: mujoco.MjModel, data: mujoco.MjData, g: int, points: np.ndarray) -> np.ndarray:
    """Which points (N, 3, world frame) lie strictly inside geom g, at the pose of ``data``."""
    q = (points - data.geom_xpos[g]) @ data.geom_xmat[g].reshape(3, 3)
    size, kind = model.geom_size[g], int(model.geom_type[g])
    if kind == _G.mjGEOM_BOX:
        return np.all(np.abs(q) < size, axis=1)
    if kind == _G.mjGEOM_SPHERE:
        return np.linalg.norm(q, axis=1) < size[0]
    if kind == _G.mjGEOM_ELLIPSOID:
        return np.sum((q / size) ** 2, axis=1) < 1
    if kind == _G.mjGEOM_CYLINDER:
        return (np.hypot(q[:, 0], q[:, 1]) < size[0]) & (np.abs(q[:, 2]) < size[1])
    if kind == _G.mjGEOM_CAPSULE:
        along = np.clip(q[:, 2], -size[1], size[1])
        return np.linalg.norm(q - np.column_stack([np.zeros((len(q), 2)), along]), axis=1) < size[0]
    return _inside_mesh(_mesh(model, g), q)


def _inside_mesh(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Points (N, 3) strictly inside a closed triangle mesh (T, 3, 3), same frame: a ray along an irrational
    direction crosses its triangles an odd number of times (Moller-Trumbore)."""
    direction = np.array([0.5773, 0.5774, 0.5773 + 1e-4 * np.pi])
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ti,ti->t", e1, p)
    ok = np.abs(det) > 1e-18
    t, e1, e2, p, det = t[ok], e1[ok], e2[ok], p[ok], det[ok]
    s = q[:, None] - t[None, :, 0]                       # (N, T, 3)
    u = np.einsum("nti,ti->nt", s, p) / det
    qv = np.cross(s, e1[None])
    v = np.einsum("i,nti->nt", direction, qv) / det
    distance = np.einsum("nti,ti->nt", qv, e2) / det
    hits = (u >= 0) & (v >= 0) & (u + v <= 1) & (distance > 0)
    return hits.sum(axis=1) % 2 == 1


def _mesh(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray]:
    """A mesh geom's triangles (T, 3, 3), in its frame."""
    mesh = model.geom_dataid[g]
    vert = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    face = model.mesh_face[model.mesh_faceadr[mesh]:model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
    return vert[face].astype(float)


def _outward(model: mujoco.MjModel, g: int) -> np.ndarray:
    """A mesh geom's triangles (T, 3, 3) wound counter-clockwise seen from outside, as `_triangles` takes them: a
    closed mesh wound the other way throughout (negative volume) is turned over; SceneError for one whose triangles
    are wound both ways (an edge run the same way by two triangles), whose outside no winding tells."""
    mesh = model.geom_dataid[g]
    face = model.mesh_face[model.mesh_faceadr[mesh]:model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
    t = _mesh(model, g)
    face = face[np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1) > 0]
    edges = np.concatenate([face[:, [0, 1]], face[:, [1, 2]], face[:, [2, 0]]])
    if len(np.unique(edges, axis=0)) < len(edges):
        raise SceneError(f"attach: the triangles of mesh geom {model.geom(g).name or g!r} are wound both ways (some "
                         f"face inward): wind every triangle counter-clockwise seen from outside")
    closed = len(np.unique(np.concatenate([edges, edges[:, ::-1]]), axis=0)) == len(edges)
    volume = np.einsum("ti,ti->", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6
    return t[:, ::-1] if closed and volume < 0 else t


def _area(model: mujoco.MjModel, g: int) -> float:
    """A geom's surface area (for an ellipsoid, an upper bound)."""
    size, kind = model.geom_size[g], int(model.geom_type[g])
    if kind == _G.mjGEOM_BOX:
        a, b, c = size
        return 8 * (a * b + b * c + c * a)
    if kind == _G.mjGEOM_MESH:
        t = _mesh(model, g)
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    if kind in (_G.mjGEOM_SPHERE, _G.mjGEOM_ELLIPSOID):
        return 4 * np.pi * max(size if kind == _G.mjGEOM_ELLIPSOID else size[:1]) ** 2
    r, half = size[0], size[1]
    return 4 * np.pi * r * half + (4 if kind == _G.mjGEOM_CAPSULE else 2) * np.pi * r ** 2


def _geom_elements(model: mujoco.MjModel, g: int, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    size, kind = model.geom_size[g], int(model.geom_type[g])
    if kind == _G.mjGEOM_BOX:
        return _box(size, h)
    if kind == _G.mjGEOM_SPHERE:
        return _bands(np.full(3, size[0]), 0.0, np.pi, 0.0, h)
    if kind == _G.mjGEOM_ELLIPSOID:
        return _bands(size, 0.0, np.pi, 0.0, h)
    if kind == _G.mjGEOM_MESH:
        return _triangles(_outward(model, g), h)
    r, half = size[0], size[1]
    if kind == _G.mjGEOM_CYLINDER:
        ends = [_disk(r, half, 1.0, h), _disk(r, -half, -1.0, h)]
    else:
        ends = [_bands(np.full(3, r), 0.0, np.pi / 2, half, h), _bands(np.full(3, r), np.pi / 2, np.pi, -half, h)]
    return _join([_side(r, half, h), *ends])


def _join(parts):
    return tuple(np.concatenate(p) for p in zip(*parts))


def _midpoints(lo: float, hi: float, n: int) -> np.ndarray:
    return lo + (hi - lo) * (np.arange(n) + 0.5) / n


def _count(length: float, h: float, multiple: int = 1) -> int:
    """Cells of size at most h along a length, a multiple of ``multiple``."""
    return multiple * max(1, math.ceil(length / h / multiple - 1e-9))


# Azimuthal cells come in multiples of 4 and polar bands in pairs, so that cell edges, never element centres, lie
# on the planes through the geom's axes: there a face stops leading a motion along an axis, and a centre on the
# edge would lead or not by rounding.
AZIMUTH = 4


def _box(size: np.ndarray, h: float):
    parts = []
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        ni, nj = _count(2 * size[i], h), _count(2 * size[j], h)
        u, v = np.meshgrid(_midpoints(-size[i], size[i], ni), _midpoints(-size[j], size[j], nj), indexing="ij")
        for sign in (1.0, -1.0):
            centre = np.zeros((ni * nj, 3))
            centre[:, i], centre[:, j], centre[:, k] = u.ravel(), v.ravel(), sign * size[k]
            normal = np.zeros((ni * nj, 3))
            normal[:, k] = sign
            parts.append((centre, normal, np.full(ni * nj, 4 * size[i] * size[j] / (ni * nj))))
    return _join(parts)


def _bands(axes: np.ndarray, theta0: float, theta1: float, z: float, h: float):
    """An ellipsoid with semi-axes ``axes`` between polar angles theta0 and theta1, shifted by z along its axis:
    bands of equal polar angle, each split into azimuthal cells about h long."""
    a, b, c = axes
    reach = max(axes)
    bands = _count(reach * (theta1 - theta0), h, 2)
    edges = np.linspace(theta0, theta1, bands + 1)
    parts = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        theta = 0.5 * (lo + hi)
        n = _count(2 * np.pi * reach * np.sin(theta), h, AZIMUTH)
        phi = _midpoints(0.0, 2 * np.pi, n)
        unit = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                np.full(n, np.cos(theta))])
        normal = unit / axes
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        stretch = np.linalg.norm(unit * np.array([b * c, a * c, a * b]), axis=1)
        parts.append((unit * axes + [0.0, 0.0, z], normal, (np.cos(lo) - np.cos(hi)) * 2 * np.pi / n * stretch))
    return _join(parts)


def _side(r: float, half: float, h: float):
    """A cylinder's side, radius r, from -half to half along z."""
    n, m = _count(2 * np.pi * r, h, AZIMUTH), _count(2 * half, h)
    phi, z = np.meshgrid(_midpoints(0.0, 2 * np.pi, n), _midpoints(-half, half, m), indexing="ij")
    normal = np.column_stack([np.cos(phi.ravel()), np.sin(phi.ravel()), np.zeros(n * m)])
    centre = normal * r + np.column_stack([np.zeros((n * m, 2)), z.ravel()])
    return centre, normal, np.full(n * m, 2 * np.pi * r * 2 * half / (n * m))


def _disk(r: float, z: float, facing: float, h: float):
    """A disk of radius r at height z, its normal along facing * z: rings split into sectors about h long."""
    rings = _count(r, h)
    edges = np.linspace(0.0, r, rings + 1)
    parts = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        mid = 0.5 * (lo + hi)
        n = _count(2 * np.pi * mid, h, AZIMUTH)
        phi = _midpoints(0.0, 2 * np.pi, n)
        centre = np.column_stack([mid * np.cos(phi), mid * np.sin(phi), np.full(n, z)])
        normal = np.tile([0.0, 0.0, facing], (n, 1))
        parts.append((centre, normal, np.full(n, np.pi * (hi ** 2 - lo ** 2) / n)))
    return _join(parts)


def _triangles(t: np.ndarray, h: float):
    """Triangles (T, 3, 3), counter-clockwise seen from outside, each cut into m^2 equal triangles with m such
    that their edges are at most h."""
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    cross = np.cross(e1, e2)
    double_area = np.linalg.norm(cross, axis=1)
    keep = double_area > 0
    t, e1, e2, cross, double_area = t[keep], e1[keep], e2[keep], cross[keep], double_area[keep]
    longest = np.max(np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2), axis=1)
    cuts = np.maximum(1, np.ceil(longest / h - 1e-9)).astype(int)
    parts = []
    for m in np.unique(cuts):
        # barycentric centroids of the m^2 sub-triangles: m(m+1)/2 pointing up, m(m-1)/2 down
        i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        up = i + j <= m - 1
        down = i + j <= m - 2
        s = np.concatenate([(i[up] + 1 / 3) / m, (i[down] + 2 / 3) / m])
        u = np.concatenate([(j[up] + 1 / 3) / m, (j[down] + 2 / 3) / m])
        pick = cuts == m
        centre = (t[pick, 0, None] + s[None, :, None] * e1[pick, None] + u[None, :, None] * e2[pick, None])
        normal = np.repeat((cross[pick] / double_area[pick, None])[:, None], len(s), axis=1)
        area = np.repeat(0.5 * double_area[pick, None] / m ** 2, len(s), axis=1)
        parts.append((centre.reshape(-1, 3), normal.reshape(-1, 3), area.ravel()))
    return _join(parts)
