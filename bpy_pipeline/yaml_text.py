"""YAML text to Python values, through libyaml's parser when PyYAML was built with it.

``load_yaml(text)`` gives the values ``yaml.safe_load(text)`` gives (the same safe resolver), about
ten times faster: the product's label table, sensor presets and class maps are parsed at every start,
and with the pure-Python parser that alone took a second of a one-frame run.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from .errors import InputError

SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser when present, else PyYAML's own


def load_yaml(text: str):
    """The Python value of YAML ``text`` (mappings, lists, str, int, float, bool, None; safe tags only)."""
    return yaml.load(text, Loader=SAFE_LOADER)


# The one guard every YAML file a user gives goes through (configs, --set values, fit's model files, arm models):
MAX_BYTES = 16 << 20  # a file larger than this is refused before it is parsed
MAX_DEPTH = 64  # nesting of mappings and lists (the deepest real config is under 10)
MAX_VALUES = 100_000  # scalars, keys included, once aliases are expanded; parsing 100,000 takes seconds


def check_yaml_size(text: str, where: str) -> None:
    """``InputError`` when the YAML ``text`` nests mappings and lists deeper than :data:`MAX_DEPTH` or holds more
    than :data:`MAX_VALUES` scalars once its aliases are expanded (read as events, without building the tree:
    PyYAML's tree builder recurses, and builds a large tree slowly; an alias counts the values of its anchor, so
    nine levels of ten aliases each count 10**9, not 90)."""
    depth = values = 0
    anchors: dict[str, int] = {}  # anchor -> the values it expands to
    opened: list[tuple[str | None, int]] = []  # the open collections: (anchor, values before it)

    def count(n: int) -> None:
        nonlocal values
        values += n
        if values > MAX_VALUES:
            raise InputError(
                f"{where}: holds more than {MAX_VALUES:,} values (aliases expanded), not a config (a scene of more objects belongs in a .blend or mesh file)"
            )

    for event in yaml.parse(text, Loader=SAFE_LOADER):
        if isinstance(event, yaml.ScalarEvent):
            count(1)
            if event.anchor:
                anchors[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            count(anchors.get(event.anchor, 1))
        elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                raise InputError(f"{where}: nested deeper than {MAX_DEPTH} levels, not a config")
            opened.append((event.anchor, values))
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
            anchor, before = opened.pop()
            if anchor:
                anchors[anchor] = max(values - before, 1)


def read_yaml_text(text: str, where: str):
    """The value of a user's YAML ``text`` through the guard (:func:`check_yaml_size`); ``yaml.YAMLError`` as PyYAML raises it."""
    check_yaml_size(text, where)
    return load_yaml(text)


def read_yaml_file(path: str | Path, what: str = "config file"):
    """The value of a user's YAML file, read through the guard: at most :data:`MAX_BYTES` read (``/dev/zero`` or a
    huge file is refused, not read for ever), UTF-8, :func:`check_yaml_size`; ``InputError`` naming the file."""
    path = Path(path)
    try:
        if path.is_dir():
            raise InputError(f"{path}: is a folder, not a {what}")
        with open(path, "rb") as handle:
            raw = handle.read(MAX_BYTES + 1)
        if len(raw) > MAX_BYTES:
            raise InputError(f"{path}: larger than {MAX_BYTES >> 20} MB, not a {what}")
        text = raw.decode("utf-8")
    except OSError as err:
        raise InputError(f"{path}: cannot read the {what} ({err.strerror or err})") from None
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not UTF-8 text (byte {err.start}); save the {what} as UTF-8 YAML") from None
    try:
        return read_yaml_text(text, str(path))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        raise InputError(f"{path}: not valid YAML{f' at line {mark.line + 1}' if mark else ''}") from None
