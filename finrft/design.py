"""Design keys: edits of a user's MJCF model by name, made on its MjSpec before it compiles, in the scene keys'
vocabulary. ``model.geom.fin.size.0`` is the first size of the geom named fin, ``model.body.leg.pos.2`` the height
of body leg, ``model.joint.hip.stiffness`` a joint's stiffness, ``model.actuator.j1.kp`` a position servo's gain.
They go wherever scene keys go (``--set``, ``--bounds``, ``--grid``, `UserScene.replace`), and a scene holds them
in ``model.design`` (``["geom.fin.size.0=0.02", ...]``), so its TOML and its HDF5 carry the model it ran.

The grammar is checked with the scene; the names and indices against the model as it is read (`apply`), before
anything runs: each failure is one SceneError naming the key and what the model has.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import SceneError

# The kinds of MJCF element a design key may edit, as MjSpec names them (spec.geom(name), spec.geoms).
KINDS = ("body", "geom", "joint", "actuator", "site", "tendon")
# The SI unit of an attribute, where it has one whatever the element (a key's --bounds may then carry mm, g, deg).
UNITS = {"size": "m", "pos": "m", "fromto": "m", "mass": "kg", "ipos": "m", "margin": "m", "gap": "m",
         "width": "m"}
# Attributes in m on a slide joint and in rad on a hinge: the key alone does not say which, so they take plain SI
# numbers, never a unit suffix (20mm on a hinge would be 0.02 rad).
JOINT_UNIT = ("range", "springref", "ref")
# Array attributes that MJCF writes as one number (MuJoCo 4 keeps polynomial terms after it): no index is the first.
FIRST = {("joint", "stiffness"), ("joint", "damping"), ("tendon", "stiffness"), ("tendon", "damping")}


def is_key(key: str) -> bool:
    """Whether a dotted scene key is a design key, ``model.KIND.NAME.ATTRIBUTE[.INDEX]``."""
    parts = key.split(".")
    return len(parts) >= 4 and parts[0] == "model" and parts[1] in KINDS


def parse(key: str) -> tuple[str, str, str, int | None]:
    """A design key (with or without its ``model.`` prefix) as (kind, name, attribute, index or None);
    SceneError for one that is not so. A name may hold dots: the attribute is the last word but an index."""
    where = key if key.startswith("model.") else f"model.{key}"
    parts = where.split(".")[1:]
    index = None
    if len(parts) >= 4 and parts[-1].isdigit():
        index = int(parts.pop())
    if len(parts) < 3 or parts[0] not in KINDS or not all(parts):
        raise SceneError(f"design key '{where}' must look like model.KIND.NAME.ATTRIBUTE or "
                         f"model.KIND.NAME.ATTRIBUTE.INDEX, KIND one of {', '.join(KINDS)} (e.g. "
                         f"model.geom.fin.size.0)")
    return parts[0], ".".join(parts[1:-1]), parts[-1], index


def unit(key: str) -> str:
    """A design key's SI unit where its attribute has one ("" otherwise: SI, whatever the element's)."""
    kind, _, attribute, _ = parse(key)
    if kind == "actuator":
        return ""
    return UNITS.get(attribute, "")


def entries(design: tuple[str, ...]) -> dict[str, float]:
    """A scene's ``model.design`` as {key without "model.": value}; SceneError for an entry that is not
    KEY=NUMBER."""
    out: dict[str, float] = {}
    for entry in design:
        key, sep, text = entry.partition("=")
        key = key.strip().removeprefix("model.")
        parse(key)
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not math.isfinite(value):
            raise SceneError(f"model.design entry {entry!r} must be KEY=NUMBER, e.g. \"geom.fin.size.0=0.02\"")
        if key in out:
            raise SceneError(f"model.design sets {key} twice: give each design key once")
        out[key] = value
    return out


def merged(design: tuple[str, ...], updates: dict[str, float]) -> tuple[str, ...]:
    """``model.design`` with ``updates`` (design keys, "model." prefix or not) set, in the order first given."""
    values = entries(design)
    for key, value in updates.items():
        values[key.removeprefix("model.")] = value
    return tuple(f"{key}={value!r}" for key, value in values.items())


def _element(spec: Any, kind: str, name: str, where: str) -> Any:
    element = getattr(spec, kind)(name)
    if element is None:
        names = [e.name for e in getattr(spec, f"{kind}s") if e.name]
        raise SceneError(f"{where}: the model has no {kind} named {name!r} (its {kind}s: "
                         f"{', '.join(names[:12]) + (', ...' if len(names) > 12 else '') or 'none named'})")
    return element


def _numeric(element: Any) -> list[str]:
    names = []
    for attr in dir(element):
        if attr.startswith("_"):
            continue
        value = getattr(element, attr, None)
        if isinstance(value, float) or (isinstance(value, np.ndarray) and value.dtype.kind == "f"):
            names.append(attr)
    return names


def apply(spec: Any, design: tuple[str, ...]) -> None:
    """Make a scene's ``model.design`` edits on ``spec`` (an MjSpec, before it compiles); SceneError naming the
    key for a name the model does not have, an attribute that is not a number or an array of them, or an index
    outside its array. ``kp`` and ``kv`` of an actuator are its position servo's gains (gainprm[0] and
    -biasprm[1], -biasprm[2]); ``kv`` of a velocity servo is its gain (gainprm[0] and -biasprm[2])."""
    for key, value in entries(design).items():
        element, attribute, index = _target(spec, key)
        if _servo_gain(key):
            gains, biases = element.gainprm, element.biasprm
            if attribute == "kp":
                gains[0], biases[1] = value, -value
            else:
                if _velocity_servo(element):
                    gains[0] = value
                biases[2] = -value
            element.gainprm, element.biasprm = gains, biases
        elif index is None:
            setattr(element, attribute, value)
        else:
            current = getattr(element, attribute)
            flat = current.ravel().copy()
            flat[index] = value
            setattr(element, attribute, flat.reshape(current.shape))


def current(spec: Any, key: str) -> float:
    """The model's own value of a design key (SceneError as `apply`)."""
    key = key.removeprefix("model.")
    element, attribute, index = _target(spec, key)
    if _servo_gain(key):
        return float(element.gainprm[0] if attribute == "kp" else -element.biasprm[2])
    value = getattr(element, attribute)
    return float(value if index is None else value.ravel()[index])


def _servo_gain(key: str) -> bool:
    kind, _, attribute, _ = parse(key)
    return kind == "actuator" and attribute in ("kp", "kv")


def _target(spec: Any, key: str) -> tuple[Any, str, int | None]:
    """The element a design key edits, its attribute and the index in it (None: a number)."""
    kind, name, attribute, index = parse(key)
    where = f"model.{key}"
    element = _element(spec, kind, name, where)
    if _servo_gain(key):
        _check_servo(element, attribute, index, where)
        return element, attribute, None
    current = getattr(element, attribute, None) if not attribute.startswith("_") else None
    if isinstance(current, np.ndarray) and current.dtype.kind == "f":
        if index is None and (kind, attribute) in FIRST:
            index = 0
        if index is None or not 0 <= index < current.size:
            raise SceneError(f"{where}: {kind} {name!r}'s {attribute} holds {current.size} numbers: give an "
                             f"index from 0 to {current.size - 1}, as model.{kind}.{name}.{attribute}.0")
        return element, attribute, index
    if isinstance(current, float):
        if index is not None:
            raise SceneError(f"{where}: {kind} {name!r}'s {attribute} is one number: leave the index out, as "
                             f"model.{kind}.{name}.{attribute}")
        return element, attribute, None
    raise SceneError(f"{where}: a {kind} has no numeric attribute {attribute!r} (its numbers: "
                     f"{', '.join(_numeric(element))}{', kp, kv' if kind == 'actuator' else ''})")


def _check_servo(actuator: Any, gain: str, index: int | None, where: str) -> None:
    """SceneError unless ``actuator`` is a position servo (kp: gainprm[0] = -biasprm[1]; kv: -biasprm[2])."""
    import mujoco
    if index is not None:
        raise SceneError(f"{where}: {gain} is one number: leave the index out")
    position = actuator.biastype == mujoco.mjtBias.mjBIAS_AFFINE and actuator.biasprm[1] == -actuator.gainprm[0]
    if not (position or (gain == "kv" and _velocity_servo(actuator))):
        raise SceneError(f"{where}: actuator {actuator.name!r} is not a position servo (<position>)"
                         f"{' nor a velocity servo (<velocity>)' if gain == 'kv' else ''}: {gain} is a servo's gain; "
                         f"set its gainprm and biasprm instead (model.actuator.NAME.gainprm.0)")


def _velocity_servo(actuator: Any) -> bool:
    """A <velocity> actuator: force kv (ctrl - qdot), gainprm[0] = kv = -biasprm[2], no position term."""
    import mujoco
    return (actuator.biastype == mujoco.mjtBias.mjBIAS_AFFINE and actuator.biasprm[1] == 0
            and actuator.gainprm[0] > 0 and actuator.biasprm[2] == -actuator.gainprm[0])
