"""The write stage's faster paths give the bytes of the plain ones: the KITTI image's compiled paint, the PLY records'
compiled copy, the label lines' choice of points, the preview's order statistics, the packed x y z (intensity) columns."""

import numpy as np
import pytest

from bpy_pipeline.config import CameraConfig
from bpy_pipeline.io import kitti, ply, preview
from bpy_pipeline.io._records import packed_columns
from bpy_pipeline.lidar.points import POINT_DTYPE
from bpy_pipeline.labels import load_class_table
from samples import random_points


def camera_cloud(n: int, seed: int) -> np.ndarray:
    """Points ahead of the default camera and around it: ties, points behind it, outside the image, on its edges, NaN."""
    rng = np.random.default_rng(seed)
    pts = random_points(n, rng, extent=30.0, instances=40)
    pts["x"] = np.round(rng.uniform(-5, 40, n), 1)  # many equal depths
    pts["x"][:50] = np.nan
    pts["y"][50:100] = 1e30  # beyond any pixel
    pts["x"][100:150] = 0.05  # nearer than MIN_DEPTH
    pts["semantic"][150:200] = 60000  # beyond the colour table: its last colour
    k, tr = kitti.camera_matrices(CameraConfig())
    width, height = CameraConfig().resolution
    on_edge = np.linalg.solve(tr[:, :3], (np.array([[0.0, 0.0, 1.0], [width, height, 1.0], [width - 1e-9, 0.0, 1.0]]) * 10.0 - tr[:, 3]).T).T
    for axis, name in enumerate("xyz"):
        pts[name][200:203] = on_edge[:, axis]  # pixels on the image's edges (as float32 rounds them)
    return pts


@pytest.mark.parametrize("dot", [1, 2, 3, 4])
def test_the_kitti_images_compiled_paint_gives_the_numpy_paths_pixels(monkeypatch, dot):
    if kitti._square_kernels() is None:
        pytest.skip("numba is not installed (or BPY_PIPELINE_SCAN_KERNEL=numpy): only the numpy path exists")
    lut = load_class_table().color_lut()
    for seed in range(3):
        pts = camera_cloud(20000, seed)
        compiled = kitti.render_image(pts, CameraConfig(), lut, dot=dot)
        with monkeypatch.context() as patch:
            patch.setattr(kitti, "_square_kernels", lambda: None)
            numpy_path = kitti.render_image(pts, CameraConfig(), lut, dot=dot)
        assert np.array_equal(compiled, numpy_path) and len(np.unique(compiled.reshape(-1, 3), axis=0)) > 5
    assert np.array_equal(kitti.render_image(pts[:0], CameraConfig(), lut), np.broadcast_to(np.array(kitti.IMAGE_BACKGROUND, np.uint8), compiled.shape))


def test_the_ply_records_compiled_copy_gives_the_field_by_field_bytes(monkeypatch):
    assert ply.byte_runs(POINT_DTYPE, ply.PLY_DTYPE) == ply.KERNEL_RUNS
    assert ply.byte_runs(np.dtype([("x", ">f4")]), np.dtype([("x", ">f4")])) is None  # big-endian: not a copy of bytes
    assert ply.byte_runs(np.dtype([("x", "<f8")]), np.dtype([("x", "<f4")])) is None  # a conversion
    pts = random_points(5000, np.random.default_rng(3), instances=2**31)
    pts["semantic"][:10] = 65535
    pts["ring"][:10] = 65535
    reference = np.empty(len(pts), ply.PLY_DTYPE)
    for name in ply.PLY_DTYPE.names:
        reference[name] = pts[ply.point_field(name)]
    if ply._records_kernel() is None:
        pytest.skip("numba is not installed (or BPY_PIPELINE_SCAN_KERNEL=numpy): only the numpy path exists")
    assert ply.ply_records(pts).tobytes() == reference.tobytes() and ply.ply_records(pts[:0]).tobytes() == b""
    monkeypatch.setattr(ply, "_records_kernel", lambda: None)
    assert ply.ply_records(pts).tobytes() == reference.tobytes()


def test_the_label_lines_points_are_those_of_one_stable_sort_by_instance():
    rng = np.random.default_rng(4)
    for instances, top in [(rng.integers(0, 50, 3000), 50), (rng.integers(0, 2**32, 3000, dtype=np.uint64).astype(np.uint32), 2**32)]:
        wanted = np.unique(np.concatenate([instances[rng.integers(0, len(instances), 12)], [top + 7, 0]]))
        order = np.argsort(instances, kind="stable")
        expected = order[np.isin(instances[order], wanted)]
        assert np.array_equal(kitti.points_of_instances(instances, wanted), expected)
    assert len(kitti.points_of_instances(instances, np.zeros(0, np.int64))) == 0


@pytest.mark.filterwarnings("ignore:invalid value encountered in subtract")
def test_the_order_statistics_are_one_partitions():
    """Large arrays take a sample's bracket; the values are one whole partition's: periodic data (a scan's rings),
    sorted and reversed data, ties, NaN and infinities, float32."""
    rng = np.random.default_rng(6)
    n = 50001
    for values in (rng.normal(0, 30, n), np.tile(np.linspace(-2, 2, 64), n // 64 + 1)[:n], np.sort(rng.normal(0, 1, n)),
                   np.sort(rng.normal(0, 1, n))[::-1], np.round(rng.normal(0, 1, n), 1), np.full(n, 2.5),
                   np.where(rng.random(n) < 0.3, np.nan, rng.normal(0, 1, n)), np.where(rng.random(n) < 0.02, np.inf, rng.normal(0, 1, n)),
                   rng.normal(0, 30, n).astype(np.float32)):
        for ranks in ([0], [n - 1], [n // 100, n // 100 + 1, n - n // 100 - 1, n - n // 100], [n // 2 - 1, n // 2], [5, n // 2, n - 5]):
            expected = np.partition(np.array(values, np.float64), ranks)[ranks]
            assert np.array_equal(preview.order_statistics(values, ranks), expected, equal_nan=True)
        assert np.array_equal(preview.percentiles(values, (1, 99)), np.percentile(values.astype(np.float64), (1, 99)), equal_nan=True) or np.isnan(values).any()


def test_packed_columns_are_the_fields_stacked():
    pts = random_points(1000, np.random.default_rng(8))
    for names in (("x", "y", "z"), ("x", "y", "z", "intensity"), ("x", "z"), ("intensity", "range")):
        assert np.array_equal(packed_columns(pts, names), np.column_stack([pts[name] for name in names]).astype("<f4"))
    pts["x"][:3] = [np.nan, np.inf, -0.0]
    for names in (("x", "y", "z"), ("x", "y", "z", "intensity"), ("x", "z")):  # as a block then cast, or field by field: the same bits
        wide = packed_columns(pts, names, np.float64)
        assert wide.dtype == np.float64 and wide.tobytes() == np.column_stack([pts[name].astype(np.float64) for name in names]).tobytes()


def test_the_compiled_labels_are_pack_labels(monkeypatch):
    from bpy_pipeline.io import semantickitti
    from bpy_pipeline.io.class_maps import semantic_kitti_lut

    pts = random_points(5000, np.random.default_rng(9), instances=1 << 16)
    pts["semantic"][:5] = [0, 1, 65535, 40, 255]
    lut = semantic_kitti_lut()
    expected = {None: semantickitti.pack_labels(pts["semantic"], pts["instance"]), "lut": semantickitti.pack_labels(lut[pts["semantic"]], pts["instance"])}
    for kernel in ("compiled", "numpy"):
        if kernel == "numpy":
            monkeypatch.setattr(semantickitti, "_labels_kernel", lambda: None)
        elif semantickitti._labels_kernel() is None:
            continue
        assert np.array_equal(semantickitti.frame_labels(pts), expected[None])
        assert np.array_equal(semantickitti.frame_labels(pts, lut), expected["lut"]) and semantickitti.frame_labels(pts, lut).dtype == np.dtype("<u4")
        assert np.array_equal(semantickitti.frame_labels(pts[1000:1100], lut), expected["lut"][1000:1100])


def test_class_counts_are_bincounts(monkeypatch):
    ids = np.random.default_rng(10).integers(0, 300, 20000).astype(np.uint16)
    expected = np.append(np.bincount(ids, minlength=300)[:260], np.count_nonzero(ids >= 260))
    assert np.array_equal(preview.class_counts(ids, 260), expected) and np.array_equal(preview.class_counts(ids[:0], 260), np.zeros(261))
    monkeypatch.setattr(preview, "_count_kernel", lambda: None)
    assert np.array_equal(preview.class_counts(ids, 260), expected)


def test_the_shared_xyzi_block_writes_the_same_files_and_digests(tmp_path):
    """SemanticKITTI's and the KITTI layout's velodyne files and OpenPCDet's points written from one x y z intensity
    block and its digest: the bytes and the recorded sha256 of writing each from the points (more than one chunk)."""
    import hashlib
    import os

    from bpy_pipeline.io import openpcdet, semantickitti
    from bpy_pipeline.io._records import CACHED_CHUNK, xyzi_block
    from bpy_pipeline.io.atomic import atomic_write, digests_while_writing, hashed_open

    pts = random_points(3 * CACHED_CHUNK + 5, np.random.default_rng(12), instances=1 << 16)
    files = {}
    for shared in (None, xyzi_block(pts)):
        out = tmp_path / ("shared" if shared else "alone")
        with digests_while_writing() as digests:
            written = [*semantickitti.write_semantickitti(out, 0, 3, pts, xyzi=shared),
                       *kitti.write_frame_text(out, "000003", pts, None, CameraConfig(), xyzi=shared),
                       *openpcdet.write_frame(out, "000003", pts, None, xyzi=shared)]
        for path in written:
            data = path.read_bytes()
            assert digests[os.path.abspath(path)] == hashlib.sha256(data).hexdigest()
            files.setdefault(path.relative_to(out), []).append(data)
    assert len(files) == 8 and all(a == b for a, b in files.values())
    with pytest.raises(ValueError, match="first write"), atomic_write(tmp_path / "x.bin") as tmp, hashed_open(tmp) as f:
        f.write(b"header")
        f.write(xyzi_block(pts).array, xyzi_block(pts).sha256)
