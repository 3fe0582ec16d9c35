"""The scene schema: every physical and numerical parameter of a simulation, in SI units.

A plate scene is a TOML file with the sections ``[plate]``, ``[rft]``, ``[medium]`` and ``[sim]`` (its
``[medium]`` is `Immersion`); a user's model (`UserScene`) ``[model]``, ``[medium]``, ``[[drive]]`` and
``[[control]]`` (arrays of tables, see `finrft.schema`) and ``[sim]`` (its ``[medium]`` is `Medium`, the surface
laws'). This module declares the shared sections (the chain, the laws'
``[rft]`` and ``[medium]``, the numerics) and these two kinds, their keys, types, units, allowed values and
defaults; an experiment with a scene of its own declares its sections in its module and registers the kind
(`register_scene`): the robot's in `finrft.experiments.swim` (`RobotScene`), the intrusion's in
`finrft.experiments.intrusion` (`IntrusionScene`). The keys of the laws are not here either: each law declares
its own (``KEYS`` in its module, `finrft.laws`), and `RFT` and `Medium` are built from them. The schema engine
that validates, reads and writes any scene is `finrft.schema`; everything else reads a validated scene.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar, Mapping

from . import design, laws, media, methods, schema
from .attach import MAX_ELEMENT_SIZE
from .errors import SceneError
from .files import read_text, read_toml
from .laws import drft, sandswim
from .surfaces import deforming, hfield
from .schema import field as _f
# Importable from here as before; their homes are the schema engine, the errors and the file reader.
from .schema import field_of, split_key, to_toml  # noqa: F401


# A chain's mass matrix is dense (every hinge moves the segments beyond it), so the cost of a step grows as N^2 to
# N^3: with 100 physical segments a 10 mm drag already takes ~2 s under the newton method, 200 take ~15 s.
MAX_SEGMENTS = 100

# The keys of a chain's one-sided stop: a soft or rigid chain has none.
ORIGAMI = ("kind", ("origami",))
# The keys of the methods that size their own steps: a fixed step has none.
ADAPTIVE = ("method", methods.adaptive())


# Why a chain's lengths stop at 1 m: a plate or fin of granular RFT is centimetres in size, and a larger value is
# one in mm (the command line's unit) written where the scene's metres belong.
IN_MM = "scene lengths are in metres; a value in mm is 1000 times larger: give 33 mm as 0.033 or \"33mm\""


@dataclass(frozen=True)
class Chain:
    """Rigid segments in series on compliant hinges: the plate, or a robot's fin."""

    kind: str = _f("origami", "", "origami: one-sided stop; soft: compliant both ways; rigid: one body",
                   choices=("origami", "soft", "rigid"))
    segments: int = _f(3, "", "number of rigid segments in series", minimum=1, exclusive=False,
                       maximum=MAX_SEGMENTS, why_maximum="a step's cost grows as N^2..N^3 in the chain's dense "
                       "mass matrix")
    segment_length: float = _f(0.033, "m", "length of one segment", minimum=0.0, maximum=1.0,
                               why_maximum=IN_MM)
    segment_mass: float = _f(0.00289, "kg", "mass of one segment, at its midpoint", minimum=0.0)
    segment_inertia: float = _f(2.623e-7, "kg m^2", "rotational inertia of a segment about z through its centre",
                                minimum=0.0)
    stiffness: float = _f(0.04863, "N m/rad", "hinge spring stiffness k", minimum=0.0, exclusive=False)
    springref: float = _f(0.0, "rad", "hinge rest angle; the origami stop sits here")
    damping: float = _f(0.04555, "N m s/rad", "hinge damping b", minimum=0.0, exclusive=False)
    stop: str = _f("penalty", "", "origami stop: the penalty spring (taken implicitly by the newton method), or a "
                   "MuJoCo joint limit",
                   choices=("limit", "penalty"), used_by=ORIGAMI)
    stop_stiffness: float = _f(1.0e4, "N m/rad", "penalty stop: torque -(k_stop (d + |d|)) d for hinge deflection d",
                               minimum=0.0, used_by=ORIGAMI)


@dataclass(frozen=True)
class Plate(Chain):
    rod_length: float = _f(0.007, "m", "extension rod from the driven base point to the first hinge", minimum=0.0,
                           maximum=1.0, why_maximum=IN_MM)
    rod_mass: float = _f(0.010, "kg", "mass of the extension rod, at its midpoint", minimum=0.0)
    rod_inertia: float = _f(4.08e-8, "kg m^2", "rotational inertia of the rod about z through its centre",
                            minimum=0.0)
    chain: str = _f("planar", "", "planar: hinges about z only; spatial: each segment also turns freely about "
                    "its own x and y axes (a 3D chain)", choices=("planar", "spatial"))
    rigid_as: str = _f("body", "", "rigid plate: one body, or hinged segments held together by weld constraints",
                       choices=("body", "welds"), used_by=("kind", ("rigid",)))


RFT = schema.section("RFT", (
    ("law", str, _f("paper", "", laws.described(), choices=laws.names)),
    ("v_reg", float, _f(0.001, "m/s", "speed below which the rate-independent force fades out (tanh)",
                        minimum=0.0, maximum=laws.LARGEST_V_REG, why_maximum=laws.WHY_LARGEST_V_REG)),
    *laws.keys()), __name__,
    "The segment law of a chain's segments: its name, its regularisation speed, and the keys every segment law "
    "declares (``KEYS`` in its module, `finrft.laws`); a law reads its own.")


@dataclass(frozen=True)
class Sim:
    integrator: str = _f("implicitfast", "", "MuJoCo integrator",
                         choices=("euler", "implicitfast", "implicit", "rk4"))
    dt: float = _f(1.0e-4, "s", "time step", minimum=0.0)
    backend: str = _f("native", "", "where the RFT force is computed: the C plugin, or a Python callback "
                      "(native falls back to python when the plugin is unavailable)", choices=("native", "python"))
    method: str = _f("newton", "", methods.described(), choices=methods.names())
    max_step: float = _f(1e-3, "s", "adaptive methods: largest step", minimum=0.0, used_by=ADAPTIVE)
    tolerance: float = _f(1e-4, "", "adaptive methods: error per step, relative (absolute below 1e-3)", minimum=0.0,
                          maximum=0.1, why_maximum="a looser step-doubling test accepts steps of any error",
                          used_by=ADAPTIVE)
    record_dt: float = _f(0.02, "s", "interval between recorded samples (rounded to whole steps)", minimum=0.0)


@dataclass(frozen=True)
class Model:
    path: str = _f("", "", "the MJCF file (relative to the scene file); finrft run MODEL.xml overrides it")
    bodies: tuple[str, ...] = _f((), "", "the bodies the medium acts on (their geoms are cut into surface elements)")
    geoms: tuple[str, ...] = _f((), "", "geoms the medium acts on, by name, beside model.bodies (their bodies' other "
                                "geoms left out)")
    keyframe: str = _f("", "", "a keyframe of the model (its <key name=...>) the run starts from: its joint "
                       "positions, velocities and activations, then each drive at its start; empty: the "
                       "model's own qpos0 at rest")
    design: tuple[str, ...] = _f((), "", "edits of the model by name before it compiles, KIND.NAME.ATTRIBUTE[.INDEX]"
                                 "=VALUE in SI (e.g. \"geom.fin.size.0=0.02\"; KIND body, geom, joint, actuator, "
                                 "site or tendon; an actuator's kp, kv: its position servo's gains, kv a velocity "
                                 "servo's); --set model.geom.fin.size.0=20mm sets one (finrft.design)")


Medium = schema.section("Medium", (
    ("law", str, _f("li2013", "", "the surface law on the surface elements: li2013, the granular RFT of Li, Zhang & "
                    "Goldman 2013 in 3D (Treers, Cao & Stuart 2021); li2013-planar, its planar form (no force across "
                    "an element's plane of motion: cannot swim); rft3d, the 3D RFT of Agarwal, Goldman & Kamrin 2023",
                    choices=lambda: laws.names(laws.SURFACE))),
    ("name", str, _f("", "", "a named medium of the catalogue (finrft medium --list), which gives li2013's zeta or "
                     "its own coefficients, rft3d's bulk density and internal friction; empty: li2013's generic "
                     "coefficients scaled by zeta")),
    ("surface_z", float, _f(0.0, "m", "height of the free surface (gravity along -z); the medium lies below")),
    ("surface", str, _f("flat", "", "the free surface (finrft.surfaces): flat, the horizontal plane at surface_z; "
                        "plane, at any tilt (surface_point, surface_normal); hfield, a heightfield (the model's "
                        "<hfield> named medium.hfield, else one generated by the hfield_ keys); deforming, a generated "
                        "heightfield the bodies displace (finrft.surfaces.deforming); depth is measured along the "
                        "model's gravity", choices=("flat", "plane", "hfield", "deforming"))),
    ("surface_point", tuple[float, ...], _f((0.0, 0.0, 0.0), "m", "plane: a point of the surface; hfield: the "
                                            "grid's centre (where no geom of the model shows it)",
                                            used_by=("surface", ("plane", "hfield", "deforming")))),
    ("surface_normal", tuple[float, ...], _f((0.0, 0.0, 1.0), "", "plane: its normal, out of the sand",
                                             used_by=("surface", ("plane",)))),
    ("hfield", str, _f("", "", "hfield: an <hfield> of the model (its geom, if any, places it and must not "
                       "collide); empty: generated from hfield_shape", used_by=("surface", ("hfield",)))),
    ("hfield_shape", str, _f("slope", "", "a generated hfield, level with gravity, rising along x at hfield_slope: "
                             "slope, nothing more; steps, stairs hfield_height high and hfield_length deep; noise, "
                             "smooth random ground of standard deviation hfield_height over hfield_length; pile, a "
                             "cone hfield_height high, hfield_length in radius", choices=hfield.SHAPES,
                             used_by=("surface", ("hfield", "deforming")))),
    ("hfield_extent", float, _f(1.0, "m", "a generated hfield's half-extent (a square about surface_point)",
                                minimum=0.0, used_by=("surface", ("hfield", "deforming")))),
    ("hfield_spacing", float, _f(0.01, "m", "a generated hfield's grid spacing", minimum=0.0,
                                 used_by=("surface", ("hfield", "deforming")))),
    ("hfield_slope", float, _f(0.0, "rad", "a generated hfield's incline along x",
                               used_by=("surface", ("hfield", "deforming")))),
    ("hfield_height", float, _f(0.01, "m", "a generated hfield's step height, noise deviation or pile height",
                                used_by=("surface", ("hfield", "deforming")))),
    ("hfield_length", float, _f(0.05, "m", "a generated hfield's step depth, noise correlation length or pile "
                                "radius", minimum=0.0, used_by=("surface", ("hfield", "deforming")))),
    ("hfield_seed", int, _f(0, "", "a generated noise hfield's random seed",
                            used_by=("surface", ("hfield", "deforming")))),
    ("hfield_heading", float, _f(0.0, "rad", "a generated hfield's x axis (its incline's direction): the world's x "
                                 "turned this far about up, towards y", used_by=("surface", ("hfield", "deforming")))),
    ("pile_factor", float, _f(0.0, "", "deforming: the wheel group's pile rule, an element in raised sand takes its "
                              "depth times this factor (finrft.surfaces.deforming; theirs 0.2843); 0: none",
                              minimum=0.0, exclusive=False, used_by=("surface", ("deforming",)))),
    ("compaction", float, _f(0.0, "", "deforming: the share of the sand the body sweeps that is compacted under it "
                             "instead of going to the berm (finrft.surfaces.deforming); 0: all to the berm, the wheel "
                             "group's model", minimum=0.0, exclusive=False, maximum=1.0,
                             why_maximum="a share of the swept sand", used_by=("surface", ("deforming",)))),
    ("berm", str, _f("velocity", "", "deforming: where the sand the body sweeps goes (finrft.surfaces.deforming): "
                     "velocity, ahead of each element along its horizontal motion and to its sides; facing, a leading "
                     "element's along its outward normal (the side it faces)", choices=("velocity", "facing"),
                     used_by=("surface", ("deforming",)))),
    ("surface_update", float, _f(deforming.MOVE, "", "deforming: the surface steps once an element may have moved "
                                 "this share of its grid's finer spacing", minimum=0.0,
                                 used_by=("surface", ("deforming",)))),
    ("relax_tolerance", float, _f(deforming.STEP_TOLERANCE, "", "deforming: the slope (tan) above tan(angle of "
                                  "repose) that relaxation leaves", minimum=0.0,
                                  used_by=("surface", ("deforming",)))),
    ("angle_of_repose", float, _f(0.0, "rad", "deforming: the slope the surface relaxes to; 0: the medium's "
                                  "catalogued angle_of_repose", minimum=0.0, exclusive=False,
                                  used_by=("surface", ("deforming",)))),
    ("bed_depth", float, _f(0.0, "m", "the sand's thickness: a rigid floor (a plane geom with contacts) this far "
                            "below the surface along gravity (an hfield's: below its lowest point); 0: unbounded",
                            minimum=0.0, exclusive=False)),
    ("element_size", float, _f(0.005, "m", "size of the surface elements", minimum=0.0,
                               maximum=MAX_ELEMENT_SIZE, why_maximum=IN_MM)),
    ("v_reg", float, _f(laws.SURFACE_V_REG, "m/s", "every element's force times tanh(max(n.v, 0) / v_reg): the "
                        "smooth onset of the leading-face switch and of the speed (finrft.laws.regularised); 0: "
                        "none, the law's step as published", minimum=0.0, exclusive=False,
                        maximum=laws.LARGEST_V_REG, why_maximum=laws.WHY_LARGEST_V_REG,
                        least=laws.LEAST_V_REG, why_least=f"Newton's method settles velocities to 1e-10 m/s; a "
                        f"ramp narrower than {laws.LEAST_V_REG:g} m/s leaves a resting body's force wherever it "
                        f"stopped")),
    ("drft_lambda", float, _f(0.0, "", "DRFT's rate-dependent term (Agarwal et al. 2021 Sci. Adv.): the leading "
                              "elements also take a pressure drft_lambda * bulk_density * (v.n)^2; 0: off, the "
                              "quasi-static law alone; the paper fits O(1) values", minimum=0.0, exclusive=False)),
    ("bulk_density", float, _f(0.0, "kg/m^3", "the medium's bulk (critical) density, for drft_lambda > 0 and "
                               "rft3d's rho_c; 0: the catalogued medium's (medium.name), if it has one",
                               minimum=0.0, exclusive=False)),
    *laws.keys(laws.SURFACE)), __name__,
    "The medium of a user's model or an intrusion: its surface law, named medium and free surface, and the keys "
    "every surface law declares (``KEYS`` in its module, `finrft.laws`).")


@dataclass(frozen=True)
class Immersion:
    """What a chain of segments (the plate, the robot's fins) is immersed in: the medium, named for provenance, and
    what the sand-swimming law's coefficients follow from (`finrft.media.sandswim_coefficients`). Not `Medium`,
    the surface laws' section: a chain's law acts on segments, so surface elements and their law have no place
    here, and the chain's depth and height do."""

    name: str = _f("", "", "a medium of the catalogue (finrft medium --list); empty: unnamed")
    depth: float = _f(0.010, "m", "depth of the chain's top edge below the free surface", minimum=0.0,
                      exclusive=False, maximum=1.0, why_maximum=IN_MM)
    height: float = _f(0.055, "m", "the chain's vertical extent (the plate's or fin's height): a segment's face is "
                       "segment_length x height, at mean depth depth + height / 2", minimum=0.0, maximum=1.0,
                       why_maximum=IN_MM)
    bulk_density: float = _f(0.0, "kg/m^3", "the medium's critical (bulk) density, 3D-RFT's rho_c; 0: the named "
                             "medium's, if catalogued", minimum=0.0, exclusive=False)
    internal_friction: float = _f(0.0, "", "the medium's internal friction coefficient, 3D-RFT's mu_int (tan of the "
                                  "internal friction angle); 0: the named medium's, if catalogued", minimum=0.0,
                                  exclusive=False)
    surface_friction: float = _f(0.0, "", "friction coefficient between the chain and the grains, 3D-RFT's "
                                 "mu_surf; 0: the named medium's, if it catalogues one, else frictionless",
                                 minimum=0.0, exclusive=False)


# The keys a drive's profile and a control's kind use (`finrft.schema.unused`).
CONSTANT, SINE = ("profile", ("constant",)), ("profile", ("sine",))


@dataclass(frozen=True)
class JointDrive:
    joint: str = _f("", "", "the joint moved on a prescribed profile (slide: m, m/s; hinge: rad, rad/s); it follows "
                    "the profile exactly (a very large armature) and the force it needs is recorded")
    profile: str = _f("constant", "", "constant: speed, reversed after each stroke; sine: start + amplitude "
                      "sin(2 pi frequency t + phase)", choices=("constant", "sine"))
    speed: float = _f(0.1, "m/s or rad/s", "constant: speed of the joint (> 0 when it has a stroke)",
                      used_by=CONSTANT)
    stroke: float = _f(0.05, "m or rad", "constant: length of one stroke; 0: no reversal, the whole run",
                       minimum=0.0, exclusive=False, used_by=CONSTANT)
    cycles: int = _f(0, "", "constant: out-and-back cycles of a triangle wave, then the joint holds still; 0: one "
                     "stroke out", minimum=0, exclusive=False, used_by=CONSTANT)
    start: float = _f(0.0, "m or rad", "the joint's position at t = 0 (its qpos); a sine's centre")
    amplitude: float = _f(0.0, "m or rad", "sine: amplitude", used_by=SINE)
    frequency: float = _f(1.0, "Hz", "sine: frequency", minimum=0.0, used_by=SINE)
    phase: float = _f(0.0, "rad", "sine: phase", used_by=SINE)


# The control kinds that follow a reference offset + amplitude sin(2 pi frequency t + phase): the sine's ctrl itself,
# the PD law's joint position, the sensor loop's reading (`finrft.experiments.user_model.control_value`).
REFERENCED = ("kind", ("sine", "pd", "sensor"))
CLOSED = ("kind", ("pd", "sensor"))


@dataclass(frozen=True)
class Control:
    actuator: str = _f("", "", "the actuator (MJCF <actuator> name) whose ctrl this entry sets")
    kind: str = _f("constant", "", "constant: value; sine: offset + amplitude sin(2 pi frequency t + phase); table: "
                   "a CSV file of time_s,ctrl rows, linear in between (held beyond its ends); pd: ctrl = kp (r - q) + "
                   "kd (r' - q') for joint's position q tracking the reference r = offset + amplitude sin(2 pi "
                   "frequency t + phase); sensor: the same law on an MJCF <sensor>'s reading (its component index) "
                   "instead of q",
                   choices=("constant", "sine", "table", "pd", "sensor"))
    value: float = _f(0.0, "actuator's unit", "constant: the ctrl", used_by=("kind", ("constant",)))
    offset: float = _f(0.0, "actuator's unit, or the joint's or sensor's", "sine: offset; pd, sensor: the "
                       "reference's centre (m or rad for a joint, the sensor's unit)", used_by=REFERENCED)
    amplitude: float = _f(0.0, "actuator's unit, or the joint's or sensor's", "sine: amplitude; pd, sensor: the "
                          "reference's (0: a constant reference)", used_by=REFERENCED)
    frequency: float = _f(1.0, "Hz", "sine: frequency; pd, sensor: the reference's", minimum=0.0,
                          used_by=REFERENCED)
    phase: float = _f(0.0, "rad", "sine: phase; pd, sensor: the reference's", used_by=REFERENCED)
    table: str = _f("", "", "table: the CSV file (relative to the scene file), a header time_s,ctrl then rows",
                    used_by=("kind", ("table",)))
    ramp: float = _f(0.0, "s", "the ctrl (pd, sensor: the reference) rises linearly from 0 to its profile over the "
                     "first ramp seconds", minimum=0.0, exclusive=False)
    ramps: str = _f("all", "", "what the ramp scales: all (the offset too, as before); oscillation (the sine's part "
                    "only: the offset holds from t = 0, so a posture is kept while an oscillation ramps in)",
                    choices=("all", "oscillation"), used_by=REFERENCED)
    joint: str = _f("", "", "pd: the joint (slide or hinge, MJCF name) whose position tracks the reference",
                    used_by=("kind", ("pd",)))
    sensor: str = _f("", "", "sensor: the MJCF <sensor> (by name) fed back", used_by=("kind", ("sensor",)))
    index: int = _f(0, "", "sensor: which component of the sensor's reading (0 for a scalar sensor; 2 for a "
                    "framepos's z)", minimum=0, exclusive=False, used_by=("kind", ("sensor",)))
    kp: float = _f(0.0, "actuator's unit per the reference's unit", "pd, sensor: proportional gain on the error "
                   "r - y", used_by=CLOSED)
    kd: float = _f(0.0, "actuator's unit per the reference's unit per s", "pd, sensor: derivative gain on the "
                   "error's rate r' - y' (pd: the joint's velocity; sensor: the reading's change over the last step)",
                   used_by=CLOSED)


def repose(m: Any) -> float:
    """The angle of repose (rad) a deforming surface of medium section ``m`` relaxes to: its own, else the
    catalogued medium's; SceneError when neither gives one."""
    if m.angle_of_repose > 0:
        return float(m.angle_of_repose)
    catalogued = media.medium(m.name).get("angle_of_repose") if m.name else None
    if catalogued is None:
        raise SceneError(f"medium.surface = \"deforming\" needs an angle of repose: medium {m.name or '(unnamed)'} "
                         f"catalogues none; set medium.angle_of_repose (rad)")
    return float(catalogued.value)


def check_medium(m: Any) -> None:
    for key in ("surface_point", "surface_normal"):
        if len(getattr(m, key)) != 3:
            raise SceneError(f"medium.{key} must be 3 numbers (x, y, z), got {list(getattr(m, key))}")
    if m.surface == "deforming":
        repose(m)
    if m.bulk_density and not m.drft_lambda and not laws.module(m.law, laws.SURFACE).DENSITY:
        raise SceneError(f"medium.bulk_density is used by drft_lambda > 0 and a law with a density (rft3d) only, and "
                         f"this medium's law is {m.law!r} with drft_lambda = 0: set medium.drft_lambda, or leave "
                         f"bulk_density out")
    material = media.medium(m.name) if m.name else None
    catalogued = material.get("bulk_density") if material else None
    drft.density(m.drft_lambda, m.bulk_density or None, None if catalogued is None else catalogued.value,
                 "medium.bulk_density", "medium")
    law = laws.module(m.law, laws.SURFACE)
    laws.surface_parameters(m.law, law.given(m), material, f"medium.law = {m.law!r}",
                            {key: f"medium.{name}" for key, name in law.SECTION_KEYS.items()})


def resolution(sim: Any) -> str:
    """A scene's method and what sets its steps, in words: the tolerance and largest step of an adaptive method
    (its dt is only the grid of reversals and samples), else the step."""
    if methods.chooses(sim.method):
        return f"{sim.method} method (the run chooses), from dt {sim.dt:g} s"
    if methods.get(sim.method).adaptive:
        return f"{sim.method} method, tolerance {sim.tolerance:g}, steps up to {sim.max_step:g} s"
    return f"{sim.method} method, dt {sim.dt:g} s"

# The methods of a scene that offers MuJoCo's step only (ExplicitSim).
EXPLICIT_ONLY = methods.explicit()


class Sections:
    def __post_init__(self) -> None:
        schema.check_sections(self)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return dataclasses.asdict(self)

    def replace(self, **updates: Any):
        """A copy with dotted keys changed, e.g. ``scene.replace(**{"plate.kind": "soft"})``; validated."""
        data = self.to_dict()
        return scene_from_dict(schema.updated(data, type(self), updates), type(self))


def check_sim(sim: Sim) -> None:
    if not methods.chooses(sim.method) and methods.get(sim.method).implicit and sim.integrator != "implicitfast":
        raise SceneError(f"sim.method = {sim.method!r} extends MuJoCo's implicitfast integrator: set "
                         f"sim.integrator = 'implicitfast' (got {sim.integrator!r}) or use sim.method = 'explicit'")


@dataclass(frozen=True)
class Scene(Sections):
    """A plate test: the plate, the RFT law on its segments, and the numerics."""

    plate: Plate = field(default_factory=Plate)
    rft: RFT = field(default_factory=RFT)
    medium: Immersion = field(default_factory=Immersion)
    sim: Sim = field(default_factory=Sim)

    # A plate's [medium] gives its segment law's coefficients only under sandswim with its own left out (a robot's
    # feeds its arms and body too): under any other, the medium's values were silently ignored.
    USED_BY: ClassVar[dict[str, dict[str, tuple]]] = {"medium": dict.fromkeys(
        ("bulk_density", "internal_friction", "surface_friction"),
        ("rft.law", ("sandswim",), tuple(key for key, _, _ in sandswim.KEYS)))}

    def __post_init__(self) -> None:
        super().__post_init__()
        check_chain_law(self)
        check_sim(self.sim)


@dataclass(frozen=True)
class ExplicitSim(Sim):
    method: str = _f("explicit", "", "explicit: MuJoCo's step, the only method of this scene",
                     choices=EXPLICIT_ONLY)


@dataclass(frozen=True)
class RobotSim(Sim):
    # MuJoCo's usual step: the newton method takes the attached surfaces' stiff forces implicitly there; auto
    # starts its pilots from it
    dt: float = _f(1.0e-3, "s", "time step (auto: the implicit methods' first step)", minimum=0.0)
    method: str = _f(methods.AUTO, "", f"{methods.AUTO_DOC}; {methods.described()}",
                     choices=(methods.AUTO, *methods.names()))
    duration: float = _f(0.0, "s", "length of the run; 0: the constant drives' own (one stroke, or their cycles)",
                         minimum=0.0, exclusive=False)
    settle: float = _f(0.0, "s", "the summaries average over [settle, duration]", minimum=0.0, exclusive=False)


@dataclass(frozen=True)
class UserScene(Sections):
    """A user's MJCF model in the medium: the bodies RFT acts on, the law, zero or more prescribed joints
    ([[drive]]), zero or more actuators' controls ([[control]]), the numerics."""

    model: Model = field(default_factory=Model)
    medium: Medium = field(default_factory=Medium)
    drive: tuple[JointDrive, ...] = ()
    control: tuple[Control, ...] = ()
    sim: RobotSim = field(default_factory=RobotSim)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_sim(self.sim)
        check_medium(self.medium)
        check_sines(self)
        design.entries(self.model.design)

    def replace(self, **updates: Any) -> UserScene:
        """As `Sections.replace`; a design key (``model.geom.fin.size.0``, `finrft.design`) sets its entry of
        ``model.design``, in SI or with a unit suffix its attribute's unit allows."""
        edits = {key: design_value(key, updates.pop(key)) for key in list(updates) if design.is_key(key)}
        if edits:
            updates["model.design"] = design.merged(self.model.design, edits)
        return super().replace(**updates)

    def design_values(self) -> dict[str, float]:
        """The design keys this scene sets, ``model.KIND.NAME.ATTRIBUTE[.INDEX]`` -> value (SI)."""
        return {f"model.{key}": value for key, value in design.entries(self.model.design).items()}

    def without_controls(self) -> UserScene:
        """A copy without [[control]] entries: the scene a Python controller drives instead
        (``finrft.run_robot(scene.without_controls(), control=...)``)."""
        return dataclasses.replace(self, control=())

    @property
    def duration(self) -> float:
        """The run's length (s): ``sim.duration``, or the constant drives' own."""
        stroke_time, strokes = drive_timing(self)
        return stroke_time * strokes


# The fewest steps per period of a sine (drive or control) at sim.dt: fewer alias it (at one step per period a drive
# lands on its start at every step and never moves).
SINE_STEPS = 8


def check_sines(scene: UserScene) -> None:
    """SceneError for a sine [[drive]] or [[control]] with fewer than `SINE_STEPS` steps per period at sim.dt."""
    dt = scene.sim.dt
    sines = [(f"drive.{i}", j.frequency) for i, j in enumerate(scene.drive) if j.profile == "sine"]
    sines += [(f"control.{i}", c.frequency) for i, c in enumerate(scene.control)
              if c.kind == "sine" or (c.kind in CLOSED[1] and c.amplitude)]
    for where, frequency in sines:
        if 1 / (frequency * dt) < SINE_STEPS:
            raise SceneError(f"{where}.frequency = {frequency:g} Hz has {1 / (frequency * dt):.3g} steps per period "
                             f"at sim.dt = {dt:g} s, fewer than {SINE_STEPS}: set sim.dt <= "
                             f"{1 / (SINE_STEPS * frequency):.3g} s, or lower the frequency")


def design_value(key: str, value: Any) -> float:
    """A design key's value: a number, or text with a unit suffix of its attribute's unit (`finrft.design`)."""
    unit = design.unit(key)
    if isinstance(value, str) and design.parse(key)[2] in design.JOINT_UNIT and not schema.is_number(value):
        raise SceneError(f"{key} = {value!r}: give a plain number in SI, m on a slide joint or rad on a hinge (a unit "
                         f"suffix cannot tell which the joint is)")
    if isinstance(value, str):
        value = schema.quantity(value, unit, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{key} must be a finite number ({unit or 'SI'}), got {value!r}")
    return float(value)


def key_unit(cls: type, key: str) -> str:
    """A scene key's SI unit ("" when dimensionless, a name, or a design key whose attribute has none); SceneError
    for a key the scene does not have."""
    if cls is UserScene and design.is_key(key):
        return design.unit(key)
    return field_of(cls, key).metadata["unit"]


def key_value(scene: Any, key: str) -> Any:
    """A dotted key's value in ``scene`` (an array's entry ``control.0.phase``; ``control.*.phase``: the first
    entry's; a design key: its value, the model's own where the scene sets none: None)."""
    if isinstance(scene, UserScene) and design.is_key(key):
        return scene.design_values().get(key)
    section, _, rest = key.partition(".")
    value = getattr(scene, section)
    if section in schema.arrays(type(scene)):
        first, _, name = rest.partition(".")
        if first.isdigit() or first == "*":
            value, rest = value[int(first) if first.isdigit() else 0], name
        else:
            value = value[0]
    return getattr(value, rest)


def drive_timing(scene: UserScene) -> tuple[float, int]:
    """The run's grid of reversals: the stroke time every constant drive with a stroke shares (the whole run
    without one) and the strokes the run holds; SceneError when the drives and [sim] disagree (checked as the run
    is made, `finrft.UserModel.of`: a scene without drives or a duration is a valid default to build on)."""
    for i, j in enumerate(scene.drive):
        if j.profile == "constant" and j.stroke > 0 and not j.speed > 0:
            raise SceneError(f"drive.{i}.speed must be > 0 for a stroke of {j.stroke:g} (drive.{i}.stroke = 0: "
                             f"no reversal), got {j.speed!r}")
    times = {j.stroke / j.speed for j in scene.drive if j.profile == "constant" and j.stroke > 0}
    if len(times) > 1 and max(times) - min(times) > 1e-9 * max(times):
        each = ", ".join(f"{t:.4g} s" for t in sorted(times))
        raise SceneError(f"the constant drives with a stroke take different times for one ({each}): give them one "
                         f"stroke / speed, or stroke = 0")
    duration, sim = scene.sim.duration, scene.sim
    if times:
        stroke_time = min(times)
        own = max(1 if j.cycles == 0 else 2 * j.cycles for j in scene.drive
                  if j.profile == "constant" and j.stroke > 0)
        strokes = round(duration / stroke_time) if duration else own
        if duration and abs(strokes * stroke_time - duration) > 1e-9 * duration:
            raise SceneError(f"sim.duration = {duration:g} s is not a whole number of the drives' strokes "
                             f"({stroke_time:.6g} s each)")
        duration = strokes * stroke_time
    elif not duration:
        raise SceneError("sim.duration = 0 needs a constant [[drive]] with a stroke to take its length from: set "
                         "sim.duration (s)")
    else:
        stroke_time, strokes = duration, 1
    if not sim.settle < duration:
        raise SceneError(f"sim.settle = {sim.settle:g} s must be shorter than the run ({duration:.6g} s)")
    for i, c in enumerate(scene.control):
        if not c.ramp < duration:
            raise SceneError(f"control.{i}.ramp = {c.ramp:g} s must be shorter than the run ({duration:.6g} s)")
    return stroke_time, strokes


def check_chain_law(scene: Any) -> None:
    """Check a chain scene's medium and, with what the medium gives (a law may derive its coefficients from it at
    model build, `finrft.geometry.resolve`), its segment law's own keys (`finrft.laws.check`)."""
    laws.check(scene.rft, media.immersion_properties(scene.medium))


@dataclass(frozen=True)
class SceneKind:
    """A registered scene class: its built-in presets (``presets/PREFIX-NAME.toml``) and a line saying what it is
    and which commands read it (the scene reference's heading)."""

    cls: type
    presets: tuple[str, ...] = ()
    prefix: str = ""
    title: str = ""


_KINDS: dict[type, SceneKind] = {}
# Each registered scene class's presets (see `register_scene`), filled as the kinds register.
def register_scene(cls: type, *, presets: tuple[str, ...] = (), prefix: str = "", title: str = "") -> type:
    """Register a scene class: its presets are read from ``finrft/presets/PREFIX-NAME.toml`` (`preset`), and the
    scene reference lists its sections under ``title``. The experiments register their own scene kinds when
    `finrft.experiments` is imported (``import finrft`` does it). Returns the class."""
    if presets and not prefix:
        raise ValueError(f"{cls.__name__}: a scene kind with presets needs the prefix of their files")
    _KINDS[cls] = SceneKind(cls, tuple(presets), prefix, title or cls.__name__)
    return cls


def presets(cls: type) -> tuple[str, ...]:
    """The built-in scenes of a registered scene kind, by name (none for a kind without presets)."""
    return _KINDS[cls].presets if cls in _KINDS else ()


def scene_kinds() -> tuple[SceneKind, ...]:
    """The registered scene kinds, in the order they registered."""
    return tuple(_KINDS.values())


register_scene(Scene, presets=("paper", "physical"), prefix="plate",
               title="Plate tests: `finrft drag`, `rotate`, `fit`, `report`; `finrft.Scene`")
register_scene(UserScene, title="Your own model: `finrft run`; `finrft.UserScene`")


def scene_from_dict(data: Mapping[str, Any], cls: type = Scene):
    """Validate a nested mapping (as read from TOML) into a scene of class ``cls``; missing keys take the
    schema's defaults."""
    return schema.from_dict(data, cls)


# Keys that name files, relative to the scene file that gives them.
FILE_KEYS = (("rft", "table"), ("model", "path"), ("control", "table"))


def preset(name: str, cls: type = Scene):
    """A built-in scene of a registered kind by name (see `register_scene`)."""
    kind = _KINDS.get(cls)
    if kind is None:
        raise SceneError(f"{getattr(cls, '__name__', cls)!s} is not a registered scene kind (import finrft)")
    if name not in kind.presets:
        raise SceneError(f"unknown preset '{name}': use one of {', '.join(kind.presets) or '(none)'}")
    text = (resources.files("finrft") / "presets" / f"{kind.prefix}-{name}.toml").read_text()
    return scene_from_dict(read_toml(text, f"preset {name}"), cls)


def load_scene(path: str | Path | None = None, *, preset_name: str = "physical",
               overrides: Mapping[str, Any] | None = None, cls: type = Scene):
    """A scene from a TOML file (or, when no file is given, the named preset, physical as every command; a scene
    class without presets takes its schema's defaults), with dotted-key overrides applied.

    A relative path in a file (``rft.table``, ``model.path``) is taken relative to that file.
    """
    if path is None:
        scene = preset(preset_name, cls) if presets(cls) else scene_from_dict({}, cls)
    else:
        path = Path(path)
        data = read_toml(read_text(path, "scene file"), str(path))
        for section, name in FILE_KEYS:
            tables = data.get(section)
            for table in tables if isinstance(tables, list) else [tables]:  # an array of tables: each entry
                given = table.get(name) if isinstance(table, dict) else None
                if isinstance(given, str) and given and not Path(given).is_absolute():
                    table[name] = str(path.parent / given)
        scene = scene_from_dict(data, cls)
    if overrides is not None and not isinstance(overrides, Mapping):
        raise SceneError(f"overrides must map dotted keys to values, e.g. {{\"sim.dt\": 1e-4}}, got "
                         f"{type(overrides).__name__} {overrides!r:.60}")
    return scene.replace(**dict(overrides or {}))


def parse_override(text: str, cls: type = Scene) -> tuple[str, Any]:
    """``plate.stiffness=0.3`` -> ("plate.stiffness", 0.3) for a scene of class ``cls``: `finrft.schema.parse_override`;
    a user's scene takes design keys too (``model.geom.fin.size.0=20mm``, `finrft.design`)."""
    key, sep, raw = text.partition("=")
    if cls is UserScene and design.is_key(key.strip()) and sep:
        design.parse(key.strip())
        raw = raw.strip()
        return key.strip(), float(raw) if schema.is_number(raw) else raw
    return schema.parse_override(text, cls)
