"""Check plain data (parsed YAML) against frozen dataclasses, naming the key path on error.

``from_dict(cls, data, path)`` fills defaults from the dataclass, rejects unknown keys and
converts values by the field type hints (float, int, bool, str, Literal, unions, lists,
fixed-length tuples, nested dataclasses). A field may carry ``metadata={"key": "class"}`` to
be spelled differently in YAML than in Python.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from typing import Literal

from .errors import InputError


def key_of(f: dataclasses.Field) -> str:
    return f.metadata.get("key", f.name)


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
    kwargs = {f.name: convert(data[k], hints[f.name], _join(path, k)) for k, f in fields.items() if k in data}
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


def check_positive(value: float, path: str, allow_zero: bool = False) -> None:
    """``InputError`` naming ``path`` unless ``value`` > 0 (>= 0 with ``allow_zero``)."""
    if value < 0 or (value == 0 and not allow_zero):
        raise InputError(f"{path}: must be {'>= 0' if allow_zero else '> 0'}, got {value}")
