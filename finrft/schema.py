"""The schema engine: declared keys, validated values, TOML in and out. It knows no section: a scene is any frozen
dataclass whose fields are sections, each section a frozen dataclass whose fields are declared with `field` (a
default, a unit, a line of documentation, and the allowed values). `finrft.scene` declares the sections and the
scenes; each law declares its own keys (``KEYS`` in its module), from which the sections they belong to are built
(`section`).

Dotted keys name a section's entry: ``"plate.kind"``. A scene field typed ``tuple[Section, ...]`` is an array of
tables (TOML ``[[drive]]``): zero or more entries of one section, a single ``[drive]`` table read as one; its keys
are ``"drive.0.speed"`` (``"drive.speed"`` while it has at most one entry; an index one past the last adds an
entry). Every failure is a SceneError naming the key and what is allowed.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
import tomllib
import typing
from typing import Any, Callable, Iterable, Mapping

from .errors import SceneError

# One declared key of a section built from several declarations (`section`): its name, type and `field`.
Key = tuple[str, type, dataclasses.Field]


def field(default: Any, unit: str, doc: str, *, choices: tuple[str, ...] | Callable[[], tuple[str, ...]] = (),
          minimum: float | None = None, exclusive: bool = True, maximum: float | None = None,
          why_maximum: str = "", used_by: tuple[str, tuple[str, ...]] | None = None,
          least: float | None = None, why_least: str = "") -> Any:
    """A section's entry: its ``default``, its ``unit`` (SI, or the literature's where a key says so; "" when
    dimensionless or a name), one line ``doc``, and what values are allowed: ``choices`` (names, matched whatever
    their case; or a function giving them), a ``minimum`` (``exclusive`` or not) and a ``maximum`` with
    ``why_maximum``, the reason shown when it is exceeded; ``least``, the smallest magnitude a value other than 0
    may have, with ``why_least`` (a value below it is a slip of units, not a medium). ``used_by``: (the section's
    key that selects, the values that use this key), e.g. ``("kind", ("sine",))``: an entry whose selector is
    another value refuses this key at any value but its default (`unused`); a scene class's ``USED_BY`` gives such
    rules for a section it shares, their selector another section's key (`check_sections`)."""
    return dataclasses.field(default=default, metadata={"unit": unit, "doc": doc, "choices": choices,
                                                        "minimum": minimum, "exclusive": exclusive,
                                                        "maximum": maximum, "why_maximum": why_maximum,
                                                        "used_by": used_by, "least": least, "why_least": why_least})


def used_by(key: Key, selector: str, values: tuple[str, ...]) -> Key:
    """``key`` (a declaration, as a law's ``KEYS`` holds) used only where ``selector`` is one of ``values``."""
    name, kind, f = key
    return name, kind, field(f.default, **{**f.metadata, "used_by": (selector, tuple(values))})


# The units a value may be given in, as a suffix to its number ("90deg", "6e5 N/m3"): each unit's dimension and its
# size in SI. A key's value is converted to the key's own unit; a suffix of another dimension is refused. The one
# table of units of the schema, `--set`, the TOML and --bounds (`finrft.studies.bounds`).
UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0), "cm": ("length", 1e-2), "mm": ("length", 1e-3),
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180),
    "m/s": ("speed", 1.0), "mm/s": ("speed", 1e-3),
    "rad/s": ("angular speed", 1.0), "deg/s": ("angular speed", math.pi / 180),
    "s": ("time", 1.0), "ms": ("time", 1e-3), "Hz": ("frequency", 1.0),
    "kg": ("mass", 1.0), "g": ("mass", 1e-3), "N": ("force", 1.0),
    "N/m^3": ("stress per depth", 1.0), "N/m3": ("stress per depth", 1.0),
    "N/cm^3": ("stress per depth", 1e6), "N/cm3": ("stress per depth", 1e6),
    "kg/m^3": ("density", 1.0), "kg/m3": ("density", 1.0), "g/cm^3": ("density", 1e3), "g/cm3": ("density", 1e3),
}


def quantity(text: str, unit: str, where: str) -> float:
    """A number given as text, bare (in ``unit``, the key's) or with a unit suffix of `UNITS` (``"90deg"``,
    ``"6e5 N/m3"``), in ``unit``; SceneError beginning with ``where`` for text that is no number or a unit that is
    not one of ``unit`` ("m or rad": either)."""
    text = text.strip()
    suffix = next((s for s in sorted(UNITS, key=len, reverse=True)
                   if text.endswith(s) and is_number(text[:-len(s)])), None)
    try:
        number = float(text[:-len(suffix)] if suffix else text)
    except ValueError:
        raise SceneError(f"{where} must be a number ({unit or 'dimensionless'}), optionally with a unit such as "
                         f"{_examples(unit)}, got {text!r}") from None
    if suffix is None:
        return number
    fits = [u for u in unit.split(" or ") if u in UNITS and UNITS[u][0] == UNITS[suffix][0]]
    if not fits:
        raise SceneError(f"{suffix} is no unit of {where}, whose unit is {unit or 'none'}: give it in "
                         f"{unit or 'plain numbers'}" + (f", or e.g. {_examples(unit)}" if _examples(unit) else ""))
    return number * UNITS[suffix][1] / UNITS[fits[0]][1]


def is_number(text: str) -> bool:
    """Whether ``text`` is a plain number, without a unit."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _examples(unit: str) -> str:
    """The suffixes a key of ``unit`` takes, as "90deg, 1.5rad"."""
    dimensions = {UNITS[u][0] for u in unit.split(" or ") if u in UNITS}
    return ", ".join(s for s, (d, _) in UNITS.items() if d in dimensions)


def section(name: str, keys: Iterable[Key], module: str, doc: str) -> type:
    """A frozen section dataclass called ``name`` holding ``keys`` in order, defined in ``module`` (which must bind
    it to ``name``, for pickling). A key declared twice must be declared the same way (two laws may share a key,
    never disagree on it)."""
    seen: dict[str, Key] = {}
    for key in keys:
        if key[0] in seen and (seen[key[0]][1], seen[key[0]][2].default, seen[key[0]][2].metadata) != (
                key[1], key[2].default, key[2].metadata):
            raise TypeError(f"[{name}] key {key[0]!r} is declared twice, differently")
        seen.setdefault(key[0], key)
    cls = dataclasses.make_dataclass(name, list(seen.values()), frozen=True)
    cls.__module__, cls.__doc__ = module, doc
    return cls


@functools.cache
def sections(cls: type) -> dict[str, type]:
    """A scene class's sections and their types, in order (an array of tables: its entries' section)."""
    hints = typing.get_type_hints(cls)
    return {f.name: typing.get_args(hints[f.name])[0] if is_array(hints[f.name]) else hints[f.name]
            for f in dataclasses.fields(cls)}


def is_array(hint: Any) -> bool:
    """Whether a scene field's type is an array of tables, ``tuple[Section, ...]``."""
    return typing.get_origin(hint) is tuple


@functools.cache
def arrays(cls: type) -> frozenset[str]:
    """The sections of a scene class that are arrays of tables."""
    hints = typing.get_type_hints(cls)
    return frozenset(f.name for f in dataclasses.fields(cls) if is_array(hints[f.name]))


def split_key(cls: type, key: str) -> tuple[str, str]:
    """``"plate.kind"`` -> ("plate", "kind"), ``"drive.1.speed"`` -> ("drive", "speed"), or SceneError naming
    what exists."""
    return _split(cls, key)[::2]


def _split(cls: type, key: str) -> tuple[str, int | None, str]:
    """A dotted key's section, entry index (None: not an array of tables, or the index left out) and name."""
    known = sections(cls)
    section_name, _, name = key.partition(".")
    if section_name not in known or not name:
        raise SceneError(f"unknown scene key '{key}': keys look like SECTION.NAME with SECTION one of "
                         f"{', '.join(known)}")
    index = None
    if section_name in arrays(cls):
        first, dot, rest = name.partition(".")
        if first.isdigit() and dot:
            index, name = int(first), rest
    names = [f.name for f in dataclasses.fields(known[section_name])]
    if name not in names:
        raise SceneError(f"unknown scene key '{key}': [{section_name}] has {', '.join(names)}")
    return section_name, index, name


def field_of(cls: type, key: str) -> dataclasses.Field:
    """The schema entry of a dotted key (its type, unit, bounds)."""
    section_name, name = split_key(cls, key)
    return next(f for f in dataclasses.fields(sections(cls)[section_name]) if f.name == name)


def _number(key: str, value: Any, unit: str) -> float:
    """A finite number of ``unit`` (a string with a unit suffix converted); SceneError naming ``key`` otherwise."""
    if isinstance(value, str):
        value = quantity(value, unit, key)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy's scalars are numbers too
        raise SceneError(f"{key} must be a number ({unit or 'dimensionless'}), got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{key} must be finite, got {value!r}")
    return value


def check(section_name: str, f: dataclasses.Field, value: Any) -> Any:
    """``value`` for the entry ``f`` of a section, converted (an int for a float) and checked against its type,
    choices (the canonical spelling returned) and bounds; SceneError naming ``section_name.f.name`` otherwise."""
    key, meta = f"{section_name}.{f.name}", f.metadata
    if f.type in ("float", float):
        value = _number(key, value, meta["unit"])
    elif f.type in ("int", int):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise SceneError(f"{key} must be a whole number, got {value!r}")
        value = int(value)
    elif f.type in ("tuple[float, ...]", tuple[float, ...]):
        if not isinstance(value, (list, tuple)):
            raise SceneError(f"{key} must be a list of numbers ({meta['unit'] or 'dimensionless'}), e.g. [0, 0, 1], "
                             f"got {value!r}")
        return tuple(_number(key, v, meta["unit"]) for v in value)
    elif f.type == "tuple[str, ...]":
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v for v in value):
            raise SceneError(f"{key} must be a list of names, e.g. [\"box\"], got {value!r}")
        return tuple(value)
    elif not isinstance(value, str):
        raise SceneError(f"{key} must be a string, got {value!r}")
    choices = meta["choices"]() if callable(meta["choices"]) else meta["choices"]
    if choices:
        # Names match whatever their case, so MuJoCo's own spellings (Euler, RK4) name the schema's choices.
        canonical = {choice.lower(): choice for choice in choices}
        if value.lower() not in canonical:
            raise SceneError(f"{key} = {value!r} is not allowed: use one of {', '.join(choices)}")
        value = canonical[value.lower()]
    low = meta["minimum"]
    if low is not None and (value <= low if meta["exclusive"] else value < low):
        relation = ">" if meta["exclusive"] else ">="
        raise SceneError(f"{key} must be {relation} {low:g} {meta['unit']}".rstrip() + f", got {value!r}")
    high = meta["maximum"]
    if high is not None and value > high:
        raise SceneError(f"{key} must be <= {high:g} {meta['unit']}".rstrip() + f" ({meta['why_maximum']}), got "
                         f"{value!r}")
    least = meta.get("least")
    if least is not None and 0 < abs(value) < least:
        raise SceneError(f"{key} = {value:g} {meta['unit']} is implausibly small (|value| >= {least:g} "
                         f"{meta['unit']}, or 0: {meta['why_least']})")
    return value


def unused(where: str, entry: Any, default: Any, rules: Mapping[str, tuple] | None = None,
           scene: Any = None) -> None:
    """SceneError for a key of a section's ``entry`` (named ``where``) that its selector does not use (`field`'s
    ``used_by``, or ``rules``: the scene's own for a section it shares, `check_sections`) yet holds a value other
    than in ``default``, the scene's default section: a key given that would be silently ignored (a default, or a
    value set back to it, passes). A selector ``"section.key"`` is another section's key of ``scene``; a rule's
    third entry, keys of the selector's section that replace this key where any of them is given."""
    for f in dataclasses.fields(entry):
        rule = (rules or {}).get(f.name) or f.metadata.get("used_by")
        if rule is None or getattr(entry, f.name) == getattr(default, f.name):
            continue
        selector, values, *rest = rule
        owner_name, _, key = selector.rpartition(".")
        owner = getattr(scene, owner_name) if owner_name else entry
        chosen, shown = getattr(owner, key), selector if owner_name else f"{where}.{selector}"
        replacing = [k for k in (rest[0] if rest else ()) if getattr(owner, k) != next(
            g.default for g in dataclasses.fields(owner) if g.name == k)]
        if chosen in values and not replacing:
            continue
        if chosen in values:
            left = f"{owner_name}.{', '.join(rest[0])}" if owner_name else ", ".join(rest[0])
            raise SceneError(f"{where}.{f.name} is used by {selector} = {chosen!r} with {left} left out only, and "
                             f"this scene gives {owner_name + '.' if owner_name else ''}{replacing[0]}: leave "
                             f"{where}.{f.name} out, or leave {left} out to derive them from [{where}]")
        selector_default = next(g.default for g in dataclasses.fields(owner) if g.name == key)
        told = " (its default)" if chosen == selector_default else ""
        whose = "this scene's" if owner_name else "this entry's"
        raise SceneError(f"{where}.{f.name} is used by {selector} = {' or '.join(map(repr, values))} only, and "
                         f"{whose} {selector} is {chosen!r}{told}: set {shown}"
                         + (f" = {values[0]!r}" if len(values) == 1 else "") + f", or leave {f.name} out")


def check_sections(scene: Any) -> None:
    """Check a scene however it was made (``Scene(sim=Sim(dt=-1.0))`` as well as `from_dict`): each section of its
    declared class, each entry of its type, choices and bounds; the canonical values (a float for an int, a
    choice's spelling) are set in place. SceneError naming the key otherwise."""
    cls = type(scene)
    defaults = {f.name: f.default_factory for f in dataclasses.fields(cls)
                if f.default_factory is not dataclasses.MISSING}
    for section_name, section_cls in sections(cls).items():
        value = getattr(scene, section_name)
        if section_name in arrays(cls):
            if not isinstance(value, (tuple, list)):
                raise SceneError(f"[[{section_name}]] must be a tuple of {section_cls.__name__} entries, got "
                                 f"{type(value).__name__} {value!r:.60}")
            value = tuple(_checked(f"{section_name}.{i}", section_cls, entry, section_cls)
                          for i, entry in enumerate(value))
        else:
            value = _checked(section_name, section_cls, value, defaults.get(section_name, section_cls))
        object.__setattr__(scene, section_name, value)
    # A section two scenes share whose keys one of them reads only under another section's choice (a plate's
    # [medium] feeds its law's coefficients under one law alone, a robot's its arms and body too): the scene's own
    # rules, ``USED_BY`` of its class, {section: {key: rule}}, a rule as `field`'s ``used_by`` with a dotted selector.
    for section_name, rules in getattr(cls, "USED_BY", {}).items():
        unused(section_name, getattr(scene, section_name), defaults.get(section_name, sections(cls)[section_name])(),
               rules, scene)


def _checked(where: str, section_cls: type, value: Any, default: Callable[[], Any]) -> Any:
    """One section of a scene (or entry of an array of tables), its entries checked (`check`) and those its
    selectors do not use against the scene's ``default()`` section (`unused`)."""
    if type(value) is not section_cls:  # a subclass would carry keys the scene does not have
        raise SceneError(f"[{where}] must be a {section_cls.__name__} section, got {type(value).__name__} "
                         f"{value!r:.60}")
    changes = {}
    for f in dataclasses.fields(section_cls):
        given = getattr(value, f.name)
        canonical = check(where, f, given)
        if type(canonical) is not type(given) or canonical != given:
            changes[f.name] = canonical
    value = dataclasses.replace(value, **changes) if changes else value
    unused(where, value, default())
    return value


def from_dict(data: Mapping[str, Any], cls: type) -> Any:
    """Validate a nested mapping (as read from TOML) into a scene of class ``cls``; missing keys take the
    schema's defaults."""
    if not isinstance(data, Mapping):
        raise SceneError("a scene must be a table of sections")
    known = sections(cls)
    for section_name in data:
        if section_name not in known:
            raise SceneError(f"unknown scene section [{section_name}]: use {', '.join(known)}")
    defaults = cls()
    parts = {}
    for section_name, section_cls in known.items():
        if section_name in arrays(cls):
            given = data.get(section_name, ())
            entries = [given] if isinstance(given, Mapping) else given  # a single [drive] table: one entry
            if not isinstance(entries, (list, tuple)):
                raise SceneError(f"[[{section_name}]] must be an array of tables")
            parts[section_name] = tuple(_section(f"{section_name}.{i}", section_name, section_cls, entry,
                                                 section_cls()) for i, entry in enumerate(entries))
            continue
        parts[section_name] = _section(section_name, section_name, section_cls, data.get(section_name, {}),
                                       getattr(defaults, section_name))
    return cls(**parts)


def _section(where: str, section_name: str, section_cls: type, given: Any, default: Any) -> Any:
    """One validated section (or entry of an array of tables, named ``where`` in messages)."""
    if not isinstance(given, Mapping):
        raise SceneError(f"[{where}] must be a table")
    names = [f.name for f in dataclasses.fields(section_cls)]
    for name in given:
        if name not in names:
            raise SceneError(f"unknown scene key '{where}.{name}': [{section_name}] has {', '.join(names)}")
    return dataclasses.replace(default, **{f.name: check(where, f, given[f.name])
                                           for f in dataclasses.fields(section_cls) if f.name in given})


def updated(data: dict[str, dict[str, Any]], cls: type, updates: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """``data`` (a scene of class ``cls`` as nested dicts) with the dotted keys of ``updates`` set, in place; the
    keys are checked, the values are checked when the scene is validated (`from_dict`). A selector changed
    (``--set rft.law=table``) drops the keys of its section that the new choice does not use and ``updates`` do not
    set: they belonged to the choice it replaces (`unused`)."""
    for key, value in updates.items():
        section_name, index, name = _split(cls, key)
        if section_name not in arrays(cls):
            data[section_name][name] = value
            _drop_unused(data[section_name], sections(cls)[section_name], name, value, updates, f"{section_name}.")
            continue
        entries = data[section_name] = list(data[section_name])
        if index is None:
            if len(entries) > 1:
                raise SceneError(f"scene key '{key}': there are {len(entries)} [[{section_name}]] entries; name one "
                                 f"as {section_name}.N.{name} (N from 0)")
            index = 0
        if index > len(entries):
            raise SceneError(f"scene key '{key}': [[{section_name}]] has {len(entries)} entries; the next is "
                             f"{section_name}.{len(entries)}")
        if index == len(entries):
            entries.append({})
        entries[index] = {**entries[index], name: value}
        _drop_unused(entries[index], sections(cls)[section_name], name, value, updates,
                     (f"{section_name}.{index}.", f"{section_name}."))
    return data


def _drop_unused(entry: dict[str, Any], section_cls: type, selector: str, value: Any, updates: Mapping[str, Any],
                 prefixes: str | tuple[str, ...]) -> None:
    """Drop from ``entry`` the keys that ``selector`` set to ``value`` does not use, unless ``updates`` set them."""
    for f in dataclasses.fields(section_cls):
        rule = f.metadata.get("used_by")
        if rule and rule[0] == selector and str(value).lower() not in {v.lower() for v in rule[1]} and not any(
                f"{prefix}{f.name}" in updates for prefix in ((prefixes,) if isinstance(prefixes, str) else prefixes)):
            entry.pop(f.name, None)


def replace(scene: Any, updates: Mapping[str, Any]) -> Any:
    """A validated copy of ``scene`` with the dotted keys of ``updates`` changed."""
    return from_dict(updated(dataclasses.asdict(scene), type(scene), updates), type(scene))


def parse_override(text: str, cls: type) -> tuple[str, Any]:
    """``plate.stiffness=0.3`` -> ("plate.stiffness", 0.3); the value is read as TOML, else as a bare string."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SceneError(f"--set expects KEY=VALUE, got '{text}'")
    split_key(cls, key)
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def to_toml(scene: Any) -> str:
    """The full resolved scene as TOML, with units as comments, so a user can copy and edit it."""
    if not dataclasses.is_dataclass(scene) or isinstance(scene, type) or not all(
            dataclasses.is_dataclass(section) for section in sections(type(scene)).values()):
        raise SceneError(f"to_toml: a scene is written (finrft.Scene, RobotScene, ...), got {type(scene).__name__} "
                         f"{scene!r:.60}")
    lines = ["# finrft scene: each key's unit in brackets, SI but for medium.zeta (N/cm^3, the literature's); a value "
             "may carry a unit suffix: \"90deg\", \"5mm\""]
    many = arrays(type(scene))
    for section_name, cls in sections(type(scene)).items():
        entries = getattr(scene, section_name) if section_name in many else (getattr(scene, section_name),)
        if section_name in many and not entries:
            lines += ["", f"# [[{section_name}]]: none"]
        for values in entries:
            lines += ["", f"[[{section_name}]]" if section_name in many else f"[{section_name}]"]
            for f in dataclasses.fields(cls):
                value = getattr(values, f.name)
                text = json.dumps(list(value) if isinstance(value, tuple) else value) if isinstance(
                    value, (str, tuple)) else repr(value)
                unit = f" [{f.metadata['unit']}]" if f.metadata["unit"] else ""
                lines.append(f"{f.name} = {text}  #{unit} {f.metadata['doc']}")
    return "\n".join(lines) + "\n"
