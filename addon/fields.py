"""Config dataclasses seen as Blender properties: the panel is generated from the config's own fields.

A :class:`GroupView` walks a config dataclass (``config.RailwayScene``, ``config.EffectsConfig``,
...) and maps every field Blender can hold to a property of a generated ``PropertyGroup``:

==========================  ====================================
config type hint            Blender property
==========================  ====================================
``bool``                    ``BoolProperty``
``int`` / ``float``         ``IntProperty`` / ``FloatProperty``
``str``                     ``StringProperty``
``Literal[...]``            ``EnumProperty``
``list[Literal[...]]``      ``EnumProperty`` (``ENUM_FLAG``)
``tuple[float, ...]``       ``FloatVectorProperty``
``tuple[int, ...]``         ``IntVectorProperty``
a nested dataclass          ``PointerProperty`` to its own group
==========================  ====================================

Units come from the field's metadata (:func:`bpy_pipeline.schema.meta`, :func:`unit_of`): ``deg`` fields
are angles (subtype ``ANGLE``, ``EULER`` for a rotation vector: Blender shows degrees and stores radians;
:func:`read` and :func:`write` convert), ``m`` fields lengths (subtype ``DISTANCE``, ``TRANSLATION`` for a
3-vector) shown in the scene's length unit, and other 3-vectors carry X/Y/Z labels (``XYZ``). The
metadata's range sets the slider's soft limits and its help the tooltip; a field without metadata is a
plain number.

Anything else (lists of shapes, unions) is not shown and passes through untouched from the
config the panel was loaded from. Blender stores floats in 32 bits; :func:`read` hands back the
loaded config's exact value where the panel still shows it, and otherwise the shortest decimal
that gives the panel's float32, so a config survives panel -> YAML -> panel unchanged.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Literal

import bpy
import numpy as np

from .bpy_pipeline.errors import InputError
from .bpy_pipeline import schema
from .bpy_pipeline.schema import key_of

UNITS = {"hz": "Hz", "s": "s"}  # label suffixes; degrees and metres are shown by Blender's own units


def unit_of(f: dataclasses.Field) -> str:
    """``"angle"`` (degrees in the config), ``"length"`` (metres) or ``""`` for a config field, from its metadata's unit."""
    return {"deg": "angle", "m": "length"}.get(schema.unit_of(f), "")


@dataclass
class FieldView:
    """One config field shown in the panel: ``attr`` is the Blender property, ``key`` the YAML key."""

    attr: str
    key: str
    kind: str  # bool | int | float | str | enum | flags | vector | ivector | group
    items: tuple = ()  # enum identifiers
    size: int = 0  # vector length
    group: GroupView | None = None
    unit: str = ""  # "angle" (the property holds radians, the config degrees) | "length" | ""
    help: str = ""  # the tooltip (the field's metadata)
    soft: tuple = ()  # (low, high) of the slider in config units, from the metadata's soft limits or range; () none


@dataclass
class GroupView:
    """The shown fields of a config dataclass and the ``PropertyGroup`` class generated for them."""

    name: str
    fields: list[FieldView] = field(default_factory=list)
    property_group: type | None = None
    children: list[GroupView] = field(default_factory=list)

    def classes(self) -> list[type]:
        """Generated classes in registration order (nested groups first)."""
        return [c for child in self.children for c in child.classes()] + [self.property_group]


def label(attr: str) -> str:
    """``contact_wire_height`` -> ``Contact wire height``; ``rotation_deg`` -> ``Rotation`` (Blender shows °); ``rotation_hz`` -> ``Rotation (Hz)``."""
    words = attr.split("_")
    if len(words) > 1 and words[-1] == "deg":
        return " ".join(words[:-1]).capitalize()
    unit = UNITS.get(words[-1]) if len(words) > 1 else None
    text = " ".join(words[:-1] if unit else words).capitalize()
    return f"{text} ({unit})" if unit else text


def to_panel(view: FieldView, value):
    """A config value (degrees, metres) as the property holds it (radians for angles)."""
    if view.unit != "angle":
        return value
    if view.kind == "vector":
        return tuple(math.radians(float(v)) for v in value)
    return math.radians(float(value))


def _kind(hint) -> tuple[str, tuple, int] | None:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        return "bool", (), 0
    if hint in (int, float, str):
        return hint.__name__, (), 0
    if origin is Literal and all(isinstance(a, str) for a in args):
        return "enum", args, 0
    if origin is list and len(args) == 1 and typing.get_origin(args[0]) is Literal:
        return "flags", typing.get_args(args[0]), 0
    if origin is tuple and args and all(a is int for a in args):
        return "ivector", (), len(args)
    if origin is tuple and args and all(a in (int, float) for a in args):
        return "vector", (), len(args)
    if dataclasses.is_dataclass(hint):
        return "group", (), 0
    return None


def _fits(view: FieldView, default) -> bool:
    """Whether a property of ``view.kind`` can show ``default``."""
    number = isinstance(default, (int, float)) and not isinstance(default, bool)
    return {
        "bool": isinstance(default, bool),
        "int": number and isinstance(default, int),
        "float": number,
        "str": isinstance(default, str),
        "enum": default in view.items,
        "flags": isinstance(default, (list, tuple)) and set(default) <= set(view.items),
        "vector": isinstance(default, (list, tuple)) and len(default) == view.size,
        "ivector": isinstance(default, (list, tuple)) and len(default) == view.size and all(isinstance(v, int) and not isinstance(v, bool) for v in default),
        "group": isinstance(default, dict),
    }[view.kind]


def limits(f: dataclasses.Field) -> tuple:
    """``(low, high)`` the panel's slider offers for a field (its metadata's ``soft``, else its range), ``()`` when
    it gives neither end; an open end is the other's sign (0 or a huge value)."""
    m = f.metadata
    if m.get("soft"):
        return tuple(m["soft"])
    low, high = m.get("low"), m.get("high")
    if low is None and high is None:
        return ()
    return (-1e9 if low is None else low, 1e9 if high is None else high)


def _property(view: FieldView, default, update=None):
    name = label(view.attr)
    extra = {"update": update} if update is not None else {}
    if view.help:
        extra["description"] = view.help
    if view.soft and view.kind in ("int", "float", "vector", "ivector"):
        low, high = (to_panel(FieldView("", "", "float", unit=view.unit), float(v)) for v in view.soft)
        extra.update(soft_min=int(low) if view.kind in ("int", "ivector") else low, soft_max=int(high) if view.kind in ("int", "ivector") else high)
    if view.kind == "bool":
        return bpy.props.BoolProperty(name=name, default=bool(default), **extra)
    if view.kind == "int":
        return bpy.props.IntProperty(name=name, default=int(default), **extra)
    if view.kind == "float":
        subtype = {"angle": "ANGLE", "length": "DISTANCE"}.get(view.unit, "NONE")
        return bpy.props.FloatProperty(name=name, default=to_panel(view, float(default)), subtype=subtype, precision=3, step=1, **extra)
    if view.kind == "str":
        subtype = "FILE_PATH" if view.attr.endswith(("path", "file")) else "NONE"
        return bpy.props.StringProperty(name=name, default=str(default), subtype=subtype, **extra)
    items = [(v, v.replace("_", " ").capitalize(), "") for v in view.items]
    if view.kind == "enum":
        return bpy.props.EnumProperty(name=name, items=items, default=default, **extra)
    if view.kind == "flags":
        return bpy.props.EnumProperty(name=name, items=items, default=set(default), options={"ENUM_FLAG"}, **extra)
    if view.kind == "ivector":  # pixel sizes, counts: whole numbers, X/Y/Z labels for three
        return bpy.props.IntVectorProperty(name=name, size=view.size, default=tuple(int(v) for v in default), subtype="XYZ" if view.size == 3 else "NONE",
                                           **extra)
    if view.kind == "vector":
        if view.size == 3:  # X/Y/Z labels; EULER and TRANSLATION carry degrees and the length unit
            subtype, unit = {"angle": ("EULER", "ROTATION"), "length": ("TRANSLATION", "LENGTH")}.get(view.unit, ("XYZ", "NONE"))
        else:  # (min, max) pairs and the like: units, no component names
            subtype, unit = "NONE", {"angle": "ROTATION", "length": "LENGTH"}.get(view.unit, "NONE")
        default = to_panel(view, tuple(float(v) for v in default))
        return bpy.props.FloatVectorProperty(name=name, size=view.size, default=default, subtype=subtype, unit=unit, precision=3, **extra)
    return bpy.props.PointerProperty(type=view.group.property_group)


def group_view(cls, name: str, defaults: dict, only=None, skip=(), extra: dict | None = None) -> GroupView:
    """Generate the ``PropertyGroup`` class ``name`` for dataclass ``cls``.

    defaults : YAML key -> value, the values a fresh panel shows (the default config's)
    only, skip : field names to show (all representable fields when ``only`` is ``None``) or not
    extra : more annotations of the generated class (properties of the panel's own)
    """
    hints = typing.get_type_hints(cls)
    view = GroupView(name)
    annotations = dict(extra or {})
    for f in dataclasses.fields(cls):
        if (only is not None and f.name not in only) or f.name in skip:
            continue
        kind = _kind(hints[f.name])
        if kind is None or key_of(f) not in defaults:
            continue
        fv = FieldView(f.name, key_of(f), *kind)
        if fv.kind in ("float", "vector"):
            fv.unit = unit_of(f)
        fv.help, fv.soft = f.metadata.get("help", ""), limits(f)
        if not _fits(fv, defaults[fv.key]):
            continue  # e.g. an optional vector that is None by default: passes through, not shown
        if fv.kind == "group":
            fv.group = group_view(hints[f.name], f"{name}_{f.name}", defaults[fv.key])
            view.children.append(fv.group)
        view.fields.append(fv)
        annotations[fv.attr] = _property(fv, defaults[fv.key])
    view.property_group = type(name, (bpy.types.PropertyGroup,), {"__annotations__": annotations})
    return view


def exact_float(panel_value: float, loaded=None, angle: bool = False) -> float:
    """The config value for a float the panel shows: ``loaded`` when its float32 is the panel's, else the shortest decimal.

    angle : the panel holds radians and the config degrees
    """
    if isinstance(loaded, (int, float)) and not isinstance(loaded, bool):
        if np.float32(math.radians(loaded) if angle else loaded) == np.float32(panel_value):
            return float(loaded)
    return float(str(np.float32(math.degrees(panel_value) if angle else panel_value)))


def leaves(view: GroupView, prefix: str = "") -> list[str]:
    """Dotted YAML key paths of every shown field that is not a group (``track.start``, ``noise.sigma``)."""
    out = []
    for fv in view.fields:
        path = f"{prefix}{fv.key}"
        out += leaves(fv.group, f"{path}.") if fv.kind == "group" else [path]
    return out


def read(group, view: GroupView, base: dict) -> dict:
    """``base`` (plain config data) with the fields the panel shows replaced by the panel's values."""
    out = copy.deepcopy(base)
    for fv in view.fields:
        value, loaded = getattr(group, fv.attr), base.get(fv.key)
        if fv.kind == "float":
            value = exact_float(value, loaded, fv.unit == "angle")
        elif fv.kind == "vector":
            loaded = loaded if isinstance(loaded, (list, tuple)) and len(loaded) == fv.size else [None] * fv.size
            value = [exact_float(v, b, fv.unit == "angle") for v, b in zip(value, loaded)]
        elif fv.kind == "ivector":
            value = [int(v) for v in value]
        elif fv.kind == "flags":
            kept = [v for v in (loaded or []) if v in value]  # keep the loaded order of what is still ticked
            value = kept + [v for v in fv.items if v in value and v not in kept]
        elif fv.kind == "group":
            value = read(value, fv.group, loaded if isinstance(loaded, dict) else {})
        out[fv.key] = value
    return out


def write(group, view: GroupView, data: dict, where: str) -> None:
    """Show the plain config data ``data`` (validated already) in ``group``; ``where`` is its key path."""
    for fv in view.fields:
        if fv.key not in data:
            continue
        value = data[fv.key]
        if fv.kind == "group":
            write(getattr(group, fv.attr), fv.group, value, f"{where}.{fv.key}")
            continue
        if fv.kind == "flags":
            value = set(value)
        elif fv.kind == "vector":
            value = to_panel(fv, tuple(float(v) for v in value))
        elif fv.kind == "ivector":
            value = tuple(int(v) for v in value)
        elif fv.kind == "float":
            value = to_panel(fv, value)
        try:
            setattr(group, fv.attr, value)
        except (TypeError, ValueError, OverflowError) as err:
            raise InputError(f"{where}.{fv.key}: the panel cannot hold {value!r} ({err})") from None
