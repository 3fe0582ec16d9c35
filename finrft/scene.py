"""The scene schema: every physical and numerical parameter of a simulation, in SI units.

A scene is a TOML file with the sections ``[plate]``, ``[rft]`` and ``[sim]``. This module is the one place
where keys, types, units, allowed values and defaults are declared; everything else reads a validated `Scene`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping


class SceneError(ValueError):
    """A scene file, preset or override that cannot be used; the message names the key and what is allowed."""


def _f(default: Any, unit: str, doc: str, *, choices: tuple[str, ...] = (), minimum: float | None = None,
       exclusive: bool = True) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc, "choices": choices, "minimum": minimum,
                                            "exclusive": exclusive})


@dataclass(frozen=True)
class Plate:
    kind: str = _f("origami", "", "origami: one-sided stop; soft: compliant both ways; rigid: one body",
                   choices=("origami", "soft", "rigid"))
    segments: int = _f(3, "", "number of rigid segments in series", minimum=1, exclusive=False)
    segment_length: float = _f(0.033, "m", "length of one segment", minimum=0.0)
    segment_mass: float = _f(0.00289, "kg", "mass of one segment, at its midpoint", minimum=0.0)
    segment_inertia: float = _f(2.6e-7, "kg m^2", "rotational inertia of a segment about z through its centre",
                                minimum=0.0)
    rod_length: float = _f(0.007, "m", "extension rod from the driven base point to the first hinge", minimum=0.0)
    rod_mass: float = _f(0.010, "kg", "mass of the extension rod, at its midpoint", minimum=0.0)
    rod_inertia: float = _f(4.1e-8, "kg m^2", "rotational inertia of the rod about z through its centre",
                            minimum=0.0)
    stiffness: float = _f(0.209, "N m/rad", "hinge spring stiffness k", minimum=0.0, exclusive=False)
    springref: float = _f(0.0, "rad", "hinge rest angle; the origami stop sits here")
    damping: float = _f(1.43, "N m s/rad", "hinge damping b", minimum=0.0, exclusive=False)
    stop: str = _f("limit", "", "origami stop: MuJoCo joint limit, or the reference's penalty spring",
                   choices=("limit", "penalty"))
    stop_stiffness: float = _f(1.0e4, "N m/rad", "penalty stop: torque -(k_stop (d + |d|)) d for hinge deflection d",
                               minimum=0.0)


@dataclass(frozen=True)
class RFT:
    law: str = _f("paper", "", "paper: direction-cosine law; table: F_perp(theta), F_par(theta) from a CSV",
                  choices=("paper", "table"))
    f_perp: float = _f(1.2, "N", "normal force coefficient per segment (paper law)")
    f_par: float = _f(-0.2, "N", "tangential force coefficient per segment (paper law; < 0 feeds energy in)")
    v_reg: float = _f(0.001, "m/s", "speed below which the rate-independent force fades out (tanh)", minimum=0.0)
    table: str = _f("", "", "table law: CSV with columns attack_deg, f_perp_N, f_par_N (relative to the scene file)")


@dataclass(frozen=True)
class Sim:
    integrator: str = _f("implicitfast", "", "MuJoCo integrator",
                         choices=("euler", "implicitfast", "implicit", "rk4"))
    dt: float = _f(1.0e-4, "s", "time step", minimum=0.0)
    backend: str = _f("native", "", "where the RFT force is computed: the C plugin, or a Python callback "
                      "(native falls back to python when the plugin is unavailable)", choices=("native", "python"))
    record_dt: float = _f(0.005, "s", "interval between recorded samples (rounded to whole steps)", minimum=0.0)


@dataclass(frozen=True)
class Scene:
    plate: Plate = field(default_factory=Plate)
    rft: RFT = field(default_factory=RFT)
    sim: Sim = field(default_factory=Sim)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return dataclasses.asdict(self)

    def replace(self, **updates: Any) -> "Scene":
        """A copy with dotted keys changed, e.g. ``scene.replace(**{"plate.kind": "soft"})``; validated."""
        data = self.to_dict()
        for key, value in updates.items():
            section, name = _split_key(key)
            data[section][name] = value
        return scene_from_dict(data)


SECTIONS: dict[str, type] = {"plate": Plate, "rft": RFT, "sim": Sim}
PRESETS = ("paper",)


def _split_key(key: str) -> tuple[str, str]:
    section, _, name = key.partition(".")
    if section not in SECTIONS or not name:
        raise SceneError(f"unknown scene key '{key}': keys look like SECTION.NAME with SECTION one of "
                         f"{', '.join(SECTIONS)}")
    names = [f.name for f in dataclasses.fields(SECTIONS[section])]
    if name not in names:
        raise SceneError(f"unknown scene key '{key}': [{section}] has {', '.join(names)}")
    return section, name


def _check(section: str, f: dataclasses.Field, value: Any) -> Any:
    key, meta = f"{section}.{f.name}", f.metadata
    if f.type in ("float", float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{key} must be a number ({meta['unit'] or 'dimensionless'}), got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise SceneError(f"{key} must be finite, got {value!r}")
    elif f.type in ("int", int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{key} must be a whole number, got {value!r}")
    elif not isinstance(value, str):
        raise SceneError(f"{key} must be a string, got {value!r}")
    if meta["choices"] and value not in meta["choices"]:
        raise SceneError(f"{key} = {value!r} is not allowed: use one of {', '.join(meta['choices'])}")
    low = meta["minimum"]
    if low is not None and (value <= low if meta["exclusive"] else value < low):
        relation = ">" if meta["exclusive"] else ">="
        raise SceneError(f"{key} must be {relation} {low:g} {meta['unit']}".rstrip() + f", got {value!r}")
    return value


def scene_from_dict(data: Mapping[str, Any]) -> Scene:
    """Validate a nested mapping (as read from TOML) into a Scene; missing keys take the schema defaults."""
    if not isinstance(data, Mapping):
        raise SceneError("a scene must be a table of sections")
    for section in data:
        if section not in SECTIONS:
            raise SceneError(f"unknown scene section [{section}]: use {', '.join(SECTIONS)}")
    parts = {}
    for section, cls in SECTIONS.items():
        given = data.get(section, {})
        if not isinstance(given, Mapping):
            raise SceneError(f"[{section}] must be a table")
        for name in given:
            _split_key(f"{section}.{name}")
        values = {f.name: _check(section, f, given[f.name]) for f in dataclasses.fields(cls) if f.name in given}
        parts[section] = cls(**values)
    scene = Scene(**parts)
    if scene.rft.law == "table" and not scene.rft.table:
        raise SceneError("rft.law = 'table' needs rft.table, the path of a CSV with attack_deg, f_perp_N, f_par_N")
    return scene


def _read_toml(text: str, origin: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {exc}") from None


def preset(name: str) -> Scene:
    """A built-in scene by name (see PRESETS)."""
    if name not in PRESETS:
        raise SceneError(f"unknown preset '{name}': use one of {', '.join(PRESETS)}")
    text = (resources.files("finrft") / "presets" / f"{name}.toml").read_text()
    return scene_from_dict(_read_toml(text, f"preset {name}"))


def load_scene(path: str | Path | None = None, *, preset_name: str = "paper",
               overrides: Mapping[str, Any] | None = None) -> Scene:
    """A scene from a TOML file (or the named preset when no file is given), with dotted-key overrides applied.

    A relative ``rft.table`` path in a file is taken relative to that file.
    """
    if path is None:
        scene = preset(preset_name)
    else:
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise SceneError(f"cannot read scene file {path}: {exc.strerror}") from None
        data = _read_toml(text, str(path))
        table = data.get("rft", {}).get("table") if isinstance(data.get("rft"), dict) else None
        if isinstance(table, str) and table and not Path(table).is_absolute():
            data["rft"]["table"] = str(path.parent / table)
        scene = scene_from_dict(data)
    return scene.replace(**dict(overrides or {}))


def parse_override(text: str) -> tuple[str, Any]:
    """``plate.stiffness=0.3`` -> ("plate.stiffness", 0.3); the value is read as TOML, else as a bare string."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SceneError(f"--set expects KEY=VALUE, got '{text}'")
    _split_key(key)
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def to_toml(scene: Scene) -> str:
    """The full resolved scene as TOML, with units as comments, so a user can copy and edit it."""
    lines = ["# finrft scene: SI units throughout"]
    for section, cls in SECTIONS.items():
        lines += ["", f"[{section}]"]
        values = getattr(scene, section)
        for f in dataclasses.fields(cls):
            value = getattr(values, f.name)
            text = json.dumps(value) if isinstance(value, str) else repr(value)
            unit = f" [{f.metadata['unit']}]" if f.metadata["unit"] else ""
            lines.append(f"{f.name} = {text}  #{unit} {f.metadata['doc']}")
    return "\n".join(lines) + "\n"
