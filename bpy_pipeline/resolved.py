"""The resolved config with the source of every value (``bpy-pipeline config --resolved``), as Hydra's ``--cfg job``.

Where a value comes from, lowest first (a later source replaces an earlier one, key by key):

1. ``default``: the config's dataclasses (:mod:`bpy_pipeline.config`), and ``DEFAULT_SENSOR`` when
   neither the config nor the builder names a sensor preset;
2. ``preset NAME``: the sensor preset's fields (``lidar/sensor/sensors.yaml``);
3. ``builder NAME``: the builder's own sensor (``Builder.sensor``: it names the preset, and its fields
   refine it), used only when the config names no preset;
4. ``profile NAME``: the preset's effects profile (noise, drop, intensity), unless ``effects.ideal``;
5. ``config``: the config file;
6. ``--set``: the command line's overrides.

A value no source names (a field derived from others, ``columns`` from the resolution, say) is
``derived``. Pure: nothing here builds or scans.
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import yaml

from .builders.base import BUILDERS
from .config import DEFAULT_SENSOR, apply_override, config_from_dict, config_to_dict, read_config_file
from .lidar.sensor.sensors import SensorSpec, preset_effects, presets
from .schema import to_plain

PRECEDENCE = ("default", "preset", "builder", "profile", "config", "--set")


def _has(tree, path: tuple) -> bool:
    for key in path:
        if not isinstance(tree, dict) or key not in tree:
            return False
        tree = tree[key]
    return True


def _leaves(tree, path: tuple = ()):
    if isinstance(tree, dict) and tree:
        for key, value in tree.items():
            yield from _leaves(value, path + (key,))
    else:
        yield path, tree


def resolved(path: str | Path | None = None, overrides: list[str] = ()) -> tuple[dict, dict[tuple, str]]:
    """``(tree, sources)``: the resolved config of the file ``path`` (``None``: the defaults) with ``overrides``
    (``key.path=value``) as plain data, and ``{key path: source}`` for every leaf (see the module docstring)."""
    given = read_config_file(path) if path else {}
    on_line: dict = {}
    data = copy.deepcopy(given)
    for assignment in overrides:
        apply_override(on_line, assignment)
        apply_override(data, assignment)
    config = config_from_dict(data)
    tree = config_to_dict(config)
    builder_name = config.scene.builder
    builder_sensor = BUILDERS.get(builder_name).sensor
    builder_output = BUILDERS.get(builder_name).output
    output_from_builder = builder_output(config.scene.params) if builder_output is not None else {}
    named = _has(given, ("sensor", "preset")) or _has(on_line, ("sensor", "preset"))
    from_builder = builder_sensor if not named else {}
    preset = config.sensor.spec.name
    preset_fields = presets().get(preset, {})
    default_sensor = DEFAULT_SENSOR if not named and "preset" not in from_builder else {}
    profile = {} if config.effects.ideal else preset_effects(preset)
    sources: dict[tuple, str] = {}
    spec_defaults = _spec_defaults()
    for key, value in _leaves(tree):
        rest = key[1:]
        if _has(on_line, key):
            source = "--set"
        elif _has(given, key):
            source = "config"
        elif key[0] == "effects" and _has(profile, rest):
            source = f"profile {preset}"
        elif key[0] == "output" and _has(output_from_builder, rest):
            source = f"builder {builder_name}"
        elif key[0] == "sensor" and _has(from_builder, rest):
            source = f"builder {builder_name}"
        elif key[0] == "sensor" and _has(default_sensor, rest):
            source = "default"
        elif key[0] == "sensor" and _has(preset_fields, rest):
            source = f"preset {preset}"
        elif key[0] == "sensor" and len(rest) == 1 and rest[0] in spec_defaults:
            source = "default" if _same(spec_defaults[rest[0]], value) else "derived"
        else:
            source = "default"
        sources[key] = source
    return tree, sources


def _spec_defaults() -> dict:
    """SensorSpec field -> its default, as plain data."""
    out = {}
    for f in dataclasses.fields(SensorSpec):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def _same(a, b) -> bool:
    return to_plain(a) == to_plain(b)


def render(tree: dict, sources: dict[tuple, str]) -> str:
    """The tree as YAML, each leaf followed by ``# source``."""
    lines = []

    def walk(node, path: tuple, indent: int):
        for key, value in node.items():
            here = path + (key,)
            pad = "  " * indent
            if isinstance(value, dict) and value:
                lines.append(f"{pad}{key}:")
                walk(value, here, indent + 1)
            else:
                text = yaml.safe_dump(value, default_flow_style=True, width=10**9).strip()
                if text.endswith("\n...") or text.endswith("..."):
                    text = text.removesuffix("...").strip()
                lines.append(f"{pad}{key}: {text}  # {sources.get(here, 'default')}")

    walk(tree, (), 0)
    return "\n".join(lines) + "\n"
