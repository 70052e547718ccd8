"""Check plain data (parsed YAML) against frozen dataclasses, naming the key path on error.

``from_dict(cls, data, path)`` fills defaults from the dataclass, rejects unknown keys and
converts values by the field type hints (float, int, bool, str, Literal, unions, lists,
fixed-length tuples, nested dataclasses). A field may carry ``metadata={"key": "class"}`` to
be spelled differently in YAML than in Python.

A field's unit, allowed range and help live in its metadata, written with :func:`meta`
(``sigma: float = field(default=0.0, metadata=meta("m", low=0, help="along the beam"))``), and nowhere else:
:func:`from_dict` refuses a value outside the range (naming the key, the range and the unit) while it reads YAML,
:func:`check_ranges` refuses the same in a tree built or changed in Python (``bpy_pipeline.run`` checks the Config it
is given), the Blender panel takes the unit and soft limits (addon/fields.py), and :func:`reference` lists every field
for the generated docs/config.md. The sections' own checks keep only the rules a range cannot say (one field against
another, names, shapes, "0 or 1..100000").
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
import types
import typing
from typing import Literal

from .errors import InputError


def key_of(f: dataclasses.Field) -> str:
    return f.metadata.get("key", f.name)


# units a field's metadata may name; "" is a plain number (a ratio, a count, a probability)
UNITS = ("", "m", "deg", "s", "Hz", "m/s", "1/m", "px", "m^2", "mm/h", "ns")


def meta(unit: str = "", low: float | None = None, high: float | None = None, *, low_open: bool = False, high_open: bool = False,
         soft: tuple[float, float] | None = None, help: str = "", key: str | None = None) -> dict:
    """A field's metadata: ``unit`` (one of :data:`UNITS`), the allowed range ``low``..``high`` (either end
    ``None``: open-ended; ``low_open`` / ``high_open``: that end itself not allowed), ``soft`` the range the
    panel's slider offers, ``help`` one line for the panel's tooltip and the config reference, ``key`` the
    YAML spelling when it differs from the field's name. A tuple or list field's range holds for each item."""
    if unit not in UNITS:
        raise ValueError(f"unit {unit!r}: expected one of {UNITS}")
    out = {"unit": unit, "low": low, "high": high, "low_open": low_open, "high_open": high_open, "soft": soft, "help": help}
    if key is not None:
        out["key"] = key
    return out


def unit_of(f: dataclasses.Field) -> str | None:
    """The unit a field's metadata gives (``""``: a plain number), ``None`` when it carries no :func:`meta`."""
    return f.metadata.get("unit")


def range_text(m) -> str:
    """The allowed range of metadata ``m`` in words (``0..1``, ``>= 0 m``, ``0..90 deg (90 excluded)``)."""
    low, high, unit = m.get("low"), m.get("high"), m.get("unit", "")
    suffix = f" {unit}" if unit else ""
    if low is not None and high is not None:
        excluded = [str(v) for v, is_open in ((low, m.get("low_open")), (high, m.get("high_open"))) if is_open]
        return f"{low}..{high}{suffix}" + (f" ({' and '.join(excluded)} excluded)" if excluded else "")
    if low is not None:
        return f"{'>' if m.get('low_open') else '>='} {low}{suffix}"
    if high is not None:
        return f"{'<' if m.get('high_open') else '<='} {high}{suffix}"
    return ""


def check_range(value, m, path: str) -> None:
    """``InputError`` naming ``path`` when ``value`` (a number, or each number of a list or tuple) lies outside the
    range of metadata ``m``, or is no number at all (a field with a range holds numbers: a tree built in Python may
    hold anything)."""
    if value is None or isinstance(value, bool) or (m.get("low") is None and m.get("high") is None):
        return
    if hasattr(value, "tolist") and not isinstance(value, numbers.Real):  # a numpy array given in Python
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            check_range(v, m, f"{path}[{k}]")
        return
    if not isinstance(value, numbers.Real):
        raise InputError(f"{path}: expected a number, got {value!r}")
    low, high = m.get("low"), m.get("high")
    below = value != value or (low is not None and (value < low or (m.get("low_open") and value == low)))  # NaN lies in no range
    above = high is not None and (value > high or (m.get("high_open") and value == high))
    if below or above:
        verb = "lie in" if low is not None and high is not None else "be"
        raise InputError(f"{path}: must {verb} {range_text(m)}, got {value}")


def check_ranges(obj, path: str = "") -> None:
    """``InputError`` naming the key path of the first value of dataclass ``obj`` (and of the dataclasses it holds,
    directly or in a list or tuple) outside its field's metadata range: what :func:`from_dict` checks while it reads
    YAML, for a tree built or changed in Python. A field with ``metadata={"inline": True}`` (a section whose keys are
    written in its parent's mapping: ``scene``'s parameters, ``sensor``'s spec) adds no key to the path."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = path if f.metadata.get("inline") else _join(path, key_of(f))
        if _section(value):
            check_ranges(value, key)
        elif isinstance(value, (list, tuple)) and any(_section(v) or _named_section(v) for v in value):
            for k, item in enumerate(value):
                if _section(item):
                    check_ranges(item, f"{key}[{k}]")
                elif _named_section(item):  # (name, section): written under its name (scene.population.person)
                    check_ranges(item[1], _join(key, item[0]))
        else:
            check_range(value, f.metadata, key)


def _section(value) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _named_section(value) -> bool:
    return isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str) and _section(value[1])


def _type_name(hint) -> str:
    origin = typing.get_origin(hint)
    if origin is Literal:
        return " | ".join(repr(a) for a in typing.get_args(hint))
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(hint))
    if origin is list:
        item = _type_name(typing.get_args(hint)[0]).removeprefix("an ").removeprefix("a ")
        return f"a list of {item}s" if " " not in item else f"a list of ({item})"
    if origin is tuple:
        return f"a list of {len(typing.get_args(hint))} numbers"
    if dataclasses.is_dataclass(hint):
        return "a mapping"
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string", dict: "a mapping", type(None): "null"}.get(hint, str(hint))


def convert(value, hint, path: str):
    """Check ``value`` against the type ``hint`` and return it converted; ``InputError`` names ``path``."""
    origin = typing.get_origin(hint)
    wrong = InputError(f"{path}: expected {_type_name(hint)}, got {value!r}")
    if origin is Literal:
        if value not in typing.get_args(hint):
            raise wrong
        return value
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(hint):
            try:
                return convert(value, option, path)
            except InputError:
                continue
        raise wrong
    if origin is list:
        if not isinstance(value, (list, tuple)):
            raise wrong
        (item,) = typing.get_args(hint)
        return [convert(v, item, f"{path}[{i}]") for i, v in enumerate(value)]
    if origin is tuple:
        items = typing.get_args(hint)
        if not isinstance(value, (list, tuple)) or len(value) != len(items):
            raise wrong
        return tuple(convert(v, t, f"{path}[{i}]") for i, (v, t) in enumerate(zip(value, items)))
    if dataclasses.is_dataclass(hint):
        if isinstance(value, str) and hasattr(hint, "named"):  # a section given by a profile's name
            return hint.named(value, path)
        return from_dict(hint, value, path)
    if hint is float:
        if isinstance(value, str):  # YAML 1.1 reads 2e-3 (no dot) as a string
            try:
                value = float(value)
            except ValueError:
                raise wrong from None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value or abs(value) == float("inf"):
            raise wrong
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise wrong
        return value
    if hint in (bool, str, dict) and isinstance(value, hint):
        return value
    if hint is type(None) and value is None:  # `float | None` given as null
        return None
    raise wrong


@functools.lru_cache(maxsize=None)
def _hints(cls) -> dict:
    """``typing.get_type_hints(cls)``, once per class (it evaluates the annotations: about 1 ms a call)."""
    return typing.get_type_hints(cls)


def from_dict(cls, data, path: str = ""):
    """Build dataclass ``cls`` from a mapping, filling defaults; ``InputError`` naming the key path."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"{path or 'config'}: expected a mapping, got {data!r}")
    hints = _hints(cls)
    fields = {key_of(f): f for f in dataclasses.fields(cls)}
    unknown = sorted(set(map(str, data)) - set(fields))
    if unknown:
        raise InputError(f"{_join(path, unknown[0])}: unknown key; allowed: {', '.join(fields)}")
    kwargs = {}
    for k, f in fields.items():
        if k in data:
            kwargs[f.name] = convert(data[k], hints[f.name], _join(path, k))
            check_range(kwargs[f.name], f.metadata, _join(path, k))
    try:
        return cls(**kwargs)
    except TypeError as err:  # a required field is missing
        raise InputError(f"{path or 'config'}: {err}") from None


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else str(key)


def to_plain(value):
    """A dataclass (or anything inside one) as plain YAML data keyed as in YAML: the inverse of :func:`from_dict`."""
    if dataclasses.is_dataclass(value):
        return {key_of(f): to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value


def reference(cls, path: str = "") -> list[tuple[str, str, str, str, str, str]]:
    """``[(key path, type, default, unit, range, help)]`` of every field of dataclass ``cls`` and the
    dataclasses nested in it, as docs/config.md lists them (a field without :func:`meta` has empty unit,
    range and help)."""
    hints = _hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        key = _join(path, key_of(f))
        hint = hints[f.name]
        options = [a for a in typing.get_args(hint) if a is not type(None)] if typing.get_origin(hint) in (typing.Union, types.UnionType) else [hint]
        if len(options) == 1 and dataclasses.is_dataclass(options[0]):  # a section (or an optional one)
            rows += reference(options[0], key)
            continue
        if f.default is not dataclasses.MISSING:
            default = to_plain(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = to_plain(f.default_factory())
        else:
            default = "(required)"
        rows.append((key, _type_name(hint), repr(default) if isinstance(default, str) else str(default), f.metadata.get("unit", ""),
                     range_text(f.metadata), f.metadata.get("help", "")))
    return rows
