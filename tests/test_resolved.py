"""``bpy-pipeline config --resolved``: the resolved tree with the source of every value, one documented precedence."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from bpy_pipeline.config import config_to_dict, load_config
from bpy_pipeline.resolved import PRECEDENCE, render, resolved

ROOT = Path(__file__).resolve().parents[1]


def test_each_value_names_its_source_and_the_later_source_wins(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump({"seed": 3, "scene": {"builder": "parking"}, "effects": {"noise": {"sigma": 0.01}}}))
    tree, sources = resolved(path, ["seed=5", "sensor.rotation_hz=10"])
    assert tree == config_to_dict(load_config(path, ["seed=5", "sensor.rotation_hz=10"]))  # the tree a run resolves
    assert tree["seed"] == 5 and sources[("seed",)] == "--set"  # --set over the file
    assert sources[("scene", "builder")] == "config" and sources[("frames",)] == "default"
    assert tree["sensor"]["preset"] == "vlp16" and sources[("sensor", "preset")] == "builder parking"  # the builder names its preset
    assert sources[("sensor", "rotation_hz")] == "--set"  # the builder's 20 Hz, replaced
    assert sources[("sensor", "channels")] == "preset vlp16"
    assert sources[("effects", "noise", "sigma")] == "config"
    assert sources[("effects", "drop", "model")] == "profile vlp16"  # the preset's effects profile
    assert set(sources) == {k for k, _ in _leaves(tree)}


def test_a_preset_named_by_the_config_replaces_the_builders_sensor_and_ideal_drops_the_profile():
    _, sources = resolved(None, ["scene.builder=parking", "sensor.preset=hdl64e", "effects.ideal=true"])
    assert sources[("sensor", "preset")] == "--set" and sources[("sensor", "rotation_hz")] == "preset hdl64e"
    assert sources[("effects", "drop", "model")] == "default"
    tree, sources = resolved(None, [])
    assert sources[("sensor", "preset")] == "default" and tree["sensor"]["sampling_factor"] == 0.25 and sources[("sensor", "sampling_factor")] == "default"
    assert PRECEDENCE == ("default", "preset", "builder", "profile", "config", "--set")


def test_the_command_prints_yaml_with_sources_and_refuses_a_bad_key_in_one_line():
    done = subprocess.run([sys.executable, "-m", "bpy_pipeline", "config", "--resolved", "--set", "seed=9"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "seed: 9  # --set\n" in done.stdout
    assert yaml.safe_load(done.stdout)["seed"] == 9  # comments aside, it is the YAML of the tree
    bad = subprocess.run([sys.executable, "-m", "bpy_pipeline", "config", "--resolved", "--set", "sensor.nope=1"], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "sensor.nope" in bad.stderr


def test_render_is_the_tree():
    tree, sources = resolved(None, ["frames=2"])
    assert yaml.safe_load(render(tree, sources)) == tree


def _leaves(tree, path=()):
    if isinstance(tree, dict) and tree:
        for key, value in tree.items():
            yield from _leaves(value, path + (key,))
    else:
        yield path, tree


def test_a_builders_output_defaults_sit_under_the_config():
    """The industrial hall's KITTI camera (1 m from the -x wall, 1.73 m above the floor) is the builder's; a config's key wins."""
    tree, sources = resolved(None, ["scene.builder=industrial_hall"])
    assert tree["output"]["kitti"]["camera"]["position"] == [-7.0, 0.0, -2.77] and tree["output"]["kitti"]["camera"]["resolution"] == [1242, 750]
    assert sources[("output", "kitti", "camera", "position")] == "builder industrial_hall"
    tree, sources = resolved(None, ["scene.builder=industrial_hall", "scene.sensor_height=4.0", "output.kitti.camera.resolution=[640,480]"])
    assert tree["output"]["kitti"]["camera"]["position"] == [-7.0, 0.0, -2.27] and tree["output"]["kitti"]["camera"]["resolution"] == [640, 480]
    assert sources[("output", "kitti", "camera", "resolution")] == "--set"


def test_the_kitti_frame_needs_one_sensor_on_a_builders_ground():
    from bpy_pipeline.config import config_from_dict
    from bpy_pipeline.errors import InputError

    assert config_from_dict({"output": {"frame": "kitti"}}).output.frame == "kitti"
    with pytest.raises(InputError, match="output.frame: kitti"):
        config_from_dict({"scene": {"builder": "street"}, "output": {"frame": "kitti"}})  # the street's default sensor is a rig
