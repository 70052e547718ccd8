"""PLY point clouds: binary little-endian, one vertex property per :data:`POINT_DTYPE` field.

Property names and types are chosen so the viewers users open them in load every field:
Open3D (0.20's tensor reader keeps only uchar, int, float and double properties; it skips
ushort and uint) and CloudCompare (in command-line mode it loads a property as a scalar
field only under its ``scalar_`` naming convention, and strips the prefix)::

    x y z float (m), intensity float (0..1), scalar_semantic int, scalar_instance int,
    scalar_ring int, scalar_time double (s from frame start), scalar_range float (m),
    scalar_bounces uchar

The vertex element is one packed structured array (:data:`PLY_DTYPE`, 41 bytes a point) written
with one ``tofile``. :func:`read_ply` reads these files and others (a ``scalar_`` prefix is
dropped when matching properties to :data:`POINT_DTYPE` fields) back into POINT_DTYPE records.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import numpy as np

from ..errors import InputError, path_argument
from ..compiled import compiled_wanted
from ..lidar.points import POINT_DTYPE
from ._records import CACHED_CHUNK, as_points, chunks
from .atomic import atomic_write, hashed_open

# PLY scalar type names (both spellings of the spec) -> numpy type character codes.
PLY_TYPES = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}  # fmt: skip
# What the writer uses for each numpy type.
PLY_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint", "f4": "float", "f8": "double"}
FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}


PREFIX = "scalar_"  # CloudCompare's naming convention for scalar fields
PLY_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), (PREFIX + "semantic", "<i4"), (PREFIX + "instance", "<i4"),
     (PREFIX + "ring", "<i4"), (PREFIX + "time", "<f8"), (PREFIX + "range", "<f4"), (PREFIX + "bounces", "u1")]
)  # fmt: skip


def point_field(prop: str) -> str:
    """The :data:`POINT_DTYPE` field a PLY property stands for (``scalar_semantic`` -> ``semantic``)."""
    return prop[len(PREFIX):] if prop.startswith(PREFIX) and prop[len(PREFIX):] in POINT_DTYPE.names else prop


def _runs(source: np.dtype, target: np.dtype) -> list[tuple[str, ...]]:
    """Consecutive fields both dtypes store with the same types in the same order: ``[(target names...), ...]``."""
    runs, run = [], []
    for name in target.names:
        field = point_field(name)
        same = field in source.names and source[field] == target[name]
        if same and run and source.fields[field][1] == source.fields[point_field(run[-1])][1] + source[point_field(run[-1])].itemsize \
                and target.fields[name][1] == target.fields[run[-1]][1] + target[run[-1]].itemsize:  # fmt: skip
            run.append(name)
            continue
        if run:
            runs.append(tuple(run))
        run = [name] if same else []
        if not same:
            runs.append((name,))
    if run:
        runs.append(tuple(run))
    return runs


def _block(dtype: np.dtype, names: tuple[str, ...], rename=lambda n: n) -> np.dtype:
    """A view of ``dtype`` holding fields ``names`` (consecutive bytes) as one opaque field ``b``."""
    first = dtype.fields[rename(names[0])][1]
    size = sum(dtype[rename(n)].itemsize for n in names)
    return np.dtype({"names": ["b"], "formats": [f"V{size}"], "offsets": [first], "itemsize": dtype.itemsize})


def byte_runs(source: np.dtype, target: np.dtype) -> tuple[tuple[int, int, int], ...] | None:
    """``((source offset or -1, target offset, bytes), ...)``: how a ``target`` record's bytes come from a ``source`` record's,
    -1 for zero bytes, adjacent runs merged; ``None`` where a field is not a plain copy of bytes. A field is one when both
    are little-endian and of the same type, or when the source is an unsigned integer and the target an integer at least
    as wide (zero bytes above; a signed target of the same width reads the same value below 2**31: PLY's instance ids)."""
    runs: list[list[int]] = []

    def add(src: int, dst: int, size: int) -> None:
        last = runs[-1] if runs else None
        if last and last[1] + last[2] == dst and ((src < 0 and last[0] < 0) or (src >= 0 and last[0] >= 0 and last[0] + last[2] == src)):
            last[2] += size
        else:
            runs.append([src, dst, size])

    for name in target.names:
        field = point_field(name)
        if field not in (source.names or ()):
            return None
        (a, src), (b, dst) = source.fields[field][:2], target.fields[name][:2]
        if a.byteorder == ">" or b.byteorder == ">":
            return None
        if a == b:
            add(src, dst, a.itemsize)
        elif a.kind == "u" and b.kind in "iu" and b.itemsize >= a.itemsize:
            add(src, dst, a.itemsize)
            if b.itemsize > a.itemsize:
                add(-1, dst + a.itemsize, b.itemsize - a.itemsize)
        else:
            return None
    return tuple(tuple(run) for run in runs)


# The runs the compiled copy is written for (POINT_DTYPE -> PLY_DTYPE): x y z intensity semantic; semantic's upper bytes;
# instance, ring; ring's upper bytes; time, range, bounces
KERNEL_RUNS = ((0, 0, 18), (-1, 18, 2), (18, 20, 6), (-1, 26, 2), (24, 28, 13))


@cache
def _records_kernel():
    """The compiled record copy (numba, cached on disk): ``copy(source (n, 37) uint8, target (n, 41) uint8)`` by
    :data:`KERNEL_RUNS`; ``None`` without numba, with ``BPY_PIPELINE_SCAN_KERNEL=numpy``, or where the two layouts'
    :func:`byte_runs` are not those runs. The same bytes as the numpy path."""
    if not compiled_wanted() or POINT_DTYPE.itemsize != 37 or PLY_DTYPE.itemsize != 41 or byte_runs(POINT_DTYPE, PLY_DTYPE) != KERNEL_RUNS:
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def copy(source, target):  # pragma: no cover (compiled)
        for r in range(source.shape[0]):
            for c in range(18):
                target[r, c] = source[r, c]
            target[r, 18] = 0
            target[r, 19] = 0
            for c in range(6):
                target[r, 20 + c] = source[r, 18 + c]
            target[r, 26] = 0
            target[r, 27] = 0
            for c in range(13):
                target[r, 28 + c] = source[r, 24 + c]

    return copy


def ply_records(points: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``(n,)`` :data:`PLY_DTYPE` records of ``(n,)`` POINT_DTYPE points (instance ids must be < 2**31), in ``out``
    (a C-contiguous ``(n,)`` PLY_DTYPE array) when given.

    POINT_DTYPE points go through one compiled copy of bytes (:func:`_records_kernel`) where numba is there. Otherwise
    fields stored alike in both (x, y, z, intensity; time and range) are copied a run of bytes at a time, the others
    converted field by field. The bytes of a field-by-field copy either way.
    """
    out = np.empty(len(points), PLY_DTYPE) if out is None else out
    kernel = _records_kernel() if points.dtype == POINT_DTYPE and len(points) else None
    if kernel is not None:
        kernel(np.ascontiguousarray(points).view(np.uint8).reshape(len(points), POINT_DTYPE.itemsize), out.view(np.uint8).reshape(len(out), PLY_DTYPE.itemsize))
        return out
    source = points.dtype
    for run in _runs(source, PLY_DTYPE):
        if len(run) == 1:
            out[run[0]] = points[point_field(run[0])]
        else:
            out.view(_block(PLY_DTYPE, run))["b"] = points.view(_block(source, run, point_field))["b"]
    return out


def ply_header(n: int, dtype: np.dtype = PLY_DTYPE) -> bytes:
    """The ASCII header (``end_header`` and its newline included) for ``n`` vertices of ``dtype``."""
    lines = ["ply", "format binary_little_endian 1.0", "comment bpy_pipeline point record: metres, seconds", f"element vertex {n}"]
    for name in dtype.names:
        code = f"{dtype[name].kind}{dtype[name].itemsize}"
        lines.append(f"property {PLY_NAMES[code]} {name}")
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def write_ply(path: str | os.PathLike, points: np.ndarray) -> Path:
    """Write ``points`` as a binary little-endian PLY point cloud, every field kept.

    Parameters
    ----------
    path : str or PathLike
        Destination file; parent folders are created, the file appears atomically.
    points : (n,) POINT_DTYPE
        Points (``n`` may be 0). Other structured arrays with the same fields are cast.

    Returns
    -------
    path : Path
        The written file.
    """
    path = Path(path)
    pts = as_points(points, str(path))
    if len(pts) and int(pts["instance"].max()) > np.iinfo(np.int32).max:
        raise InputError(f"{path}: PLY scalar_instance is int (Open3D reads no uint); got instance ids up to {int(pts['instance'].max())}")
    with atomic_write(path) as tmp, hashed_open(tmp) as f:  # hashed as written (the dataset's commit reads no file back)
        f.write(ply_header(len(pts)))
        buffer = np.empty(min(len(pts), CACHED_CHUNK), PLY_DTYPE)  # one buffer, reused: no new memory a chunk
        for part in chunks(len(pts), CACHED_CHUNK):
            f.write(ply_records(pts[part], buffer[: part.stop - part.start]))
    return path


def parse_header(f, path: Path) -> tuple[str, list[tuple[str, int, list[tuple[str, str | tuple]]]]]:
    """Read the header from an open binary file; return ``(format, elements)``.

    ``elements`` lists ``(name, count, properties)``; a property is ``(name, numpy code)`` or
    ``(name, (count code, item code))`` for a list property. The file is left at the first data byte.
    """
    if f.readline().strip() != b"ply":
        raise InputError(f"{path}: not a PLY file (it does not start with 'ply')")
    fmt = None
    elements: list = []
    while True:
        raw = f.readline()
        if not raw:
            raise InputError(f"{path}: PLY header has no end_header line")
        words = raw.decode("ascii", "replace").split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        key = words[0]
        try:
            if key == "end_header":
                break
            if key == "format":
                fmt = words[1]
                if fmt not in FORMATS:
                    raise InputError(f"{path}: unsupported PLY format {fmt!r}; allowed: {', '.join(FORMATS)}")
            elif key == "element":
                elements.append((words[1], int(words[2]), []))
                if elements[-1][1] < 0:
                    raise InputError(f"{path}: PLY element {words[1]!r}: count {words[2]} is negative")
            elif key == "property" and words[1] == "list":
                elements[-1][2].append((words[4], (PLY_TYPES[words[2]], PLY_TYPES[words[3]])))
            elif key == "property":
                elements[-1][2].append((words[2], PLY_TYPES[words[1]]))
            else:
                raise InputError(f"{path}: unexpected PLY header line {raw.strip()!r}")
        except (IndexError, KeyError, ValueError):
            raise InputError(f"{path}: malformed PLY header line {raw.strip()!r}") from None
    if fmt is None:
        raise InputError(f"{path}: PLY header has no format line")
    return fmt, elements


def read_ply(path: str | os.PathLike) -> np.ndarray:
    """Read the vertices of a PLY file as an ``(n,)`` :data:`POINT_DTYPE` array.

    Reads binary (little or big endian) and ASCII files. Vertex properties are matched to
    :data:`POINT_DTYPE` fields by name (a ``scalar_`` prefix dropped) and cast; fields the file does not have are zero and
    extra properties are ignored. Elements before ``vertex`` are skipped if they have only
    scalar properties (binary) or are read line by line (ASCII). ``InputError`` naming the
    file for anything it cannot read (not a PLY, list properties on the vertex, truncated data).
    """
    path = Path(path_argument(path))
    try:
        f = open(path, "rb")
    except OSError as err:
        raise InputError(f"{path}: cannot open PLY file ({err.strerror})") from None
    with f:
        try:
            return _read_vertices(f, path)
        except (ValueError, TypeError) as err:  # a value that is not a number, properties numpy cannot lay out
            raise InputError(f"{path}: PLY data does not match its header ({str(err).splitlines()[0]})") from None


def _read_vertices(f, path: Path) -> np.ndarray:
    """The vertices of the open PLY file ``f`` (see :func:`read_ply`)."""
    fmt, elements = parse_header(f, path)
    order = FORMATS[fmt]
    for name, count, props in elements:
        if any(isinstance(code, tuple) for _, code in props):
            if name == "vertex":
                raise InputError(f"{path}: list properties on the vertex element are not supported")
            if order is not None:
                raise InputError(f"{path}: cannot skip element {name!r} with list properties before 'vertex'")
        dtype = np.dtype([(prop, (order or "<") + code) for prop, code in props if not isinstance(code, tuple)])
        if name == "vertex":
            if not props:
                raise InputError(f"{path}: PLY element vertex has no properties (x, y and z are needed)")
            if order is None:
                table = np.loadtxt(f, dtype=np.float64, ndmin=2, max_rows=count) if count else np.zeros((0, len(props)))
                if table.shape != (count, len(props)):
                    raise InputError(f"{path}: expected {count} ASCII vertex rows of {len(props)} values, got {table.shape}")
                data = {point_field(prop): table[:, i] for i, (prop, _) in enumerate(props)}
            else:
                left = os.fstat(f.fileno()).st_size - f.tell()
                if count * dtype.itemsize > left:
                    raise InputError(f"{path}: truncated PLY: element vertex claims {count} vertices of {dtype.itemsize} bytes; "
                                     f"the file holds {left // max(dtype.itemsize, 1)}")
                arr = np.fromfile(f, dtype=dtype, count=count)
                if len(arr) != count:
                    raise InputError(f"{path}: truncated PLY: {len(arr)} of {count} vertices present")
                data = {point_field(prop): arr[prop] for prop in dtype.names}
            out = np.zeros(count, POINT_DTYPE)
            for field in POINT_DTYPE.names:
                if field in data:
                    out[field] = data[field]
            return out
        if order is None:
            for k in range(count):
                if not f.readline():
                    raise InputError(f"{path}: PLY element {name!r} claims {count} rows; the file ends after {k}")
        else:
            f.seek(count * dtype.itemsize, os.SEEK_CUR)
    raise InputError(f"{path}: PLY file has no vertex element")
