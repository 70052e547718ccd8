"""Pointcept NPY folders: file names, shapes, dtypes, the -1 instance convention, atomic folders."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import npy as npy_module
from bpy_pipeline.io import read_npy_folder, write_npy_folder
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
    np.testing.assert_array_equal(segment, pts["semantic"])
    np.testing.assert_array_equal(instance, np.where(pts["instance"] == 0, -1, pts["instance"].astype(np.int64)))
    if n:
        assert (instance == -1).any() and (instance > 0).any() and not (instance == 0).any()
    back = read_npy_folder(tmp_path / "000000")
    for name in ("x", "y", "z", "intensity", "semantic", "instance"):
        np.testing.assert_array_equal(back[name], pts[name], err_msg=name)
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
