"""Sensor rigs: config, merged clouds with a sensor index, per-sensor bytes equal to single-sensor runs, boxes per
camera, skipped empty frames, and the flash camera's images with several returns per pixel."""

import dataclasses
import json

import numpy as np
import pytest

from bpy_pipeline.config import config_from_dict, config_to_dict, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.points import POINT_DTYPE
from bpy_pipeline.rig import RIG_POINT_DTYPE, RIG_PRESETS, merge_clouds, merged_boxes, rig_from_data, split_cloud

BOX_CLASSES = ["car", "van", "truck", "bus", "person", "bicycle", "motorcycle", "rider"]
YAWS = (80.0, 0.0, -80.0)
PLATFORM = (-7.6, -7.6, 0.15)


# ----------------------------------------------------------------------------- pure
def test_rig_presets_and_config_round_trip():
    config = load_config({"scene": {"builder": "street"}})
    rig = config.sensor.rig
    assert [s.spec.name for s in rig] == ["flash96x16_carla"] * 3 and [s.rotation_deg[2] for s in rig] == [80.0, 0.0, -80.0]
    assert all(s.position == (0.0, 0.0, 2.0) for s in rig)  # the thesis's 2 m post
    spec = rig[0].spec
    assert spec.horizontal_fov_deg == (-40.0, 40.0) and spec.max_range == 35.0 and spec.columns == 96 and spec.channels == 16
    assert config_from_dict(config_to_dict(config)) == config
    roof = rig_from_data("car_roof")
    assert roof[0].spec.horizontal_fov_deg == (-180.0, 180.0) and len(roof) == 5
    custom = load_config({"sensor": {"rig": [{"preset": "vlp16", "max_range": 30.0, "position": [0, 0, 1]}, {"preset": "flash96x16"}]}})
    assert custom.sensor.rig[0].spec.max_range == 30.0 and custom.sensor.spec.name == "vlp16"
    assert set(RIG_PRESETS) == {"flash_post_240", "car_roof"}


@pytest.mark.parametrize("sensor, key", [
    ({"rig": "tripod"}, "sensor.rig"),
    ({"rig": [{"position": [0, 0, 1]}]}, r"sensor.rig\[0\]"),
    ({"rig": [{"preset": "vlp16", "position": [0, 1]}]}, r"sensor.rig\[0\].position"),
    ({"rig": "flash_post_240", "preset": "vlp16"}, "sensor.preset"),
    ({"rig": [{"preset": "nope"}]}, r"sensor.rig\[0\]"),
])
def test_bad_rigs_name_their_key(sensor, key):
    with pytest.raises(InputError, match=key):
        load_config({"sensor": sensor})


def test_merged_cloud_keeps_each_cloud_and_its_index():
    rng = np.random.default_rng(0)
    clouds = []
    for n in (5, 0, 7):
        c = np.zeros(n, POINT_DTYPE)
        for name in ("x", "y", "z", "range"):
            c[name] = rng.normal(size=n)
        c["instance"] = rng.integers(0, 9, n)
        clouds.append(c)
    merged = merge_clouds(clouds)
    assert merged.dtype == RIG_POINT_DTYPE and merged["sensor"].tolist() == [0] * 5 + [2] * 7
    for k, part in enumerate(split_cloud(merged)):
        assert part.tobytes() == clouds[k].tobytes()
    moved = merge_clouds(clouds, [pose_matrix((1, 2, 3), (0, 0, 90))] * 3)
    assert np.allclose(moved["x"][:5], 1 - clouds[0]["y"], atol=1e-6) and np.allclose(moved["z"][:5], 3 + clouds[0]["z"], atol=1e-6)


def test_merged_boxes_sum_the_sensors_points_and_keep_a_box_split_by_a_boundary():
    from bpy_pipeline.geometry.boxes import BOX_DTYPE

    a, b = np.zeros(2, BOX_DTYPE), np.zeros(1, BOX_DTYPE)
    a["class_name"], a["instance"], a["points"], a["truncation"] = ["car", "person"], [1, 2], [8, 3], [0.5, 0.0]
    b["class_name"], b["instance"], b["points"], b["truncation"] = ["car"], [1], [7], [0.4]
    kept = merged_boxes([a, b], {"car": 12}, 6)
    assert kept["instance"].tolist() == [1] and int(kept["points"][0]) == 15 and kept["truncation"][0] == np.float32(0.4)


# ----------------------------------------------------------------------------- in Blender
def _street(sensor, formats, effects=None, frames=1, **output):
    data = {"seed": 4, "frames": frames, "scene": {"builder": "street", "fov_aware": False, "vehicles": {"mean": 10.0, "std": 0.0, "max": 40.0},
                                                   "pedestrians": {"mean": 10.0, "std": 0.0, "max": 40.0}},
            "sensor": sensor, "output": {"formats": formats, "preview": False, "boxes": {"formats": ["openpcdet"], "classes": BOX_CLASSES}, **output}}
    if effects is not None:
        data["effects"] = effects
    return load_config(data)


# Random effects draw from each sensor's own generator (rig.member_rng), a single run from the frame's:
# the runs compare byte for byte with deterministic effects; the generators are compared on their own below.
EXACT = {"drop": {"model": "none"}, "noise": {"sigma": 0.0}}
THREE_CAMERAS = {"position": list(PLATFORM), "rotation_deg": [0.0, 0.0, 0.0],
                 "rig": [{"preset": "flash96x16_carla", "position": [0.0, 0.0, 2.0], "rotation_deg": [0.0, 0.0, 45.0 + y]} for y in YAWS]}


@pytest.mark.bpy
def test_three_camera_rig_is_the_union_of_three_single_camera_runs_byte_for_byte(bpy_scene, tmp_path):
    from bpy_pipeline.io.boxes import read_openpcdet_labels
    from bpy_pipeline.io.ply import read_ply
    from bpy_pipeline.plan import run

    rig_config = _street(THREE_CAMERAS, ["ply", "rig"], effects=EXACT)
    run(rig_config, tmp_path / "rig", log=lambda s: None)
    from plyfile import PlyData

    vertex = PlyData.read(str(tmp_path / "rig" / "rig" / "000000.ply"))["vertex"].data
    assert "sensor" in vertex.dtype.names and set(np.unique(vertex["sensor"])) == {0, 1, 2}
    merged = np.array(vertex.tolist(), dtype=RIG_POINT_DTYPE)
    min_points = rig_config.output.boxes.min_points
    for k, yaw in enumerate(YAWS):
        single = _street({"preset": "flash96x16_carla", "position": [PLATFORM[0], PLATFORM[1], PLATFORM[2] + 2.0], "rotation_deg": [0.0, 0.0, 45.0 + yaw]},
                         ["ply"], effects=EXACT)
        run(single, tmp_path / f"single{k}", log=lambda s: None)
        alone = (tmp_path / f"single{k}" / "ply" / "000000.ply").read_bytes()
        assert (tmp_path / "rig" / "rig" / f"sensor{k}" / "000000.ply").read_bytes() == alone
        points = read_ply(tmp_path / f"single{k}" / "ply" / "000000.ply")
        assert len(points) > 100
        expected = merge_clouds([points], [rig_config.sensor.rig[k].matrix()])  # into the platform frame, as the rig moves them
        expected["sensor"] = k
        ours = merged[merged["sensor"] == k]
        assert ours.tobytes() == expected.tobytes()
        labels = (tmp_path / f"single{k}" / "openpcdet" / "labels" / "000000.txt").read_text()
        assert (tmp_path / "rig" / "rig" / f"sensor{k}" / "labels" / "000000.txt").read_text() == labels
        for box in read_openpcdet_labels(tmp_path / "rig" / "rig" / f"sensor{k}" / "labels" / "000000.txt"):
            inside = points[points["instance"] == _instance_of(tmp_path / f"single{k}", box)]
            assert len(inside) >= min_points.get(str(box["class_name"]).lower(), rig_config.output.boxes.min_points_default)
    record = json.loads((tmp_path / "rig" / "records" / "000000.json").read_text())
    assert record["points"] == len(merged) == sum(s["points"] for s in record["rig"]["sensors"])
    per_sensor = {b["instance"] for s in record["rig"]["sensors"] for b in s.get("boxes", [])}
    assert per_sensor <= {b["instance"] for b in record["boxes"]}  # a box kept by one camera is kept merged
    # each camera times its trace and its effects apart
    members = {stage: [s["timings_s"][stage] for s in record["rig"]["sensors"]] for stage in ("scan", "effects")}
    assert all(t > 0 for t in members["scan"] + members["effects"])
    assert record["timings_s"]["effects"] == pytest.approx(sum(members["effects"]), abs=5e-4)  # the frame adds them up
    assert record["timings_s"]["scan"] >= sum(members["scan"]) - 5e-4  # and merges the clouds in its scan


def _instance_of(folder, box) -> int:
    """The instance of a written box, from the single run's record (the box with the same centre)."""
    record = json.loads((folder / "records" / "000000.json").read_text())
    from bpy_pipeline.io.boxes import read_openpcdet_labels

    boxes = read_openpcdet_labels(folder / "openpcdet" / "labels" / "000000.txt")
    k = int(np.argmin(np.linalg.norm(boxes["centre"] - box["centre"], axis=1)))
    return record["boxes"][k]["instance"]


@pytest.mark.bpy
def test_rig_sensors_draw_from_their_own_generators(bpy_scene):
    from bpy_pipeline.frame import Run
    from bpy_pipeline.plan import make_frame
    from bpy_pipeline.stages.rig import member_config
    from bpy_pipeline.stages.scan import scan_buffers
    from bpy_pipeline.rig import member_rng

    noisy = {"noise": {"sigma": 0.02}, "drop": {"model": "uniform", "probability": 0.2}}
    config = _street(THREE_CAMERAS, ["rig"], effects=noisy)
    frame = make_frame(Run(config), 0)
    for k, sub in enumerate(frame.rig.frames):
        # sensor k alone, at its pose on the platform, with its generator, gives the rig's sensor-k bytes
        alone = member_config(config, k)
        alone = dataclasses.replace(alone, sensor=dataclasses.replace(alone.sensor, position=tuple(sub.pose[:3, 3]), rotation_deg=(0.0, 0.0, 45.0 + YAWS[k])))
        points, pose = scan_buffers(sub.buffers, alone, member_rng(config.seed, 0, k), 0)
        assert np.array_equal(pose, sub.pose) and len(points) > 100
        assert points.tobytes() == sub.points.tobytes()
        other, _ = scan_buffers(sub.buffers, alone, member_rng(config.seed, 0, k + 1), 0)
        assert other.tobytes() != points.tobytes()  # the effects are random: another generator, other bytes


@pytest.mark.bpy
def test_skip_empty_records_skipped_frames_and_can_fill_the_requested_kept_frames(bpy_scene, tmp_path):
    from bpy_pipeline.plan import run

    sparse = {"builder": "street", "vehicles": {"mean": 0.0, "std": 1.0, "max": 3.0}, "parked": {"mean": 0.0, "std": 0.0, "max": 0.0},
              "pedestrians": {"mean": 0.0, "std": 1.0, "max": 3.0}, "bicycles": {"mean": 0.0, "std": 0.0, "max": 0.0},
              "motorcycles": {"mean": 0.0, "std": 0.0, "max": 0.0}}
    data = {"seed": 1, "frames": 6, "scene": sparse, "sensor": THREE_CAMERAS,
            "output": {"formats": ["ply"], "preview": False, "skip_empty": True, "boxes": {"formats": ["openpcdet"], "classes": BOX_CLASSES}}}
    run(load_config(data), tmp_path / "a", log=lambda s: None)
    records = [json.loads(p.read_text()) for p in sorted((tmp_path / "a" / "records").glob("*.json"))]
    assert [r["index"] for r in records] == list(range(6))
    skipped = [r["index"] for r in records if r.get("skipped")]
    assert 0 < len(skipped) < 6
    for r in records:
        if r.get("skipped"):
            assert r["files"] == [] and not (tmp_path / "a" / "ply" / f"{r['index']:06d}.ply").exists() and "labelled object" in r["reason"]
        else:
            assert len(r["boxes"]) >= 1 and (tmp_path / "a" / "ply" / f"{r['index']:06d}.ply").exists()
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert manifest["summary"]["frames"] == 6 - len(skipped) and manifest["summary"]["skipped"]["frames"] == len(skipped)
    sets = tmp_path / "a" / "openpcdet" / "ImageSets"
    # output.split; no file for an empty split
    image_set = [i for name in ("train", "val", "test") if (sets / f"{name}.txt").exists() for i in (sets / f"{name}.txt").read_text().split()]
    assert sorted(int(i) for i in image_set) == [r["index"] for r in records if not r.get("skipped")]
    # `frames` kept frames: indices go on; the first indices skip exactly as before
    data["output"]["frames_kept"] = True
    run(load_config(data), tmp_path / "b", log=lambda s: None)
    again = {int(p.stem): json.loads(p.read_text()) for p in (tmp_path / "b" / "records").glob("*.json")}
    assert sum(1 for r in again.values() if not r.get("skipped")) == 6
    for r in records:
        assert bool(again[r["index"]].get("skipped")) == bool(r.get("skipped")) and again[r["index"]]["sha256"] == r["sha256"]


@pytest.mark.bpy
def test_flash_image_has_two_returns_where_a_pixel_spans_a_pole_and_the_wall_behind(bpy_scene, tmp_path):
    from bpy_pipeline.io.rig_outputs import read_flash_image
    from bpy_pipeline.plan import run

    shapes = [{"type": "box", "size": [0.2, 10.0, 4.0], "position": [12.0, 0.0, 0.0], "class": "wall"},
              {"type": "cylinder", "size": [0.05, 3.0], "position": [6.0, 0.0, 0.0], "class": "mast"}]
    config = load_config({"scene": {"builder": "primitives", "shapes": shapes},
                          "sensor": {"preset": "flash96x16", "max_range": 20.0, "position": [0.0, 0.0, 0.0]},
                          "output": {"formats": ["ply", "flash_image"], "preview": False}})
    run(config, tmp_path, log=lambda s: None)
    image = read_flash_image(tmp_path / "flash_image" / "000000.npy")
    assert image.shape == (2, 16, 96)
    two = image["depth"][1] > 0
    assert two.any()
    first, second = image[0][two], image[1][two]
    assert np.allclose(first["depth"], 6.0, atol=0.2) and np.allclose(second["depth"], 11.9, atol=0.3)
    assert set(np.unique(first["semantic"])) == {config_sem("mast")} and set(np.unique(second["semantic"])) == {config_sem("wall")}
    assert (first["intensity"] < 0.5).all()  # a pole filling part of a pixel returns part of its light
    wall_only = (image["depth"][0] > 11.0) & ~two
    assert wall_only.sum() > 100 and (image["depth"][1][wall_only] == 0).all()  # a plain wall is one return
    assert (tmp_path / "flash_image" / "000000.png").exists()


def config_sem(name: str) -> int:
    from bpy_pipeline.labels import load_class_table

    return load_class_table().id_of(name)


def test_out_of_reach_is_conservative():
    from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
    from bpy_pipeline.rig import out_of_reach

    spec = resolve_sensor({"preset": "flash96x16_carla"})  # +-40 deg, +-6.67 deg, 35 m
    centres = np.array([[10, 0, 0], [-10, 0, 0], [10, 9.5, 0], [10, 7.5, 0], [50, 0, 0], [36, 0, 0], [0.5, 0, 0], [10, 0, 3.0], [10, 0, 1.5]], float)
    radii = np.array([1.0, 1.0, 0.5, 1.0, 1.0, 2.0, 1.0, 1.0, 1.0])
    assert out_of_reach(spec, np.eye(4), centres, radii).tolist() == [False, True, True, False, True, False, False, True, False]
    spinning = resolve_sensor({"preset": "vlp16"})
    assert out_of_reach(spinning, np.eye(4), centres, radii).tolist() == [False, False, False, False, False, False, False, False, False]
