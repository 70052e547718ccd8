"""Mixed-domain training data for the sim-to-real benchmark: synthetic cars and pedestrians cast into real HDL-64E backgrounds.

The method of *Annotation-free Generation of Training Data Using Mixed Domains for Segmentation of 3D
LiDAR Point Clouds* (the parking paper: synthetic cars in recorded scans of an empty car park) and of
*Point Cloud Wall Projection for Realistic Road Data Augmentation* (the KITTI paper: objects placed on
the ground of real KITTI scans), done with the project's ``real_scan`` builder (docs/mixing.md): every
firing of the real sweep is cast at the inserted meshes, one return per firing.

Annotation-free as the parking paper: its backgrounds are recordings of empty scenes. We have none, so
each real background is **emptied** first, and only then do synthetic objects go in:

- ``X_points.npy`` + ``X_labels.npy`` (SemanticKITTI *training* ids 0..19): the points of the movable
  classes (:data:`MOVABLE_TRAINING_IDS`: car, bicycle, motorcycle, truck, other-vehicle, person,
  bicyclist, motorcyclist) are removed; the rest keep their real class, mapped to SemanticKITTI raw ids
  with the official inverse learning map (:data:`LEARNING_MAP_INV`, ``learning_map_inv`` of
  semantic-kitti.yaml) and, in the mixed frame, by name to the project's classes (``keep_labels``).
  Such a file has no reflectance: 0 is written.
- a KITTI object frame (``..._NNNNNN.bin`` velodyne, x y z reflectance, with ``..._NNNNNN_label_2.txt`` and
  ``..._NNNNNN_calib.txt`` beside it, or the ``velodyne/ label_2/ calib/`` layout): the points inside every
  labelled box except DontCare, the box grown by :data:`KITTI_BOX_MARGIN` (0.2 m) on every side, are
  removed. Its other points carry **no class** (KITTI labels objects only): they are written as raw 0 and
  become the project's ``unlabeled`` (id 0) in the mixed frame. ``unlabeled`` trains as ignored (its
  ``learning_map`` is 0; Pointcept ``segment.npy`` -1; ``bpy_pipeline.evaluate`` maps it to -1), so a
  model trained on such frames learns only from the inserted objects there: the training must treat
  unlabelled points as ignored, never as "background". Its boxes cover the front camera's view only:
  real objects behind the car stay in, unlabelled.

The emptied backgrounds are written to ``workdir/backgrounds`` as SemanticKITTI ``NNNNNN.bin`` (float32 x y z
reflectance) + ``NNNNNN.label`` (uint32, raw semantic id, instance 0), in the order given, and the pipeline
runs ``scene.builder: real_scan`` over that folder with the ``hdl64e`` preset: frame k mixes background
k mod n (the builder takes the folder's scans in name order, cycling). Each frame gets cars by the KITTI
paper's rule (``kitti_rule``: random ground returns 6-50 m away, clear of each other and of real non-ground
returns, yaw by its equation (1)) and pedestrians by the parking paper's (``parking_rule``: a count, a
distance of 4-20 m and an angle about the sensor, turned until the spot is empty ground, not mostly hidden);
the near limits keep objects off the recording car, whose own returns a scan lacks. The preset's fitted
drop and noise act on the inserted returns only.

Leakage: :func:`make_mixed_dataset` reads the given background files (and a KITTI frame's own label_2 and
calib) and nothing else; the caller keeps them apart from its test frames.

Each background is checked to be in its sensor's frame (the cast fires from the origin): a scan with
fewer than :data:`SENSOR_FRAME_SHARE` of its returns within :data:`SENSOR_FRAME_RADIUS_M` of the origin is
refused (the first shared copy of SemanticKITTI 000700 was such a scan: moved by 100 m, its nearest return
lay 29.5 m from the origin).

Run as a benchmark: ``python benchmarks/sim2real_mixed.py [--small]`` times the emptying and the mixing
(CPU seconds per mixed frame) on the real scans in ../shared/real_scans and writes
``benchmarks/results/sim2real_mixed.json``.
"""

from __future__ import annotations

import re
import resource
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bpy_pipeline.errors import InputError  # noqa: E402
from bpy_pipeline.evaluate.labelled import KittiBox, kitti_object_files, npy_pair, points_in_box, read_kitti_calib, read_kitti_labels, velodyne_to_camera  # noqa: E402

# SemanticKITTI training id -> raw id: `learning_map_inv` of semantic-kitti.yaml (semantic-kitti-api, config/semantic-kitti.yaml)
LEARNING_MAP_INV = {
    0: 0, 1: 10, 2: 11, 3: 15, 4: 18, 5: 20, 6: 30, 7: 31, 8: 32, 9: 40, 10: 44, 11: 48, 12: 49, 13: 50, 14: 51,
    15: 70, 16: 71, 17: 72, 18: 80, 19: 81,
}  # fmt: skip
MOVABLE_TRAINING_IDS = (1, 2, 3, 4, 5, 6, 7, 8)  # car, bicycle, motorcycle, truck, other-vehicle, person, bicyclist, motorcyclist
KITTI_BOX_MARGIN = 0.2  # m, every side of a KITTI box: its object's points that the box just misses go too
SENSOR_FRAME_RADIUS_M = 10.0
SENSOR_FRAME_SHARE = 0.01  # a roof HDL-64E has about half its returns within 10 m of it (ground rings); 000700 has none
BACKGROUND_FOLDER = "backgrounds"
PRESET = "hdl64e"

# What each frame inserts (the pipeline's scene.kitti_rule and scene.parking_rule)
EGO_CLEARANCE_M = 6.0  # no inserted car centre nearer the sensor (a 4.6 m car then ends >= 3.7 m away: off the recording car's roof-mount footprint)
CAR_RULE = {"enabled": True, "type": "car", "count": 5, "candidates": 200, "collision_distance": 5.0, "max_range": 50.0, "min_range": EGO_CLEARANCE_M}
PERSON_RULE = {
    "enabled": True, "type": "person",
    "count": {"kind": "normal", "mean": 5.0, "std": 2.0, "min": 2.0, "max": 10.0},
    "distance": {"kind": "normal", "mean": 10.0, "std": 20.0, "min": 4.0, "max": 20.0},  # the paper's 2.5 m min: inside a car's footprint
}  # fmt: skip


@dataclass
class Background:
    """One emptied real frame in its sensor frame (x forward, y left, z up, metres).

    points : (n, 4) float32 x y z reflectance (0..1; 0 where the file has none)
    raw : (n,) uint32 SemanticKITTI raw semantic id (instance 0)
    removed : how many movable-object points were taken out
    source : the file it came from; kind : its reader (:data:`BACKGROUND_READERS`)
    """

    points: np.ndarray
    raw: np.ndarray
    removed: int
    source: Path
    kind: str


def read_npy_background(path: Path) -> Background:
    """An ``X_points.npy`` / ``X_labels.npy`` pair (either name), emptied of :data:`MOVABLE_TRAINING_IDS`."""
    points_path, labels_path = npy_pair(path)
    try:
        xyz = np.load(points_path)
        labels = np.load(labels_path)
    except (ValueError, OSError, EOFError) as err:
        raise InputError(f"{path}: not a numpy array file ({err})") from None
    if xyz.ndim != 2 or xyz.shape[1] < 3 or xyz.dtype.kind != "f":
        raise InputError(f"{points_path}: expected (n, 3) or (n, 4) float points, got {xyz.dtype} {xyz.shape}")
    labels = labels.reshape(-1) if labels.ndim == 2 and labels.shape[1] == 1 else labels
    if labels.ndim != 1 or labels.dtype.kind not in "iu" or len(labels) != len(xyz):
        raise InputError(f"{labels_path}: expected {len(xyz)} integer labels (n,) or (n, 1), got {labels.dtype} {labels.shape}")
    bad = (labels < 0) | (labels >= len(LEARNING_MAP_INV))
    if bad.any():
        raise InputError(
            f"{labels_path}: SemanticKITTI training ids are 0..{len(LEARNING_MAP_INV) - 1}; label {int(labels[bad][0])} at point {int(np.flatnonzero(bad)[0])}"
        )
    keep = ~np.isin(labels, MOVABLE_TRAINING_IDS)
    out = np.zeros((int(keep.sum()), 4), np.float32)
    out[:, :3] = xyz[keep, :3]
    if xyz.shape[1] > 3:
        out[:, 3] = xyz[keep, 3]
    inverse = np.array([LEARNING_MAP_INV[k] for k in range(len(LEARNING_MAP_INV))], np.uint32)
    return Background(out, inverse[labels[keep].astype(np.int64)], int((~keep).sum()), path, "npy")


def grown(box: KittiBox, margin: float) -> KittiBox:
    """``box`` grown by ``margin`` m on every side (its bottom centre moves ``margin`` down: camera y points down)."""
    h, w, l = box.size
    x, y, z = box.centre
    return KittiBox(box.type, box.box2d, (h + 2 * margin, w + 2 * margin, l + 2 * margin), (x, y + margin, z), box.ry)


def kitti_object_points(path: Path, margin: float = KITTI_BOX_MARGIN) -> np.ndarray:
    """``(n,)`` bool over the velodyne points of KITTI object frame ``path``: inside a labelled box (DontCare excepted) grown by ``margin`` m."""
    files = kitti_object_files(path)
    if files is None:
        raise InputError(f"{path}: a KITTI object frame needs its label_2 file (label_2/{path.stem}.txt or *_label_2.txt with its frame number beside it)")
    label_file, calib_file = files
    xyz = np.fromfile(path, np.float32).reshape(-1, 4)[:, :3]
    camera = velodyne_to_camera(xyz, read_kitti_calib(calib_file))
    inside = np.zeros(len(xyz), bool)
    for box in read_kitti_labels(label_file):
        if box.type != "DontCare":
            inside |= points_in_box(camera, grown(box, margin))
    return inside


def read_kitti_background(path: Path) -> Background:
    """A KITTI object frame emptied of its labelled objects; every point left is raw 0 (unlabelled: module notes)."""
    size = path.stat().st_size
    if size % 16:
        raise InputError(f"{path}: {size} bytes are not whole KITTI records (float32 x y z reflectance)")
    data = np.fromfile(path, np.float32).reshape(-1, 4)
    inside = kitti_object_points(path)
    return Background(np.ascontiguousarray(data[~inside]), np.zeros(int((~inside).sum()), np.uint32), int(inside.sum()), path, "kitti_object")


BACKGROUND_READERS: dict[str, Callable[[Path], Background]] = {"npy": read_npy_background, "kitti_object": read_kitti_background}


def background_kind(path: Path) -> str:
    """Which reader of :data:`BACKGROUND_READERS` takes ``path``."""
    if path.name.endswith(("_points.npy", "_labels.npy")):
        return "npy"
    if path.suffix.lower() == ".bin":
        return "kitti_object"
    raise InputError(f"backgrounds: {path}: expected X_points.npy (+ X_labels.npy) or a KITTI object frame .bin with its label_2 and calib")


def check_sensor_frame(points: np.ndarray, source: Path) -> None:
    """``InputError`` unless ``(n, >= 3)`` points surround the origin as a scan in its sensor's frame does (module notes)."""
    near = np.hypot(points[:, 0], points[:, 1]) <= SENSOR_FRAME_RADIUS_M
    share = float(near.mean()) if len(points) else 0.0
    if share < SENSOR_FRAME_SHARE:
        nearest = float(np.hypot(points[:, 0], points[:, 1]).min(initial=np.inf))
        raise InputError(
            f"backgrounds: {source}: not in its sensor's frame ({share:.1%} of its returns within {SENSOR_FRAME_RADIUS_M:g} m of the origin, "
            f"the nearest {nearest:.1f} m away); the cast fires from the origin, so give scans in the sensor frame"
        )


def empty_background(path: Path) -> Background:
    """The real frame ``path`` without its movable objects (module notes), checked to be in its sensor's frame."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"backgrounds: {path} is not a file")
    background = BACKGROUND_READERS[background_kind(path)](path)
    if not len(background.points):
        raise InputError(f"backgrounds: {path}: no points left once its movable objects are removed")
    check_sensor_frame(background.points, path)
    return background


def write_background(background: Background, folder: Path, index: int) -> Path:
    """``folder/NNNNNN.bin`` (float32 x y z reflectance) and ``NNNNNN.label`` (uint32 raw id, instance 0); returns the ``.bin``."""
    scan = folder / f"{index:06d}.bin"
    np.ascontiguousarray(background.points, np.float32).tofile(scan)
    np.ascontiguousarray(background.raw, np.uint32).tofile(scan.with_suffix(".label"))
    return scan


def prepare_folder(folder: Path) -> None:
    """Create ``folder``, or clear the scans a previous call wrote there; refuse one holding anything else
    (the builder reads every scan of the folder: nothing else may be mixed in)."""
    folder.mkdir(parents=True, exist_ok=True)
    ours = re.compile(r"^\d{6}\.(bin|label)$")
    others = [p.name for p in folder.iterdir() if not ours.match(p.name)]
    if others:
        raise InputError(f"workdir: {folder} holds other files ({', '.join(sorted(others)[:3])}); give a workdir of its own")
    for p in folder.iterdir():
        p.unlink()


def mixed_config(folder: Path, frames: int, seed: int, rules: dict | None = None) -> dict:
    """The pipeline config of the mixed dataset: ``real_scan`` over ``folder`` (module notes), PLY only, no preview, no boxes;
    ``rules`` (scene keys: ``kitti_rule``, ``parking_rule``, ``parking_rules``) replace the papers' rules where given."""
    config = {
        "frames": frames,
        "seed": seed,
        "scene": {
            "builder": "real_scan", "path": str(folder), "format": "semantickitti", "preset": PRESET, "keep_labels": True,
            "background_class": "unlabeled", "kitti_rule": dict(CAR_RULE), "parking_rule": dict(PERSON_RULE),
        },
        "sensor": {"preset": PRESET},
        "output": {"formats": ["ply"], "preview": False, "boxes": {"formats": []}},
    }  # fmt: skip
    config["scene"].update(rules or {})
    return config


def cpu_seconds() -> float:
    """CPU seconds of this process and its finished children (user + system)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def make_mixed_dataset(backgrounds: list[Path], out: Path, frames_per_background: int, seed: int, workdir: Path, rules: dict | None = None) -> Path:
    """Synthetic cars and pedestrians cast into the emptied real ``backgrounds`` (module notes); returns ``out``,
    the dataset folder (``ply/NNNNNN.ply`` with per-point ``semantic`` in the project's class ids, ``records/NNNNNN.json``
    with each frame's inserted objects under ``scene``, ``manifest.json`` with the timings ``make_mixed_dataset``
    measured under ``sim2real_mixed``).

    backgrounds : real labelled frames, ``X_points.npy`` (+ ``X_labels.npy`` beside it) or KITTI object ``.bin``
        (with its label_2 and calib); frame k mixes background k mod len(backgrounds)
    out : the dataset folder (a new one, or one this function wrote before: it is overwritten)
    frames_per_background : frames per background (>= 1); the dataset has len(backgrounds) * frames_per_background
    seed : the run's seed (placements, object shapes, drop and noise)
    workdir : scratch folder; the emptied backgrounds go to ``workdir/backgrounds``
    rules : scene keys that replace the papers' rules (:func:`mixed_config`), e.g. what ``bpy-pipeline match`` fits
    """
    import json

    import bpy_pipeline as bp

    if not backgrounds:
        raise InputError("backgrounds: give at least one real frame")
    if int(frames_per_background) != frames_per_background or frames_per_background < 1:
        raise InputError(f"frames_per_background: a whole number >= 1, got {frames_per_background!r}")
    start = cpu_seconds()
    emptied = [empty_background(Path(p)) for p in backgrounds]  # every file checked before anything is written
    folder = Path(workdir) / BACKGROUND_FOLDER
    prepare_folder(folder)
    for k, background in enumerate(emptied):
        write_background(background, folder, k)
    emptying = cpu_seconds() - start
    frames = len(emptied) * int(frames_per_background)
    config = bp.load_config(mixed_config(folder, frames, seed, rules))
    start = cpu_seconds()
    bp.run(config, out, mode="overwrite" if (Path(out) / "manifest.json").exists() else "new", log=lambda line: None)
    mixing = cpu_seconds() - start
    manifest_path = Path(out) / "manifest.json"
    written = json.loads(manifest_path.read_text())
    written["sim2real_mixed"] = {
        "backgrounds": [{"source": str(b.source), "kind": b.kind, "points": int(len(b.points)), "removed": b.removed} for b in emptied],
        "frames": frames,
        "cpu_s_emptying": round(emptying, 3),
        "cpu_s_per_frame": round(mixing / frames, 3),
    }
    manifest_path.write_text(json.dumps(written, indent=1))
    return Path(out)


def main() -> None:
    """The benchmark: CPU seconds per mixed frame on the shared real HDL-64E scans that are in their sensor's frame."""
    import json
    import tempfile

    from common import RESULTS, arguments, report

    args = arguments(__doc__.splitlines()[0])
    real = ROOT.parent / "shared" / "real_scans"
    candidates = [real / "semantickitti_seq01_000000_points.npy", real / "semantickitti_seq01_000001_points.npy", real / "kitti_hdl64e_004747.bin"]
    backgrounds = [p for p in candidates if p.exists()][: 1 if args.small else None]
    per = 1 if args.small else 3
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = make_mixed_dataset(backgrounds, Path(tmp) / "mixed", per, 7, Path(tmp) / "work")
        facts = json.loads((out / "manifest.json").read_text())["sim2real_mixed"]
        for k in range(facts["frames"]):
            record = json.loads((out / "records" / f"{k:06d}.json").read_text())["scene"]
            objects = record["objects"]
            rows.append({
                "frame": k, "background": Path(facts["backgrounds"][k % len(backgrounds)]["source"]).name,
                "cars": sum(o["class"] == "car" for o in objects), "people": sum(o["class"] == "person" for o in objects),
                "inserted_points": record["inserted_points"], "mixing_ms": round(sum(record["timings_ms"].values()), 1),
            })  # fmt: skip
    notes = {
        "cpu_s_per_frame": facts["cpu_s_per_frame"],
        "cpu_s_emptying_all": facts["cpu_s_emptying"],
        "backgrounds": [dict(b, source=Path(b["source"]).name) for b in facts["backgrounds"]],
        "what": "CPU s per frame: the whole pipeline run (Blender's empty scene reset, mixing, PLY writing) over its frames; "
                "mixing_ms: the record's stage wall times",
    }
    report("sim2real_mixed", rows, args.out if args.out else RESULTS, notes)


if __name__ == "__main__":
    main()
