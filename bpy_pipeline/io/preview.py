"""Preview images of a labelled cloud: a perspective view from behind and above the sensor, and a top view.

The image is two panels side by side on a dark background:

- left, a perspective view from behind and above the sensor (sensor frame: x forward), looking at the
  middle of the cloud, nearer points drawn over farther ones;
- right, a top view (x up the image, y to the left, as seen from above behind the sensor) cropped to
  where most points are (the 1st to 99th percentile of x and y; when one class holds more than 40 %
  of the points, as a railway's ground does, of the other classes' points, so ground rings do not
  shrink the scene), with a scale bar.

Points are coloured by class; a legend names the classes present; 3D boxes (BOX_DTYPE, the frame
of the points) are drawn in both panels in white. Rasterisation is vectorised numpy; text uses a
built-in 3 x 5 pixel font; PNG encoding uses only ``zlib`` and ``struct`` (level 1: the image is
mostly background, and level 1 is about as small here at a fraction of the time). The preview is
drawn in palette indices (a byte a pixel: the frame's colours, then one a class present) and written
as an indexed PNG: a third of the bytes to compress of an RGB image, with the same pixels once decoded.
"""

from __future__ import annotations

import os
import struct
import zlib
from functools import cache
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..compiled import compiled_wanted
from ..geometry.boxes import box_corners
from ._records import as_points, packed_columns
from .atomic import atomic_write, hashed_open

BACKGROUND = (24, 24, 28)  # not a class colour of assets_manifest/labels.yaml
INK = (235, 235, 235)  # text, scale bar and boxes
MARGIN = 8  # pixels around the cloud inside each panel
PNG_LEVEL = 1
SIZE = (1280, 560)  # (width, height) pixels
FONT = {  # 3 x 5 glyphs, rows top to bottom
    "a": ("010", "101", "111", "101", "101"), "b": ("110", "101", "110", "101", "110"), "c": ("011", "100", "100", "100", "011"),
    "d": ("110", "101", "101", "101", "110"), "e": ("111", "100", "110", "100", "111"), "f": ("111", "100", "110", "100", "100"),
    "g": ("011", "100", "101", "101", "011"), "h": ("101", "101", "111", "101", "101"), "i": ("111", "010", "010", "010", "111"),
    "j": ("001", "001", "001", "101", "010"), "k": ("101", "101", "110", "101", "101"), "l": ("100", "100", "100", "100", "111"),
    "m": ("101", "111", "111", "101", "101"), "n": ("110", "101", "101", "101", "101"), "o": ("010", "101", "101", "101", "010"),
    "p": ("110", "101", "110", "100", "100"), "q": ("010", "101", "101", "110", "011"), "r": ("110", "101", "110", "101", "101"),
    "s": ("011", "100", "010", "001", "110"), "t": ("111", "010", "010", "010", "010"), "u": ("101", "101", "101", "101", "111"),
    "v": ("101", "101", "101", "101", "010"), "w": ("101", "101", "111", "111", "101"), "x": ("101", "101", "010", "101", "101"),
    "y": ("101", "101", "010", "010", "010"), "z": ("111", "001", "010", "100", "111"), "0": ("111", "101", "101", "101", "111"),
    "1": ("010", "110", "010", "010", "111"), "2": ("110", "001", "010", "100", "111"), "3": ("110", "001", "010", "001", "110"),
    "4": ("101", "101", "111", "001", "001"), "5": ("111", "100", "110", "001", "110"), "6": ("011", "100", "110", "101", "010"),
    "7": ("111", "001", "010", "010", "010"), "8": ("010", "101", "010", "101", "010"), "9": ("010", "101", "011", "001", "110"),
    " ": ("000", "000", "000", "000", "000"), ".": ("000", "000", "000", "000", "010"), "-": ("000", "000", "111", "000", "000"),
    "_": ("000", "000", "000", "000", "111"),
}  # fmt: skip
GLYPHS = {char: np.array([[c == "1" for c in line] for line in rows]) for char, rows in FONT.items()}  # (5, 3) bool each
BOX_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))


FRAME_COLOURS = (BACKGROUND, INK, (60, 60, 66))  # a preview's palette entries 0 (the background), 1 (text, scale bar, boxes) and 2 (the divider)
PEN, DIVIDER = (1,), (2,)  # their indices as one-channel pixel values


def _png(kind: int, rows: np.ndarray, w: int, level: int, palette: np.ndarray | None = None) -> bytes:
    """PNG file bytes: 8-bit colour type ``kind`` (2 truecolour, 3 indexed with ``palette`` (m, 3) uint8),
    ``w`` pixels wide, from ``rows`` (h, bytes a row) uint8 without their filter bytes (0, None, is put before each)."""
    h = rows.shape[0]
    filtered = np.empty((h, 1 + rows.shape[1]), np.uint8)
    filtered[:, 0] = 0
    filtered[:, 1:] = rows

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = (chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, kind, 0, 0, 0))
              + (b"" if palette is None else chunk(b"PLTE", np.ascontiguousarray(palette, np.uint8).tobytes())))
    return b"\x89PNG\r\n\x1a\n" + header + chunk(b"IDAT", zlib.compress(filtered, level)) + chunk(b"IEND", b"")


def encode_png(rgb: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """PNG file bytes of an ``(h, w, 3) uint8`` RGB image (8-bit truecolour, no filtering)."""
    rgb = np.ascontiguousarray(rgb, np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (h, w, 3) uint8 image, got shape {rgb.shape}")
    h, w, _ = rgb.shape
    return _png(2, rgb.reshape(h, 3 * w), w, level)


def encode_png_indexed(index: np.ndarray, palette: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """PNG file bytes of an ``(h, w) uint8`` image of indices into ``palette`` ((m, 3) uint8, m <= 256; 8-bit indexed colour, no filtering)."""
    index, palette = np.ascontiguousarray(index, np.uint8), np.asarray(palette, np.uint8)
    if index.ndim != 2 or palette.ndim != 2 or palette.shape[1] != 3 or not 1 <= len(palette) <= 256:
        raise ValueError(f"expected an (h, w) uint8 index image and an (m, 3) palette of 1 to 256 colours, got shapes {index.shape} and {palette.shape}")
    return _png(3, index, index.shape[1], level, palette)


@cache
def _splat_kernel():
    """The compiled splat (numba, cached on disk), or ``None`` without numba or when
    ``BPY_PIPELINE_SCAN_KERNEL=numpy`` asks for the numpy path (both paint the same pixels)."""
    if not compiled_wanted():
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def splat_into(flat, pixel, depth, colors, best):  # pragma: no cover (compiled)
        for i in range(len(pixel)):  # in order: a point at least as deep as the pixel's best so far wins it
            p = pixel[i]
            if depth[i] >= best[p]:
                best[p] = depth[i]
                for c in range(flat.shape[1]):  # the pixel's channels (3 for RGB, 1 for a palette index)
                    flat[p, c] = colors[i, c]

    return splat_into


@cache
def _panels_kernel():
    """The compiled projection-to-pixels and splat of both panels in one pass over the points (numba, cached on disk), or
    ``None`` (as :func:`_splat_kernel`). Each point's pixel in each panel comes from the numpy path's operations in its order
    (no fused multiply-add, no fast-math), so both paint the same pixels: the panels' pixels are apart, so painting a point
    into both before the next point gives what painting every point into one panel, then into the other, gives."""
    if _splat_kernel() is None:
        return None
    import numba

    # flat: the (height * width,) image; best_top and best_side (height * panel_width,) float64: the top view's and the
    # perspective's depth per pixel, -inf where empty.
    # xyz: (n, 3) float32 points, each value taken to float64 as numpy's path has them; semantic (n,) class ids, entry
    # their palette indices. numpy's path: col, row = rint(u), rint(v) as int64, kept where 0 <= col < panel_width and
    # 0 <= row < height (the float tests on the rounded values decide alike, also for NaN and out-of-range values, which
    # numpy's int64 cast turns into the smallest int64); then the splat's rule in point order (at least as deep wins).
    @numba.njit(cache=True, nogil=True)
    def panels(flat, best_top, best_side, xyz, semantic, entry, centre0, centre1, scale, eye, rotation, focal, half_w, half_h, width,
               panel_width, height):  # pragma: no cover (compiled)
        for i in range(len(xyz)):
            x, y, z = np.float64(xyz[i, 0]), np.float64(xyz[i, 1]), np.float64(xyz[i, 2])
            colour = entry[semantic[i]]
            # the top view, right: u = half_w - (y - centre1) * scale, v = half_h - (x - centre0) * scale, depth z
            col = np.rint(half_w - (y - centre1) * scale)
            row = np.rint(half_h - (x - centre0) * scale)
            if col >= 0.0 and col < panel_width and row >= 0.0 and row < height:
                q = np.int64(row) * panel_width + np.int64(col)
                if z >= best_top[q]:
                    best_top[q] = z
                    flat[np.int64(row) * width + np.int64(col) + panel_width] = colour
            # the perspective, left, in the camera frame as _camera has it; in front (depth > 0.1):
            # u = half_w + focal * x / depth, v = half_h + focal * y / depth, depth -depth
            dx, dy, dz = x - eye[0], y - eye[1], z - eye[2]
            cam0 = dx * rotation[0, 0] + dy * rotation[0, 1] + dz * rotation[0, 2]
            cam1 = dx * rotation[1, 0] + dy * rotation[1, 1] + dz * rotation[1, 2]
            cam2 = dx * rotation[2, 0] + dy * rotation[2, 1] + dz * rotation[2, 2]
            if cam2 > 0.1:
                col = np.rint(half_w + focal * cam0 / cam2)
                row = np.rint(half_h + focal * cam1 / cam2)
                if col >= 0.0 and col < panel_width and row >= 0.0 and row < height:
                    q = np.int64(row) * panel_width + np.int64(col)
                    depth = -cam2
                    if depth >= best_side[q]:
                        best_side[q] = depth
                        flat[np.int64(row) * width + np.int64(col)] = colour

    return panels


@cache
def _count_kernel():
    """The compiled count of :func:`class_counts` (numba, cached on disk), or ``None`` (as :func:`_splat_kernel`)."""
    if _splat_kernel() is None:
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def count(ids, counts):  # pragma: no cover (compiled)
        top = len(counts) - 1
        for i in range(len(ids)):
            counts[min(np.int64(ids[i]), top)] += 1

    return count


def class_counts(ids: np.ndarray, k: int) -> np.ndarray:
    """``(k + 1,)`` int64: how many of the ``(n,)`` non-negative integer ``ids`` are ``0 .. k - 1``, then how many are ``k`` or more."""
    kernel = _count_kernel()
    if kernel is None:
        return np.bincount(np.minimum(ids, k), minlength=k + 1)
    counts = np.zeros(k + 1, np.int64)
    kernel(ids, counts)
    return counts


def splat(image: np.ndarray, col: np.ndarray, row: np.ndarray, depth: np.ndarray, colors: np.ndarray, depth_image: np.ndarray | None = None) -> None:
    """Paint ``colors`` (n, c) at pixels ``(row, col)`` of ``image`` ((h, w, c): c = 3 for RGB, 1 for palette indices) in place; the largest ``depth`` wins.

    Of equal depths the later point wins. depth_image : ``(height, width)`` float64 depth of what
    ``image`` holds (-inf where empty), updated in place, so a cloud can be painted part by part.
    With numba, one compiled pass in point order (a point at least as deep as the best so far
    takes the pixel: the last of the deepest ends there, as in the numpy path below).
    """
    if len(col) == 0:
        return
    pixels = image.shape[0] * image.shape[1]
    pixel = row * image.shape[1] + col
    best = np.full(pixels, -np.inf) if depth_image is None else depth_image.reshape(-1)
    kernel = _splat_kernel()
    if kernel is not None and image.flags.c_contiguous and best.flags.c_contiguous and (depth_image is None or np.shares_memory(best, depth_image)):
        kernel(image.reshape(pixels, -1), np.ascontiguousarray(pixel, np.int64), np.ascontiguousarray(depth, np.float64),
               np.ascontiguousarray(colors, image.dtype).reshape(len(pixel), -1), best)
        return
    np.maximum.at(best, pixel, depth)
    wins = np.flatnonzero(depth >= best[pixel])
    last = np.full(pixels, -1, np.int64)
    np.maximum.at(last, pixel[wins], wins)
    painted = np.flatnonzero(last >= 0)
    image.reshape(pixels, -1)[painted] = np.reshape(colors, (len(pixel), -1))[last[painted]]


@cache
def _glyph(char: str, scale: int) -> np.ndarray:
    """``(5 * scale, 3 * scale)`` bool: the glyph of ``char`` (a space for an unknown one), each pixel a ``scale`` square."""
    mask = GLYPHS.get(char, GLYPHS[" "]).repeat(scale, axis=0).repeat(scale, axis=1)
    mask.flags.writeable = False  # shared by every call
    return mask


def draw_text(image: np.ndarray, text: str, col: int, row: int, scale: int = 2, color=INK) -> int:
    """Write ``text`` (lower-cased; unknown characters as spaces) with its top left at ``(col, row)``; returns the end column."""
    for char in text.lower():
        mask = _glyph(char, scale)
        h, w = mask.shape
        r0, c0 = max(row, 0), max(col, 0)
        r1, c1 = min(row + h, image.shape[0]), min(col + w, image.shape[1])
        if r1 > r0 and c1 > c0:
            image[r0:r1, c0:c1][mask[r0 - row : r1 - row, c0 - col : c1 - col]] = color
        col += w + scale
    return col


def draw_segments(image: np.ndarray, starts: np.ndarray, ends: np.ndarray, color=INK, covered: np.ndarray | None = None) -> None:
    """Lines between pixel positions ``starts`` and ``ends`` (k, 2) as (col, row) floats; parts outside are clipped, and
    pixels where ``covered`` ((height, width) bool, optional) is true are left as they are."""
    if len(starts) == 0:
        return
    length = np.ceil(np.abs(ends - starts).max(axis=1)).astype(np.int64) + 1
    length = np.minimum(length, 4 * sum(image.shape[:2]))
    end = np.cumsum(length)  # one past each segment's samples
    which = np.repeat(np.arange(len(starts)), length)
    # np.linspace(0, 1, n) of every segment at once, bit for bit: k * (1 / (n - 1)), and 1 exactly at the end
    t = (np.arange(end[-1]) - np.repeat(end - length, length)) * (1.0 / np.maximum(length - 1, 1))[which]
    t[end[length > 1] - 1] = 1.0
    points = starts[which] + t[:, None] * (ends[which] - starts[which])
    col, row = np.rint(points).astype(np.int64).T
    keep = (col >= 0) & (col < image.shape[1]) & (row >= 0) & (row < image.shape[0])
    if covered is not None:
        keep[keep] = ~covered[row[keep], col[keep]]
    image[row[keep], col[keep]] = color


def nice_length(span: float) -> float:
    """A 1, 2 or 5 times a power of ten near a fifth of ``span`` (m): the scale bar's length."""
    target = max(span / 5, 1e-3)
    power = 10.0 ** np.floor(np.log10(target))
    return float(min((m * power for m in (1, 2, 5, 10)), key=lambda v: abs(v - target)))


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``(3, 3)`` world-to-camera rotation: rows right, down, forward (camera looks at ``target``, z up)."""
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([0.0, -1.0, 0.0])
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def _camera(p: np.ndarray, eye: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``(n, 3)`` camera-frame coordinates of ``(n, 3)`` points: ``(p - eye)`` times each row of the ``(3, 3)`` ``rotation``,
    added in axis order (a row's products summed one by one, as the compiled perspective does, instead of a matrix product
    whose summing order BLAS chooses): the same values in both paths."""
    d = p - eye
    cam = d[:, :1] * rotation[:, 0]
    cam += d[:, 1:2] * rotation[:, 1]
    cam += d[:, 2:3] * rotation[:, 2]
    return cam


SAMPLED = 8192  # from this many values on, order statistics are bracketed by a sample first (:func:`order_statistics`)
GOLDEN = (5**0.5 - 1) / 2  # the sample's positions: multiples of the golden ratio's fraction, a low-discrepancy sequence


def order_statistics(values: np.ndarray, ranks: list[int]) -> list[float]:
    """The values at positions ``ranks`` (sorted, each in ``[0, n)``) of ``np.sort(values)`` ((n,) floats), as floats.

    Exactly what one ``np.partition`` of the whole array gives (NaNs last), cheaper for large arrays: each run of nearby
    ranks is bracketed by two values of a sorted sample of 2,048, and only the values inside the bracket are
    partitioned, once the counts show the bracket holds those ranks (else the whole array is, as before).
    """
    values = np.ascontiguousarray(values)
    n = len(values)
    if n < SAMPLED:
        part = np.partition(values, ranks)
        return [float(part[r]) for r in ranks]
    sample = np.sort(values[(np.arange(2048) * GOLDEN % 1.0 * n).astype(np.int64)])  # spread without a stride: scans are periodic by ring
    m = len(sample)
    out: dict[int, float] = {}
    groups: list[list[int]] = []
    for r in ranks:  # ranks within a few sample steps of each other share a bracket
        if groups and r - groups[-1][-1] <= 4 * (n // m):
            groups[-1].append(r)
        else:
            groups.append([r])
    for group in groups:
        margin = int(4 * np.sqrt(m * 0.25)) + 8  # four standard deviations of a sample quantile's position, and some
        low, high = group[0] * m // n - margin, group[-1] * m // n + margin
        bracket = np.ones(n, bool) if low <= 0 else values >= sample[low]
        if high < m - 1:
            bracket &= values <= sample[high]
        below = 0 if low <= 0 else int(np.count_nonzero(values < sample[low]))
        inside = values[bracket]
        if below <= group[0] and group[-1] < below + len(inside):  # every value below the bracket ranks before it, every one above after it
            part = np.partition(inside, [r - below for r in group])
            out.update((r, float(part[r - below])) for r in group)
        else:
            part = np.partition(values, group)
            out.update((r, float(part[r])) for r in group)
    return [out[r] for r in ranks]


def percentiles(values: np.ndarray, q) -> list[float]:
    """``np.percentile(values, q)`` (its default, linear interpolation) of a ``(n,)`` float array with ``n >= 1`` taken to
    float64, from the order statistics it needs (:func:`order_statistics`): the same values at a fraction of the time. A
    float32 array is searched as it is (a rank's value is the same in either width), half the bytes."""
    n = len(values)
    at = [float(p) / 100 * (n - 1) for p in q]
    below = [int(np.floor(a)) for a in at]
    ranks = sorted({r for b in below for r in (b, min(b + 1, n - 1))})
    value = dict(zip(ranks, order_statistics(values, ranks)))
    out = []
    for a, b in zip(at, below):
        lo, hi, t = value[b], value[min(b + 1, n - 1)], a - b
        out.append(float(hi - (hi - lo) * (1 - t) if t >= 0.5 else lo + (hi - lo) * t))  # numpy's lerp, both halves
    return out


def median(values: np.ndarray) -> float:
    """``np.median`` of a ``(n,)`` float array with ``n >= 1`` taken to float64, from its middle order statistic(s)
    (:func:`order_statistics`; a float32 array's as it is, as :func:`percentiles`)."""
    n = len(values)
    lo, hi = order_statistics(values, sorted({(n - 1) // 2, n // 2})) * (2 if n % 2 else 1)
    return (lo + hi) / 2 if n % 2 == 0 else hi


def render_preview(points: np.ndarray, color_lut: np.ndarray, size: tuple[int, int] = SIZE, dot: int = 1, boxes: np.ndarray | None = None,
                   names: dict | None = None) -> np.ndarray:
    """The preview as an ``(height, width, 3) uint8`` RGB array (see the module docstring and :func:`render_indexed` for the arguments)."""
    index, palette = render_indexed(points, color_lut, size, dot, boxes, names)
    return np.take(palette, index[..., 0], axis=0)


def render_indexed(points: np.ndarray, color_lut: np.ndarray, size: tuple[int, int] = SIZE, dot: int = 1, boxes: np.ndarray | None = None,
                   names: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The preview in palette indices: ``(index, palette)``, ``palette[index[..., 0]]`` being the RGB image.

    index : (height, width, 1) uint8, or uint16 where more than 253 classes are present; palette : (m, 3)
    uint8, :data:`FRAME_COLOURS` then the colour of each class present, in class order.

    Parameters
    ----------
    points : (n,) POINT_DTYPE
        Points; those with non-finite coordinates are left out.
    color_lut : (k, 3) uint8
        RGB colour per raw class id (``load_class_table().color_lut()``); ``semantic`` must be < k.
    size : (width, height) int
        Image size in pixels; each panel is ``width // 2`` wide.
    dot : int
        Side of the square drawn per point, in pixels.
    boxes : (b,) BOX_DTYPE or None
        Boxes to draw, in the frame of the points.
    names : {class id: name} or None
        Class names for the legend (none drawn without them).
    """
    pts = as_points(points, "preview")
    lut = np.asarray(color_lut, np.uint8)
    width, height = int(size[0]), int(size[1])
    if width < 2 or height < 1 or dot < 1:
        raise InputError(f"preview: size must be at least (2, 1) pixels and dot >= 1, got size {size}, dot {dot}")
    if lut.ndim != 2 or lut.shape[1] != 3:
        raise InputError(f"preview: color_lut must be a (k, 3) uint8 table, got shape {lut.shape}")
    xyz = packed_columns(pts, ("x", "y", "z"))  # (n, 3) float32; float64 wherever a value enters arithmetic, as numpy's path has it
    semantic = pts["semantic"]
    if not np.isfinite(xyz).all():  # copies only when some point must go
        keep = np.isfinite(xyz).all(axis=1)
        xyz, semantic = xyz[keep], semantic[keep]
    frame = np.array(FRAME_COLOURS, np.uint8)
    if len(xyz) == 0:
        return np.zeros((height, width, 1), np.uint8), frame
    per_class = class_counts(semantic, len(lut))  # points per class (a count, not a sort)
    if per_class[-1]:
        raise InputError(f"preview: semantic id {int(semantic.max())} has no colour (color_lut has {len(lut)} entries)")
    per_class = per_class[:-1]
    ids = np.flatnonzero(per_class)
    counts = per_class[ids]
    palette = np.concatenate([frame, lut[ids]])
    entry = np.zeros(len(lut), np.uint8 if len(palette) <= 256 else np.uint16)  # each class's palette index
    entry[ids] = np.arange(len(frame), len(palette))
    image = np.zeros((height, width, 1), entry.dtype)  # all background
    panel = width // 2
    corners = box_corners(boxes) if boxes is not None and len(boxes) else np.zeros((0, 8, 3))
    offsets = np.arange(dot) - (dot - 1) // 2
    du, dv = (a.ravel() for a in np.meshgrid(offsets, offsets))

    # top view: x up, y left; cropped to the bulk of the points, or of the points of the other classes
    # when one class (a railway's ground rings) holds most of them
    others = len(semantic) - counts.max()  # the points not of the class that holds most
    keep = semantic != ids[counts.argmax()] if counts.max() > 0.4 * len(semantic) and others >= 100 else None
    bulk = [xyz[:, axis] if keep is None else xyz[:, axis][keep] for axis in (0, 1)]  # x, y of the bulk, each (m,) float32
    low, high = (np.array(v) for v in zip(*(percentiles(column, (1, 99)) for column in bulk)))
    span = np.maximum(high - low, 1e-6)
    low, high = low - 0.05 * span, high + 0.05 * span
    inner_w, inner_h = panel - 2 * MARGIN, height - 2 * MARGIN
    scale = min(inner_w / (high[1] - low[1]), inner_h / (high[0] - low[0]))
    centre = (low + high) / 2

    def top(p):
        p = np.asarray(p, np.float64)
        return (panel - 1) / 2 - (p[:, 1] - centre[1]) * scale, (height - 1) / 2 - (p[:, 0] - centre[0]) * scale

    # perspective: from behind and above the sensor, looking at the middle of the cropped region
    extent = float(np.hypot(*(high - low)))
    target = np.array([centre[0], centre[1], float(median(xyz[:, 2]))])
    eye = np.array([min(0.0, low[0]) - 0.35 * extent, 0.0, target[2] + 0.45 * extent])
    rotation = look_at(eye, target)
    focal = 0.5 * panel / np.tan(np.radians(30.0))

    def perspective(p):
        cam = _camera(np.asarray(p, np.float64), eye, rotation)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (panel - 1) / 2 + focal * cam[:, 0] / cam[:, 2], (height - 1) / 2 + focal * cam[:, 1] / cam[:, 2], cam[:, 2]

    # The points go into the top view, its boxes, scale bar and label are drawn, then the points go into the perspective
    # and its boxes are drawn. With one pixel a point, one compiled pass paints both panels' points first; the top view's
    # boxes then leave alone the perspective's painted pixels they reach into (the points painted over them otherwise).
    kernel = _panels_kernel() if len(du) == 1 else None
    colors = best = None  # the numpy path's: each point's palette index (n, 1), and the depth per pixel

    def paint(col, row, depth, left, panel_width):
        inside = (col >= 0) & (col < panel_width) & (row >= 0) & (row < height)
        col, row, depth, color = col[inside], row[inside], depth[inside], colors[inside]
        if len(du) == 1:  # one pixel a point: already inside the panel
            splat(image, col + left, row, depth, color, best)
            return
        col = np.clip(col[:, None] + du, 0, panel_width - 1).ravel() + left
        row = np.clip(row[:, None] + dv, 0, height - 1).ravel()
        splat(image, col, row, np.repeat(depth, len(du)), np.repeat(color, len(du), axis=0), best)

    if kernel is not None:
        best_side, best_top = np.full((2, height * panel), -np.inf)  # each panel's depth per pixel
        kernel(image.reshape(-1), best_top, best_side, np.ascontiguousarray(xyz), semantic, entry, float(centre[0]), float(centre[1]), float(scale),
               eye, rotation, float(focal), (panel - 1) / 2, (height - 1) / 2, width, panel, height)  # fmt: skip
    else:
        colors = np.take(entry, semantic)[:, None]
        best = np.full((height, width), -np.inf)  # the two panels' pixels are apart, so one serves both
        u, v = top(xyz)
        paint(np.rint(u).astype(np.int64), np.rint(v).astype(np.int64), xyz[:, 2], panel, panel)
    if len(corners):
        cu, cv = top(corners[:, :4].reshape(-1, 3))
        quad = np.stack([cu, cv], axis=1).reshape(-1, 4, 2) + [panel, 0]
        covered = None
        if kernel is not None:  # the perspective's pixels already painted
            covered = np.zeros((height, width), bool)
            covered[:, :panel] = (best_side > -np.inf).reshape(height, panel)
        draw_segments(image, quad.reshape(-1, 2), np.roll(quad, -1, axis=1).reshape(-1, 2), PEN, covered)
    bar = nice_length(inner_w / scale)
    x0, y0 = panel + MARGIN + 6, height - MARGIN - 10
    image[y0 : y0 + 3, x0 : x0 + int(round(bar * scale))] = PEN
    draw_text(image, f"{bar:g} m", x0 + int(round(bar * scale)) + 6, y0 - 3, color=PEN)

    if kernel is None:
        u, v, depth = perspective(xyz)
        front = depth > 0.1
        paint(np.rint(np.where(front, u, -1)).astype(np.int64), np.rint(np.where(front, v, -1)).astype(np.int64), -depth, 0, panel)
    if len(corners):
        cu, cv, cd = perspective(corners.reshape(-1, 3))
        pix = np.stack([cu, cv], axis=1).reshape(-1, 8, 2)
        ok = (cd.reshape(-1, 8) > 0.1).all(axis=1)
        edges = np.array(BOX_EDGES)
        starts, ends = pix[ok][:, edges[:, 0]].reshape(-1, 2), pix[ok][:, edges[:, 1]].reshape(-1, 2)
        ends = np.clip(ends, -1e4, 1e4)
        draw_segments(image, np.clip(starts, -1e4, 1e4), ends, PEN)
    image[:, panel - 1 : panel + 1] = DIVIDER

    if names:  # legend: a swatch and the name of each class present, most points first
        row = MARGIN
        for class_id in ids[np.argsort(-counts, kind="stable")]:
            if row + 12 > height:
                break
            image[row : row + 10, MARGIN : MARGIN + 10] = entry[class_id]
            draw_text(image, str(names.get(int(class_id), class_id)), MARGIN + 16, row, color=PEN)
            row += 14
    return image, palette


def write_preview(path: str | os.PathLike, points: np.ndarray, color_lut: np.ndarray, size: tuple[int, int] = SIZE, dot: int = 1,
                  boxes: np.ndarray | None = None, names: dict | None = None) -> Path:
    """Write the preview of ``points`` as a PNG (see :func:`render_preview` for the arguments).

    An empty cloud gives a valid image of background only. Returns the written path.
    """
    path = Path(path)
    index, palette = render_indexed(points, color_lut, size, dot, boxes, names)
    data = encode_png_indexed(index[..., 0], palette) if len(palette) <= 256 else encode_png(np.take(palette, index[..., 0], axis=0))
    with atomic_write(path) as tmp, hashed_open(tmp) as f:
        f.write(data)
    return path
