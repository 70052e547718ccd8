"""The range-image projection of a labelled scan: RangeNet++'s spherical projection, as range-image networks read scans.

Each point goes to the pixel of its elevation and azimuth: ``ROWS`` rows spread evenly over +3 to -25 degrees
of elevation (row 0 the highest; points outside are clipped to the edge rows), ``width`` columns over 360
degrees of azimuth (column 0 looks backwards, azimuth increases to the left, as in RangeNet++). The
projection is that of "RangeNet++: Fast and Accurate LiDAR Semantic Segmentation" (Milioto et al., 2019), at
the HDL-64E's 64 rows; it does not read ring numbers, so real scans without them and generated scans are
projected alike. When several points fall on one pixel the nearest is kept; every point keeps its pixel
(:attr:`RangeImage.pixel`), so a prediction per pixel is a prediction per point (back-projection).

Channels (:data:`CHANNELS`, float32): x, y, z, range (m), remission (0..1; 0 when the scan has none or the
channel is switched off) and the mask (1: a return, 0: no return: a dropped or absent ray).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .labelled import LabelledScan

ROWS = 64
WIDTH = 512
FOV_UP_DEG = 3.0
FOV_DOWN_DEG = -25.0
CHANNELS = ("x", "y", "z", "range", "remission", "mask")


@dataclass
class RangeImage:
    """One scan as a range image.

    image : (len(CHANNELS), rows, width) float32
    labels : (rows, width) int64 evaluation label of each pixel's kept point, -1 where none or ignored
    pixel : (n,) int64 flat pixel index (row * width + column) of every point of the scan
    """

    image: np.ndarray
    labels: np.ndarray
    pixel: np.ndarray


def pixels(points: np.ndarray, rows: int = ROWS, width: int = WIDTH) -> tuple[np.ndarray, np.ndarray]:
    """``(row, column)`` int64 arrays of ``(n, 3)`` points in the spherical projection (module notes)."""
    points = np.asarray(points, np.float64)
    distance = np.maximum(np.linalg.norm(points, axis=1), 1e-6)
    elevation = np.degrees(np.arcsin(np.clip(points[:, 2] / distance, -1.0, 1.0)))
    azimuth = np.arctan2(points[:, 1], points[:, 0])
    v = (FOV_UP_DEG - elevation) / (FOV_UP_DEG - FOV_DOWN_DEG)  # 0 at the top of the field of view
    u = 0.5 * (1.0 - azimuth / np.pi)  # 0 looking backwards, 0.5 forward
    row = np.clip(np.floor(v * rows), 0, rows - 1).astype(np.int64)
    column = np.clip(np.floor(u * width), 0, width - 1).astype(np.int64)
    return row, column


def project(scan: LabelledScan, width: int = WIDTH, remission: bool = True) -> RangeImage:
    """The :class:`RangeImage` of ``scan``; ``remission=False`` (or a scan without it) leaves that channel 0."""
    row, column = pixels(scan.points, ROWS, width)
    flat = row * width + column
    distance = np.linalg.norm(scan.points.astype(np.float64), axis=1)
    order = np.argsort(-distance, kind="stable")  # farthest first: the nearest of a pixel is written last and wins
    image = np.zeros((len(CHANNELS), ROWS * width), np.float32)
    labels = np.full(ROWS * width, -1, np.int64)
    kept = flat[order]
    image[0:3, kept] = scan.points[order].T
    image[3, kept] = distance[order]
    if remission and scan.remission is not None:
        image[4, kept] = scan.remission[order]
    image[5, kept] = 1.0
    labels[kept] = scan.labels[order]
    return RangeImage(image.reshape(len(CHANNELS), ROWS, width), labels.reshape(ROWS, width), flat)


def returns_per_row(points: np.ndarray, width: int = WIDTH) -> np.ndarray:
    """``(ROWS,)`` float64 share of each row's pixels that hold a return (the drop pattern, row 0 the highest)."""
    row, column = pixels(points, ROWS, width)
    hit = np.zeros(ROWS * width, bool)
    hit[row * width + column] = True
    return hit.reshape(ROWS, width).mean(axis=1)
