"""Readers of real LiDAR scans, each into the project's sensor frame (x forward, y left, z up, metres).

:func:`read_real_scan` reads one scan by format (``nuscenes``, ``kitti``, ``semantickitti``,
``npy``, ``ply``, ``las``, ``pcd``; guessed from the file where it can be) into a :class:`RealScan`.
What each reader does with the file's axes:

- ``nuscenes``: float32 records ``x y z intensity ring`` of LIDAR_TOP, whose frame is x right,
  y forward, z up: turned to x forward, y left (``x' = y, y' = -x``). Intensity 0..255 -> 0..1.
  Every firing is listed, empty ones included (near the origin: see :mod:`bpy_pipeline.mixing.firings`).
- ``kitti`` / ``semantickitti``: float32 ``x y z reflectance``, already x forward, y left, z up;
  returns only (no ring field). ``semantickitti`` also reads the ``.label`` file of the same stem
  (beside the scan or in ``../labels/``): uint32, semantic in the low 16 bits, instance in the high 16.
- ``npy``: an organised ``(rings, columns, >= 4)`` array (x y z intensity, zeros for an empty
  firing) or ``(n, >= 3)`` points; taken as the sensor frame.
- ``ply`` / ``las`` / ``pcd``: a user's own sensor, taken as the sensor frame; fields ``x y z``,
  ``intensity`` (LAS: /65535; others: as given, /255 when above 1) and ``ring`` when present.
"""

from __future__ import annotations

import struct

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, require

FORMATS = ("nuscenes", "kitti", "semantickitti", "npy", "ply", "las", "pcd")
NUSCENES_TO_SENSOR = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # x' = y, y' = -x


@dataclass
class RealScan:
    """One real scan in the sensor frame.

    points : (n, 3) float64, metres, x forward, y left, z up (empty firings included where the file lists them)
    intensity : (n,) float64, 0..1
    ring : (n,) int64 laser index, or ``None`` when the file has none
    labels : (n,) uint32 SemanticKITTI labels (semantic low 16 bits, instance high 16), or ``None``
    organised : the file lists every firing in firing order (column after column, rings 0..r-1), empty ones included
    rings : rings of an organised file (``None`` otherwise)
    format, path : what was read
    notes : how the file was interpreted (axes, units) and what is approximate, for the manifest
    kept : (file rows,) bool the file's points kept (non-finite ones left out), or ``None`` when every one is:
        labels given beside the file have one a file row
    """

    points: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray | None = None
    labels: np.ndarray | None = None
    organised: bool = False
    rings: int | None = None
    format: str = ""
    path: str = ""
    notes: list[str] = field(default_factory=list)
    kept: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.points)


def guess_format(path: Path) -> str:
    """The format of ``path`` from its suffix and, for ``.bin``, its size and name."""
    suffix = path.suffix.lower()
    if suffix in (".npy", ".ply", ".las", ".laz", ".pcd"):
        return {".laz": "las"}.get(suffix, suffix[1:])
    if suffix == ".bin":
        size = path.stat().st_size
        name = path.name.lower()
        if path.with_suffix(".label").exists() or (path.parent.parent / "labels" / (path.stem + ".label")).exists():
            return "semantickitti"
        if "nuscenes" in name or "lidar_top" in name or (size % 20 == 0 and size % 16 != 0):
            return "nuscenes"
        if size % 16 == 0 and size % 20 != 0:
            return "kitti"
        raise InputError(f"scene.format: cannot tell whether {path} is a nuScenes (5 floats a point) or KITTI (4 floats) scan; "
                         "give scene.format: nuscenes or kitti")
    raise InputError(f"scene.format: cannot guess the format of {path}; give one of {', '.join(FORMATS)}")


MAX_RINGS = 1024  # ring ids of a real scan are below this (the densest spinning LiDARs have 128 channels)


def _floats(path: Path, fields: int, what: str) -> np.ndarray:
    """``(n, fields)`` float64 records of a float32 file whose size must be a whole number of records."""
    size = path.stat().st_size
    record = 4 * fields
    if size % record:
        raise InputError(f"{path}: {size} bytes are not whole records of {fields} fields of float32 ({what}): {size % record} bytes left over")
    return np.fromfile(path, np.float32).reshape(-1, fields).astype(np.float64)


def read_nuscenes(path: Path) -> RealScan:
    data = _floats(path, 5, "nuScenes: x y z intensity ring")
    ring_values = data[:, 4]
    bad = ~((ring_values >= 0) & (ring_values < MAX_RINGS) & (ring_values == np.round(ring_values)))
    if bad.any():
        raise InputError(f"{path}: field ring: expected whole numbers 0 .. {MAX_RINGS - 1}; "
                         f"record {int(np.flatnonzero(bad)[0])} has {ring_values[bad][0]:g} ({int(bad.sum())} records out of range)")
    ring = ring_values.astype(np.int64)
    rings = int(ring.max()) + 1 if len(ring) else 0
    organised = rings > 0 and len(data) % rings == 0 and bool((ring == np.tile(np.arange(rings), len(data) // rings)).all())
    return RealScan(
        data[:, :3] @ NUSCENES_TO_SENSOR.T, data[:, 3] / 255.0, ring, None, organised, rings if organised else None, "nuscenes", str(path),
        ["axes: nuScenes LIDAR_TOP (x right, y forward, z up) turned to x forward, y left, z up", "intensity: 0..255 / 255"],
    )


def label_path(path: Path) -> Path | None:
    """The SemanticKITTI ``.label`` file of scan ``path``: beside it, or in ``../labels/``."""
    for candidate in (path.with_suffix(".label"), path.parent.parent / "labels" / (path.stem + ".label")):
        if candidate.exists():
            return candidate
    return None


def read_kitti(path: Path, labels: bool = False) -> RealScan:
    data = _floats(path, 4, "KITTI: x y z reflectance")
    scan = RealScan(data[:, :3].copy(), np.clip(data[:, 3], 0.0, 1.0), None, None, False, None, "semantickitti" if labels else "kitti", str(path),
                    ["axes: KITTI velodyne (x forward, y left, z up), unchanged"])
    if labels:
        found = label_path(path)
        if found is None:
            raise InputError(f"{path}: no .label file beside it or in ../labels/ (scene.format: semantickitti needs one; use kitti for the scan alone)")
        if found.stat().st_size % 4:
            raise InputError(f"{found}: {found.stat().st_size} bytes are not whole uint32 labels: {found.stat().st_size % 4} bytes left over")
        scan.labels = np.fromfile(found, np.uint32)
        if len(scan.labels) != len(data):
            raise InputError(f"{found}: {len(scan.labels)} labels for {len(data)} points of {path}")
    return scan


def read_npy(path: Path) -> RealScan:
    try:
        array = np.load(path)
    except (ValueError, OSError, EOFError) as err:
        raise InputError(f"{path}: not a numpy array file ({err})") from None
    if not isinstance(array, np.ndarray):
        raise InputError(f"{path}: expected one array (.npy), got an archive of several (.npz)")
    if array.dtype.kind not in "fiu":
        raise InputError(f"{path}: expected an array of numbers, got {array.dtype}")
    if array.ndim == 3 and array.shape[2] >= 4:
        rings, columns = array.shape[:2]
        flat = array.transpose(1, 0, 2).reshape(-1, array.shape[2]).astype(np.float64)  # column after column
        ring = np.tile(np.arange(rings), columns)
        intensity = flat[:, 3] / (255.0 if flat[:, 3].max(initial=0) > 1 else 1.0)
        return RealScan(flat[:, :3], intensity, ring, None, True, rings, "npy", str(path),
                        ["organised (rings, columns, x y z intensity) taken as the sensor frame"])
    if array.ndim == 2 and array.shape[1] >= 3:
        data = array.astype(np.float64)
        intensity = data[:, 3] if data.shape[1] > 3 else np.zeros(len(data))
        return RealScan(data[:, :3], intensity / (255.0 if intensity.max(initial=0) > 1 else 1.0), None, None, False, None, "npy", str(path),
                        ["points (n, x y z [intensity]) taken as the sensor frame"])
    raise InputError(f"{path}: expected an organised (rings, columns, >= 4) array or (n, >= 3) points, got shape {array.shape}")


def _from_fields(fields: dict, path: Path, fmt: str, intensity_scale: float | None = None) -> RealScan:
    for k in "xyz":
        if k not in fields:
            raise InputError(f"{path}: no '{k}' field (a {fmt} scan needs x, y and z)")
    xyz = np.column_stack([np.asarray(fields[k], np.float64) for k in "xyz"])
    intensity = np.asarray(fields.get("intensity", np.zeros(len(xyz))), np.float64)
    scale = intensity_scale or (255.0 if intensity.max(initial=0) > 1 else 1.0)
    ring = None
    if "ring" in fields:
        values = np.asarray(fields["ring"], np.float64)
        bad = ~((values >= 0) & (values < MAX_RINGS) & (values == np.round(values)))
        if bad.any():
            raise InputError(f"{path}: field ring: expected whole numbers 0 .. {MAX_RINGS - 1}; point {int(np.flatnonzero(bad)[0])} has {values[bad][0]:g}")
        ring = values.astype(np.int64)
    notes = [f"{fmt}: taken as the sensor frame (x forward, y left, z up)", f"intensity / {scale:g}"]
    return RealScan(xyz, intensity / scale, ring, None, False, None, fmt, str(path), notes)


def read_ply(path: Path) -> RealScan:
    PlyData = require("plyfile", "mixing", f"{path}: reading a PLY scan").PlyData

    try:
        vertex = PlyData.read(str(path))["vertex"]
    except Exception as err:  # plyfile raises several types on bad files
        raise InputError(f"{path}: not a readable PLY file with a vertex element ({err})") from None
    from .ply import point_field  # this package's PLY names its label fields scalar_ring etc. (CloudCompare's convention)

    return _from_fields({point_field(name): vertex[name] for name in vertex.data.dtype.names}, path, "ply")


def check_las_layout(path: Path) -> None:
    """``InputError`` when a LAS header's layout does not fit its file: the VLRs it claims (54 bytes each at
    least) must lie between the header and the point data, and the point data must start inside the file
    (laspy reads a claimed VLR count before anything else: 4 billion of them took hours)."""
    with open(path, "rb") as f:
        head = f.read(104)
    if len(head) < 104 or head[:4] != b"LASF":
        return  # laspy's own message names what is wrong
    header_size, offset, vlrs = struct.unpack_from("<HII", head, 94)
    size = path.stat().st_size
    if offset > size:
        raise InputError(f"{path}: LAS header puts the point data at byte {offset}; the file has {size} bytes")
    if header_size > offset or vlrs * 54 > offset - header_size:
        raise InputError(f"{path}: LAS header claims {vlrs} VLRs (54 bytes each at least) between bytes {header_size} and {offset}; they cannot fit")


def read_las(path: Path) -> RealScan:
    try:
        import laspy
    except ImportError:
        raise InputError(f"{path}: reading LAS needs laspy (pip install 'bpy-pipeline[las]')") from None
    check_las_layout(path)
    try:
        with laspy.open(str(path)) as reader:
            header = reader.header
            claimed, offset, record = int(header.point_count), int(header.offset_to_point_data), int(header.point_format.size)
        compressed = path.suffix.lower() == ".laz" or bool(getattr(header, "are_points_compressed", False))
        if not compressed and claimed * record > path.stat().st_size - offset:
            have = (path.stat().st_size - offset) // max(record, 1)
            raise InputError(f"{path}: LAS header point count claims {claimed} records of {record} bytes; the file holds {have}")
        las = laspy.read(str(path))
    except InputError:
        raise
    except Exception as err:  # laspy raises many types on bad files
        raise InputError(f"{path}: not a readable LAS file ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})") from None
    if len(las.points) != claimed:
        raise InputError(f"{path}: LAS header point count claims {claimed} records; {len(las.points)} were read")
    fields = {"x": las.x, "y": las.y, "z": las.z, "intensity": las.intensity}
    names = set(las.point_format.dimension_names)
    if "ring" in names:
        fields["ring"] = las["ring"]
    return _from_fields(fields, path, "las", 65535.0)


def read_pcd(path: Path) -> RealScan:
    from .pcd import read_pcd_fields  # the header checked against the bytes

    data = read_pcd_fields(path)
    for k in ("x", "y", "z", "intensity", "ring"):
        if k in data and data[k].ndim != 1:
            raise InputError(f"{path}: PCD field {k!r} has COUNT {data[k].shape[1]}; expected 1")
    return _from_fields(data, path, "pcd")


READERS = {
    "nuscenes": read_nuscenes,
    "kitti": read_kitti,
    "semantickitti": lambda path: read_kitti(path, labels=True),
    "npy": read_npy,
    "ply": read_ply,
    "las": read_las,
    "pcd": read_pcd,
}


def read_real_scan(path, format: str | None = None) -> RealScan:
    """Read a real scan into the sensor frame (module notes). ``format``: one of :data:`FORMATS`, ``None`` to guess."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"scene.path: {path} is not a file")
    fmt = format or guess_format(path)
    if fmt not in READERS:
        raise InputError(f"scene.format: {fmt!r} is not one of {', '.join(FORMATS)}")
    try:
        scan = READERS[fmt](path)
    except OSError as err:
        raise InputError(f"{path}: cannot read the scan ({err.strerror or err})") from None
    finite = np.isfinite(scan.points).all(axis=1)
    if not finite.all():
        if scan.organised:
            scan.points[~finite] = 0.0  # an organised file marks empty firings with NaN sometimes: empty here too
        else:
            keep = finite
            scan.points, scan.intensity = scan.points[keep], scan.intensity[keep]
            scan.ring = None if scan.ring is None else scan.ring[keep]
            scan.labels = None if scan.labels is None else scan.labels[keep]
            scan.kept = keep
        scan.notes.append(f"{int((~finite).sum())} non-finite points {'taken as empty firings' if scan.organised else 'left out'}")
    if len(scan) == 0:
        raise InputError(f"{path}: the scan holds no points")
    bad = ~np.isfinite(scan.intensity)
    if bad.any():
        raise InputError(f"{path}: field intensity: {int(bad.sum())} of {len(scan)} values are not finite (first at point {int(np.flatnonzero(bad)[0])})")
    return scan
