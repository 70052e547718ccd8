"""LAS 1.4 point clouds, point data record format 6, written with numpy alone.

File layout: a 375-byte header (:data:`HEADER_DTYPE`), two VLRs (the Extra Bytes VLR, user id
``LASF_Spec`` record id 4, describing five extra dimensions; the Classification Lookup VLR,
``LASF_Spec`` record id 0, naming every classification code of the file), then ``n`` records of
43 bytes: the 30-byte PDRF 6 record (:data:`PDRF6_DTYPE`) followed by the extra bytes. Mapping
from :data:`POINT_DTYPE`::

    x y z      -> X Y Z int32, coordinate = X * scale + offset (m)
    intensity  -> intensity uint16, round(intensity * 65535) for intensity in 0..1
    semantic   -> classification uint8: the ASPRS class where one has the same meaning (ground 2,
                  building 6, rail 10, road surface 11, wire guard 13, wire conductor 14, tower 15,
                  wire-structure connector 16, overhead structure 19; labels.yaml ``asprs``), else
                  the user-definable code 64 + raw id; and extra dimension "semantic" uint16 (raw id)
    time       -> gps_time float64 (s from frame start; global encoding says GPS week time)
    instance   -> extra dimension "instance" uint32
    ring       -> extra dimension "ring" uint16
    range      -> extra dimension "range" float32 (m)
    bounces    -> extra dimension "bounces" uint8
    every point: return number 1 of 1, other fields zero

The synthetic flag (classification flag bit 0) is not set: ASPRS defines it for points added to
a survey that was scanned, while every point here is synthetic, and readers that drop or grey out
flagged points would hide the whole cloud. The file says where it comes from in its generating
software field instead. Points are in the sensor (or world) frame of the run, not a geographic
one, so the file has no CRS VLR. Reference: ASPRS LAS Specification 1.4 R15.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

import numpy as np

from ..errors import InputError, path_argument
from ..lidar.points import POINT_DTYPE
from ._records import as_points, chunks
from .atomic import atomic_write
from .class_maps import ASPRS_NAMES, ClassMaps, load_class_maps

HEADER_DTYPE = np.dtype(
    [
        ("file_signature", "S4"),
        ("file_source_id", "<u2"),
        ("global_encoding", "<u2"),
        ("guid_1", "<u4"),
        ("guid_2", "<u2"),
        ("guid_3", "<u2"),
        ("guid_4", "u1", (8,)),
        ("version_major", "u1"),
        ("version_minor", "u1"),
        ("system_identifier", "S32"),
        ("generating_software", "S32"),
        ("creation_day", "<u2"),
        ("creation_year", "<u2"),
        ("header_size", "<u2"),
        ("offset_to_point_data", "<u4"),
        ("number_of_vlrs", "<u4"),
        ("point_data_format", "u1"),
        ("point_data_record_length", "<u2"),
        ("legacy_point_count", "<u4"),
        ("legacy_points_by_return", "<u4", (5,)),
        ("scale", "<f8", (3,)),
        ("offset", "<f8", (3,)),
        ("max_x", "<f8"),
        ("min_x", "<f8"),
        ("max_y", "<f8"),
        ("min_y", "<f8"),
        ("max_z", "<f8"),
        ("min_z", "<f8"),
        ("start_of_waveform_data", "<u8"),
        ("start_of_first_evlr", "<u8"),
        ("number_of_evlrs", "<u4"),
        ("point_count", "<u8"),
        ("points_by_return", "<u8", (15,)),
    ]
)
assert HEADER_DTYPE.itemsize == 375

VLR_HEADER_DTYPE = np.dtype(
    [("reserved", "<u2"), ("user_id", "S16"), ("record_id", "<u2"), ("record_length_after_header", "<u2"), ("description", "S32")]
)
assert VLR_HEADER_DTYPE.itemsize == 54

EXTRA_BYTES_DTYPE = np.dtype(
    [
        ("reserved", "u1", (2,)),
        ("data_type", "u1"),
        ("options", "u1"),
        ("name", "S32"),
        ("unused", "u1", (4,)),
        ("no_data", "u1", (24,)),
        ("min", "u1", (24,)),
        ("max", "u1", (24,)),
        ("scale", "<f8", (3,)),
        ("offset", "<f8", (3,)),
        ("description", "S32"),
    ]
)
assert EXTRA_BYTES_DTYPE.itemsize == 192

PDRF6_DTYPE = np.dtype(
    [
        ("X", "<i4"),
        ("Y", "<i4"),
        ("Z", "<i4"),
        ("intensity", "<u2"),
        ("returns", "u1"),  # bits 0-3 return number, bits 4-7 number of returns
        ("flags", "u1"),  # classification flags, scanner channel, scan direction, edge of flight line
        ("classification", "u1"),
        ("user_data", "u1"),
        ("scan_angle", "<i2"),
        ("point_source_id", "<u2"),
        ("gps_time", "<f8"),
    ]
)
assert PDRF6_DTYPE.itemsize == 30

# (name, numpy type, LAS extra-bytes data type code, description)
EXTRA_DIMENSIONS = (
    ("semantic", "<u2", 3, "bpy_pipeline raw class id"),
    ("instance", "<u4", 5, "object instance id, 0 for none"),
    ("ring", "<u2", 3, "laser channel"),
    ("range", "<f4", 9, "metres along the beam"),
    ("bounces", "u1", 1, "mirror reflections before the hit"),
)
RECORD_DTYPE = np.dtype(PDRF6_DTYPE.descr + [(name, code) for name, code, _, _ in EXTRA_DIMENSIONS])
GLOBAL_ENCODING_WKT = 1 << 4  # the LAS 1.4 spec requires the WKT bit for PDRF 6..10
SOFTWARE = b"bpy_pipeline"


CLASSIFICATION_LOOKUP_DTYPE = np.dtype([("class_number", "u1"), ("description", "S15")])


def classification_lookup_vlr(codes: np.ndarray, maps: ClassMaps) -> bytes:
    """The Classification Lookup VLR (``LASF_Spec``, record id 0): 256 entries of 16 bytes, each code used named.

    codes : the classification codes present; a standard ASPRS code gets its ASPRS name, a
    user-definable one (64 + raw id) the project's class name.
    """
    from ..labels import load_class_table

    names = load_class_table().names
    table = np.zeros(256, CLASSIFICATION_LOOKUP_DTYPE)
    table["class_number"] = np.arange(256)
    for code in np.flatnonzero(np.bincount(codes, minlength=256)):  # the codes present (a count, not a sort)
        code = int(code)
        raws = [names[r] for r in sorted(names) if int(maps.asprs[r]) == code]
        text = ASPRS_NAMES.get(code) if code < 64 else (raws[0] if raws else f"class {code}")
        table[code]["description"] = (text or "reserved")[:15].encode("ascii", "replace")
    header = np.zeros((), VLR_HEADER_DTYPE)
    header["user_id"] = b"LASF_Spec"
    header["record_id"] = 0
    header["record_length_after_header"] = table.nbytes
    header["description"] = b"Classification lookup"
    return header.tobytes() + table.tobytes()


def extra_bytes_vlr() -> bytes:
    """The Extra Bytes VLR (header and one 192-byte descriptor per extra dimension)."""
    descriptors = np.zeros(len(EXTRA_DIMENSIONS), EXTRA_BYTES_DTYPE)
    for i, (name, _, code, description) in enumerate(EXTRA_DIMENSIONS):
        descriptors[i]["data_type"] = code
        descriptors[i]["name"] = name.encode("ascii")
        descriptors[i]["description"] = description.encode("ascii")
    header = np.zeros((), VLR_HEADER_DTYPE)
    header["user_id"] = b"LASF_Spec"
    header["record_id"] = 4
    header["record_length_after_header"] = descriptors.nbytes
    header["description"] = b"bpy_pipeline point record fields"
    return header.tobytes() + descriptors.tobytes()


def default_offset(xyz: np.ndarray) -> np.ndarray:
    """``(3,) float64``: the floor of the minimum of each column of ``xyz`` (n, 3); zeros when empty."""
    if len(xyz) == 0:
        return np.zeros(3)
    return np.floor(xyz.min(axis=0))


def write_las(
    path: str | os.PathLike,
    points: np.ndarray,
    scale: float = 0.001,
    offset=None,
    creation_date: datetime.date | None = None,
    maps: ClassMaps | None = None,
) -> Path:
    """Write ``points`` as a LAS 1.4 file (point data record format 6 with extra bytes).

    Parameters
    ----------
    path : str or PathLike
        Destination file; parent folders are created, the file appears atomically.
    points : (n,) POINT_DTYPE
        Points (``n`` may be 0). ``semantic`` must be <= 255 and ``x y z intensity`` finite.
    scale : float or (3,) float
        Metres per coordinate unit; 0.001 keeps millimetres.
    offset : None or (3,) float
        Coordinate offset in metres; default the floor of the minimum coordinates, so the int32
        coordinates reach about 2,000 km from it at millimetre scale.
    creation_date : datetime.date or None
        Written as the header's creation day and year; None (default) writes zeros so the same
        points give the same bytes on any day.
    maps : ClassMaps or None
        The class table's maps (ASPRS codes); default :func:`~.class_maps.load_class_maps`.

    Returns
    -------
    path : Path
        The written file.
    """
    path = Path(path)
    pts = as_points(points, str(path))
    maps = load_class_maps() if maps is None else maps
    n = len(pts)
    # The extents from each column's minimum and maximum (a NaN or an infinity makes them non-finite).
    low = np.array([pts[c].min() if n else np.inf for c in "xyz"], np.float64)
    high = np.array([pts[c].max() if n else -np.inf for c in "xyz"], np.float64)
    if n and not (np.isfinite(low).all() and np.isfinite(high).all() and np.isfinite([pts["intensity"].min(), pts["intensity"].max()]).all()):
        raise InputError(f"{path}: LAS cannot store non-finite coordinates or intensity")
    semantic = pts["semantic"]
    scale = np.broadcast_to(np.asarray(scale, np.float64), (3,)).copy()
    if not (np.isfinite(scale).all() and (scale > 0).all()):
        raise InputError(f"{path}: LAS scale must be positive and finite, got {scale.tolist()}")
    offset = default_offset(low[None] if n else low[:0]) if offset is None else np.broadcast_to(np.asarray(offset, np.float64), (3,)).copy()
    if not np.isfinite(offset).all():
        raise InputError(f"{path}: LAS offset must be finite, got {offset.tolist()}")
    # Quantising is monotonic, so the extreme points give the extreme int32 values and stored coordinates.
    q_low, q_high = (np.rint((bound - offset) / scale) for bound in (low, high))
    limit = np.iinfo(np.int32)
    if n and (q_low.min() < limit.min or q_high.max() > limit.max):
        raise InputError(
            f"{path}: coordinates do not fit LAS int32 with scale {scale.tolist()} and offset {offset.tolist()}; "
            "use a larger scale or an offset nearer the points"
        )
    classification = maps.asprs[semantic]
    vlrs = extra_bytes_vlr() + classification_lookup_vlr(classification, maps)
    header = np.zeros((), HEADER_DTYPE)
    header["file_signature"] = b"LASF"
    header["global_encoding"] = GLOBAL_ENCODING_WKT
    header["version_major"], header["version_minor"] = 1, 4
    header["system_identifier"] = b"OTHER"
    header["generating_software"] = SOFTWARE
    if creation_date is not None:
        header["creation_day"] = creation_date.timetuple().tm_yday
        header["creation_year"] = creation_date.year
    header["header_size"] = HEADER_DTYPE.itemsize
    header["offset_to_point_data"] = HEADER_DTYPE.itemsize + len(vlrs)
    header["number_of_vlrs"] = 2
    header["point_data_format"] = 6
    header["point_data_record_length"] = RECORD_DTYPE.itemsize
    header["scale"], header["offset"] = scale, offset
    if n:  # the extents of the coordinates as stored
        (header["min_x"], header["min_y"], header["min_z"]) = q_low * scale + offset
        (header["max_x"], header["max_y"], header["max_z"]) = q_high * scale + offset
    header["point_count"] = n
    header["points_by_return"][0] = n

    with atomic_write(path) as tmp, open(tmp, "wb") as f:
        f.write(header.tobytes())
        f.write(vlrs)
        for part in chunks(n):  # one structured array a chunk (all of a frame up to a million points), one write
            records = las_records(pts[part], classification[part], offset, scale)
            records.tofile(f)
    return path


def las_records(pts: np.ndarray, classification: np.ndarray, offset: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``(n,)`` :data:`RECORD_DTYPE` records of ``(n,)`` POINT_DTYPE points (coordinates checked to fit int32)."""
    records = np.zeros(len(pts), RECORD_DTYPE)
    work = np.empty(len(pts), np.float64)
    for axis, name in enumerate("xyz"):
        np.subtract(pts[name], offset[axis], out=work, dtype=np.float64)
        np.divide(work, scale[axis], out=work)
        records[name.upper()] = np.rint(work, out=work)
    np.clip(pts["intensity"], 0.0, 1.0, out=work, dtype=np.float64)
    records["intensity"] = np.rint(np.multiply(work, 65535.0, out=work), out=work)
    records["returns"] = 1 | (1 << 4)
    records["classification"] = classification
    records["gps_time"] = pts["time"]
    for name, _, _, _ in EXTRA_DIMENSIONS:
        records[name] = pts[name]
    return records


# LAS extra-bytes data type codes 1..10 -> numpy types.
EXTRA_BYTES_TYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8", 9: "<f4", 10: "<f8"}


def read_las(path: str | os.PathLike) -> np.ndarray:
    """Read a LAS 1.4 point data record format 6 file as ``(n,)`` :data:`POINT_DTYPE`.

    The inverse of :func:`write_las` (coordinates come back as ``X * scale + offset`` cast to
    float32, intensity as ``intensity / 65535``, semantic from classification, time from
    gps_time); extra dimensions named like :data:`POINT_DTYPE` fields are read from the Extra
    Bytes VLR (``semantic``, the raw class id, replaces the classification), others are skipped,
    and absent ones are zero. Other point formats, compressed
    (LAZ) files and older versions raise ``InputError``; use ``laspy`` for those.
    """
    path = Path(path_argument(path))
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read LAS file ({err.strerror})") from None
    if len(raw) < HEADER_DTYPE.itemsize or raw[:4] != b"LASF":
        raise InputError(f"{path}: not a LAS file (no LASF signature)")
    header = np.frombuffer(raw, HEADER_DTYPE, count=1)[0]
    version = (int(header["version_major"]), int(header["version_minor"]))
    if version != (1, 4) or int(header["point_data_format"]) != 6:
        raise InputError(
            f"{path}: only LAS 1.4 point format 6 is read here, got LAS {version[0]}.{version[1]} "
            f"format {int(header['point_data_format']) & 0x3F}"
        )
    fields = list(PDRF6_DTYPE.descr)
    position = int(header["header_size"])
    for k in range(int(header["number_of_vlrs"])):
        if position + VLR_HEADER_DTYPE.itemsize > len(raw):
            raise InputError(f"{path}: LAS header number_of_vlrs claims {int(header['number_of_vlrs'])} VLRs; the file ends in VLR {k}")
        vlr = np.frombuffer(raw, VLR_HEADER_DTYPE, count=1, offset=position)[0]
        position += VLR_HEADER_DTYPE.itemsize
        size = int(vlr["record_length_after_header"])
        if position + size > len(raw):
            raise InputError(f"{path}: LAS VLR {k} claims {size} bytes; the file ends before them")
        if vlr["user_id"] == b"LASF_Spec" and int(vlr["record_id"]) == 4:
            for d in np.frombuffer(raw, EXTRA_BYTES_DTYPE, count=size // EXTRA_BYTES_DTYPE.itemsize, offset=position):
                name = d["name"].decode("ascii", "replace")
                code = EXTRA_BYTES_TYPES.get(int(d["data_type"]))
                fields.append((name, code) if code else (f"_skip{len(fields)}", f"V{int(d['options'])}"))
        position += size
    try:
        record = np.dtype(fields)
    except (ValueError, TypeError) as err:
        raise InputError(f"{path}: LAS Extra Bytes VLR describes fields numpy cannot lay out ({err})") from None
    length = int(header["point_data_record_length"])
    if record.itemsize > length:
        raise InputError(f"{path}: records of {length} bytes are shorter than their {record.itemsize}-byte description")
    record = np.dtype({"names": record.names, "formats": [record[i] for i in range(len(record))],
                       "offsets": [record.fields[name][1] for name in record.names], "itemsize": length})
    n = int(header["point_count"])
    start = int(header["offset_to_point_data"])
    if start + n * length > len(raw) or start < int(header["header_size"]):
        raise InputError(f"{path}: LAS header point_count claims {n} points of {length} bytes from byte {start}; "
                         f"the file holds {max(len(raw) - start, 0) // max(length, 1)}")
    records = np.frombuffer(raw, record, count=n, offset=start)
    out = np.zeros(n, POINT_DTYPE)
    for axis, name in enumerate("xyz"):
        out[name] = records[name.upper()] * header["scale"][axis] + header["offset"][axis]
    out["intensity"] = records["intensity"] / 65535.0
    out["semantic"] = records["classification"]  # another writer's file: its classification (overwritten by a "semantic" extra dimension)
    out["time"] = records["gps_time"]
    for name, _, _, _ in EXTRA_DIMENSIONS:
        if name in record.names:
            out[name] = records[name]
    return out
