"""A field's unit, range and help live in its dataclass metadata (``schema.meta``), read by the schema's range
check, the panel (addon/fields.py) and the generated docs/config.md."""

from __future__ import annotations

import dataclasses
import importlib
import sys
import typing
from pathlib import Path

import pytest

from bpy_pipeline import config as cfg
from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.schema import UNITS, check_range, from_dict, meta, range_text, reference

ROOT = Path(__file__).resolve().parents[1]


def config_classes() -> list[type]:
    """The dataclasses config.py itself defines (the lidar and builder ones carry their own fields)."""
    return [v for v in vars(cfg).values() if isinstance(v, type) and dataclasses.is_dataclass(v) and v.__module__ == cfg.__name__]


def numeric(hint) -> bool:
    """A number, a tuple or list of numbers, or an optional one."""
    args = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
    return any(a in (int, float) or (typing.get_origin(a) in (tuple, list) and numeric(typing.get_args(a)[0])) for a in args)


def test_every_number_of_config_py_carries_its_unit():
    missing = []
    for cls in config_classes():
        hints = typing.get_type_hints(cls)
        missing += [f"{cls.__name__}.{f.name}" for f in dataclasses.fields(cls) if numeric(hints[f.name]) and f.metadata.get("unit") not in UNITS]
    assert not missing, f"numeric config fields without meta(unit=...): {missing}"
    assert len(config_classes()) >= 15


def nested_classes(cls, seen=None) -> list[type]:
    """``cls`` and every dataclass its fields hold (directly, optionally or in a list)."""
    seen = [] if seen is None else seen
    if cls in seen:
        return seen
    seen.append(cls)
    for hint in typing.get_type_hints(cls).values():
        for arg in [hint, *typing.get_args(hint)]:
            if isinstance(arg, type) and dataclasses.is_dataclass(arg):
                nested_classes(arg, seen)
    return seen


def test_every_number_of_a_builders_parameters_carries_its_unit():
    """The panel shows them: each one's unit comes from its metadata, never from its name."""
    from bpy_pipeline.builders import BUILDERS
    from bpy_pipeline.population.params import Population

    classes = [c for name, entry in BUILDERS.items() for c in nested_classes(entry.params)] + nested_classes(Population)
    # a Distribution's numbers take the unit of the field that holds it (a count, metres, degrees): not listed
    classes = [c for c in dict.fromkeys(classes) if c.__module__.startswith(("bpy_pipeline.builders", "bpy_pipeline.mixing.section"))]
    missing = []
    for cls in classes:
        hints = typing.get_type_hints(cls)
        missing += [
            f"{cls.__module__}.{cls.__name__}.{f.name}" for f in dataclasses.fields(cls) if numeric(hints[f.name]) and f.metadata.get("unit") not in UNITS
        ]
    assert not missing, f"numeric builder fields without meta(unit=...): {missing}"
    assert len(classes) >= 15


def test_every_number_the_panel_shows_of_the_lidar_sections_carries_its_unit():
    """Weather, materials, the reading model, car glass and paint, distributions and the drop MLP: the panel
    (addon/fields.py) has no name guessing left, so a number without metadata would be shown as a plain number."""
    from bpy_pipeline.lidar.effects.drop.mlp import MLP
    from bpy_pipeline.lidar.sensor.sensors import SensorSpec

    roots = [cfg.EffectsConfig, cfg.OutputConfig, cfg.SensorConfig, cfg.TrajectoryConfig, SensorSpec, MLP, *cfg.BUILDER_PARAMS.values()]
    classes = list(dict.fromkeys(c for root in roots for c in nested_classes(root)))
    missing = []
    for cls in classes:
        hints = typing.get_type_hints(cls)
        missing += [
            f"{cls.__module__}.{cls.__name__}.{f.name}" for f in dataclasses.fields(cls) if numeric(hints[f.name]) and f.metadata.get("unit") not in UNITS
        ]
    assert not missing, f"numeric fields without meta(unit=...): {missing}"
    assert len(classes) >= 40


def test_weather_and_materials_ranges_come_from_the_metadata():
    with pytest.raises(InputError, match=r"^effects\.weather\.fog\.backscatter: must lie in 0\.\.1 \(0 excluded\), got 0\.0$"):
        load_config(None, ["effects.weather.fog.backscatter=0"])
    with pytest.raises(InputError, match=r"^effects\.weather\.snow\.terminal_velocity: must lie in 0\.05\.\.10 m/s, got 20\.0$"):
        load_config(None, ["effects.weather.snow.terminal_velocity=20"])
    with pytest.raises(InputError, match=r"^effects\.materials\.retroreflector\.max_angle_deg: must lie in 1\.\.90 deg, got 0\.5$"):
        load_config(None, ["effects.materials.retroreflector.max_angle_deg=0.5"])


def test_a_value_outside_the_range_is_refused_naming_the_key_range_and_unit():
    with pytest.raises(InputError, match=r"^effects\.noise\.sigma: must be >= 0 m, got -0\.1$"):
        load_config(None, ["effects.noise.sigma=-0.1"])
    with pytest.raises(InputError, match=r"^effects\.mirrors\.normal_return_deg: must lie in 0\.\.90 deg \(90 excluded\), got 90\.0$"):
        load_config(None, ["effects.mirrors.normal_return_deg=90"])
    with pytest.raises(InputError, match=r"^output\.boxes\.occlusion_levels\[2\]: must lie in 0\.\.1, got -0\.1$"):
        load_config(None, ["output.boxes.occlusion_levels=[0.8, 0.4, -0.1]"])
    with pytest.raises(InputError, match=r"^effects\.intensity\.reference_range: must be > 0 m, got 0\.0$"):
        load_config(None, ["effects.intensity.reference_range=0"])
    edge = load_config(None, ["effects.mirrors.normal_return_deg=0", "effects.intensity.offset=0.5"])  # the ends that are allowed
    assert edge.effects.mirrors.normal_return_deg == 0.0 and edge.effects.intensity.offset == 0.5


def test_meta_range_words_and_bad_units():
    assert range_text(meta("", 0, 1)) == "0..1" and range_text(meta("m", low=0)) == ">= 0 m"
    assert range_text(meta("", 0, 1, low_open=True)) == "0..1 (0 excluded)" and range_text(meta("s")) == ""
    with pytest.raises(ValueError, match="unit 'metres'"):
        meta("metres")
    check_range(None, meta("m", low=0), "x")  # an optional value left out
    check_range(True, meta("", 0, 0), "x")  # booleans are not numbers here

    @dataclasses.dataclass(frozen=True)
    class Probe:
        size: tuple[float, float] = dataclasses.field(default=(1.0, 1.0), metadata=meta("m", low=0, low_open=True, help="edge lengths"))

    with pytest.raises(InputError, match=r"^probe\.size\[1\]: must be > 0 m, got 0\.0$"):
        from_dict(Probe, {"size": [1, 0]}, "probe")
    assert reference(Probe, "probe") == [("probe.size", "a list of 2 numbers", "[1.0, 1.0]", "m", "> 0 m", "edge lengths")]


def test_docs_config_md_is_the_generated_reference():
    assert (ROOT / "docs" / "config.md").read_text() == cfg.config_reference() + "\n", \
        "docs/config.md is stale: python -m bpy_pipeline config --reference > docs/config.md"


@pytest.fixture(scope="module")
def panel_fields(tmp_path_factory):
    """addon/fields.py imported as the extension imports it (a package beside its bpy_pipeline)."""
    pytest.importorskip("bpy")
    package = tmp_path_factory.mktemp("ext") / "panel_probe"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "fields.py").write_text((ROOT / "addon" / "fields.py").read_text())
    (package / "bpy_pipeline").symlink_to(ROOT / "bpy_pipeline")
    sys.path.insert(0, str(package.parent))
    try:
        yield importlib.import_module("panel_probe.fields")
    finally:
        sys.path.remove(str(package.parent))


def field_of(cls, name):
    return next(f for f in dataclasses.fields(cls) if f.name == name)


@pytest.mark.bpy
def test_the_panel_takes_units_from_the_metadata(panel_fields):
    assert panel_fields.unit_of(field_of(cfg.NoiseConfig, "sigma")) == "length"
    assert panel_fields.unit_of(field_of(cfg.NoiseConfig, "angular_jitter_deg")) == "angle"
    # "offset" is a length word for the name guess, but the intensity offset is a fraction: the metadata wins
    assert panel_fields.unit_of(field_of(cfg.IntensityConfig, "offset")) == ""
    assert panel_fields.unit_of(field_of(cfg.TrajectoryConfig, "start_time")) == ""
    from bpy_pipeline.lidar.effects.intensity import ReadingModel
    from bpy_pipeline.lidar.effects.materials import GlossyPaint
    from bpy_pipeline.lidar.effects.weather.fog import FogConfig

    assert panel_fields.unit_of(field_of(FogConfig, "visibility")) == "length"  # no length word in its name
    assert panel_fields.unit_of(field_of(FogConfig, "backscatter")) == ""
    assert panel_fields.unit_of(field_of(ReadingModel, "compensated_range")) == "length"
    assert panel_fields.unit_of(field_of(GlossyPaint, "lobe_deg")) == "angle"
    assert not hasattr(panel_fields, "LENGTH_WORDS")
    assert panel_fields.limits(field_of(cfg.MirrorConfig, "max_bounces")) == (0, 255)
    view = panel_fields.group_view(cfg.MirrorConfig, "PANEL_PROBE_mirrors", {"max_bounces": 3, "normal_return_deg": 0.5, "label": "target"})
    shown = {fv.attr: fv for fv in view.fields}
    assert shown["normal_return_deg"].unit == "angle" and shown["normal_return_deg"].soft == (0, 90)
    assert "normal incidence" in shown["normal_return_deg"].help
