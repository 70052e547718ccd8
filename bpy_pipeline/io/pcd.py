"""PCD point clouds (Point Cloud Library format 0.7), binary, with the label fields.

Header and fields::

    FIELDS x y z intensity semantic instance ring time range bounces
    SIZE   4 4 4 4         4        4        4    8    4     1
    TYPE   F F F F         I        I        I    F    F     U

Types follow what Open3D's tensor reader keeps (as for PLY, signed ints rather than the record's
unsigned ones); ``DATA binary``: the records packed, 41 bytes a point. :func:`read_pcd` reads
these files (and other binary or ASCII PCD files with matching field names) as POINT_DTYPE.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..lidar.points import POINT_DTYPE
from ._records import as_points, chunks
from .atomic import atomic_write

PCD_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("semantic", "<i4"), ("instance", "<i4"),
     ("ring", "<i4"), ("time", "<f8"), ("range", "<f4"), ("bounces", "u1")]
)  # fmt: skip
PCD_TYPES = {"f": "F", "i": "I", "u": "U"}


def pcd_header(n: int, dtype: np.dtype = PCD_DTYPE) -> bytes:
    """The ASCII header of a binary PCD file of ``n`` points of ``dtype``."""
    fields = dtype.names
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format (bpy_pipeline point record: metres, seconds)",
        "VERSION 0.7",
        "FIELDS " + " ".join(fields),
        "SIZE " + " ".join(str(dtype[f].itemsize) for f in fields),
        "TYPE " + " ".join(PCD_TYPES[dtype[f].kind] for f in fields),
        "COUNT " + " ".join("1" for _ in fields),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA binary",
    ]
    return ("\n".join(lines) + "\n").encode("ascii")


def write_pcd(path: str | os.PathLike, points: np.ndarray) -> Path:
    """Write ``(n,)`` POINT_DTYPE ``points`` as a binary PCD file (atomically); instance ids must be < 2**31."""
    path = Path(path)
    pts = as_points(points, str(path))
    if len(pts) and int(pts["instance"].max()) > np.iinfo(np.int32).max:
        raise InputError(f"{path}: PCD instance is a 4-byte signed int; got instance ids up to {int(pts['instance'].max())}")
    with atomic_write(path) as tmp, open(tmp, "wb") as f:
        f.write(pcd_header(len(pts)))
        for part in chunks(len(pts)):
            records = np.empty(part.stop - part.start, PCD_DTYPE)
            for name in PCD_DTYPE.names:
                records[name] = pts[name][part]
            records.tofile(f)
    return path


def read_pcd(path: str | os.PathLike) -> np.ndarray:
    """Read a binary or ASCII PCD file as ``(n,)`` POINT_DTYPE (fields matched by name; others zero)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read PCD file ({err.strerror})") from None
    header, position = {}, 0
    while True:
        end = raw.find(b"\n", position)
        if end < 0:
            raise InputError(f"{path}: PCD header has no DATA line")
        words = raw[position:end].decode("ascii", "replace").split()
        position = end + 1
        if words and not words[0].startswith("#"):
            header[words[0].upper()] = words[1:]
            if words[0].upper() == "DATA":
                break
    try:
        fields, sizes, types = header["FIELDS"], [int(s) for s in header["SIZE"]], header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
        n = int(header["POINTS"][0])
        kind = header["DATA"][0]
    except (KeyError, ValueError, IndexError):
        raise InputError(f"{path}: PCD header lacks FIELDS, SIZE, TYPE, POINTS or DATA") from None
    dtype = np.dtype([(f, f"<{t.lower()}{s}", (c,)) if c > 1 else (f, f"<{t.lower()}{s}") for f, s, t, c in zip(fields, sizes, types, counts)])
    if kind == "binary":
        if len(raw) - position < n * dtype.itemsize:
            raise InputError(f"{path}: truncated PCD: {n} points of {dtype.itemsize} bytes do not fit")
        data = np.frombuffer(raw, dtype, count=n, offset=position)
    elif kind == "ascii":
        table = np.loadtxt(raw[position:].decode("ascii").splitlines(), ndmin=2) if n else np.zeros((0, len(fields)))
        data = {f: table[:, i] for i, f in enumerate(fields)}
    else:
        raise InputError(f"{path}: PCD DATA {kind!r} is not read here (binary or ascii)")
    out = np.zeros(n, POINT_DTYPE)
    for name in POINT_DTYPE.names:
        if name in fields:
            out[name] = data[name]
    return out
