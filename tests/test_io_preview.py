"""Preview PNG: decodes, bounded size, the class colours present, equal aspect in the top view, occlusion, legend, boxes, scale bar."""

import struct
import zlib

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import preview, render_preview, write_preview
from bpy_pipeline.geometry.boxes import BOX_DTYPE
from bpy_pipeline.io.preview import BACKGROUND, INK, SIZE
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points


def decode_png(data: bytes, kinds_seen: list | None = None) -> np.ndarray:
    """A minimal decoder for 8-bit RGB or indexed, non-interlaced PNGs with unfiltered rows; checks every CRC.
    ``kinds_seen`` (a list) receives the colour type."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, header, kinds, palette = 8, b"", None, [], None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length])
        assert zlib.crc32(kind + body) & 0xFFFFFFFF == crc, kind
        kinds.append(kind)
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"PLTE":
            assert len(body) % 3 == 0 and 3 <= len(body) <= 768
            palette = np.frombuffer(body, np.uint8).reshape(-1, 3)
        elif kind == b"IDAT":
            idat += body
    assert pos == len(data) and kinds[0] == b"IHDR" and kinds[-1] == b"IEND"
    w, h, depth, color_type, compression, filter_method, interlace = header
    assert (depth, compression, filter_method, interlace) == (8, 0, 0, 0) and color_type in (2, 3)
    if kinds_seen is not None:
        kinds_seen.append(color_type)
    channels = 3 if color_type == 2 else 1
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + channels * w)
    assert not raw[:, 0].any(), "row filter types other than None are not decoded here"
    if color_type == 2:
        return raw[:, 1:].reshape(h, w, 3)
    assert kinds.index(b"PLTE") < kinds.index(b"IDAT") and raw[:, 1:].max() < len(palette)
    return palette[raw[:, 1:]]


def colours(image):
    return {tuple(int(c) for c in rgb) for rgb in np.unique(image.reshape(-1, 3), axis=0)}


LUT = load_class_table().color_lut()


FRAME = set(preview.FRAME_COLOURS)  # background, text, scale bar, boxes, the line between the views


def test_png_shows_the_present_class_colours_and_no_other(tmp_path):
    rng = np.random.default_rng(0)
    pts = empty_points(2000)
    pts["x"], pts["y"], pts["z"] = rng.uniform(-50, 50, (3, 2000))
    classes = np.array([1, 3, 8, 21])
    pts["semantic"] = classes[rng.integers(0, 4, 2000)]
    image = decode_png(write_preview(tmp_path / "p.png", pts, LUT, size=(400, 200)).read_bytes())
    assert image.shape == (200, 400, 3)
    assert colours(image) - FRAME == {tuple(int(c) for c in LUT[k]) for k in classes}
    assert (image[:, :199] != BACKGROUND).any(axis=2).any() and (image[:, 201:] != BACKGROUND).any(axis=2).any()


def test_empty_cloud_is_a_valid_background_image(tmp_path):
    image = decode_png(write_preview(tmp_path / "p.png", empty_points(0), LUT).read_bytes())
    assert image.shape == (SIZE[1], SIZE[0], 3) and colours(image) == {BACKGROUND}


def test_size_is_bounded_for_huge_coordinates():
    pts = empty_points(3)
    pts["x"], pts["y"], pts["z"] = [-1e6, 0, 1e6], [5e5, 0, 1], [0, 1, 2]
    pts["semantic"] = 5
    image = render_preview(pts, LUT)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    assert 1 <= (image == LUT[5]).all(axis=2).sum() <= 6


def painted_box(image, colour):
    rows, cols = np.nonzero((image == colour).all(axis=2))
    return cols.max() - cols.min(), rows.max() - rows.min()


def test_equal_aspect_in_the_top_view():
    # a 10 m x 20 m grid of points (x forward is up the image): 20 m wide, 10 m tall on screen
    xs, ys = np.meshgrid(np.linspace(0, 10, 41), np.linspace(-10, 10, 81), indexing="ij")
    pts = empty_points(xs.size)
    pts["x"], pts["y"] = xs.ravel(), ys.ravel()
    pts["semantic"] = 17
    image = render_preview(pts, LUT, size=(800, 400))
    width, height = painted_box(image[:, 401:], LUT[17])
    assert abs(width / height - 2.0) < 0.05 and width > 300


def test_higher_points_cover_lower_ones_from_above_and_the_perspective_shows_depth():
    pts = empty_points(4)
    pts["x"], pts["y"], pts["z"] = [0, 0, 10, -10], [0, 0, 5, -5], [1, 3, 0, 0]
    pts["semantic"] = [1, 8, 2, 2]  # ground below a contact wire
    top = render_preview(pts, LUT, size=(200, 100))[:, 101:]
    assert tuple(LUT[8]) in colours(top) and tuple(LUT[1]) not in colours(top)
    # in perspective the viewer is behind and above the sensor (-x): points along x stay apart on screen
    pts = empty_points(4)
    pts["x"] = [20.0, 40.0, 0.0, 60.0]
    pts["z"] = [0.0, 0.0, 0.0, 0.0]
    pts["semantic"] = [8, 1, 2, 2]
    image = render_preview(pts, LUT, size=(400, 200))[:, :199]
    assert tuple(LUT[8]) in colours(image) and tuple(LUT[1]) in colours(image)  # different pixels: both seen


def test_legend_names_the_classes_and_boxes_are_drawn():
    rng = np.random.default_rng(1)
    pts = empty_points(3000)
    pts["x"], pts["y"] = rng.uniform(-20, 20, (2, 3000))
    pts["semantic"] = 1
    plain = render_preview(pts, LUT, size=(600, 300))
    labelled = render_preview(pts, LUT, size=(600, 300), names={1: "ground"})
    corner = (slice(0, 30), slice(0, 120))
    assert not (plain[corner] == INK).all(axis=2).any() and (labelled[corner] == INK).all(axis=2).sum() > 20
    box = np.zeros(1, BOX_DTYPE)
    box["centre"], box["size"], box["heading"] = (5.0, 5.0, 0.5), (4.0, 2.0, 1.5), 0.3
    boxed = render_preview(pts, LUT, size=(600, 300), boxes=box)
    top = (slice(0, 270), slice(301, 600))  # above the scale bar
    assert (boxed[top] == INK).all(axis=2).sum() > (plain[top] == INK).all(axis=2).sum() + 40
    assert (plain[270:, 301:] == INK).all(axis=2).any()  # the scale bar and its length


def test_nan_points_are_skipped_and_unknown_classes_refused():
    pts = empty_points(3)
    pts["x"] = [0, np.nan, 1]
    pts["semantic"] = 3
    assert colours(render_preview(pts, LUT, size=(100, 50))) - FRAME == {tuple(LUT[3])}
    pts["semantic"] = len(LUT)
    with pytest.raises(InputError, match="no colour"):
        render_preview(pts, LUT)


def splat_by_pixel(image, col, row, depth, colors, depth_image):
    """The rule written out one point at a time: a point paints its pixel when its depth is at least what the pixel holds."""
    for k in range(len(col)):
        if depth[k] >= depth_image[row[k], col[k]]:
            depth_image[row[k], col[k]] = depth[k]
            image[row[k], col[k]] = colors[k]


def test_splat_keeps_the_nearest_point_and_the_later_of_equal_depths():
    from bpy_pipeline.io.preview import splat

    rng = np.random.default_rng(5)
    n = 3000
    col, row = rng.integers(0, 12, n), rng.integers(0, 9, n)  # many points a pixel
    depth = rng.integers(0, 6, n).astype(float)  # many ties
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    expected, held = np.zeros((9, 12, 3), np.uint8), np.full((9, 12), -np.inf)
    held[0, :], held[1, :] = 10.0, 5.0  # a first part already painted there: nearer than all, as near as the nearest
    expected_held = held.copy()
    splat_by_pixel(expected, col, row, depth, colors, expected_held)
    image = np.zeros((9, 12, 3), np.uint8)
    splat(image, col, row, depth, colors, held)
    assert (image == expected).all() and (held == expected_held).all()
    alone, expected_alone = np.zeros((9, 12, 3), np.uint8), np.zeros((9, 12, 3), np.uint8)
    splat(alone, col, row, depth, colors)
    splat_by_pixel(expected_alone, col, row, depth, colors, np.full((9, 12), -np.inf))
    assert (alone == expected_alone).all() and (alone != image).any()


def test_the_compiled_panel_paint_gives_the_numpy_paths_pixels(monkeypatch):
    """A cloud with ties, points behind the perspective camera, points outside both panels and coordinates far off
    (pixels beyond int64 in the numpy path), and boxes whose top-view lines reach into the perspective's panel: the
    compiled projection-and-splat of both panels and the numpy path (a panel at a time) paint the same image."""
    from bpy_pipeline.io import preview

    if preview._panels_kernel() is None:
        pytest.skip("numba is not installed (or BPY_PIPELINE_SCAN_KERNEL=numpy): only the numpy path exists")
    rng = np.random.default_rng(11)
    pts = empty_points(20000)
    for axis in "xyz":
        pts[axis] = np.round(rng.normal(0, 8, len(pts)), 1)  # rounded: many equal depths and pixels
    pts["x"][:200] = -40.0  # behind the perspective camera
    pts["y"][200:300] = 1e25  # beyond any pixel, beyond int64 once projected
    pts["semantic"] = rng.integers(0, len(LUT), len(pts))
    boxes = np.zeros(4, BOX_DTYPE)
    boxes["size"] = 2.0
    boxes["centre"][2:] = [[0.0, 60.0, 0.0], [5.0, 35.0, 1.0]]  # far left of the top view's crop (about y within +-20 m): drawn in the perspective's panel
    boxes["size"][2:] = [[8.0, 50.0, 3.0], [4.0, 30.0, 2.0]]
    compiled = render_preview(pts, LUT, boxes=boxes, names=load_class_table().names)
    monkeypatch.setattr(preview, "_panels_kernel", lambda: None)
    monkeypatch.setattr(preview, "_splat_kernel", lambda: None)
    numpy_path = render_preview(pts, LUT, boxes=boxes, names=load_class_table().names)
    assert (compiled == numpy_path).all() and len(colours(compiled) - FRAME) > 3


def test_segments_drawn_at_once_paint_the_pixels_of_one_linspace_per_segment():
    """draw_segments samples every segment in one pass; a segment at a time with np.linspace (the reference
    below, the code it replaced) paints the same pixels: zero-length segments, long ones cut at the image's
    bound, and segments partly or wholly outside."""

    def reference(image, starts, ends, color=preview.INK):
        length = np.minimum(np.ceil(np.abs(ends - starts).max(axis=1)).astype(np.int64) + 1, 4 * sum(image.shape[:2]))
        t = np.concatenate([np.linspace(0.0, 1.0, n) for n in length])
        which = np.repeat(np.arange(len(starts)), length)
        col, row = np.rint(starts[which] + t[:, None] * (ends[which] - starts[which])).astype(np.int64).T
        keep = (col >= 0) & (col < image.shape[1]) & (row >= 0) & (row < image.shape[0])
        image[row[keep], col[keep]] = color

    rng = np.random.default_rng(7)
    for trial in range(30):
        k = int(rng.integers(1, 200))
        starts = rng.uniform(-100, 400, (k, 2))
        ends = starts + rng.normal(0, [3, 40, 400][trial % 3], (k, 2))
        ends[::5] = starts[::5]  # zero length: one sample
        ends[1] = starts[1] + 1e5  # longer than the cap
        ours, theirs = np.zeros((240, 320, 3), np.uint8), np.zeros((240, 320, 3), np.uint8)
        preview.draw_segments(ours, starts, ends)
        reference(theirs, starts, ends)
        assert np.array_equal(ours, theirs)
        assert ours.any()


def test_the_written_preview_is_indexed_and_decodes_to_the_rendered_pixels(tmp_path):
    """write_preview writes palette indices (a third of the bytes to compress): decoded, the pixels of render_preview,
    boxes, legend and scale bar included; with more classes present than a palette holds, a truecolour PNG of the same pixels."""
    rng = np.random.default_rng(4)
    pts = empty_points(5000)
    pts["x"], pts["y"], pts["z"] = rng.uniform(-30, 30, 5000), rng.uniform(-20, 20, 5000), rng.uniform(-2, 3, 5000)
    pts["semantic"] = np.array([10, 40, 30, 50])[rng.integers(0, 4, 5000)]
    boxes = np.zeros(2, BOX_DTYPE)
    boxes["centre"] = [[5.0, 2.0, 0.5], [-8.0, -4.0, 0.8]]
    boxes["size"] = [[4.0, 2.0, 1.5], [0.6, 0.6, 1.8]]
    table = load_class_table()
    kinds = []
    decoded = decode_png(write_preview(tmp_path / "p.png", pts, LUT, boxes=boxes, names=table.names).read_bytes(), kinds)
    rendered = render_preview(pts, LUT, boxes=boxes, names=table.names)
    assert kinds == [3] and np.array_equal(decoded, rendered) and (rendered == INK).all(axis=2).sum() > 100
    assert (tmp_path / "p.png").stat().st_size < len(preview.encode_png(rendered))

    many = np.tile(np.arange(300, dtype=np.uint8)[:, None], 3)  # 300 classes (colours repeat: the palette need not be unique)
    pts["semantic"] = rng.integers(0, 300, 5000)
    kinds = []
    decoded = decode_png(write_preview(tmp_path / "q.png", pts, many).read_bytes(), kinds)
    assert kinds == [2] and np.array_equal(decoded, render_preview(pts, many))


def test_an_indexed_png_needs_a_palette_of_1_to_256_colours_and_a_2d_index():
    index = np.zeros((4, 5), np.uint8)
    with pytest.raises(ValueError, match="palette of 1 to 256 colours"):
        preview.encode_png_indexed(index, np.zeros((257, 3), np.uint8))
    with pytest.raises(ValueError, match="index image"):
        preview.encode_png_indexed(np.zeros((4, 5, 1), np.uint8), np.zeros((2, 3), np.uint8))
    assert np.array_equal(decode_png(preview.encode_png_indexed(index + 1, [[0, 0, 0], [9, 8, 7]])), np.full((4, 5, 3), [9, 8, 7], np.uint8))


def test_the_crop_percentiles_and_the_median_are_numpys():
    """The preview's crop (1st and 99th percentiles) and its camera target's height (the median) come from one partition
    each: the values ``np.percentile`` and ``np.median`` give, for odd and even counts, ties and a single value."""
    from bpy_pipeline.io.preview import median, percentiles

    rng = np.random.default_rng(5)
    for n in [1, 2, 3, 4, 7, 100, 101, 1234, 20001]:
        for values in (rng.normal(0, 30, n), np.round(rng.normal(0, 3, n), 1), np.full(n, 2.5)):
            assert percentiles(values, (1, 99)) == list(np.percentile(values, [1, 99]))
            assert median(values) == np.median(values)
