"""Config: defaults, round trip, overrides, and one clear error per bad key."""

import pytest

from bpy_pipeline.config import config_from_dict, config_to_dict, load_config, read_config_file, save_config
from bpy_pipeline.errors import InputError


def test_defaults_round_trip(tmp_path):
    config = load_config()
    assert config.scene.builder == "railway"
    assert config_from_dict(config_to_dict(config)) == config
    save_config(config, tmp_path / "c.yaml")
    assert load_config(tmp_path / "c.yaml") == config


def test_stable_keys_of_design_work_as_written(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(
        """
seed: 7
frames: 2
scene:
  builder: primitives
  shapes:
    - {type: box, size: [1, 2, 3], position: [5, 0, 1], rotation_deg: [0, 0, 45], class: wall, material: mirror, reflectivity: 0.9}
    - {type: cylinder, size: [0.5, 2], position: [0, 5, 1], class: pillar}
sensor:
  preset: vlp16
  position: [0, 0, 1.5]
  rotation_deg: [0, 0, 90]
  max_range: 50
effects:
  noise: {sigma: 0.01}
  drop: {model: uniform, probability: 0.1}
  mirrors: {max_bounces: 2}
output:
  formats: [ply, semantickitti, las, npy]
  frame: world
"""
    )
    config = load_config(path)
    assert config.seed == 7 and config.frames == 2
    box = config.scene.params.shapes[0]
    assert box.size == [1.0, 2.0, 3.0] and box.class_name == "wall" and box.material == "mirror"
    assert config.sensor.spec.max_range == 50 and config.sensor.spec.channels == 16
    assert config.sensor.rotation_deg == (0.0, 0.0, 90.0)
    assert config.effects.drop.probability == 0.1 and config.output.frame == "world"
    assert config_from_dict(config_to_dict(config)) == config


def test_set_overrides_reach_nested_keys_and_list_items():
    config = load_config(None, ["scene.builder=primitives", "scene.shapes=[{type: sphere, size: 2}]", "scene.shapes.0.reflectivity=0.25",
                                "sensor.max_range=30"])
    assert config.scene.params.shapes[0].reflectivity == 0.25
    assert config.sensor.spec.max_range == 30.0


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["scene.gauge_width=1"], "scene.gauge_width"),
        (["frames=two"], "frames"),
        (["frames=0"], "frames"),
        (["sensor.min_range=200"], "sensor.min_range"),
        (["sensor.preset=hdl999"], "sensor.preset"),
        (["sensor.channels=1.5"], "sensor.channels"),
        (["sensor.position=[0, 0]"], "sensor.position"),
        (["effects.drop.model=magic"], "effects.drop.model"),
        (["effects.drop.probability=2"], "effects.drop.probability"),
        (["output.formats=[xyz]"], "output.formats[0]"),
        (["scene.builder=forest"], "scene.builder"),
        (["scene.builder=primitives", "scene.shapes=[{type: cone}]"], "scene.shapes[0].type"),
        (["scene.builder=primitives", "scene.shapes=[{type: box, size: [1, 2]}]"], "scene.shapes[0].size"),
        (["scene.builder=blend"], "scene.path"),
        (["labels.name_rules=[{match: '(', class: wall}]"], "labels.name_rules"),
        (["seed"], "--set 'seed'"),
    ],
)
def test_bad_values_name_their_key(overrides, key):
    from bpy_pipeline.labels import load_class_table, parse_rules

    with pytest.raises(InputError) as err:
        config = load_config(None, overrides)
        parse_rules(config.labels.name_rules, "labels.name_rules", load_class_table().names)
    message = str(err.value)
    assert message.startswith(key), message
    assert "\n" not in message


def test_missing_and_malformed_files_name_the_file(tmp_path):
    with pytest.raises(InputError, match="nope.yaml"):
        read_config_file(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: [unclosed\n")
    with pytest.raises(InputError, match=r"bad.yaml: not valid YAML at line"):
        read_config_file(bad)
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("42\n")
    with pytest.raises(InputError, match="scalar.yaml: expected a mapping"):
        read_config_file(scalar)


def test_optional_fields_take_null_and_name_it_in_errors():
    from dataclasses import dataclass

    from bpy_pipeline.errors import InputError
    from bpy_pipeline.schema import from_dict

    @dataclass(frozen=True)
    class Section:
        limit: float | None = 1.0

    assert from_dict(Section, {"limit": None}, "s").limit is None
    assert from_dict(Section, {"limit": 2}, "s").limit == 2.0
    with pytest.raises(InputError, match=r"s.limit: expected a number or null, got 'x'"):
        from_dict(Section, {"limit": "x"}, "s")
