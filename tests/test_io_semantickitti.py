"""SemanticKITTI: byte-exact round trip of a real sample, label bit layout, 16-bit instance limit."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import read_bin, read_label, read_semantickitti, write_semantickitti
from bpy_pipeline.lidar.points import empty_points


def random_points(n, rng):
    pts = empty_points(n)
    for name in "xyz":
        pts[name] = rng.uniform(-80, 80, n)
    pts["intensity"] = rng.uniform(0, 1, n)
    pts["semantic"] = rng.integers(0, 2**16, n)
    pts["instance"] = rng.integers(0, 2**16, n)
    pts["ring"] = rng.integers(0, 64, n)
    pts["time"] = rng.uniform(0, 0.1, n)
    return pts


def test_real_sample_round_trips_byte_for_byte(tmp_path, real_scan):
    bin_path, label_path = real_scan("semantickitti_sample.bin"), real_scan("semantickitti_sample.label")
    scan = read_bin(bin_path)
    semantic, instance = read_label(label_path)
    assert scan.shape == (50, 4) and scan.dtype == np.float32
    assert semantic.dtype == np.uint16 and instance.dtype == np.uint16 and semantic.shape == (50,)
    pts = empty_points(len(scan))
    for i, name in enumerate(("x", "y", "z", "intensity")):
        pts[name] = scan[:, i]
    pts["semantic"], pts["instance"] = semantic, instance
    out_bin, out_label = write_semantickitti(tmp_path, 8, 123, pts)
    assert out_bin.read_bytes() == bin_path.read_bytes()
    assert out_label.read_bytes() == label_path.read_bytes()
    assert read_semantickitti(out_bin, out_label).tobytes() == read_semantickitti(bin_path, label_path).tobytes()


@pytest.mark.parametrize("n", [0, 2000])
def test_round_trip_keeps_what_the_format_holds(tmp_path, n):
    pts = random_points(n, np.random.default_rng(0))
    bin_path, label_path = write_semantickitti(tmp_path, 5, 42, pts)
    assert bin_path == tmp_path / "sequences" / "05" / "velodyne" / "000042.bin"
    assert label_path == tmp_path / "sequences" / "05" / "labels" / "000042.label"
    assert bin_path.stat().st_size == 16 * n and label_path.stat().st_size == 4 * n
    back = read_semantickitti(bin_path, label_path)
    for name in ("x", "y", "z", "intensity", "semantic", "instance"):
        np.testing.assert_array_equal(back[name], pts[name], err_msg=name)
    for name in ("ring", "time", "range", "bounces"):
        assert not back[name].any(), name


def test_label_bit_layout(tmp_path):
    pts = empty_points(2)
    pts["semantic"], pts["instance"] = [7, 0xFFFF], [3, 0xFFFF]
    _, label_path = write_semantickitti(tmp_path, 0, 0, pts)
    assert np.fromfile(label_path, "<u4").tolist() == [0x00030007, 0xFFFFFFFF]


def test_instance_above_16_bits_is_refused_and_nothing_written(tmp_path):
    pts = empty_points(3)
    pts["instance"] = [1, 65536, 2]
    with pytest.raises(InputError, match="65535"):
        write_semantickitti(tmp_path, 0, 0, pts)
    assert not any(p.is_file() for p in tmp_path.rglob("*"))


def test_bad_files_and_arguments(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"\0" * 20)
    with pytest.raises(InputError, match="whole number"):
        read_bin(tmp_path / "a.bin")
    (tmp_path / "a.label").write_bytes(b"\0" * 6)
    with pytest.raises(InputError, match="whole number"):
        read_label(tmp_path / "a.label")
    bin_path, _ = write_semantickitti(tmp_path, 0, 0, random_points(4, np.random.default_rng(0)))
    _, other_label = write_semantickitti(tmp_path, 0, 1, random_points(5, np.random.default_rng(1)))
    with pytest.raises(InputError, match="5 labels for 4 points"):
        read_semantickitti(bin_path, other_label)
    with pytest.raises(InputError, match="sequence"):
        write_semantickitti(tmp_path, -1, 0, empty_points(1))
