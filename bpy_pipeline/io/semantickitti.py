"""SemanticKITTI scans: ``velodyne/NNNNNN.bin`` points and ``labels/NNNNNN.label`` labels.

Layout under a dataset root (as the SemanticKITTI devkit expects)::

    root/sequences/SS/velodyne/NNNNNN.bin     float32 (n, 4): x y z (m), remission (0..1)
    root/sequences/SS/labels/NNNNNN.label     uint32 (n,): semantic | instance << 16

Both files are little-endian and headerless. The format holds x, y, z, intensity, semantic
and a 16-bit instance; ring, time, range and bounces are not kept.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..lidar.points import POINT_DTYPE
from ._records import as_points, chunks
from .atomic import atomic_write

MAX_INSTANCE = 0xFFFF


def scan_paths(root: str | os.PathLike, sequence: int, frame: int) -> tuple[Path, Path]:
    """``(bin_path, label_path)`` of one frame: ``root/sequences/SS/{velodyne,labels}/NNNNNN.*``."""
    for name, value in (("sequence", sequence), ("frame", frame)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise InputError(f"SemanticKITTI {name}: expected an integer >= 0, got {value!r}")
    folder = Path(root) / "sequences" / f"{int(sequence):02d}"
    stem = f"{int(frame):06d}"
    return folder / "velodyne" / f"{stem}.bin", folder / "labels" / f"{stem}.label"


def pack_labels(semantic: np.ndarray, instance: np.ndarray, where: str = "SemanticKITTI labels") -> np.ndarray:
    """``(n,) uint32`` labels: ``semantic`` (n,) in the low 16 bits, ``instance`` (n,) in the high 16.

    ``InputError`` naming ``where`` when an instance id does not fit in 16 bits (no silent wrap).
    """
    instance = np.asarray(instance)
    check_instances(instance, where)
    return np.asarray(semantic).astype("<u4") | (instance.astype("<u4") << 16)


def check_instances(instance: np.ndarray, where: str = "SemanticKITTI labels") -> None:
    """``InputError`` naming ``where`` when an instance id of ``instance`` (n,) does not fit in 16 bits."""
    if instance.size and int(instance.max()) > MAX_INSTANCE:
        bad = int(np.count_nonzero(instance > MAX_INSTANCE))
        raise InputError(
            f"{where}: SemanticKITTI stores instance ids 0..{MAX_INSTANCE} in the high 16 bits of the label; "
            f"{bad} points have larger ids (max {int(instance.max())})"
        )


def write_semantickitti(root: str | os.PathLike, sequence: int, frame: int, points: np.ndarray) -> tuple[Path, Path]:
    """Write one frame as ``root/sequences/SS/velodyne/NNNNNN.bin`` and ``.../labels/NNNNNN.label``.

    Parameters
    ----------
    root : str or PathLike
        Dataset root; folders are created.
    sequence : int
        Sequence number (``SS``, two digits or more).
    frame : int
        Frame number (``NNNNNN``, six digits or more).
    points : (n,) POINT_DTYPE
        ``x y z`` (m) and ``intensity`` (0..1) go to the ``.bin`` as float32 ``(n, 4)``;
        ``semantic`` and ``instance`` (<= 65535, else ``InputError``) to the ``.label``.

    Returns
    -------
    (bin_path, label_path) : tuple of Path
        Both files appear atomically; neither is written when the input is rejected.
    """
    bin_path, label_path = scan_paths(root, sequence, frame)
    pts = as_points(points, str(bin_path))
    check_instances(pts["instance"], str(label_path))
    with atomic_write(bin_path) as tmp_bin, atomic_write(label_path) as tmp_label, open(tmp_bin, "wb") as f_bin, open(tmp_label, "wb") as f_label:
        for part in chunks(len(pts)):
            scan = np.empty((part.stop - part.start, 4), "<f4")
            for i, name in enumerate(("x", "y", "z", "intensity")):
                scan[:, i] = pts[name][part]
            scan.tofile(f_bin)
            pack_labels(pts["semantic"][part], pts["instance"][part], str(label_path)).tofile(f_label)
    return bin_path, label_path


def read_bin(path: str | os.PathLike, columns: int = 4) -> np.ndarray:
    """Read a KITTI-style ``.bin`` scan as ``(n, columns)`` float32 (x, y, z, remission, ...).

    ``columns`` is 4 for KITTI and SemanticKITTI, 5 for nuScenes sweeps. ``InputError`` naming
    the file when it is missing or its size is not a whole number of rows.
    """
    path = Path(path)
    try:
        data = np.fromfile(path, "<f4")
    except OSError as err:
        raise InputError(f"{path}: cannot read scan ({err.strerror})") from None
    if data.size % columns:
        raise InputError(f"{path}: {data.size * 4} bytes is not a whole number of {columns}-float32 rows")
    return data.reshape(-1, columns)


def read_label(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a SemanticKITTI ``.label`` file as ``(semantic (n,) uint16, instance (n,) uint16)``."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read labels ({err.strerror})") from None
    if len(raw) % 4:
        raise InputError(f"{path}: {len(raw)} bytes is not a whole number of uint32 labels")
    labels = np.frombuffer(raw, "<u4")
    return (labels & 0xFFFF).astype(np.uint16), (labels >> 16).astype(np.uint16)


def read_semantickitti(bin_path: str | os.PathLike, label_path: str | os.PathLike | None = None) -> np.ndarray:
    """Read a ``.bin`` scan and (optionally) its ``.label`` file as ``(n,)`` :data:`POINT_DTYPE`.

    ``x y z intensity`` come from the scan, ``semantic`` and ``instance`` from the labels
    (zero without a label file); ``ring``, ``time``, ``range`` and ``bounces`` are zero.
    ``InputError`` when the two files hold different point counts.
    """
    scan = read_bin(bin_path)
    out = np.zeros(len(scan), POINT_DTYPE)
    for i, name in enumerate(("x", "y", "z", "intensity")):
        out[name] = scan[:, i]
    if label_path is not None:
        semantic, instance = read_label(label_path)
        if len(semantic) != len(scan):
            raise InputError(f"{label_path}: {len(semantic)} labels for {len(scan)} points in {bin_path}")
        out["semantic"] = semantic
        out["instance"] = instance
    return out
