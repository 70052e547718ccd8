"""Pointcept NPY folders: file names, shapes, dtypes, training ids with -1 ignored, no instances on stuff, atomic folders."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import npy as npy_module
from bpy_pipeline.io import read_npy_folder, write_npy_folder
from bpy_pipeline.io.class_maps import load_class_maps
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points
from samples import random_points


@pytest.mark.parametrize("n", [0, 1000])
def test_files_shapes_dtypes_and_round_trip(tmp_path, n):
    pts = random_points(n, np.random.default_rng(0), instances=5)
    paths = write_npy_folder(tmp_path / "000000", pts)
    assert [p.name for p in paths] == ["coord.npy", "strength.npy", "segment.npy", "instance.npy"]
    assert sorted(p.name for p in (tmp_path / "000000").iterdir()) == sorted(p.name for p in paths)
    coord, strength, segment, instance = (np.load(p) for p in paths)
    assert coord.shape == (n, 3) and coord.dtype == np.float32
    assert strength.shape == (n, 1) and strength.dtype == np.float32
    assert segment.shape == (n,) and segment.dtype == np.int32
    assert instance.shape == (n,) and instance.dtype == np.int32
    np.testing.assert_array_equal(coord, np.stack([pts["x"], pts["y"], pts["z"]], axis=1))
    np.testing.assert_array_equal(strength[:, 0], pts["intensity"])
    table, maps = load_class_table(), load_class_maps()
    np.testing.assert_array_equal(segment, [table.learning_map[int(s)] - 1 for s in pts["semantic"]])
    thing = maps.things[pts["semantic"]]
    np.testing.assert_array_equal(instance, np.where((pts["instance"] == 0) | ~thing, -1, pts["instance"].astype(np.int64)))
    if n:
        assert (instance == -1).any() and (instance > 0).any() and not (instance == 0).any()
        assert (segment == -1).any() and segment.max() == max(table.learning_map[int(s)] for s in pts["semantic"]) - 1
    back = read_npy_folder(tmp_path / "000000", maps)
    for name in ("x", "y", "z", "intensity"):
        np.testing.assert_array_equal(back[name], pts[name], err_msg=name)
    kept = segment >= 0  # raw ids come back where the training id is one raw id's (ignored ones are unlabeled)
    np.testing.assert_array_equal(back["semantic"][kept], pts["semantic"][kept])
    assert not back["semantic"][~kept].any()
    assert not back["time"].any()


def test_rewrite_replaces_folder_and_failure_keeps_old_one(tmp_path, monkeypatch):
    folder = tmp_path / "npy" / "000001"
    write_npy_folder(folder, random_points(10, np.random.default_rng(0), instances=5))
    (folder / "stale.npy").write_bytes(b"x")
    write_npy_folder(folder, random_points(20, np.random.default_rng(1), instances=5))
    assert not (folder / "stale.npy").exists() and len(read_npy_folder(folder)) == 20

    calls = []
    real_header = np.lib.format.write_array_header_1_0

    def failing_header(f, header):  # the third file of the folder fails
        calls.append(f)
        if len(calls) == 3:
            raise OSError("No space left on device")
        real_header(f, header)

    monkeypatch.setattr(npy_module.np.lib.format, "write_array_header_1_0", failing_header)
    with pytest.raises(OSError):
        write_npy_folder(folder, random_points(30, np.random.default_rng(2), instances=5))
    monkeypatch.undo()
    assert len(read_npy_folder(folder)) == 20
    assert [p.name for p in folder.parent.iterdir()] == ["000001"]


def test_instance_beyond_int32_is_refused(tmp_path):
    pts = empty_points(2)
    pts["instance"] = [1, 2**31]
    with pytest.raises(InputError, match="int32"):
        write_npy_folder(tmp_path / "f", pts)
    assert list(tmp_path.iterdir()) == []


def test_reader_checks_files(tmp_path):
    with pytest.raises(InputError, match="coord.npy"):
        read_npy_folder(tmp_path)
    np.save(tmp_path / "coord.npy", np.zeros((4, 3), np.float32))
    np.save(tmp_path / "segment.npy", np.array([-1, 2, 3, 4], np.int32))
    assert read_npy_folder(tmp_path)["semantic"].tolist() == [0, 2, 3, 4]
    np.save(tmp_path / "segment.npy", np.zeros(5, np.int32))
    with pytest.raises(InputError, match="segment.npy"):
        read_npy_folder(tmp_path)


def test_pointcept_segment_of_named_classes(tmp_path):
    table = load_class_table()
    by_name = {name: i for i, name in table.names.items()}
    pts = empty_points(4)
    pts["semantic"] = [by_name["unlabeled"], by_name["reflection"], by_name["ground"], by_name["car"]]
    pts["instance"] = [0, 7, 5, 9]  # ground (stuff) has an instance in the record; Pointcept gets none
    write_npy_folder(tmp_path / "f", pts)
    segment, instance = np.load(tmp_path / "f" / "segment.npy"), np.load(tmp_path / "f" / "instance.npy")
    assert segment.tolist() == [-1, -1, table.learning_map[by_name["ground"]] - 1, table.learning_map[by_name["car"]] - 1]
    assert instance.tolist() == [-1, -1, -1, 9]
