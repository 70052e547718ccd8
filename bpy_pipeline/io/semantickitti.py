"""SemanticKITTI scans: ``velodyne/NNNNNN.bin`` points and ``labels/NNNNNN.label`` labels.

Layout under a dataset root (as the SemanticKITTI devkit expects)::

    root/sequences/SS/velodyne/NNNNNN.bin     float32 (n, 4): x y z (m), remission (0..1)
    root/sequences/SS/labels/NNNNNN.label     uint32 (n,): semantic | instance << 16

Both files are little-endian and headerless. The format holds x, y, z, intensity, semantic
and a 16-bit instance; ring, time, range and bounces are not kept.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import numpy as np

from ..errors import InputError, path_argument
from ..compiled import compiled_wanted
from ..lidar.points import POINT_DTYPE
from ._records import CACHED_CHUNK, XYZI, XyziBlock, as_points, chunks, packed_columns
from .atomic import atomic_write, hashed_open

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


@cache
def _labels_kernel():
    """The compiled :func:`frame_labels` (numba, cached on disk), or ``None`` without numba or with
    ``BPY_PIPELINE_SCAN_KERNEL=numpy``: ``pack(semantic (n,) uint16, instance (n,) uint32, lut (65536,) uint16, use_lut, out (n,) uint32)``."""
    if not compiled_wanted():
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def pack(semantic, instance, lut, use_lut, out):  # pragma: no cover (compiled)
        for i in range(len(out)):
            label = np.uint32(lut[semantic[i]]) if use_lut else np.uint32(semantic[i])
            out[i] = label | (np.uint32(instance[i]) << np.uint32(16))

    return pack


def frame_labels(points: np.ndarray, semantic_lut: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """``(n,) <u4``: the ``.label`` values of ``(n,)`` POINT_DTYPE ``points`` (:func:`pack_labels` of ``semantic_lut[semantic]``,
    or of ``semantic`` without a table, and ``instance``), whose instance ids the caller has checked (:func:`check_instances`);
    in ``out`` ((n,) <u4) when given. One compiled pass where numba is there and the table covers every uint16 id; the same
    values either way."""
    out = np.empty(len(points), "<u4") if out is None else out
    kernel = _labels_kernel()
    lut = np.zeros(1, np.uint16) if semantic_lut is None else semantic_lut
    if (kernel is None or points.dtype != POINT_DTYPE or lut.dtype != np.uint16 or lut.ndim != 1
            or (semantic_lut is not None and len(lut) < 1 << 16)):
        semantic = points["semantic"] if semantic_lut is None else semantic_lut[points["semantic"]]
        out[:] = pack_labels(semantic, points["instance"])
        return out
    kernel(points["semantic"], points["instance"], lut, semantic_lut is not None, out)
    return out


def write_semantickitti(root: str | os.PathLike, sequence: int, frame: int, points: np.ndarray, semantic_lut: np.ndarray | None = None,
                        xyzi: XyziBlock | None = None) -> tuple[Path, Path]:
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
    semantic_lut : (65536,) uint16, optional
        The label space written: ``semantic_lut[semantic]`` (SemanticKITTI's raw ids:
        :func:`~.class_maps.semantic_kitti_lut`); ``None`` writes ``semantic`` as it is.
    xyzi : :class:`~._records.XyziBlock`, optional
        The points' x y z intensity and their sha256, made once for the files that hold these bytes: the ``.bin`` is
        written from it in one piece.

    Returns
    -------
    (bin_path, label_path) : tuple of Path
        Both files appear atomically; neither is written when the input is rejected.
    """
    bin_path, label_path = scan_paths(root, sequence, frame)
    pts = as_points(points, str(bin_path))
    check_instances(pts["instance"], str(label_path))
    with atomic_write(bin_path) as tmp_bin, atomic_write(label_path) as tmp_label, hashed_open(tmp_bin) as f_bin, hashed_open(tmp_label) as f_label:
        scan, labels = np.empty((min(len(pts), CACHED_CHUNK), 4), "<f4"), np.empty(min(len(pts), CACHED_CHUNK), "<u4")  # reused a chunk
        if xyzi is not None:
            f_bin.write(xyzi.array, xyzi.sha256)
        for part in chunks(len(pts), CACHED_CHUNK):
            size = part.stop - part.start
            if xyzi is None:
                f_bin.write(packed_columns(pts[part], XYZI, out=scan[:size]))
            f_label.write(frame_labels(pts[part], semantic_lut, labels[:size]))
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
    scan = read_bin(path_argument(bin_path, "bin_path"))
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


# ----------------------------------------------------------------------------- the dataset's index
def label_counts(paths) -> np.ndarray:
    """``(65536,)`` int64 points per raw semantic id over the ``.label`` files ``paths``."""
    counts = np.zeros(1 << 16, np.int64)
    for path in paths:
        labels = np.fromfile(path, "<u4")
        counts += np.bincount(labels & 0xFFFF, minlength=1 << 16)
    return counts


def pose_lines(poses: list[np.ndarray], tr: np.ndarray) -> str:
    """``poses.txt``: each frame's camera pose relative to the first frame's camera, 3 x 4 row-major.

    poses : (4, 4) sensor-to-world transforms; tr : (3, 4) ``Tr`` (velodyne to camera) of ``calib.txt``,
    so the devkit's ``inv(Tr) @ pose @ Tr`` gives back the sensor's motion.
    """
    tr4 = np.vstack([tr, [0.0, 0.0, 0.0, 1.0]])
    first = np.linalg.inv(np.asarray(poses[0], float))
    rows = []
    for pose in poses:
        camera = tr4 @ first @ np.asarray(pose, float) @ np.linalg.inv(tr4)
        rows.append(" ".join(f"{v:.12e}" for v in camera[:3].ravel()))
    return "".join(row + "\n" for row in rows)


MMDET3D_INFOS = "semantickitti_infos_{}.pkl"  # mmdetection3d's ann_file names (configs/_base_/datasets/semantickitti.py)


def frame_sequences(records: list[dict]) -> dict[int, list[dict]]:
    """``{sequence: records in frame order}`` of the records whose files hold a SemanticKITTI scan."""
    out: dict[int, list[dict]] = {}
    for record in sorted(records, key=lambda r: r["index"]):
        for rel in record["files"]:
            parts = Path(rel).parts
            if len(parts) == 4 and parts[0] == "sequences" and parts[2] == "velodyne":
                out.setdefault(int(parts[1]), []).append(record)
                break
    return dict(sorted(out.items()))


def mmdet3d_infos(sequences: dict[int, list[dict]], numbers) -> dict:
    """mmdetection3d's SemanticKITTI info file (``tools/dataset_converters/semantickitti_converter.py``'s layout)
    over the written scans of sequences ``numbers``: paths relative to the dataset root (its ``data_root``)."""
    data_list = []
    for sequence in numbers:
        for record in sequences.get(sequence, []):
            stem = f"{record['index']:06d}"
            data_list.append({
                "lidar_points": {"lidar_path": f"sequences/{sequence:02d}/velodyne/{stem}.bin", "num_pts_feats": 4},
                "pts_semantic_mask_path": f"sequences/{sequence:02d}/labels/{stem}.label",
                "sample_id": f"{sequence}{record['index']}",
            })  # fmt: skip
    return {"metainfo": {"DATASET": "SemanticKITTI"}, "data_list": data_list}


def write_index(out_dir: str | os.PathLike, records: list[dict], config) -> list[Path]:
    """The dataset files beside the scans: ``semantic-kitti.yaml``, ``sequences/SS/{calib,poses,times}.txt`` and
    mmdetection3d's ``semantickitti_infos_{train,val,test}.pkl``.

    ``semantic-kitti.yaml`` holds the class table the devkit's way, in the label space written
    (``output.semantickitti.labels``: :func:`~.class_maps.semantic_kitti_space_yaml` or, for ``project``,
    :func:`~.class_maps.semantic_kitti_yaml`), ``content`` counted over the written labels and ``split`` the
    sequences that hold scans (:mod:`.splits`: train 00-07, 09, 10; valid 08; test 11-21). Each such sequence
    gets ``calib.txt`` (``output.kitti.camera``: P0..P3 and ``Tr``), ``poses.txt`` and ``times.txt``, one line per
    scan in file order, from the records' sensor poses and the frame period (frame index x the sensor's frame
    time, or the moving platform's time where a record has one). The stock sequences of a split that holds scans
    but got none of them get empty ``velodyne/`` and ``labels/`` folders: Pointcept lists every one of them.
    A split without scans gets no info file.
    """
    import pickle

    import yaml

    from ..lidar.sensor.sensors import frame_time
    from .class_maps import semantic_kitti_space_yaml, semantic_kitti_yaml
    from .kitti import calib_text, camera_matrices
    from .splits import SEQUENCES, split_of_sequence

    out_dir = Path(out_dir)
    sequences = frame_sequences(records)
    counts = label_counts(out_dir / f for r in records for f in r["files"] if f.endswith(".label") and "/labels/" in f)
    by_split = {name: [s for s in sequences if split_of_sequence(s) == name] for name in SEQUENCES}
    split = {"train": by_split["train"], "valid": by_split["val"], "test": by_split["test"]}
    project = config.output.semantickitti.labels == "project"
    table = (semantic_kitti_yaml if project else semantic_kitti_space_yaml)(counts, split, config.output.class_map or None)
    space = ("the project's raw ids (output.semantickitti.labels: project)" if project
             else "SemanticKITTI's raw ids (labels.yaml semantickitti:, listed under project_classes)")
    written = []
    with atomic_write(out_dir / "semantic-kitti.yaml") as tmp:
        tmp.write_text(f"# The class table of this dataset in the SemanticKITTI devkit's layout (color_map is BGR).\n"
                       f"# .label files hold {space}; learning_map gives the training ids.\n" + yaml.safe_dump(table, sort_keys=False))
    written.append(out_dir / "semantic-kitti.yaml")
    for name, numbers in by_split.items():
        path = out_dir / MMDET3D_INFOS.format(name)
        if not numbers:
            path.unlink(missing_ok=True)
            continue
        with atomic_write(path) as tmp:
            tmp.write_bytes(pickle.dumps(mmdet3d_infos(sequences, numbers), protocol=2))  # mmengine.dump's protocol
        written.append(path)
        for sequence in SEQUENCES[name]:
            for folder in ("velodyne", "labels"):
                (out_dir / "sequences" / f"{sequence:02d}" / folder).mkdir(parents=True, exist_ok=True)
    if not sequences:
        return written
    k, tr = camera_matrices(config.output.kitti.camera)
    period = frame_time(config.sensor.spec)
    calib = "".join(line.replace("Tr_velo_to_cam:", "Tr:") + "\n" for line in calib_text(k, tr).splitlines() if line.startswith(("P", "Tr_velo")))
    for sequence, scans in sequences.items():
        folder = out_dir / "sequences" / f"{sequence:02d}"
        times = [float(r["trajectory"]["start_time_s"]) if isinstance(r.get("trajectory"), dict) and "start_time_s" in r["trajectory"] else r["index"] * period
                 for r in scans]
        texts = {
            "calib.txt": calib,
            "poses.txt": pose_lines([np.asarray(r["sensor_pose"], float) for r in scans], tr),
            "times.txt": "".join(f"{t:.6e}\n" for t in times),
        }
        for name, text in texts.items():
            with atomic_write(folder / name) as tmp:
                tmp.write_text(text)
            written.append(folder / name)
    return written
