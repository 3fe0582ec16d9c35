"""The registry of force laws: each law is one module here, found by its name.

A segment law (module-level ``KIND = "segment"``) gives the granular resistive force on rigid segments, the single
source of truth of its formula; its C twin is ``plugins/laws/NAME.c``, which the native plugin finds by the same
name. Its module provides

- ``parameters(rft) -> dict``: its coefficients from a scene's ``[rft]`` section, intensive (per unit area and
  depth, N/m^3) where they are forces (the table law reads its CSV here);
- ``INTENSIVE``: the names among them that scale with a segment's size, times `segment_scale` (m^3) the keyword
  arguments of ``force`` for one segment (N), `per_segment`;
- ``force(v, x_axis, y_axis, v_reg, **parameters) -> (N, 3)``, pure numpy: the force (N, world frame) on N segments
  from their midpoint velocities ``v`` (N, 3), their unit axes ``x_axis`` (N, 3) and in-plane normals ``y_axis``
  (N, 3); every law fades out below the speed ``v_reg`` (the implicit methods difference it on that scale);
- ``feeds_energy(parameters) -> str``: why the law can push a segment along its own motion (F.v > 0), or "" when
  it dissipates at every velocity and orientation;
- optionally ``config(parameters) -> dict[str, str]``: its keys of the native plugin's config, when they are not
  its parameters' numbers written out;
- optionally ``check(rft, medium)``: SceneError for a ``[rft]`` section it cannot run (a key it needs left out),
  ``medium`` what the chain's ``[medium]`` gives to derive coefficients from (`finrft.media.immersion_properties`:
  bulk density, internal and surface friction) or None; called on every chain scene (`check`);
- ``KEYS``: its own keys of a scene's ``[rft]`` section, ``(name, type, finrft.schema.field(default, unit, doc,
  ...))`` each; the section (`finrft.scene.RFT`) is built from every segment law's (`keys`), so a new law's keys,
  units and documentation are declared in its module alone.

A surface law (``KIND = "surface"``) gives the force on the surface elements of any body (`finrft.attach`); its C
twin is in plugins/finrft_surface.c. Its module provides

- ``element_forces(normal, velocity, depth, area, coefficients=..., **parameters) -> (N, 3)``, pure numpy;
- ``Coefficients`` (its fit's coefficients) and ``DEFAULT``, the set it takes unless given others;
- ``PARAMETERS``, the names of its parameters of the medium (`finrft.attach` takes them by these names), and
  ``SECTION_KEYS``, the key of each in a scene's ``[medium]``; ``DENSITY``, the one that is the medium's bulk
  density ("" for none);
- ``given(section) -> dict``: its parameters as a scene's ``[medium]`` gives them (None: not given);
  ``catalogued(material) -> (dict, coefficients or None)``: those a catalogued medium gives; ``checked(parameters,
  where, shown) -> dict``: them validated, defaults filled in (`surface_parameters` does all three);
- ``config(parameters) -> dict[str, str]``: its scale keys of the native plugin's config;
- ``FEEDS_ENERGY``: why it can feed energy in, or "";
- ``KEYS``: its own keys of a scene's ``[medium]``, as a segment law's of ``[rft]``.

A surface law whose name is no Python identifier (``li2013-planar``) gives it as ``NAME``; one with a known limit
gives ``CAVEAT``, which `finrft.attach` warns of once per process.

Every surface law's force, DRFT's term included, is regularised in one place, `regularised`: times
tanh(max(n . v, 0) / v_reg), a smooth ramp of the leading-face switch and of the speed (the segment laws' v_reg).

A surface term (``KIND = "surface-term"``, DRFT's) adds to any surface law.

A law of any kind may also draw its stress map (``finrft law NAME``): ``stress_map(medium) -> dict`` of flat arrays
of one length, one entry per grid point, for a catalogued medium (`finrft.media.Material`): first two grid axes
named ``*_deg`` (the figure's x then y axis), then its fields, each with its unit in the module's ``MAP_UNITS``;
optionally ``map_note(medium) -> str``, one line on the map's scale, and ``MAP_QUANTITY``, what the fields are
(default: stress per unit depth).
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
import warnings
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Callable, Mapping

import numpy as np

from .. import schema
from ..errors import SceneError

SEGMENT = "segment"  # the KIND of a segment law
SURFACE = "surface"  # the KIND of a surface law

Law = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@functools.cache
def _modules() -> dict[str, ModuleType]:
    found = (importlib.import_module(f"{__name__}.{info.name}") for info in pkgutil.iter_modules(__path__)
             if not info.name.startswith("_"))
    # a law's name is its module's, or its NAME where a module name cannot spell it (li2013-planar)
    return {getattr(m, "NAME", m.__name__.rsplit(".", 1)[-1]): m for m in found}


@functools.cache
def _registry(kind: str = SEGMENT) -> dict[str, ModuleType]:
    return {name: module for name, module in _modules().items() if getattr(module, "KIND", "") == kind}


def mapped() -> dict[str, ModuleType]:
    """The laws of any kind that draw their stress map, by name (see the module's docstring)."""
    return {name: module for name, module in sorted(_modules().items()) if hasattr(module, "stress_map")}


def names(kind: str = SEGMENT) -> tuple[str, ...]:
    """The laws of a kind (segment laws by default), by name."""
    return tuple(sorted(_registry(kind)))


def module(name: str, kind: str = SEGMENT) -> ModuleType:
    """The module of a law of a kind (a segment law by default)."""
    return _registry(kind)[name]


def described(kind: str = SEGMENT) -> str:
    """Every law of a kind in a few words each (its module's ``SUMMARY``), as the schema documents the choice."""
    return "; ".join(f"{name}: {getattr(module(name, kind), 'SUMMARY', '')}" for name in names(kind))


def keys(kind: str = SEGMENT) -> tuple[Any, ...]:
    """Every law's own keys (``KEYS``) of a kind, the laws by name: what a scene's section for them holds, each
    used only by the laws that declare it or read it (their ``SECTION_KEYS``): a key of another law than the
    section's ``law``, given, is refused (`finrft.schema.unused`)."""
    declared: dict[str, Any] = {}
    for name in names(kind):
        for key in getattr(module(name, kind), "KEYS", ()):
            declared.setdefault(key[0], key)

    def users(key: str) -> tuple[str, ...]:
        return tuple(name for name in names(kind)
                     if key in {k[0] for k in getattr(module(name, kind), "KEYS", ())}
                     or key in getattr(module(name, kind), "SECTION_KEYS", {}).values())
    return tuple(schema.used_by(key, "law", users(name)) for name, key in declared.items())


# A segment law's normal-force coefficient (N/m^3, per unit area and depth) below this is refused as a slip of
# units. Granular resistance per unit depth is of order rho g times a friction coefficient: the weakest catalogued
# medium's zeta is 0.33 N/cm^3 = 3.3e5 N/m^3 (finrft/media.toml) and the paper's weak shallow-plate fit 1.8e4
# N/m^3, while 100 N/m^3 is rho g of a bed of 10 kg/m^3, lighter than any grains. A scene written when coefficients
# were forces per segment (N, of order 0.1 to 10) lands far below it.
LEAST_COEFFICIENT = 100.0
WHY_LEAST = ("granular resistance is of order rho g, >= 1e4 N/m^3 for any grains; the weakest catalogued medium "
             "gives 3.3e5: a value in N per segment? divide it by the face's area x mean depth, m^3")

# The smallest regularisation speed (m/s) a scene may give other than 0: Newton's method stops within 1e-10 m/s
# of the velocity (finrft.integrate.NEWTON_TOLERANCE); a ramp 1000 times wider keeps the force a body at rest
# takes from it within 0.1 % (a narrower one leaves the rest force wherever Newton's method stopped in the ramp).
LEAST_V_REG = 1e-7
# The largest (m/s): granular RFT is the rate-independent law of slow motion through grains, below about 1 m/s; a
# wider ramp leaves every force at those speeds below tanh(1) = 76 % of the law's and growing with the speed, a
# viscous drag rather than the law (a value in mm/s, the command line's unit, lands here).
LARGEST_V_REG = 1.0
WHY_LARGEST_V_REG = ("RFT's force is rate-independent at the speeds it holds at, below about 1 m/s; a wider ramp "
                     "scales it down with the speed there, a viscous drag: is the value in mm/s?")


def check(rft: Any, medium: tuple[float, float, float] | None) -> None:
    """Check a scene's ``[rft]`` section with its segment law's own ``check``, when the law has one: SceneError
    naming what it needs. ``medium``: what the chain's ``[medium]`` gives to derive coefficients from, or None."""
    own = getattr(module(rft.law), "check", None)
    if own is not None:
        own(rft, medium)


def segment_scale(length: float, height: float, depth: float) -> float:
    """What a segment law's intensive coefficients (N/m^3) are multiplied by to give one segment's forces (N): the
    area of a vertical face ``length`` x ``height`` (m) times its mean depth, its top edge ``depth`` below the free
    surface. Granular stress grows in proportion to depth (RFT's zeta, N/m^3), so a face's force is stress x area
    at its mean depth."""
    return length * height * (depth + height / 2)


@dataclass(frozen=True)
class SegmentLaw:
    """A segment law bound to one segment: its name, v_reg (m/s) and the keyword arguments of its ``force`` for that
    segment, forces in N (`per_segment`)."""

    law: str
    v_reg: float
    parameters: Mapping[str, Any] = field(hash=False)


def per_segment(rft: Any, length: float, height: float, depth: float) -> SegmentLaw:
    """The law of a scene's ``[rft]`` section on a segment whose face is ``length`` x ``height`` (m), its top edge
    ``depth`` below the surface: its INTENSIVE coefficients (N/m^3) times `segment_scale`, multiplied in the order
    length, height, mean depth, in which a per-segment value converted to N/m^3 with 17 digits (the paper presets')
    comes back exactly."""
    law = module(rft.law)
    intensive = getattr(law, "INTENSIVE", ())
    params = {key: ((value * length) * height) * (depth + height / 2) if key in intensive else value
              for key, value in law.parameters(rft).items()}
    return SegmentLaw(rft.law, rft.v_reg, params)


def bind(law: SegmentLaw) -> Law:
    """A segment's law as ``f(v, x_axis, y_axis) -> (N, 3)``."""
    force, params, v_reg = module(law.law).force, dict(law.parameters), law.v_reg
    return lambda v, x, y: force(v, x, y, v_reg, **params)


def plugin_config(law: SegmentLaw) -> dict[str, str]:
    """The native plugin's config keys of a segment's law: its name, v_reg and its own parameters."""
    own_law, params = module(law.law), dict(law.parameters)
    own = own_law.config(params) if hasattr(own_law, "config") else {key: repr(float(value))
                                                                       for key, value in params.items()}
    return {"law": law.law, "v_reg": repr(law.v_reg), **own}


def surface_parameters(law: str, given: dict[str, float | None], material: Any, where: str,
                       shown: dict[str, str] | None = None) -> tuple[dict[str, float], Any]:
    """A surface law's parameters and the coefficients a catalogued medium gives it (None: none): each parameter as
    ``given`` (None: not given) or else as the catalogued ``material`` gives it (a `finrft.media.Material`, or None),
    then checked by the law. A value both given and catalogued, or given for another surface law, is refused:
    SceneError beginning with ``where``, each parameter named as in ``shown`` (default: by its own name)."""
    surface = _registry(SURFACE)
    law_module = surface[law]
    shown = shown or {}
    foreign = [key for key, value in given.items() if value is not None and key not in law_module.PARAMETERS]
    if foreign:
        owner = next(name for name, m in sorted(surface.items()) if foreign[0] in getattr(m, "PARAMETERS", ()))
        raise SceneError(f"{where}: {', '.join(shown.get(k, k) for k in foreign)} belong to law {owner}, not {law}")
    found, coefficients = law_module.catalogued(material) if material is not None else ({}, None)
    intruder = getattr(law_module, "INTRUDER", ())
    both = [shown.get(key, key) for key in found if given.get(key) is not None and key not in intruder]
    if both:
        raise SceneError(f"{where}: the named medium {material.name!r} gives {', '.join(both)}: leave "
                         f"{', '.join(both)} out, or name no medium (one or the other)")
    own = {key: value for key, value in given.items() if value is not None}
    return law_module.checked({**given, **found, **own}, where, shown), coefficients


class FeedsEnergy(RuntimeWarning):
    """A scene's law can feed energy in (the paper's model, say): allowed, to reproduce published runs."""


def feeds_energy(law: SegmentLaw | None) -> str:
    """Why a segment's law can push it along its own motion, or "" when it dissipates; "" too for None (a scene
    without a segment law: a surface law's, whose dissipation its tests show)."""
    return "" if law is None else module(law.law).feeds_energy(dict(law.parameters))


_warned: list[str] = []  # the reason this process has warned of: once is enough


def warn_feeds_energy(law: str, reason: str, kept: str) -> None:
    """Warn (FeedsEnergy) that a law can feed energy in, and why it is kept, once per process."""
    if reason and not _warned:
        _warned.append(reason)
        warnings.warn(f"RFT law '{law}' feeds energy in: {reason} ({kept})", FeedsEnergy, stacklevel=3)


def warn_if_feeds_energy(law: SegmentLaw | None) -> None:
    """Warn (FeedsEnergy) when a segment's law can feed energy in, once per process; None passes."""
    if not _warned and law is not None:
        warn_feeds_energy(law.law, feeds_energy(law),
                          "kept to reproduce published runs; result files record it as law_feeds_energy")


# The surface laws' default regularisation speed, m/s: see `regularised`. A body resting on the medium creeps at
# about v_reg atanh(weight / full force) (the ramp needs some speed to carry any load): 0.05 mm/s for a 0.5 kg box
# at 0.1 mm/s against 0.32 mm/s at 1 mm/s (newton, 1 ms steps; tests/test_implicit_surfaces.py). The implicit
# methods take the stiffness that brings; MuJoCo's explicit step needs dt below about 2 m v_reg / F.
SURFACE_V_REG = 1e-4


# An element moving into the medium at most this share of v_reg has no force: the ramp would leave it less than
# that share (FINRFT_RAMP_FLOOR in plugins/finrft.h). Rounding puts a face moving along itself on either side of
# n . v = 0 (the sides of a rolling wheel, a third of its submerged elements); the native plugin then skips its law.
RAMP_FLOOR = 1e-12


def regularised(force: np.ndarray, normal: np.ndarray, velocity: np.ndarray, v_reg: float) -> np.ndarray:
    """Surface elements' forces (N, 3) times tanh(max(n . v, 0) / v_reg), none up to n . v = RAMP_FLOOR v_reg: the
    one regularisation of every surface law, the analogue of the segment laws' v_reg (m/s; 0: none, the laws' step
    as published).

    A rate-independent surface law switches its full stress on at n . v = 0+ (the leading-face test) and flips it
    with the velocity; the ramp makes the force continuous there, and at v = 0, over the speed v_reg. DRFT's term
    (-lambda rho (n.v)^2 n) is already continuous at n . v = 0 and ramped with the rest: below v_reg it is less
    than lambda rho v_reg^2 per unit area, 1.6e-3 Pa at 1 mm/s, against a law's kPa. The ramp costs
    1 - tanh(u/v_reg) of an element's force at normal speed u: 4e-9 at 10 v_reg, 0.5 % at 3 v_reg, so a face moving
    at >= 0.3 mm/s into the medium keeps its force within 0.5 % at the default v_reg = 0.1 mm/s (`SURFACE_V_REG`);
    grazing faces of curved bodies lose more: at v_reg = 1 mm/s a 6 cm sphere dragged at 0.1 m/s loses 0.024 % of its
    force, at 0.01 m/s 5.4 % (the loss goes as v_reg / speed); tests/test_regularisation.py."""
    force = np.asarray(force, dtype=float)
    if v_reg == 0:
        return force
    v_n = np.einsum("...i,...i", np.asarray(normal, dtype=float), np.asarray(velocity, dtype=float))
    # below RAMP_FLOOR v_reg, none at all: as the C twin, which skips the law there
    return force * np.where(v_n > RAMP_FLOOR * v_reg, np.tanh(np.maximum(v_n, 0.0) / v_reg), 0.0)[..., None]


def regularised_slopes(force: np.ndarray, slope: np.ndarray, normal: np.ndarray, velocity: np.ndarray,
                       v_reg: float) -> tuple[np.ndarray, np.ndarray]:
    """`regularised` forces (N, 3) and their derivatives in the velocity (N, 3, 3), given the unramped ones:
    d(r F)/dv = r dF/dv + r'(n . v) F n^T, r = tanh(n . v / v_reg), r' = (1 - r^2) / v_reg."""
    force, slope = np.asarray(force, dtype=float), np.asarray(slope, dtype=float)
    if v_reg == 0:
        return force, slope
    normal = np.asarray(normal, dtype=float)
    v_n = np.einsum("...i,...i", normal, np.asarray(velocity, dtype=float))
    on = v_n > RAMP_FLOOR * v_reg
    ramp = np.where(on, np.tanh(np.maximum(v_n, 0.0) / v_reg), 0.0)
    rate = np.where(on, (1 - ramp * ramp) / v_reg, 0.0)
    return (ramp[..., None] * force,
            ramp[..., None, None] * slope + rate[..., None, None] * force[..., :, None] * normal[..., None, :])


_cautioned: set[str] = set()  # the laws whose CAVEAT this process has warned of


def warn_caveat(law: str) -> None:
    """Warn (UserWarning) of a surface law's CAVEAT, if it has one, once per process."""
    caveat = getattr(module(law, SURFACE), "CAVEAT", "")
    if caveat and law not in _cautioned:
        _cautioned.add(law)
        warnings.warn(caveat, UserWarning, stacklevel=3)


def components(v: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray,
               v_reg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What every law starts from: the ramp tanh(|v| / v_reg) and the direction cosines v^.x^ and v^.y^ (0 at
    rest)."""
    speed = np.linalg.norm(v, axis=-1)
    safe = np.where(speed > 0.0, speed, 1.0)
    ramp = np.tanh(speed / v_reg)
    vx = np.einsum("...i,...i->...", v, x_axis) / safe
    vy = np.einsum("...i,...i->...", v, y_axis) / safe
    return ramp, vx, vy
