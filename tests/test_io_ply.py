"""PLY: binary little-endian, every point field; checked against plyfile and trimesh."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import read_ply, write_ply
from bpy_pipeline.lidar.points import POINT_DTYPE, empty_points
from samples import random_points


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_round_trip_is_exact(tmp_path, n):
    pts = random_points(n, np.random.default_rng(0))
    path = write_ply(tmp_path / "c.ply", pts)
    back = read_ply(path)
    assert back.dtype == POINT_DTYPE and back.tobytes() == pts.tobytes()


def test_header_and_size(tmp_path):
    pts = random_points(7, np.random.default_rng(0))
    raw = write_ply(tmp_path / "c.ply", pts).read_bytes()
    header, body = raw.split(b"end_header\n", 1)
    lines = header.decode("ascii").splitlines()
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    assert "element vertex 7" in lines
    props = [line.split()[1:] for line in lines if line.startswith("property")]
    assert props == [
        ["float", "x"], ["float", "y"], ["float", "z"], ["float", "intensity"], ["ushort", "semantic"],
        ["uint", "instance"], ["ushort", "ring"], ["double", "time"], ["float", "range"], ["uchar", "bounces"],
    ]  # fmt: skip
    assert POINT_DTYPE.itemsize == 37 and len(body) == 7 * 37


def test_plyfile_reads_every_field(tmp_path):
    plyfile = pytest.importorskip("plyfile", reason="plyfile is the independent PLY reader (pip install plyfile)")
    pts = random_points(500, np.random.default_rng(0))
    data = plyfile.PlyData.read(str(write_ply(tmp_path / "c.ply", pts)))
    assert data.byte_order == "<" and not data.text
    vertex = data["vertex"]
    assert vertex.count == 500
    for name in POINT_DTYPE.names:
        assert vertex[name].dtype.str.lstrip("<|") == POINT_DTYPE[name].str.lstrip("<|"), name
        np.testing.assert_array_equal(vertex[name], pts[name], err_msg=name)


def test_trimesh_loads_a_point_cloud(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    pts = random_points(300, np.random.default_rng(0))
    cloud = trimesh.load(write_ply(tmp_path / "c.ply", pts))
    assert isinstance(cloud, trimesh.PointCloud)
    np.testing.assert_array_equal(cloud.vertices, np.stack([pts["x"], pts["y"], pts["z"]], axis=1))


@pytest.mark.parametrize("text,byte_order", [(True, "="), (False, ">")])
def test_reads_foreign_ply_ascii_and_big_endian(tmp_path, text, byte_order):
    plyfile = pytest.importorskip("plyfile", reason="plyfile writes the foreign PLY files (pip install plyfile)")
    rng = np.random.default_rng(0)
    vertex = np.zeros(20, [("intensity", "f8"), ("z", "f4"), ("x", "f4"), ("y", "f4"), ("red", "u1")])
    for name in ("intensity", "x", "y", "z"):
        vertex[name] = rng.uniform(0, 1, 20)
    faces = np.zeros(2, [("vertex_indices", "i4", (3,))])
    faces["vertex_indices"] = [[0, 1, 2], [2, 3, 4]]
    path = tmp_path / "foreign.ply"
    elements = [plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(faces, "face")]
    plyfile.PlyData(elements, text=text, byte_order=byte_order).write(str(path))
    back = read_ply(path)
    assert len(back) == 20
    for name in ("x", "y", "z", "intensity"):
        np.testing.assert_allclose(back[name], vertex[name], rtol=1e-6, err_msg=name)
    assert not back["semantic"].any() and not back["time"].any()


def test_rejects_non_ply_and_truncated_files(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"hello\n")
    with pytest.raises(InputError, match="not a PLY"):
        read_ply(bad)
    path = write_ply(tmp_path / "c.ply", random_points(10, np.random.default_rng(0)))
    path.write_bytes(path.read_bytes()[:-5])
    with pytest.raises(InputError, match="truncated"):
        read_ply(path)
    with pytest.raises(InputError, match="cannot open"):
        read_ply(tmp_path / "missing.ply")


def test_rejects_points_without_the_record_fields(tmp_path):
    with pytest.raises(InputError, match="structured array"):
        write_ply(tmp_path / "c.ply", np.zeros((5, 3), np.float32))
    assert list(tmp_path.iterdir()) == []
