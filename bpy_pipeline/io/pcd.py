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


MAX_PCD_HEADER = 1 << 16  # bytes before DATA; a longer header is not a PCD file
PCD_NUMPY = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8",
             ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8"}  # fmt: skip


def read_pcd_fields(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The fields of a binary or ASCII PCD file, ``{name: (n,) or (n, count) array}``, with the header checked
    against the bytes: FIELDS, SIZE, TYPE and COUNT agree, ``POINTS`` = ``WIDTH`` x ``HEIGHT``, and the data
    holds exactly ``POINTS`` records (binary: ``POINTS`` x record size bytes; ASCII: ``POINTS`` rows of one
    value per field column). A lie is an ``InputError`` naming the file, the field, the claim and what was found."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read PCD file ({err.strerror or err})") from None
    header, position = {}, 0
    while True:
        end = raw.find(b"\n", position, MAX_PCD_HEADER)
        if end < 0:
            raise InputError(f"{path}: PCD header has no DATA line (in its first {MAX_PCD_HEADER} bytes)")
        words = raw[position:end].decode("ascii", "replace").split()
        position = end + 1
        if words and not words[0].startswith("#"):
            header[words[0].upper()] = words[1:]
            if words[0].upper() == "DATA":
                break
    try:
        fields, sizes, types = header["FIELDS"], [int(x) for x in header["SIZE"]], [t.upper() for t in header["TYPE"]]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
        n = int(header["POINTS"][0])
        kind = header["DATA"][0].lower()
    except (KeyError, ValueError, IndexError):
        raise InputError(f"{path}: PCD header lacks FIELDS, SIZE, TYPE, POINTS or DATA, or they are not numbers") from None
    if not (len(fields) == len(sizes) == len(types) == len(counts)) or not fields:
        raise InputError(f"{path}: PCD header: FIELDS ({len(fields)}), SIZE ({len(sizes)}), TYPE ({len(types)}) and COUNT ({len(counts)}) "
                         "must list the same fields")
    if len(set(fields)) != len(fields):
        raise InputError(f"{path}: PCD header: FIELDS names a field twice ({' '.join(fields)})")
    for name, size, kind_, count in zip(fields, sizes, types, counts):
        if (kind_, size) not in PCD_NUMPY or count < 1:
            raise InputError(f"{path}: PCD field {name!r}: TYPE {kind_} SIZE {size} COUNT {count} is not a known type (F 4/8, I or U 1/2/4/8, COUNT >= 1)")
    if n < 0:
        raise InputError(f"{path}: PCD POINTS: must be >= 0, got {n}")
    try:
        width, height = int(header.get("WIDTH", [n])[0]), int(header.get("HEIGHT", [1])[0])
    except ValueError:
        raise InputError(f"{path}: PCD WIDTH and HEIGHT must be integers") from None
    if width * height != n:
        raise InputError(f"{path}: PCD header: WIDTH x HEIGHT = {width} x {height} = {width * height}, but POINTS says {n}")
    dtype = np.dtype([(f, PCD_NUMPY[(t, s)], (c,)) if c > 1 else (f, PCD_NUMPY[(t, s)]) for f, s, t, c in zip(fields, sizes, types, counts)])
    if kind == "binary":
        have = len(raw) - position
        if have != n * dtype.itemsize:
            raise InputError(f"{path}: PCD POINTS claims {n} points of {dtype.itemsize} bytes ({n * dtype.itemsize} bytes); "
                             f"the data holds {have} bytes ({have / dtype.itemsize:.6g} points)")
        data = np.frombuffer(raw, dtype, count=n, offset=position)
        return {f: data[f] for f in fields}
    if kind == "ascii":
        columns = sum(counts)
        rows = [line.split() for line in raw[position:].decode("ascii", "replace").splitlines() if line.strip()]
        if len(rows) != n:
            raise InputError(f"{path}: PCD POINTS claims {n} points; the ASCII data holds {len(rows)} rows")
        bad = next((k for k, r in enumerate(rows) if len(r) != columns), None)
        if bad is not None:
            raise InputError(f"{path}: PCD ASCII row {bad}: {len(rows[bad])} values, the fields need {columns}")
        try:
            table = np.array(rows, np.float64).reshape(n, columns)
        except ValueError:
            raise InputError(f"{path}: PCD ASCII data holds a value that is not a number") from None
        out, at = {}, 0
        for f, c in zip(fields, counts):
            out[f] = table[:, at] if c == 1 else table[:, at : at + c]
            at += c
        return out
    raise InputError(f"{path}: PCD DATA {kind!r} is not read here (binary or ascii; re-save with pcl_convert_pcd_ascii_binary)")


def read_pcd(path: str | os.PathLike) -> np.ndarray:
    """Read a binary or ASCII PCD file as ``(n,)`` POINT_DTYPE (fields matched by name; others zero; :func:`read_pcd_fields` checks it)."""
    data = read_pcd_fields(path)
    n = len(next(iter(data.values())))
    out = np.zeros(n, POINT_DTYPE)
    for name in POINT_DTYPE.names:
        if name in data:
            if data[name].ndim != 1:
                raise InputError(f"{path}: PCD field {name!r} has COUNT {data[name].shape[1]}; the point record holds one value")
            out[name] = data[name]
    return out
