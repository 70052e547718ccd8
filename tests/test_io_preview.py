"""Preview PNG: decodes, bounded size, exactly the class colours plus background, equal aspect, occlusion."""

import struct
import zlib

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import render_preview, write_preview
from bpy_pipeline.io.preview import BACKGROUND
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points


def decode_png(data: bytes) -> np.ndarray:
    """A minimal decoder for 8-bit RGB, non-interlaced PNGs with unfiltered rows; checks every CRC."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, header, kinds = 8, b"", None, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length])
        assert zlib.crc32(kind + body) & 0xFFFFFFFF == crc, kind
        kinds.append(kind)
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
    assert pos == len(data) and kinds[0] == b"IHDR" and kinds[-1] == b"IEND"
    w, h, depth, color_type, compression, filter_method, interlace = header
    assert (depth, color_type, compression, filter_method, interlace) == (8, 2, 0, 0, 0)
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    assert not raw[:, 0].any(), "row filter types other than None are not decoded here"
    return raw[:, 1:].reshape(h, w, 3)


def colours(image):
    return {tuple(int(c) for c in rgb) for rgb in np.unique(image.reshape(-1, 3), axis=0)}


LUT = load_class_table().color_lut()


def test_png_shows_exactly_the_present_class_colours(tmp_path):
    rng = np.random.default_rng(0)
    pts = empty_points(2000)
    pts["x"], pts["y"], pts["z"] = rng.uniform(-50, 50, (3, 2000))
    classes = np.array([1, 3, 8, 21])
    pts["semantic"] = classes[rng.integers(0, 4, 2000)]
    image = decode_png(write_preview(tmp_path / "p.png", pts, LUT, size=(400, 200)).read_bytes())
    assert image.shape == (200, 400, 3)
    assert colours(image) == {tuple(int(c) for c in LUT[k]) for k in classes} | {BACKGROUND}
    assert (image[:, :200] != BACKGROUND).any(axis=2).any() and (image[:, 200:] != BACKGROUND).any(axis=2).any()


def test_empty_cloud_is_a_valid_background_image(tmp_path):
    image = decode_png(write_preview(tmp_path / "p.png", empty_points(0), LUT).read_bytes())
    assert image.shape == (800, 1600, 3) and colours(image) == {BACKGROUND}


def test_size_is_bounded_for_huge_coordinates():
    pts = empty_points(3)
    pts["x"], pts["y"], pts["z"] = [-1e6, 0, 1e6], [5e5, 0, 1], [0, 1, 2]
    pts["semantic"] = 5
    image = render_preview(pts, LUT)
    assert image.shape == (800, 1600, 3)
    assert (image != BACKGROUND).any(axis=2).sum() == 6  # three points in each view


def painted_box(image):
    rows, cols = np.nonzero((image != BACKGROUND).any(axis=2))
    return cols.max() - cols.min(), rows.max() - rows.min()


def test_equal_aspect_in_both_views():
    # Corners of a 10 m x 10 m square at z = 0 and z = 2: top view square, side view 10 : 2.
    xs, ys, zs = np.meshgrid([0.0, 10.0], [0.0, 10.0], [0.0, 2.0], indexing="ij")
    pts = empty_points(8)
    pts["x"], pts["y"], pts["z"] = xs.ravel(), ys.ravel(), zs.ravel()
    pts["semantic"] = 17
    image = render_preview(pts, LUT, size=(800, 400))
    top_w, top_h = painted_box(image[:, :400])
    side_w, side_h = painted_box(image[:, 400:])
    assert abs(top_w - top_h) <= 1 and top_h > 300
    assert abs(side_w / side_h - 5.0) < 0.1


def test_nearer_points_cover_farther_ones():
    pts = empty_points(4)
    pts["x"], pts["y"], pts["z"] = [0, 0, 10, 10], [0, 0, 5, 5], [1, 3, 0, 0]
    pts["semantic"] = [1, 8, 2, 2]  # ground below a contact wire
    image = render_preview(pts, LUT, size=(200, 100))
    top = image[:, :100]
    assert tuple(LUT[8]) in colours(top) and tuple(LUT[1]) not in colours(top)
    pts["z"] = [0, 0, 0, 5]
    pts["y"] = [2, -2, 0, 0]  # same x and z: the one with smaller y faces the side viewer
    pts["semantic"] = [1, 8, 2, 2]
    side = render_preview(pts, LUT, size=(200, 100))[:, 100:]
    assert tuple(LUT[8]) in colours(side) and tuple(LUT[1]) not in colours(side)


def test_nan_points_are_skipped_and_unknown_classes_refused():
    pts = empty_points(3)
    pts["x"] = [0, np.nan, 1]
    pts["semantic"] = 3
    assert colours(render_preview(pts, LUT, size=(100, 50))) == {tuple(LUT[3]), BACKGROUND}
    pts["semantic"] = len(LUT)
    with pytest.raises(InputError, match="no colour"):
        render_preview(pts, LUT)
