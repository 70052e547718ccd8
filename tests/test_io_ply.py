"""PLY: binary little-endian, every point field; checked against plyfile, trimesh, Open3D and CloudCompare."""

import shutil
import subprocess

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import read_ply, write_ply
from bpy_pipeline.io.ply import PLY_DTYPE, point_field
from bpy_pipeline.lidar.points import POINT_DTYPE
from samples import random_points

INSTANCES = 2**31  # PLY instance ids are int (Open3D reads no uint)


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_round_trip_is_exact(tmp_path, n):
    pts = random_points(n, np.random.default_rng(0), instances=INSTANCES)
    path = write_ply(tmp_path / "c.ply", pts)
    back = read_ply(path)
    assert back.dtype == POINT_DTYPE and back.tobytes() == pts.tobytes()


def test_header_and_size(tmp_path):
    pts = random_points(7, np.random.default_rng(0), instances=INSTANCES)
    raw = write_ply(tmp_path / "c.ply", pts).read_bytes()
    header, body = raw.split(b"end_header\n", 1)
    lines = header.decode("ascii").splitlines()
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    assert "element vertex 7" in lines
    props = [line.split()[1:] for line in lines if line.startswith("property")]
    assert props == [
        ["float", "x"], ["float", "y"], ["float", "z"], ["float", "intensity"], ["int", "scalar_semantic"],
        ["int", "scalar_instance"], ["int", "scalar_ring"], ["double", "scalar_time"], ["float", "scalar_range"], ["uchar", "scalar_bounces"],
    ]  # fmt: skip
    assert PLY_DTYPE.itemsize == 41 and len(body) == 7 * 41


def test_plyfile_reads_every_field(tmp_path):
    plyfile = pytest.importorskip("plyfile", reason="plyfile is the independent PLY reader (pip install plyfile)")
    pts = random_points(500, np.random.default_rng(0), instances=INSTANCES)
    data = plyfile.PlyData.read(str(write_ply(tmp_path / "c.ply", pts)))
    assert data.byte_order == "<" and not data.text
    vertex = data["vertex"]
    assert vertex.count == 500
    for name in PLY_DTYPE.names:
        assert vertex[name].dtype.str.lstrip("<|") == PLY_DTYPE[name].str.lstrip("<|"), name
        np.testing.assert_array_equal(vertex[name], pts[point_field(name)], err_msg=name)


def test_instance_ids_beyond_int32_refused(tmp_path):
    pts = random_points(5, np.random.default_rng(0), instances=10)
    pts["instance"][2] = 2**31
    with pytest.raises(InputError, match="scalar_instance is int"):
        write_ply(tmp_path / "c.ply", pts)
    assert not (tmp_path / "c.ply").exists()


def test_open3d_reads_every_label(tmp_path):
    o3d = pytest.importorskip("open3d", exc_type=ImportError, reason="Open3D is the viewer this checks (pip install open3d; Debian needs libusb-1.0-0)")
    pts = random_points(400, np.random.default_rng(1), instances=1000)
    cloud = o3d.t.io.read_point_cloud(str(write_ply(tmp_path / "c.ply", pts)))
    np.testing.assert_array_equal(cloud.point["positions"].numpy(), np.stack([pts["x"], pts["y"], pts["z"]], axis=1))
    for name in PLY_DTYPE.names[3:]:  # Open3D 0.20 skips ushort and uint properties with a warning: none here
        assert name in cloud.point, f"Open3D dropped {name}; it kept {sorted(cloud.point)}"
        np.testing.assert_array_equal(cloud.point[name].numpy().ravel(), pts[point_field(name)], err_msg=name)


def cloudcompare_export(ply, tmp_path):
    """CloudCompare's command-line mode: open ``ply`` and save it as ASCII with a header (all its scalar fields)."""
    if shutil.which("CloudCompare") is None:
        pytest.skip("CloudCompare is not installed (Debian: apt-get install cloudcompare xvfb)")
    command = ["CloudCompare", "-SILENT", "-AUTO_SAVE", "OFF", "-O", str(ply), "-C_EXPORT_FMT", "ASC", "-SEP", "SPACE", "-ADD_HEADER", "-SAVE_CLOUDS", "FILE",
               str(tmp_path / "cc.asc")]
    if shutil.which("xvfb-run"):  # CloudCompare is a Qt program: it needs a display even in silent mode
        command = ["xvfb-run", "-a", *command]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    if not (tmp_path / "cc.asc").is_file():
        pytest.skip(f"CloudCompare did not run here (exit {done.returncode}: {done.stdout[-300:]}{done.stderr[-300:]})")
    header = (tmp_path / "cc.asc").read_text().splitlines()[0].lstrip("/").split()
    return header, np.loadtxt(tmp_path / "cc.asc", comments="//", ndmin=2)


def test_cloudcompare_loads_every_label(tmp_path):
    pts = random_points(300, np.random.default_rng(2), instances=1000)
    header, table = cloudcompare_export(write_ply(tmp_path / "c.ply", pts), tmp_path)
    expected = ["X", "Y", "Z", "intensity", "semantic", "instance", "ring", "time", "range", "bounces"]
    assert header == expected, f"CloudCompare loaded {header}"
    for k, name in enumerate(expected[3:], start=3):
        np.testing.assert_allclose(table[:, k], pts[name], rtol=1e-6, atol=1e-9, err_msg=name)


def test_trimesh_loads_a_point_cloud(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    pts = random_points(300, np.random.default_rng(0), instances=INSTANCES)
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
    path = write_ply(tmp_path / "c.ply", random_points(10, np.random.default_rng(0), instances=INSTANCES))
    path.write_bytes(path.read_bytes()[:-5])
    with pytest.raises(InputError, match="truncated"):
        read_ply(path)
    with pytest.raises(InputError, match="cannot open"):
        read_ply(tmp_path / "missing.ply")


def test_rejects_points_without_the_record_fields(tmp_path):
    with pytest.raises(InputError, match="structured array"):
        write_ply(tmp_path / "c.ply", np.zeros((5, 3), np.float32))
    assert list(tmp_path.iterdir()) == []
