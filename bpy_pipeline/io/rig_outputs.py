"""Writers of a sensor rig's frame and of a flash camera's images (registered as ``rig`` and ``flash_image``).

``rig`` (needs ``sensor.rig``), frame ``NNNNNN``::

    rig/NNNNNN.ply                 the merged cloud: every point field plus ``sensor`` (uchar, index into the rig)
    rig/sensorK/NNNNNN.ply         sensor K's own cloud (its frame, or the world), the plain point record
    rig/labels/NNNNNN.txt          merged boxes, OpenPCDet lines (x y z dx dy dz heading class), the merged cloud's frame
    rig/sensorK/labels/NNNNNN.txt  sensor K's boxes (kept where it holds their minimum points), its frame

``flash_image`` (a flash camera, or a rig's flash cameras): ``flash_image/NNNNNN.npy`` (one camera)
or ``flash_image/NNNNNN_sK.npy`` (sensor K of a rig), a ``(returns, rows, columns)`` structured
array (``depth`` float32 m, ``intensity`` float32, ``semantic`` uint16, ``instance`` uint32; see
:mod:`~bpy_pipeline.lidar.cast.flash_returns`), and a PNG beside it: depth (grey, near bright) above
intensity, first return. The images are traced from the frame's exported scene by the flash stage
(:mod:`bpy_pipeline.stages.flash`: a few sub-rays per pixel of a 96 x 16 camera, milliseconds); the
writer only writes them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..lidar.sensor.sensors import FLASH_PATTERNS, check_flash
from .atomic import atomic_write
from .openpcdet import label_lines as openpcdet_lines
from .layout import frame_stem
from .ply import ply_header, write_ply
from .preview import BACKGROUND, encode_png
from .writers import Writer, register_writer

FLASH_IMAGE_DTYPE = np.dtype([("depth", "<f4"), ("intensity", "<f4"), ("semantic", "<u2"), ("instance", "<u4")])
FLASH_SUB_RAYS = 3  # per pixel side: 9 rays over each pixel's footprint
FLASH_SEPARATION = 0.3  # m between two returns of one pixel (the pulse's range resolution, assumed)
FLASH_RETURNS = 2


def write_merged_ply(path: Path, points: np.ndarray) -> Path:
    """A binary PLY of ``points`` with every field of their dtype (a rig's cloud: the point record plus ``sensor``)."""
    points = np.ascontiguousarray(points)
    with atomic_write(path) as tmp, open(tmp, "wb") as handle:
        handle.write(ply_header(len(points), points.dtype))
        points.tofile(handle)
    return path


def _labels(path: Path, boxes, names) -> Path:
    lines = openpcdet_lines(boxes, names) if boxes is not None else []
    with atomic_write(path) as tmp:
        tmp.write_text("".join(line + "\n" for line in lines))
    return path


def _write_rig(frame, out: Path) -> list[Path]:
    stem, root = frame_stem(frame.index), Path(out) / "rig"
    names = frame.config.output.boxes.names
    written = [write_merged_ply(root / f"{stem}.ply", frame.points)]
    for k, sub in enumerate(frame.rig.frames):
        written.append(write_ply(root / f"sensor{k}" / f"{stem}.ply", sub.points))
    if frame.boxes is not None:
        written.append(_labels(root / "labels" / f"{stem}.txt", frame.boxes, names))
        for k, sub in enumerate(frame.rig.frames):
            written.append(_labels(root / f"sensor{k}" / "labels" / f"{stem}.txt", sub.boxes, names))
    return written


def _check_rig(config) -> None:
    if not config.sensor.rig:
        raise InputError("output.formats: rig needs a sensor rig (sensor.rig: a rig name or a list of {preset, position, rotation_deg})")


# ----------------------------------------------------------------------------- flash images
def flash_image_array(images) -> np.ndarray:
    """``(returns, rows, columns)`` :data:`FLASH_IMAGE_DTYPE` of :class:`~bpy_pipeline.lidar.cast.flash_returns.FlashImages`
    (anything with ``depth``, ``intensity``, ``semantic`` and ``instance`` arrays of one shape)."""
    out = np.zeros(images.depth.shape, FLASH_IMAGE_DTYPE)
    for name in FLASH_IMAGE_DTYPE.names:
        out[name] = getattr(images, name)
    return out


def render_flash(image: np.ndarray, scale: int = 4) -> np.ndarray:
    """``(2 rows * scale, columns * scale, 3)`` uint8: first-return depth (grey, near bright) above its intensity."""
    first = image[0]
    rgb = np.empty((2, *first.shape, 3), np.uint8)
    rgb[:] = BACKGROUND
    hit = first["depth"] > 0
    if hit.any():
        far = max(float(first["depth"][hit].max()), 1e-9)
        rgb[0][hit] = (255.0 - 205.0 * np.clip(first["depth"][hit] / far, 0, 1)).astype(np.uint8)[:, None]
        rgb[1][hit] = (50.0 + 205.0 * np.clip(first["intensity"][hit] / max(float(first["intensity"].max()), 1e-9), 0, 1)).astype(np.uint8)[:, None]
    out = rgb.reshape(2 * first.shape[0], first.shape[1], 3)
    return np.repeat(np.repeat(out, scale, axis=0), scale, axis=1)


def _write_flash(frame, out: Path) -> list[Path]:
    """The frame's flash images (``frame.flash``: {file suffix: (returns, rows, columns) FLASH_IMAGE_DTYPE}, cast
    by the flash stage, :mod:`bpy_pipeline.stages.flash`), each as ``.npy`` and a PNG beside it."""
    written = []
    for suffix, array in frame.flash.items():
        path = Path(out) / "flash_image" / f"{frame_stem(frame.index)}{suffix}.npy"
        with atomic_write(path) as tmp:
            with open(tmp, "wb") as handle:
                np.save(handle, array, allow_pickle=False)
        png = path.with_suffix(".png")
        data = encode_png(render_flash(array))
        with atomic_write(png) as tmp:
            tmp.write_bytes(data)
        written += [path, png]
    return written


def _check_flash(config) -> None:
    if config.sensor.rig:
        if not any(s.spec.pattern in FLASH_PATTERNS for s in config.sensor.rig):
            raise InputError(f"output.formats: flash_image needs a flash camera (pattern {' or '.join(FLASH_PATTERNS)}) in sensor.rig")
        return
    check_flash(config.sensor.spec, "output.formats: flash_image")


def read_flash_image(path) -> np.ndarray:
    """The ``(returns, rows, columns)`` :data:`FLASH_IMAGE_DTYPE` array of a written flash image."""
    path = Path(path)
    try:
        image = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read a flash image ({err})") from None
    if image.dtype != FLASH_IMAGE_DTYPE or image.ndim != 3:
        raise InputError(f"{path}: expected a (returns, rows, columns) flash image, got {image.dtype} {image.shape}")
    return image


register_writer("rig", Writer(_write_rig, _check_rig))
register_writer("flash_image", Writer(_write_flash, _check_flash, needs=("flash",)))
