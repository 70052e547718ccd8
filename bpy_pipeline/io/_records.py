"""Check and normalise the points every writer receives (:mod:`bpy_pipeline.lidar.points`), and the
steps writers take through them.

Writers convert and write :data:`WRITE_CHUNK` points at a time (:func:`chunks`), so what they
allocate besides the points themselves stays a few tens of megabytes however large the scan
(a terrestrial scan holds about 10 million points); a frame's PLY and SemanticKITTI files go
:data:`CACHED_CHUNK` points at a time through one buffer.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..lidar.points import POINT_DTYPE

WRITE_CHUNK = 1 << 20  # points converted and written at a time
# points converted at a time into one buffer by the frame writers (PLY, SemanticKITTI): a few hundred kB, which the
# hash and the write call read again while they are still in the core's cache, and no new memory for each chunk
CACHED_CHUNK = 1 << 14


def chunks(n: int, size: int = WRITE_CHUNK) -> list[slice]:
    """Consecutive slices of at most ``size`` covering ``range(n)`` (none for ``n == 0``)."""
    return [slice(start, min(start + size, n)) for start in range(0, n, size)]


def as_points(points, where: str) -> np.ndarray:
    """``points`` as a C-contiguous ``(n,)`` array of :data:`POINT_DTYPE` (copied only when needed).

    Accepts any 1-D structured array holding at least the :data:`POINT_DTYPE` fields (extra
    fields are dropped, other field types are cast); ``InputError`` naming ``where`` otherwise.
    """
    arr = np.asarray(points)
    names = arr.dtype.names or ()
    missing = [name for name in POINT_DTYPE.names if name not in names]
    if missing or arr.ndim != 1:
        raise InputError(
            f"{where}: expected a 1-D structured array with fields {', '.join(POINT_DTYPE.names)}; "
            f"got shape {arr.shape} dtype {arr.dtype}"
        )
    if arr.dtype == POINT_DTYPE:
        return np.ascontiguousarray(arr)
    out = np.empty(arr.shape[0], POINT_DTYPE)
    for name in POINT_DTYPE.names:
        out[name] = arr[name]
    return out


def packed_columns(points: np.ndarray, names: tuple[str, ...], dtype="<f4", out: np.ndarray | None = None) -> np.ndarray:
    """``(n, len(names))`` array of ``dtype`` holding the fields ``names`` of the ``(n,)`` structured ``points``, in that order
    (in ``out``, a C-contiguous array of that shape and type, when given).

    Where the fields are consecutive and of one type (x, y, z and intensity of :data:`POINT_DTYPE`: float32), each record's
    bytes are copied as one block, then cast to ``dtype`` when it is another type; otherwise field by field. The same values
    either way.
    """
    dtype = np.dtype(dtype)
    out = np.empty((len(points), len(names)), dtype) if out is None else out
    fields = points.dtype.fields or {}
    first = fields[names[0]] if names[0] in fields else None
    stored = first[0] if first is not None else None
    if first is not None and all(name in fields and fields[name][0] == stored and fields[name][1] == first[1] + i * stored.itemsize
                                 for i, name in enumerate(names)):
        size = len(names) * stored.itemsize
        block = np.dtype({"names": ["b"], "formats": [f"V{size}"], "offsets": [first[1]], "itemsize": points.dtype.itemsize})
        packed = out if stored == dtype else np.empty((len(points), len(names)), stored)
        packed.view(f"V{size}")[:, 0] = points.view(block)["b"]
        if packed is not out:
            out[...] = packed
    else:
        for i, name in enumerate(names):
            out[:, i] = points[name]
    return out


XYZI = ("x", "y", "z", "intensity")


@dataclass(frozen=True)
class XyziBlock:
    """A cloud's x y z intensity as a velodyne ``.bin`` holds them: ``array`` (n, 4) <f4 (:func:`packed_columns`) and
    ``sha256``, a hashlib sha256 object of its bytes (for :meth:`~.atomic.HashedFile.write`)."""

    array: np.ndarray
    sha256: object


def xyzi_block(points: np.ndarray) -> XyziBlock:
    """The :class:`XyziBlock` of the ``(n,)`` structured ``points``."""
    array = packed_columns(points, XYZI)
    return XyziBlock(array, hashlib.sha256(array.reshape(-1).view(np.uint8)))
