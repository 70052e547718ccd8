"""Readers of real scans (bpy_pipeline/io/real_scans.py): every format into the sensor frame, and bad files."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io.real_scans import guess_format, read_real_scan


def cloud(n=200, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-20, 20, (n, 3))
    return xyz, rng.uniform(0, 1, n), rng.integers(0, 16, n)


def test_nuscenes_axes_and_organisation(real_scan):
    path = real_scan("nuscenes_hdl32e_sweep.bin")
    raw = np.fromfile(path, np.float32).reshape(-1, 5)
    scan = read_real_scan(path)
    assert scan.format == "nuscenes" and scan.organised and scan.rings == 32
    np.testing.assert_allclose(scan.points, np.column_stack([raw[:, 1], -raw[:, 0], raw[:, 2]]), atol=1e-6)
    np.testing.assert_allclose(scan.intensity, raw[:, 3] / 255.0)
    assert any("x right, y forward" in n for n in scan.notes)


def test_kitti_and_semantickitti(real_scan):
    kitti = read_real_scan(real_scan("kitti_hdl64e_000008_frontfov.bin"))
    assert kitti.format == "kitti" and len(kitti) == 17238 and kitti.labels is None
    assert (kitti.points[:, 0] > 0).mean() > 0.99  # the front camera's field of view is +x
    path = real_scan("semantickitti_sample.bin")
    assert guess_format(path) == "semantickitti"
    sk = read_real_scan(path)
    raw = np.fromfile(path.with_suffix(".label"), np.uint32)
    assert len(sk) == 50 and (sk.labels == raw).all()


def test_ply_las_pcd_npy_round_trips(tmp_path):
    plyfile = pytest.importorskip("plyfile")
    laspy = pytest.importorskip("laspy")
    xyz, intensity, ring = cloud()
    vertex = np.zeros(len(xyz), [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4"), ("ring", "u2")])
    vertex["x"], vertex["y"], vertex["z"], vertex["intensity"], vertex["ring"] = *xyz.T, intensity, ring
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")]).write(str(tmp_path / "a.ply"))
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales, header.offsets = [0.0001] * 3, [0.0] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.intensity = np.round(intensity * 65535).astype(np.uint16)
    las.write(str(tmp_path / "a.las"))
    fields = "FIELDS x y z intensity ring\nSIZE 4 4 4 4 2\nTYPE F F F F U\nCOUNT 1 1 1 1 1\n"
    body = f"VERSION 0.7\n{fields}WIDTH {len(xyz)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(xyz)}\n"
    rec = np.zeros(len(xyz), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2")])
    rec["x"], rec["y"], rec["z"], rec["intensity"], rec["ring"] = *xyz.T, intensity, ring
    (tmp_path / "b.pcd").write_bytes((body + "DATA binary\n").encode() + rec.tobytes())
    lines = "\n".join(f"{a:.6f} {b:.6f} {c:.6f} {i:.6f} {r}" for (a, b, c), i, r in zip(xyz, intensity, ring))
    (tmp_path / "a.pcd").write_text(body + "DATA ascii\n" + lines + "\n")
    np.save(tmp_path / "p.npy", np.column_stack([xyz, intensity]).astype(np.float32))
    for name, atol in (("a.ply", 1e-5), ("a.las", 1e-4), ("a.pcd", 1e-5), ("b.pcd", 1e-5), ("p.npy", 1e-5)):
        scan = read_real_scan(tmp_path / name)
        np.testing.assert_allclose(scan.points, xyz, atol=atol, err_msg=name)
        np.testing.assert_allclose(scan.intensity, intensity, atol=1e-4, err_msg=name)
        if name.endswith((".ply", ".pcd")):
            assert (scan.ring == ring).all(), name
    # an organised (rings, columns, 4) array lists every firing column after column
    grid = np.zeros((4, 10, 4), np.float32)
    grid[:, :, 0] = 5.0
    grid[1, 3] = 0.0  # an empty firing
    np.save(tmp_path / "o.npy", grid)
    scan = read_real_scan(tmp_path / "o.npy")
    assert scan.organised and scan.rings == 4 and len(scan) == 40 and (scan.ring[:4] == np.arange(4)).all()


def test_bad_files_say_which_and_why(tmp_path):
    (tmp_path / "odd.bin").write_bytes(np.zeros(7, np.float32).tobytes())
    with pytest.raises(InputError, match="scene.format"):
        read_real_scan(tmp_path / "odd.bin")
    with pytest.raises(InputError, match="4 fields"):
        read_real_scan(tmp_path / "odd.bin", "kitti")
    with pytest.raises(InputError, match="is not a file"):
        read_real_scan(tmp_path / "none.bin")
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(InputError, match="cannot guess"):
        read_real_scan(tmp_path / "x.txt")
    with pytest.raises(InputError, match="one of"):
        read_real_scan(tmp_path / "x.txt", "xyz")
    (tmp_path / "c.pcd").write_text("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA binary_compressed\n")
    with pytest.raises(InputError, match="binary_compressed"):
        read_real_scan(tmp_path / "c.pcd")
    (tmp_path / "s.bin").write_bytes(np.zeros(8, np.float32).tobytes())
    with pytest.raises(InputError, match="label"):
        read_real_scan(tmp_path / "s.bin", "semantickitti")
