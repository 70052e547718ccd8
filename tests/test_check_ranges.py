"""One source for a field's range: its metadata (``schema.meta``). ``from_dict`` checks it while reading YAML,
``check_ranges`` for a tree built or changed in Python (``bpy_pipeline.run`` checks the Config it is given), and the
sections' own checks keep only the rules a range cannot say."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

import bpy_pipeline as bp
from bpy_pipeline import config as cfg
from bpy_pipeline.builders import BUILDERS
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.effects.weather import RainConfig
from bpy_pipeline.population.params import KINDS, PersonPopulation, PlacementRules, Population, population_from_dict
from bpy_pipeline.schema import check_ranges, reference

ROOT = Path(__file__).resolve().parents[1]


def with_rain(config, rain: RainConfig):
    weather = dataclasses.replace(config.effects.weather, rain=rain)
    return dataclasses.replace(config, effects=dataclasses.replace(config.effects, weather=weather))


def test_a_config_built_in_python_is_refused_by_run_naming_the_key_as_yaml_does(tmp_path):
    config = with_rain(bp.load_config(None), RainConfig(rate=500.0))
    with pytest.raises(InputError) as api:
        bp.run(config, tmp_path / "out")  # refused before Blender: no bpy needed
    with pytest.raises(InputError) as yaml:
        bp.load_config(None, ["effects.weather.rain.rate=500"])
    assert str(api.value) == str(yaml.value) == "effects.weather.rain.rate: must lie in 0..300 mm/h, got 500.0"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("change, message", [
    (lambda c: dataclasses.replace(c, frames=0), "frames: must lie in 1..1000000000, got 0"),
    (lambda c: dataclasses.replace(c, sensor=dataclasses.replace(c.sensor, spec=dataclasses.replace(c.sensor.spec, rotation_hz=0.0))),
     "sensor.rotation_hz: must be > 0 Hz, got 0.0"),
    (lambda c: dataclasses.replace(c, scene=dataclasses.replace(c.scene, params=dataclasses.replace(
        c.scene.params, track=dataclasses.replace(c.scene.params.track, tracks=9)))), "scene.track.tracks: must lie in 1..5, got 9"),
    (lambda c: dataclasses.replace(c, limits=dataclasses.replace(c.limits, seconds=float("nan"))), "limits.seconds: must be > 0 s, got nan"),
    (lambda c: dataclasses.replace(c, output=dataclasses.replace(c.output, kitti=dataclasses.replace(
        c.output.kitti, camera=dataclasses.replace(c.output.kitti.camera, fov_deg="wide")))), "output.kitti.camera.fov_deg: expected a number, got 'wide'"),
])
def test_check_ranges_names_the_yaml_key_of_a_tree_built_in_python(change, message):
    config = bp.load_config(None)
    check_ranges(config)  # a loaded config passes
    with pytest.raises(InputError) as err:
        check_ranges(change(config))
    assert str(err.value) == message


def test_a_rig_member_and_a_population_kind_are_named_as_in_yaml():
    config = bp.load_config({"sensor": {"rig": [{"preset": "vlp16"}, {"preset": "vlp16", "position": [0, 0, 1]}]}})
    member = dataclasses.replace(config.sensor.rig[1], spec=dataclasses.replace(config.sensor.rig[1].spec, mount_height=-1.0))
    rig = dataclasses.replace(config.sensor, rig=(config.sensor.rig[0], member))
    with pytest.raises(InputError, match=r"^sensor\.rig\[1\]\.mount_height: must be >= 0 m, got -1\.0$"):
        check_ranges(dataclasses.replace(config, sensor=rig))
    population = population_from_dict({"person": {"count": 2}})
    bad = Population((("person", dataclasses.replace(PersonPopulation(), reflectivity=(0.1, 1.5))),), population.placement)
    with pytest.raises(InputError, match=r"^scene\.population\.person\.reflectivity\[1\]: must lie in 0\.\.1, got 1\.5$"):
        check_ranges(bad, "scene.population")


# ----------------------------------------------------------------------------- no hand check repeats a range
# the modules whose sections' checks were cleaned, each with the config sections it checks: a hand-written "must lie in /
# must be >= ..." for a key of those sections whose field carries a range would say the range a second time
CLEANED = {
    "bpy_pipeline/config.py": "", "bpy_pipeline/io/splits.py": "output.", "bpy_pipeline/io/formats.py": "output.",
    "bpy_pipeline/mixing/paint.py": "scene.car_paint.", "bpy_pipeline/population/params.py": "scene.population.",
    "bpy_pipeline/lidar/sensor/sensors.py": "sensor.", "bpy_pipeline/lidar/sensor/mirror_sensor.py": "sensor.reflector.",
    **{str(p.relative_to(ROOT)): "sensor." for p in (ROOT / "bpy_pipeline/lidar/sensor/patterns").glob("*.py")},
    **{str(p.relative_to(ROOT)): "effects." for p in (ROOT / "bpy_pipeline/lidar/effects").rglob("*.py")},
    "bpy_pipeline/lidar/effects/divergence.py": "sensor.divergence.", "bpy_pipeline/lidar/effects/materials.py": "",
    **{str(p.relative_to(ROOT)): "scene." for p in (ROOT / "bpy_pipeline/builders").glob("*/params.py")},
    "bpy_pipeline/builders/railway/layout.py": "scene.", "bpy_pipeline/builders/railway/assets.py": "scene.",
    "bpy_pipeline/geometry/placement.py": "scene.",
}
# "<key>: must lie in", "must be >= 0", "must be in 0..1", "must be a number in", "must be 1 .. 5"; the key as written in
# the message: a literal path, or its tail after a placeholder ("{where}.rate" -> ".rate")
RANGE_WORDING = re.compile(r"""(?:\}|["'])([\w.\[\]]*\.?[\w]+): (?:must (?:lie in|be (?:in |a number in |[<>]=? ?-?\d|\d+ \.\.))|at least \d|at most \d)""")
POSITIVE_CALL = re.compile(r"""_positive\([^,]+, f?["'](?:\{\w+\})?([\w.]+)["']""")


def ranged_keys() -> set[str]:
    """Every config key (as YAML writes it) whose field's metadata gives a range."""
    roots = [("", cfg.Config), ("sensor", cfg.SensorSpec), ("scene.population.placement", PlacementRules)]
    roots += [("scene", entry.params) for _, entry in BUILDERS.items()]
    roots += [(f"scene.population.{name}", kind.params) for name, kind in KINDS.items()]
    return {row[0] for section, cls in roots for row in reference(cls, section) if row[4]}


def repeated_ranges(sources: dict[str, tuple[str, str]], keys: set[str]) -> list[str]:
    """``sources``: name -> (text, the key prefix of the sections it checks)."""
    found = []
    for name, (text, prefix) in sources.items():
        for pattern in (RANGE_WORDING, POSITIVE_CALL):
            for match in pattern.finditer(text):
                written = match.group(1)
                hits = [k for k in keys if k.startswith(prefix) and (k == written or (written.startswith(".") and k.endswith(written)))]
                if hits:
                    found.append(f"{name}: {match.group(0)!r} repeats the range of {hits[0]}")
    return found


def test_no_hand_check_in_the_cleaned_modules_repeats_a_metadata_range():
    keys = ranged_keys()
    assert {"effects.weather.rain.rate", "scene.track.gauge", "sensor.rotation_hz", "frames", "scene.population.placement.min_visible"} <= keys
    sources = {name: ((ROOT / name).read_text(), prefix) for name, prefix in CLEANED.items()}
    assert not repeated_ranges(sources, keys)


def test_the_repeat_finder_finds_the_hand_checks_that_were_removed():
    """The test above can fail: the checks this change removed are found by it."""
    keys = ranged_keys()
    removed = {
        "rain.py": ('raise InputError(f"{where}.rate: must lie in 0..{MAX_RAIN:g} mm/h, got {rain.rate}")', "effects."),
        "layout.py": ('_positive(detail.stone_size, f"{where}.detail.stone_size")', "scene."),
        "config.py": ('raise InputError(f"seed: must be >= 0, got {config.seed}")', ""),
        "street.py": ('raise InputError(f"{where}.yard_tree_clearance: at least 0.5 m (a trunk\'s width), got {params.yard_tree_clearance}")', "scene."),
    }
    found = repeated_ranges(removed, keys)
    assert [line.split(":")[0] for line in found] == ["rain.py", "layout.py", "config.py", "street.py"], found
    kept = {"sensors.py": ('raise InputError(f"{where}.min_range: must be >= 0 and below {where}.max_range")', "sensor."),  # two fields' rule
            "real_scan.py": ('raise InputError(f"{where}.kitti_rule.min_range: must be 0 .. kitti_rule.max_range ({rule.max_range:g})")', "scene.")}
    assert not repeated_ranges(kept, keys)


def test_numpy_numbers_and_arrays_built_in_python_are_numbers():
    import numpy as np

    from bpy_pipeline.builders.street.params import StreetScene

    check_ranges(dataclasses.replace(StreetScene(), lanes_per_direction=np.int64(2), setback=np.array([0.0, 8.0])), "scene")
    with pytest.raises(InputError, match=r"^scene\.setback\[0\]: must be >= 0 m, got -1\.0$"):
        check_ranges(dataclasses.replace(StreetScene(), setback=np.array([-1.0, 8.0])), "scene")
