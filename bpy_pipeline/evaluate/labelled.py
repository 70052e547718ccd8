"""Labelled scans for the evaluation: real labelled files and generated datasets, in evaluation labels.

A :class:`LabelledScan` is one frame in the sensor frame (x forward, y left, z up, metres) with a label per
point in the evaluation space of :mod:`.label_maps` (0..C-1 the requested classes, C "other", -1 ignored)
and an object id per point. Each reader reads its source's own label space and maps it with
:mod:`.label_maps`; :data:`READERS` is the registry, :func:`load_scans` looks a path's kind up:

- ``semantickitti``: a ``.bin`` scan (float32 x y z reflectance) with its ``.label`` (uint32: semantic raw id in
  the low 16 bits, instance in the high 16) beside it (same stem) or in ``../labels/``;
- ``npy``: ``X_points.npy`` ((n, 3) or (n, 4) float, the fourth column remission 0..1) with ``X_labels.npy``
  ((n,) or (n, 1) int, SemanticKITTI training ids 0..19), as the project's real test scans are stored; a name
  starting ``squeezeseg_`` holds SqueezeSeg's KITTI-tracklet labels instead (0 background, 1 car, 2 pedestrian,
  3 cyclist: :data:`~.label_maps.SQUEEZESEG_NAMES`), which label only car, person and bicyclist;
- ``kitti_object``: a KITTI object frame, velodyne ``.bin`` with its ``label_2`` and ``calib`` text files, in
  the standard layout (``velodyne/NNNNNN.bin``, ``label_2/NNNNNN.txt``, ``calib/NNNNNN.txt``) or as files beside
  the scan whose names end with ``NNNNNN_label_2.txt`` / ``NNNNNN_calib.txt`` for the frame number in its name.
  Points inside a 3D box take its type's class; only the camera's field of view is labelled (points with camera
  z > 0 that P2 projects inside the image), the rest ignored; points projecting into a DontCare 2D box are
  ignored unless inside a box of a requested class;
- ``generated``: a dataset folder made by the pipeline (``ply/*.ply``, project class ids in ``semantic``), optionally
  every ``every``-th frame and at most ``max_frames``.

Remission (``LabelledScan.remission``, 0..1) is read where the source has it (SemanticKITTI and KITTI ``.bin``,
``(n, 4)`` ``.npy``, the ``intensity`` of generated PLY frames) and is ``None`` otherwise. Sources that label only
some classes (KITTI boxes, SqueezeSeg) say which in ``LabelledScan.known``; the metrics score a class only on
the scans that know it.

Groups (for leave-one-group-out): a SemanticKITTI sequence (the folder above ``velodyne/``, or the file name
without its trailing ``_NNNNNN`` frame number), a KITTI object frame alone, a generated dataset folder.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from ..errors import InputError, require
from ..geometry.transforms import sensor_to_output
from ..io.confined import readable_inside
from ..io.manifest import read_frame_records, read_manifest
from ..io.ply import read_ply
from ..io.real_scans import label_path as semantickitti_label_path
from ..io.real_scans import read_kitti
from . import label_maps

LINK_M = 0.5  # connected-component linking distance for objects of sources without instance ids, metres
IMAGE_SIZE = (1242, 375)  # KITTI's image_2 width, height in pixels
MAX_PLY_BYTES = 1 << 34  # a generated frame's PLY larger than this (16 GB) is not one


@dataclass
class LabelledScan:
    """One labelled frame.

    name : unique name (file stem, or ``dataset/NNNNNN``)
    group : sequence id: frames of one group are never split between training and test
    points : (n, 3) float32, metres, sensor frame (x forward, y left, z up)
    labels : (n,) int64 evaluation labels: 0..C-1 the requested classes, C other, -1 ignored
    instances : (n,) int64 object id of each point of a requested class (unique within the scan), -1 elsewhere
    classes : the requested classes (``labels`` index them)
    truth : (n,) int64 SemanticKITTI training id per point (0..19; -2 labelled but of no training class, as raw 52
        other-structure) when the source has per-point classes, ``None`` otherwise (KITTI boxes)
    source : where it was read from
    remission : (n,) float32 remission 0..1 when the source has it, else ``None``
    known : the requested classes this scan labels (``None``: all of them); its "other" points are of none of
        these, of any other class maybe (a KITTI frame's points outside every box)
    """

    name: str
    group: str
    points: np.ndarray
    labels: np.ndarray
    instances: np.ndarray
    classes: tuple[str, ...] = ("car", "person")
    truth: np.ndarray | None = None
    source: str = ""
    remission: np.ndarray | None = None
    known: tuple[str, ...] | None = None
    _features: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        self.points = np.ascontiguousarray(self.points, np.float32).reshape(-1, 3)
        self.labels = np.asarray(self.labels, np.int64).reshape(-1)
        self.instances = np.asarray(self.instances, np.int64).reshape(-1)
        self.classes = tuple(self.classes)
        n = len(self.points)
        if self.remission is not None:
            self.remission = np.asarray(self.remission, np.float32).reshape(-1)
            if len(self.remission) != n:
                raise InputError(f"{self.name}: {n} points but {len(self.remission)} remission values")
        if self.known is not None:
            self.known = tuple(c for c in self.classes if c in self.known)
        if len(self.labels) != n or len(self.instances) != n or (self.truth is not None and len(self.truth) != n):
            raise InputError(f"{self.name}: {n} points but {len(self.labels)} labels and {len(self.instances)} instances")
        if n and (self.labels.min() < -1 or self.labels.max() > len(self.classes)):
            raise InputError(f"{self.name}: labels must be -1..{len(self.classes)} for classes {', '.join(self.classes)}")

    def __len__(self) -> int:
        return len(self.points)

    def knows(self, name: str) -> bool:
        """Whether this scan labels class ``name`` (its points of that class are all marked)."""
        return self.known is None or name in self.known

    def features(self) -> np.ndarray:
        """``(n, F)`` float32 :func:`~.features.point_features` of the points, computed once."""
        if self._features is None:
            from .features import point_features

            self._features = point_features(self.points)
        return self._features


# ----------------------------------------------------------------------------- objects
def components(points: np.ndarray, radius: float = LINK_M) -> np.ndarray:
    """``(n,)`` int64 connected-component index of ``(n, 3)`` points linked within ``radius`` metres."""
    require("scipy.sparse.csgraph", "evaluate", "objects of labelled scans without instance ids (match, evaluate)")
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(points)
    if n == 0:
        return np.zeros(0, np.int64)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs), np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def object_ids(points: np.ndarray, labels: np.ndarray, classes: Sequence[str], instance: np.ndarray | None = None) -> np.ndarray:
    """``(n,)`` int64 object id per point of a requested class (-1 elsewhere), unique over the scan.

    instance : (n,) the source's instance ids (0: none); objects without one, or all when ``None``, are the
    connected components (linked within :data:`LINK_M`) of each class's points.
    """
    out = np.full(len(labels), -1, np.int64)
    next_id = 0
    for c in range(len(classes)):
        mask = labels == c
        if not mask.any():
            continue
        key = np.zeros(int(mask.sum()), np.int64)
        if instance is not None:
            key = np.asarray(instance, np.int64)[mask]
        known = key > 0
        local = np.empty(len(key), np.int64)
        if known.any():
            _, local[known] = np.unique(key[known], return_inverse=True)
        if (~known).any():
            offset = local[known].max() + 1 if known.any() else 0
            local[~known] = offset + components(points[mask][~known])
        _, local = np.unique(local, return_inverse=True)
        out[mask] = next_id + local
        next_id += int(local.max()) + 1
    return out


def strip_frame_number(stem: str) -> str:
    """``semantickitti_seq01_000002`` -> ``semantickitti_seq01`` (the group of consecutive frames); a name that is only a number stays."""
    stripped = re.sub(r"[_-]?\d{6}$", "", stem)
    return stripped or stem


# ----------------------------------------------------------------------------- readers
def read_semantickitti_scan(path: Path, classes: Sequence[str]) -> LabelledScan:
    """A SemanticKITTI ``.bin`` with its ``.label`` (module notes)."""
    found = semantickitti_label_path(path)
    if found is None:
        raise InputError(f"{path}: no label file (looked for {path.with_suffix('.label')} and {path.parent.parent / 'labels' / (path.stem + '.label')})")
    scan = read_kitti(path, labels=True)  # checks the label count against the points
    raw = scan.labels & 0xFFFF
    truth = label_maps.raw_to_training_lut()[raw]
    labels = label_maps.training_to_eval(truth, classes)
    points = scan.points.astype(np.float32)
    if path.parent.name == "velodyne":
        name, group = f"{path.parent.parent.name}/{path.stem}", path.parent.parent.name
    else:
        name, group = path.stem, strip_frame_number(path.stem)
    instance = (scan.labels >> 16).astype(np.int64)
    instance = np.where(instance > 0, (truth << 16) | instance, 0)
    return LabelledScan(name, group, points, labels, object_ids(points, labels, classes, instance), classes, truth, str(path),
                        remission=scan.intensity)


def npy_pair(path: Path) -> tuple[Path, Path]:
    """``(X_points.npy, X_labels.npy)`` of either file's path; ``InputError`` when the name or the partner is wrong."""
    name = path.name
    for suffix in ("_points.npy", "_labels.npy"):
        if name.endswith(suffix):
            stem = name[: -len(suffix)]
            points, labels = path.with_name(stem + "_points.npy"), path.with_name(stem + "_labels.npy")
            missing = [p for p in (points, labels) if not p.is_file()]
            if missing:
                raise InputError(f"{path}: missing label file {missing[0]}" if missing[0] == labels else f"{path}: missing points file {missing[0]}")
            return points, labels
    raise InputError(f"{path}: a labelled .npy scan is a pair X_points.npy + X_labels.npy; this name ends with neither")


def _load_array(path: Path) -> np.ndarray:
    try:
        return np.load(path)
    except (ValueError, OSError) as err:
        raise InputError(f"{path}: not a numpy array file ({err})") from None


def read_npy_scan(path: Path, classes: Sequence[str]) -> LabelledScan:
    """An ``X_points.npy`` / ``X_labels.npy`` pair in SemanticKITTI training ids (module notes)."""
    points_path, labels_path = npy_pair(path)
    points, labels = _load_array(points_path), _load_array(labels_path)
    if points.ndim != 2 or points.shape[1] < 3:
        raise InputError(f"{points_path}: expected (n, 3) or (n, 4) points, got shape {points.shape}")
    if labels.ndim == 2 and labels.shape[1] == 1:
        labels = labels[:, 0]
    if labels.ndim != 1 or not np.issubdtype(labels.dtype, np.integer):
        raise InputError(f"{labels_path}: expected (n,) or (n, 1) integer labels, got shape {labels.shape} {labels.dtype}")
    if len(labels) != len(points):
        raise InputError(f"{labels_path}: {len(labels)} labels for {len(points)} points in {points_path}")
    xyz = points[:, :3].astype(np.float32)
    finite = np.isfinite(xyz).all(axis=1)
    remission = np.clip(np.nan_to_num(points[:, 3].astype(np.float32)), 0.0, 1.0) if points.shape[1] > 3 else None
    xyz[~finite] = 0.0
    stem = points_path.name[: -len("_points.npy")]
    known = None
    if stem.startswith(label_maps.SQUEEZESEG_PREFIX):
        if len(labels) and (labels.min() < 0 or labels.max() >= len(label_maps.SQUEEZESEG_NAMES)):
            raise InputError(f"{labels_path}: SqueezeSeg labels must be 0..{len(label_maps.SQUEEZESEG_NAMES) - 1} ({', '.join(label_maps.SQUEEZESEG_NAMES)})")
        label_maps.check_kitti_classes(classes, str(points_path))
        eval_labels = label_maps.squeezeseg_to_eval(labels, classes)
        eval_labels[~finite] = -1
        truth, known = None, label_maps.KITTI_CLASSES
    else:
        if len(labels) and (labels.min() < 0 or labels.max() >= len(label_maps.TRAINING_NAMES)):
            raise InputError(f"{labels_path}: labels must be SemanticKITTI training ids 0..19, found {labels.min()}..{labels.max()}")
        truth = labels.astype(np.int64)
        truth[~finite] = 0
        eval_labels = label_maps.training_to_eval(truth, classes)
    return LabelledScan(stem, strip_frame_number(stem), xyz, eval_labels, object_ids(xyz, eval_labels, classes), classes, truth,
                        str(points_path), remission=remission, known=known)


# KITTI object frames
@dataclass(frozen=True)
class KittiBox:
    """One ``label_2`` line: type, 2D box (pixels) and the 3D box in the rectified camera frame
    (x right, y down, z forward; ``centre`` is the bottom centre; ``size`` is height, width, length; ``ry`` rad about y)."""

    type: str
    box2d: tuple[float, float, float, float]
    size: tuple[float, float, float]
    centre: tuple[float, float, float]
    ry: float


def frame_number(path: Path) -> str | None:
    """The last six-digit group of a file name (``kitti_hdl64e_004747.bin`` -> ``004747``)."""
    found = re.findall(r"\d{6}", path.stem)
    return found[-1] if found else None


def kitti_object_files(path: Path) -> tuple[Path, Path] | None:
    """``(label_2, calib)`` of a velodyne ``.bin``; ``None`` when there is no label_2 file; ``InputError`` when the label_2
    file is there but not the calibration."""
    number = frame_number(path)
    if number is None:
        return None
    label = calib = None
    if path.parent.name == "velodyne":
        root = path.parent.parent
        label, calib = root / "label_2" / f"{path.stem}.txt", root / "calib" / f"{path.stem}.txt"
        label, calib = (label if label.is_file() else None), (calib if calib.is_file() else None)
    if label is None:
        label = next(iter(sorted(path.parent.glob(f"*{number}_label_2.txt"))), None)
        calib = next(iter(sorted(path.parent.glob(f"*{number}_calib.txt"))), None)
    if label is None:
        return None
    if calib is None:
        raise InputError(f"{path}: KITTI object frame has {label.name} but no calib file ({path.parent / 'calib'}/{path.stem}.txt or *{number}_calib.txt)")
    return label, calib


def read_kitti_labels(path: Path) -> list[KittiBox]:
    """The boxes of a KITTI ``label_2`` file; ``InputError`` naming the file and line for a malformed one."""
    boxes = []
    try:
        lines = path.read_text().splitlines()
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror or err})") from None
    for i, line in enumerate(lines, 1):
        parts = line.split()
        if not parts:
            continue
        try:
            v = [float(x) for x in parts[1:15]]
            if len(v) != 14:
                raise ValueError
        except ValueError:
            raise InputError(f"{path}:{i}: a label_2 line is a type and 14 numbers (truncation ... rotation_y), got {line.strip()!r}") from None
        boxes.append(KittiBox(parts[0], tuple(v[3:7]), tuple(v[7:10]), tuple(v[10:13]), v[13]))
    return boxes


def read_kitti_calib(path: Path) -> dict[str, np.ndarray]:
    """``{P2: (3, 4), R0_rect: (3, 3), Tr_velo_to_cam: (3, 4)}`` of a KITTI ``calib`` file (``R0_rect`` identity when absent)."""
    values = {}
    try:
        for line in path.read_text().splitlines():
            key, _, rest = line.partition(":")
            if rest.strip():
                values[key.strip()] = np.array([float(x) for x in rest.split()])
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: not a KITTI calib file ({err})") from None
    try:
        out = {"P2": values["P2"].reshape(3, 4), "Tr_velo_to_cam": values["Tr_velo_to_cam"].reshape(3, 4)}
        out["R0_rect"] = values["R0_rect"].reshape(3, 3) if "R0_rect" in values else np.eye(3)
    except (KeyError, ValueError):
        raise InputError(f"{path}: a KITTI calib file needs P2 (12 numbers), Tr_velo_to_cam (12) and R0_rect (9)") from None
    return out


def velodyne_to_camera(points: np.ndarray, calib: dict[str, np.ndarray]) -> np.ndarray:
    """``(n, 3)`` float64 rectified camera coordinates of ``(n, 3)`` velodyne points: ``R0_rect (Tr_velo_to_cam [p; 1])``."""
    tr = calib["Tr_velo_to_cam"]
    return (np.asarray(points, np.float64) @ tr[:, :3].T + tr[:, 3]) @ calib["R0_rect"].T


def points_in_box(camera: np.ndarray, box: KittiBox) -> np.ndarray:
    """``(n,)`` bool: points (rectified camera frame) inside ``box`` (faces included)."""
    h, w, l = box.size
    c = np.array(box.centre) - (0.0, h / 2, 0.0)  # the box centre: label_2 gives the bottom centre, y down
    d = camera - c
    cos, sin = np.cos(box.ry), np.sin(box.ry)
    along = cos * d[:, 0] - sin * d[:, 2]  # object x (length): R_y(ry) maps object x to (cos, 0, -sin)
    across = sin * d[:, 0] + cos * d[:, 2]  # object z (width): (sin, 0, cos)
    return (np.abs(along) <= l / 2) & (np.abs(d[:, 1]) <= h / 2) & (np.abs(across) <= w / 2)


def read_kitti_object(path: Path, classes: Sequence[str], image_size: tuple[int, int] = IMAGE_SIZE) -> LabelledScan:
    """A KITTI object frame (module notes); ``image_size``: width, height in pixels."""
    label_2_calib = kitti_object_files(path)
    if label_2_calib is None:
        raise InputError(f"{path}: no label file: neither a SemanticKITTI .label nor a KITTI label_2 (label_2/{path.stem}.txt or *_label_2.txt beside it)")
    label_file, calib_file = label_2_calib
    label_maps.check_kitti_classes(classes, str(path))
    boxes, calib = read_kitti_labels(label_file), read_kitti_calib(calib_file)
    kitti = read_kitti(path)
    points = kitti.points
    camera = velodyne_to_camera(points, calib)
    uvw = np.column_stack([camera, np.ones(len(camera))]) @ calib["P2"].T
    front = camera[:, 2] > 0
    u = np.where(front, uvw[:, 0] / np.where(front, uvw[:, 2], 1.0), -1.0)
    v = np.where(front, uvw[:, 1] / np.where(front, uvw[:, 2], 1.0), -1.0)
    width, height = image_size
    in_view = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    other = label_maps.other_index(classes)
    labels = np.where(in_view, other, -1).astype(np.int64)
    instance = np.zeros(len(points), np.int64)
    inside_class = np.zeros(len(points), bool)
    for box in boxes:
        if box.type == "DontCare":
            x1, y1, x2, y2 = box.box2d
            labels[in_view & (u >= x1) & (u <= x2) & (v >= y1) & (v <= y2) & ~inside_class] = -1
            continue
        inside = in_view & points_in_box(camera, box)
        target = label_maps.kitti_type_to_eval(box.type, classes)
        if target < 0:
            labels[inside & ~inside_class] = -1
    for k, box in enumerate(boxes, 1):
        target = label_maps.kitti_type_to_eval(box.type, classes) if box.type != "DontCare" else -1
        if target >= 0:
            inside = in_view & points_in_box(camera, box) & ~inside_class
            labels[inside] = target
            instance[inside] = k
            inside_class |= inside
    pts = points.astype(np.float32)
    return LabelledScan(path.stem, path.stem, pts, labels, object_ids(pts, labels, classes, instance), classes, None, str(path),
                        remission=kitti.intensity, known=label_maps.KITTI_CLASSES)


# generated datasets
def read_generated(folder: Path, classes: Sequence[str], every: int = 1, max_frames: int | None = None) -> list[LabelledScan]:
    """The frames of a dataset folder made by the pipeline (``ply/*.ply``), every ``every``-th, at most ``max_frames``.

    Points written in another frame (``output.frame: world`` or ``kitti``) are moved back into the sensor frame by the
    frame record's sensor pose. Object ids are the PLY ``instance`` field.
    """
    if every < 1 or (max_frames is not None and max_frames < 1):
        raise InputError(f"{folder}: every and max_frames must be >= 1, got {every} and {max_frames}")
    manifest = read_manifest(folder) if (folder / "manifest.json").is_file() else {}
    class_names = manifest.get("class_table")
    if class_names is not None and not (isinstance(class_names,
                                                   dict) and class_names and all(str(k).isdigit() and int(k) < 1 << 16 and isinstance(v, str) for k,
                                                                                 v in class_names.items())):
        raise InputError(f"{folder / 'manifest.json'}: class_table must map class ids (0..65535) to names, got {type(class_names).__name__}")
    output = (manifest.get("config") or {}).get("output") or {}
    points_frame = output.get("frame", "sensor")
    kitti_origin = ((output.get("kitti") or {}).get("camera") or {}).get("position", (0.0, 0.0, 0.0))
    records = read_frame_records(folder) if (folder / "records").is_dir() else []
    files = []
    for record in records:
        ply = [f for f in record.get("files", []) if isinstance(f, str) and f.startswith("ply/") and f.endswith(".ply")]
        for name in ply:
            path, why = readable_inside(folder, name, MAX_PLY_BYTES)
            if path is None:
                raise InputError(f"{folder}/records: frame {record.get('index')} names {name!r}, {why}; a record's files lie in its dataset folder")
            files.append((path, np.asarray(record.get("sensor_pose", np.eye(4)), np.float64)))
    if not records:
        files = [(p, np.eye(4)) for p in sorted((folder / "ply").glob("*.ply"))]
    files = files[::every][:max_frames]
    if not files:
        raise InputError(f"{folder}: no frames: a generated dataset needs ply/*.ply (output.formats must include ply)")
    truth_lut = label_maps.project_to_training_lut(class_names)
    scans = []
    for path, pose in files:
        cloud = read_ply(path)
        xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(np.float64)
        to_output = sensor_to_output(points_frame, pose, kitti_origin)
        if to_output is not None:
            xyz = (xyz - to_output[:3, 3]) @ to_output[:3, :3]
        xyz = xyz.astype(np.float32)
        semantic = cloud["semantic"].astype(np.int64)
        truth = np.where(semantic < len(truth_lut), truth_lut[np.minimum(semantic, len(truth_lut) - 1)], 0)  # unknown ids: ignored
        labels = label_maps.training_to_eval(truth, classes)
        instance = cloud["instance"].astype(np.int64) + 1  # instance 0 is an object too; 0 is "none" for object_ids
        remission = np.asarray(cloud["intensity"], np.float32) if "intensity" in _names_of(cloud) else None
        scans.append(LabelledScan(f"{folder.name}/{path.stem}", folder.name, xyz, labels, object_ids(xyz, labels, classes, instance), classes, truth,
                                  str(path), remission=remission))
    return scans


def _names_of(cloud) -> tuple[str, ...]:
    names = getattr(getattr(cloud, "dtype", None), "names", None)
    return tuple(names) if names else tuple(cloud.keys())


# ----------------------------------------------------------------------------- the registry
def _bin_kind(path: Path) -> str:
    if semantickitti_label_path(path) is not None:
        return "semantickitti"
    return "kitti_object"  # read_kitti_object names the missing label files when there are none


READERS: dict[str, Callable[..., LabelledScan | list[LabelledScan]]] = {
    "semantickitti": lambda path, classes, **_: read_semantickitti_scan(path, classes),
    "npy": lambda path, classes, **_: read_npy_scan(path, classes),
    "kitti_object": lambda path, classes, image_size=IMAGE_SIZE, **_: read_kitti_object(path, classes, image_size),
    "generated": lambda path, classes, every=1, max_frames=None, **_: read_generated(path, classes, every, max_frames),
}
KINDS = {".bin": _bin_kind, ".npy": lambda path: "npy"}


def kind_of(path: Path) -> str:
    """The reader for ``path``: ``generated`` for a dataset folder, else by suffix; ``InputError`` otherwise."""
    if path.is_dir():
        return "generated"
    if not path.is_file():
        raise InputError(f"{path}: no such file or folder")
    guess = KINDS.get(path.suffix.lower())
    if guess is None:
        raise InputError(
            f"{path}: not a labelled scan: give a .bin (SemanticKITTI with .label, or KITTI object with label_2 and calib), an X_points.npy with X_labels.npy, "
            "or a generated dataset folder"
        )
    return guess(path)


def folder_frames(path: Path) -> list[Path]:
    """The labelled frames in a folder of real scans: every ``*_points.npy`` and every ``.bin`` with a label file."""
    out = sorted(path.glob("*_points.npy"))
    for scan in sorted(path.glob("*.bin")) + sorted(path.glob("velodyne/*.bin")):
        if semantickitti_label_path(scan) is not None or kitti_object_files(scan) is not None:
            out.append(scan)
    return out


def load_scans(sources: Iterable[str | Path | LabelledScan], classes: Sequence[str], every: int = 1, max_frames: int | None = None,
               image_size: tuple[int, int] = IMAGE_SIZE) -> list[LabelledScan]:
    """Read every source into :class:`LabelledScan` (a scan given as one is checked against ``classes`` and kept).

    A folder is a generated dataset when it holds ``ply/`` or ``manifest.json``, else a folder of real frames
    (:func:`folder_frames`). ``every`` / ``max_frames`` subsample generated datasets only.
    """
    classes = tuple(classes)
    out: list[LabelledScan] = []
    for source in sources:
        if isinstance(source, LabelledScan):
            if source.classes != classes:
                raise InputError(f"{source.name}: labelled for classes {', '.join(source.classes)}, not {', '.join(classes)}")
            out.append(source)
            continue
        path = Path(source)
        if path.is_dir() and not ((path / "ply").is_dir() or (path / "manifest.json").is_file()):
            frames = folder_frames(path)
            if not frames:
                raise InputError(
                    f"{path}: holds no labelled frames (X_points.npy + X_labels.npy, .bin + .label, KITTI .bin + label_2 + calib) and is no generated "
                    "dataset (ply/)"
                )
            out += load_scans(frames, classes, every, max_frames, image_size)
            continue
        read = READERS[kind_of(path)](path, classes, every=every, max_frames=max_frames, image_size=image_size)
        out += read if isinstance(read, list) else [read]
    return out
