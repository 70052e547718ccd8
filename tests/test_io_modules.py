"""The io modules no other test reaches directly: the point-record guard (io/_records.py), paths kept inside a
folder (io/confined.py), the run manifest (io/manifest.py), the SUSTechPOINTS writer (io/sustech.py), the writer
registry (io/writers.py), and the YAML guard (yaml_text.py)."""

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.boxes import BOX_DTYPE
from bpy_pipeline.io import _records, confined, manifest, sustech, writers
from bpy_pipeline.io.pcd import read_pcd
from bpy_pipeline.lidar.points import POINT_DTYPE, empty_points
from bpy_pipeline.yaml_text import MAX_DEPTH, MAX_VALUES, check_yaml_size, read_yaml_file, read_yaml_text


# ----------------------------------------------------------------------------- _records
def test_chunks_cover_the_range_in_order():
    assert _records.chunks(0) == []
    assert _records.chunks(7, 3) == [slice(0, 3), slice(3, 6), slice(6, 7)]


def test_as_points_casts_extra_and_other_typed_fields_and_names_a_wrong_array():
    extra = np.zeros(3, [*[(n, "<f8") for n in POINT_DTYPE.names], ("colour", "u1")])
    extra["range"] = [1.5, 2.5, 3.5]
    out = _records.as_points(extra, "points")
    assert out.dtype == POINT_DTYPE and list(out["range"]) == [1.5, 2.5, 3.5]
    same = empty_points(2)
    assert _records.as_points(same, "points") is same
    with pytest.raises(InputError, match="^cloud: expected a 1-D structured array with fields x, y, z"):
        _records.as_points(np.zeros((2, 3)), "cloud")


# ----------------------------------------------------------------------------- confined
def test_inside_keeps_relative_paths_in_their_folder(tmp_path):
    (tmp_path / "sub").mkdir()
    assert confined.inside(tmp_path, "sub/a.npy") == tmp_path / "sub" / "a.npy"
    for bad in ("../a.npy", "/etc/passwd", "", "sub/..", 5, "a\x00b"):
        assert confined.inside(tmp_path, bad) is None, bad
    os.symlink(tmp_path.parent, tmp_path / "up")
    assert confined.inside(tmp_path, "up/x") is None  # a parent folder that links outside


def test_readable_inside_says_why_not(tmp_path):
    (tmp_path / "a.txt").write_text("12345")
    assert confined.readable_inside(tmp_path, "a.txt", 10) == (tmp_path / "a.txt", "")
    assert confined.readable_inside(tmp_path, "a.txt", 4)[1] == "5 bytes, more than the 4 allowed"
    assert confined.readable_inside(tmp_path, "missing.txt", 10)[1].startswith("cannot be read")
    outside = tmp_path.parent / f"{tmp_path.name}-outside.txt"
    outside.write_text("x")
    os.symlink(outside, tmp_path / "link.txt")
    assert confined.readable_inside(tmp_path, "link.txt", 10) == (None, "a link pointing outside its folder")


def test_refuse_output_over_input(tmp_path):
    a = tmp_path / "a.yaml"
    a.write_text("x")
    confined.refuse_output_over_input(tmp_path / "b.yaml", [str(a)])
    with pytest.raises(InputError, match=r"^--out: .*a\.yaml is the input"):
        confined.refuse_output_over_input(str(tmp_path / "." / "a.yaml"), [None, str(a)])


# ----------------------------------------------------------------------------- manifest
def test_manifest_round_trips_numpy_values_and_records_come_by_index(tmp_path):
    path = manifest.write_manifest(tmp_path, {"seed": np.int64(7), "pose": np.eye(2), "out": tmp_path})
    assert path.name == "manifest.json"
    assert json.loads(path.read_text()) == {"seed": 7, "pose": [[1.0, 0.0], [0.0, 1.0]], "out": str(tmp_path)}
    (tmp_path / "records").mkdir()
    for index in (2, 0, 1):
        (tmp_path / "records" / f"x{index}.json").write_text(json.dumps({"index": index, "points": index * 10}))
    dataset = manifest.read_dataset(tmp_path)
    assert dataset["seed"] == 7 and [r["index"] for r in dataset["frames"]] == [0, 1, 2]


def test_manifest_refuses_what_json_cannot_hold_and_names_a_bad_file(tmp_path):
    with pytest.raises(ValueError, match="cannot write the manifest as JSON"):
        manifest.write_manifest(tmp_path, {"x": float("nan")})
    assert not (tmp_path / "manifest.json").exists()
    (tmp_path / "manifest.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="expected a JSON object at the top level, got list"):
        manifest.read_manifest(tmp_path)
    (tmp_path / "records").mkdir()
    (tmp_path / "records" / "000000.json").write_text('{"index": true}')
    with pytest.raises(InputError, match="not a frame record"):
        manifest.read_frame_records(tmp_path)


# ----------------------------------------------------------------------------- sustech
def test_sustech_frame_is_a_pcd_of_0_255_intensity_and_a_label_per_box(tmp_path):
    points = empty_points(3)
    points["x"], points["intensity"] = [1.0, 2.0, 3.0], [0.0, 0.5, 1.0]
    boxes = np.zeros(2, BOX_DTYPE)
    boxes["class_name"], boxes["instance"] = ["car", "robot arm"], [4, 9]
    boxes["centre"], boxes["size"], boxes["heading"] = [[1, 2, 3], [4, 5, 6]], [[4, 2, 1.5], [1, 1, 2]], [0.5, -1.0]
    pcd, label = sustech.write_frame(tmp_path, "000003", points, boxes, names={"robot arm": "Arm"})
    assert pcd == tmp_path / "sustech" / "lidar" / "000003.pcd" and label == tmp_path / "sustech" / "label" / "000003.json"
    back = read_pcd(pcd)
    assert np.allclose(back["intensity"], [0.0, 127.5, 255.0]) and np.allclose(back["x"], [1, 2, 3])
    objects = json.loads(label.read_text())
    assert [o["obj_type"] for o in objects] == ["Car", "Arm"] and [o["obj_id"] for o in objects] == ["4", "9"]
    assert objects[0]["psr"] == {"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "rotation": {"x": 0.0, "y": 0.0, "z": 0.5},
                                 "scale": {"x": 4.0, "y": 2.0, "z": 1.5}}
    assert sustech.sustech_type("unknown thing") == "Misc" and sustech.label_type("robot_arm") == "RobotArm"


# ----------------------------------------------------------------------------- writers
def test_writer_registry_and_the_writers_a_frame_goes_through():
    assert {"ply", "sustech"} <= set(writers.WRITERS.names())
    with pytest.raises(ValueError, match="ply"):
        writers.register_writer("ply", writers.Writer(writers.no_files))
    with pytest.raises(InputError, match="^output.formats: unknown output format 'xyz'"):
        writers.WRITERS.get("xyz")
    output = SimpleNamespace(formats=["ply"], preview=True, boxes=SimpleNamespace(formats=["kitti"]))
    assert writers.frame_writers(SimpleNamespace(output=output)) == ["ply", "preview", "kitti"]
    assert writers.no_files(None, None) == [] and writers.no_check(None) is None


# ----------------------------------------------------------------------------- yaml_text
def test_yaml_guard_counts_aliases_expanded_and_nesting():
    assert read_yaml_text("a: [1, 2]\nb: {c: x}", "t") == {"a": [1, 2], "b": {"c": "x"}}
    with pytest.raises(InputError, match=f"^t: nested deeper than {MAX_DEPTH} levels"):
        check_yaml_size("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "t")
    bomb = "a: &a [" + ", ".join(["x"] * 10) + "]\n" + "".join(f"{k}: &{k} [" + ", ".join([f"*{p}"] * 10) + "]\n" for p, k in zip("abcde", "bcdef"))
    with pytest.raises(InputError, match=f"^t: holds more than {MAX_VALUES:,} values"):
        check_yaml_size(bomb, "t")


def test_yaml_file_guard_names_the_file(tmp_path):
    with pytest.raises(InputError, match="is a folder, not a config file"):
        read_yaml_file(tmp_path)
    (tmp_path / "c.yaml").write_bytes(b"a: \xff\xfe")
    with pytest.raises(InputError, match="c.yaml"):
        read_yaml_file(tmp_path / "c.yaml")
