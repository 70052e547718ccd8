"""Preview images of a labelled cloud: top view (x-y) and side view (x-z), coloured by class.

The image is two equal panels side by side on a dark background: left, seen from above (x to
the right, y up; higher points drawn over lower ones); right, seen from the side (x to the
right, z up; points with smaller y, nearer a viewer on the -y side, drawn over the others).
Each panel is fitted to the cloud with equal aspect (one metre is as many pixels along both
axes). Rasterisation is vectorised; PNG encoding uses only ``zlib`` and ``struct``.
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._records import as_points, chunks
from .atomic import atomic_write

BACKGROUND = (24, 24, 28)  # not a class colour of assets_manifest/labels.yaml
MARGIN = 8  # pixels around the cloud inside each panel


def encode_png(rgb: np.ndarray, level: int = 6) -> bytes:
    """PNG file bytes of an ``(h, w, 3) uint8`` RGB image (8-bit truecolour, no filtering)."""
    rgb = np.ascontiguousarray(rgb, np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (h, w, 3) uint8 image, got shape {rgb.shape}")
    h, w, _ = rgb.shape
    rows = np.zeros((h, 1 + 3 * w), np.uint8)  # filter byte 0 (None) before each row
    rows[:, 1:] = rgb.reshape(h, 3 * w)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows.tobytes(), level)) + chunk(b"IEND", b"")


def fit(u: np.ndarray, v: np.ndarray, width: int, height: int, bounds=None) -> tuple[np.ndarray, np.ndarray]:
    """Pixel columns and rows ``(n,) int`` of points ``(u, v)`` (n,) fitted into a width x height panel.

    Equal aspect, centred, ``v`` up; a cloud with zero extent along an axis is centred on it.
    bounds : ``(u_min, u_max, v_min, v_max)`` of the whole cloud when ``u, v`` are a part of it
    """
    inner_w, inner_h = max(width - 2 * MARGIN, 1), max(height - 2 * MARGIN, 1)
    u_min, u_max, v_min, v_max = (u.min(), u.max(), v.min(), v.max()) if bounds is None else bounds
    spans = np.array([u_max - u_min, v_max - v_min])
    with np.errstate(divide="ignore"):
        ratios = np.array([(inner_w - 1) / spans[0], (inner_h - 1) / spans[1]])
    ratios = ratios[np.isfinite(ratios)]
    scale = ratios.min() if len(ratios) else 1.0
    col = np.rint((width - 1) / 2 + (u - (u_min + u_max) / 2) * scale).astype(np.int64)
    row = np.rint((height - 1) / 2 - (v - (v_min + v_max) / 2) * scale).astype(np.int64)
    return np.clip(col, 0, width - 1), np.clip(row, 0, height - 1)


def splat(image: np.ndarray, col: np.ndarray, row: np.ndarray, depth: np.ndarray, colors: np.ndarray, depth_image: np.ndarray | None = None) -> None:
    """Paint ``colors`` (n, 3) at pixels ``(row, col)`` of ``image`` in place; the largest ``depth`` wins.

    Of equal depths the later point wins. depth_image : ``(height, width)`` float64 depth of what
    ``image`` holds (-inf where empty), updated in place, so a cloud can be painted part by part.
    Unbuffered per-pixel maxima (``np.maximum.at``), no sort: 10 million points take a second.
    """
    if len(col) == 0:
        return
    pixels = image.shape[0] * image.shape[1]
    pixel = row * image.shape[1] + col
    best = np.full(pixels, -np.inf) if depth_image is None else depth_image.reshape(-1)
    np.maximum.at(best, pixel, depth)  # the deepest of what was there and of these points
    wins = np.flatnonzero(depth >= best[pixel])  # the points that reach it (a tie with an earlier part: the later wins)
    last = np.full(pixels, -1, np.int64)
    np.maximum.at(last, pixel[wins], wins)  # of tied points, the later
    painted = np.flatnonzero(last >= 0)
    image.reshape(-1, 3)[painted] = colors[last[painted]]


def render_preview(points: np.ndarray, color_lut: np.ndarray, size: tuple[int, int] = (1600, 800), dot: int = 1) -> np.ndarray:
    """The preview as an ``(height, width, 3) uint8`` RGB array (see the module docstring).

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
    """
    pts = as_points(points, "preview")
    lut = np.asarray(color_lut, np.uint8)
    width, height = int(size[0]), int(size[1])
    if width < 2 or height < 1 or dot < 1:
        raise InputError(f"preview: size must be at least (2, 1) pixels and dot >= 1, got size {size}, dot {dot}")
    if lut.ndim != 2 or lut.shape[1] != 3:
        raise InputError(f"preview: color_lut must be a (k, 3) uint8 table, got shape {lut.shape}")
    image = np.empty((height, width, 3), np.uint8)
    image[:] = BACKGROUND

    def finite(part: slice):
        """``x, y, z`` (float64) and semantic ids of the finite points of a slice of the cloud."""
        x, y, z = (pts[name][part].astype(np.float64) for name in "xyz")
        keep = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
        return x[keep], y[keep], z[keep], pts["semantic"][part][keep]

    # First pass, chunk by chunk: the cloud's extent (each panel is fitted to all of it).
    low, high, top = np.full(3, np.inf), np.full(3, -np.inf), -1
    for part in chunks(len(pts)):
        x, y, z, semantic = finite(part)
        if len(x):
            xyz = (x, y, z)
            low, high = np.minimum(low, [a.min() for a in xyz]), np.maximum(high, [a.max() for a in xyz])
            top = max(top, int(semantic.max()))
    if top < 0:
        return image
    if top >= len(lut):
        raise InputError(f"preview: semantic id {top} has no colour (color_lut has {len(lut)} entries)")
    panel = width // 2
    offsets = np.arange(dot) - (dot - 1) // 2
    du, dv = (a.ravel() for a in np.meshgrid(offsets, offsets))
    depth_image = np.full((height, width), -np.inf)
    for part in chunks(len(pts)):  # then paint each chunk over what the earlier ones left
        x, y, z, semantic = finite(part)
        colors = np.repeat(lut[semantic], len(du), axis=0)
        for left, (u, v, depth), bounds in ((0, (x, y, z), (low[0], high[0], low[1], high[1])), (panel, (x, z, -y), (low[0], high[0], low[2], high[2]))):
            col, row = fit(u, v, panel, height, bounds)
            col = np.clip(col[:, None] + du, 0, panel - 1).ravel() + left
            row = np.clip(row[:, None] + dv, 0, height - 1).ravel()
            splat(image, col, row, np.repeat(depth, len(du)), colors, depth_image)
    return image


def write_preview(
    path: str | os.PathLike, points: np.ndarray, color_lut: np.ndarray, size: tuple[int, int] = (1600, 800), dot: int = 1
) -> Path:
    """Write the top and side view of ``points`` as a PNG (see :func:`render_preview` for the arguments).

    An empty cloud gives a valid image of background only. Returns the written path.
    """
    path = Path(path)
    data = encode_png(render_preview(points, color_lut, size, dot))
    with atomic_write(path) as tmp:
        tmp.write_bytes(data)
    return path
