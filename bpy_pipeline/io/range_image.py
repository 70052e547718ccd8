"""Range images: a frame of a rows x columns sensor as an organised image, with its labels, and a PNG to look at.

Layout (:mod:`bpy_pipeline.lidar.sensor.grid`): row 0 is the highest beam, column ``c`` the ``c``-th
column fired; each point goes to the pixel of its ``ring`` and firing ``time``. Files::

    OUT/range_image/NNNNNN.npy   (rows, columns) POINT_DTYPE: the organised cloud, every field
    OUT/range_image/NNNNNN.png   range above (grey, near is bright), labels below (class colours)

In the ``.npy``, ``image["range"]`` is the range image (float32 metres) and ``image["semantic"]``
the label image (uint16 raw class ids; ``image["instance"]`` the instance ids); a pixel without
a return is all zeros (``range`` 0, as in Ouster's range images). Each beam gives at most one
point; if two points fall on one pixel (several returns of a beam), the nearer is kept.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..lidar.sensor import grid
from ..lidar.points import POINT_DTYPE
from ..lidar.sensor.sensors import SensorSpec
from ._records import as_points
from .atomic import atomic_write
from .layout import frame_stem
from .preview import BACKGROUND, encode_png


def organise(points: np.ndarray, spec: SensorSpec) -> np.ndarray:
    """``(rows, columns)`` :data:`POINT_DTYPE` image of ``points`` (p,) from a sensor of ``spec``; zeros where no return."""
    pts = as_points(points, "range image")
    grid.check_grid(spec, "range image")
    image = np.zeros(grid.image_shape(spec), POINT_DTYPE)
    row, column = grid.pixels(spec, pts["ring"], pts["time"])
    order = np.argsort(-pts["range"], kind="stable")  # farthest first: the nearest of a pixel is written last and wins
    image[row[order], column[order]] = pts[order]
    return image


def image_points(image: np.ndarray) -> np.ndarray:
    """``(p,)`` :data:`POINT_DTYPE` records of the pixels that hold a return (``range`` > 0), row by row."""
    image = np.asarray(image)
    return image[image["range"] > 0]


def render(image: np.ndarray, color_lut: np.ndarray) -> np.ndarray:
    """``(2 rows, columns, 3)`` uint8 RGB: the range image (grey, near bright) above the label image.

    Ranges are scaled to the 99th percentile of the frame's ranges, so a few far points do
    not darken the rest. Pixels without a return are the preview background.
    """
    lut = np.asarray(color_lut, np.uint8)
    hit = image["range"] > 0
    rgb = np.empty((2, *image.shape, 3), np.uint8)
    rgb[:] = BACKGROUND
    if hit.any():
        ranges = image["range"][hit].astype(np.float64)
        scale = max(float(np.percentile(ranges, 99)), 1e-9)
        grey = (255.0 - 205.0 * np.clip(ranges / scale, 0.0, 1.0)).astype(np.uint8)  # 255 at the sensor, 50 at the scale
        rgb[0][hit] = grey[:, None]
        semantic = image["semantic"][hit]
        if int(semantic.max()) >= len(lut):
            raise InputError(f"range image: semantic id {int(semantic.max())} has no colour (color_lut has {len(lut)} entries)")
        rgb[1][hit] = lut[semantic]
    return rgb.reshape(2 * image.shape[0], image.shape[1], 3)


def write_range_image(path: str | os.PathLike, points: np.ndarray, spec: SensorSpec, color_lut: np.ndarray) -> list[Path]:
    """Write ``path`` (.npy, the organised image) and its ``.png`` beside it; returns both paths."""
    path = Path(path)
    image = organise(points, spec)
    png = path.with_suffix(".png")
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, image, allow_pickle=False)
    data = encode_png(render(image, color_lut))
    with atomic_write(png) as tmp:
        tmp.write_bytes(data)
    return [path, png]


def read_range_image(path: str | os.PathLike) -> np.ndarray:
    """The ``(rows, columns)`` :data:`POINT_DTYPE` image written by :func:`write_range_image`."""
    path = Path(path)
    try:
        image = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read a range image ({err})") from None
    if image.dtype != POINT_DTYPE or image.ndim != 2:
        raise InputError(f"{path}: expected a (rows, columns) array of point records, got {image.dtype} {image.shape}")
    return image


def write_frame_range_image(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, spec: SensorSpec, color_lut: np.ndarray) -> list[Path]:
    """``OUT/range_image/NNNNNN.npy`` and ``.png`` of one frame."""
    return write_range_image(Path(out_dir) / "range_image" / f"{frame_stem(frame_index)}.npy", points, spec, color_lut)
