"""The class table's maps for the dataset formats: training ids, things and stuff, KITTI types, ASPRS codes.

All read from ``assets_manifest/labels.yaml`` (:data:`~bpy_pipeline.labels.LABELS_PATH`), beside the
class table itself (:func:`~bpy_pipeline.labels.load_class_table`). Which file holds which ids:

- raw ids (``semantic``): PLY, SemanticKITTI ``.label`` (as the SemanticKITTI devkit expects; its
  loaders apply ``learning_map`` from ``semantic-kitti.yaml``), LAS ``semantic`` extra bytes, PCD;
- training ids: Pointcept ``segment.npy`` = ``learning_map[raw] - 1`` (-1: ignored);
- ASPRS codes: LAS ``classification``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError
from ..labels import LABELS_PATH, load_class_table, normalise
from ..yaml_text import load_yaml

USER_CODES = 64  # first user-definable LAS classification code (ASPRS LAS 1.4 R15, table 17)
ASPRS_NAMES = {  # the standard classes' names (table 17), for the classification lookup VLR
    0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation", 4: "medium vegetat.",
    5: "high vegetation", 6: "building", 7: "low noise", 9: "water", 10: "rail", 11: "road surface",
    13: "wire guard", 14: "wire conductor", 15: "tower", 16: "wire connector", 17: "bridge deck",
    18: "high noise", 19: "overhead struct", 20: "ignored ground", 21: "snow", 22: "temporal excl",
}  # fmt: skip


@dataclass(frozen=True)
class ClassMaps:
    """Lookup tables indexed by any raw class id (``(65536,)`` arrays over the uint16 ``semantic``).

    Ids outside the class table train as ignored (0), are stuff, and are LAS code 64 + id up to
    191, unclassified (1) above.
    """

    training: np.ndarray  # (65536,) int32 learning_map: 0 ignored, 1..K
    things: np.ndarray  # (65536,) bool: instances counted (Pointcept keeps their instance ids)
    asprs: np.ndarray  # (65536,) uint8 LAS classification code
    kitti_names: dict  # {class name: KITTI object type}

    def segment(self, semantic: np.ndarray) -> np.ndarray:
        """Pointcept ``segment`` (n,) int32 of raw ids ``semantic`` (n,): training id - 1, -1 ignored."""
        return self.training[semantic].astype(np.int32) - 1

    def raw_of_segment(self, segment: np.ndarray) -> np.ndarray:
        """Raw ids (n,) uint16 of Pointcept ``segment`` (n,): the first raw id of each training id (ignored: 0)."""
        inverse = np.zeros(int(self.training.max()) + 1, np.uint16)
        train_ids, first = np.unique(self.training, return_index=True)
        inverse[train_ids] = first
        inverse[0] = 0
        return inverse[np.clip(np.asarray(segment, np.int64) + 1, 0, len(inverse) - 1)]

    def kitti_name(self, class_name: str, names: dict | None = None) -> str:
        """KITTI object type of a box class: ``names[class]`` (output.boxes.names), the table's, else ``Misc``."""
        if names and class_name in names:
            return str(names[class_name])
        return self.kitti_names.get(normalise(class_name), "Misc")


@lru_cache(maxsize=4)  # a file of the package, read once per process (as load_class_table)
def load_class_maps(path: Path = LABELS_PATH) -> ClassMaps:
    """The maps of the class table at ``path``; ``InputError`` naming the file and key when one is malformed."""
    table = load_class_table(path)
    try:
        raw = load_yaml(Path(path).read_text()) or {}
    except (OSError, yaml.YAMLError) as err:
        raise InputError(f"{path}: cannot read the class table ({err})") from None
    size = 1 << 16
    training = np.zeros(size, np.int32)
    for raw_id, train_id in table.learning_map.items():
        training[raw_id] = train_id
    by_name = {name: i for i, name in table.names.items()}

    def ids(key: str, names) -> list[int]:
        try:
            return [by_name[normalise(n)] for n in names]
        except KeyError as err:
            raise InputError(f"{path}: {key}: unknown class {err.args[0]!r}") from None

    things = np.zeros(size, bool)
    things[ids("things", raw.get("things", []))] = True
    asprs = np.where(np.arange(size) <= 255 - USER_CODES, USER_CODES + np.arange(size), 1)
    codes = raw.get("asprs", {}) or {}
    asprs[ids("asprs", codes)] = [int(v) for v in codes.values()]
    if (asprs < 0).any() or (asprs > 255).any():
        raise InputError(f"{path}: asprs: LAS classification codes must be 0..255")
    kitti = {normalise(k): str(v) for k, v in (raw.get("kitti_names", {}) or {}).items()}
    ids("kitti_names", kitti)
    return ClassMaps(training, things, asprs.astype(np.uint8), kitti)


def semantic_kitti_yaml(counts: np.ndarray | None = None, split: dict | None = None, class_map: dict | None = None) -> dict:
    """The dataset's ``semantic-kitti.yaml`` (the SemanticKITTI devkit's layout) in the project's raw ids
    (``output.semantickitti.labels: project``; :func:`semantic_kitti_space_yaml` is the default).

    counts : (k,) points per raw id over the dataset, for ``content`` (fractions); uniform when ``None``
    split : ``{train: [...], valid: [...], test: [...]}`` sequence numbers
    class_map : ``output.class_map``: the ``learning_map`` of the task (:func:`task_training`), else the table's
    ``color_map`` is BGR, as the devkit's files are (the project's table is RGB); ``learning_map_inv``
    maps each training id to the first raw id that trains as it; ``learning_ignore`` marks training id 0.
    """
    table = load_class_table()
    ids = sorted(table.names)
    counts = np.ones(max(ids) + 1) if counts is None else np.asarray(counts, float)
    total = counts.sum()
    task = task_training(class_map)
    learning = {i: table.learning_map[i] if task is None else int(task.training[i]) for i in ids}
    inverse: dict[int, int] = {0: 0} if task is not None else {}
    for raw_id in ids:
        inverse.setdefault(learning[raw_id], raw_id)
    return {
        "name": "bpy_pipeline",
        "labels": {i: table.names[i] for i in ids},
        "color_map": {i: [int(c) for c in table.colors[i][::-1]] for i in ids},
        "content": {i: float(counts[i] / total) if total > 0 and i < len(counts) else 0.0 for i in ids},
        "learning_map": learning,
        "learning_map_inv": dict(sorted(inverse.items())),
        "learning_ignore": {t: t == 0 for t in sorted(inverse)},
        "split": split or {"train": [], "valid": [], "test": []},
    }


SUSTECH_TYPES = ("Car", "Pedestrian", "Van", "Bus", "Truck", "ScooterRider", "Scooter", "BicycleRider", "Bicycle", "Motorcycle",
                 "MotorcyleRider", "PoliceCar", "TourCar", "RoadWorker", "Child", "BabyCart", "Cart", "Cone", "FireHydrant",
                 "SaftyTriangle", "PlatformCart", "ConstructionCart", "RoadBarrel", "TrafficBarrier", "LongVehicle", "BicycleGroup",
                 "ConcreteTruck", "Tram", "Excavator", "Animal", "TrashCan", "ForkLift", "Trimotorcycle", "FreightTricycle", "Crane",
                 "RoadRoller", "Bulldozer", "DontCare", "Misc", "Unknown", "Unknown1", "Unknown2", "Unknown3", "Unknown4", "Unknown5")
# SUSTechPOINTS' class list (naurril/SUSTechPOINTS 566f81d, public/js/obj_cfg.js ``obj_type_map``), spelled as it spells them


@lru_cache(maxsize=4)
def load_sustech_names(path: Path = LABELS_PATH) -> dict[str, str]:
    """``{class name: SUSTechPOINTS type}`` (labels.yaml ``sustech_names``); ``InputError`` for a type its class list lacks."""
    try:
        raw = (load_yaml(Path(path).read_text()) or {}).get("sustech_names", {}) or {}
    except (OSError, yaml.YAMLError) as err:
        raise InputError(f"{path}: cannot read the class table ({err})") from None
    table = load_class_table(path)
    names = {table.names[table.id_of(k, f"{path}: sustech_names")]: str(v) for k, v in raw.items()}
    bad = sorted(v for v in names.values() if v not in SUSTECH_TYPES)
    if bad:
        raise InputError(f"{path}: sustech_names: {', '.join(bad)} not in SUSTechPOINTS' class list ({', '.join(SUSTECH_TYPES)})")
    return names


# ----------------------------------------------------------------------------- SemanticKITTI's own label space
# The SemanticKITTI devkit's class table (semantic-kitti-api, config/semantic-kitti.yaml): raw id -> name,
# BGR colour and training id (0 ignored). The stock loaders (Pointcept's SemanticKITTIDataset,
# mmdetection3d's SemanticKittiDataset) hard-code this table and never read a dataset's yaml.
SEMANTIC_KITTI = {  # raw id: (name, BGR colour, training id)
    0: ("unlabeled", (0, 0, 0), 0), 1: ("outlier", (0, 0, 255), 0), 10: ("car", (245, 150, 100), 1),
    11: ("bicycle", (245, 230, 100), 2), 13: ("bus", (250, 80, 100), 5), 15: ("motorcycle", (150, 60, 30), 3),
    16: ("on-rails", (255, 0, 0), 5), 18: ("truck", (180, 30, 80), 4), 20: ("other-vehicle", (255, 0, 0), 5),
    30: ("person", (30, 30, 255), 6), 31: ("bicyclist", (200, 40, 255), 7), 32: ("motorcyclist", (90, 30, 150), 8),
    40: ("road", (255, 0, 255), 9), 44: ("parking", (255, 150, 255), 10), 48: ("sidewalk", (75, 0, 75), 11),
    49: ("other-ground", (75, 0, 175), 12), 50: ("building", (0, 200, 255), 13), 51: ("fence", (50, 120, 255), 14),
    52: ("other-structure", (0, 150, 255), 0), 60: ("lane-marking", (170, 255, 150), 9), 70: ("vegetation", (0, 175, 0), 15),
    71: ("trunk", (0, 60, 135), 16), 72: ("terrain", (80, 240, 150), 17), 80: ("pole", (150, 240, 255), 18),
    81: ("traffic-sign", (0, 0, 255), 19), 99: ("other-object", (255, 255, 50), 0),
    252: ("moving-car", (245, 150, 100), 1), 253: ("moving-bicyclist", (200, 40, 255), 7), 254: ("moving-person", (30, 30, 255), 6),
    255: ("moving-motorcyclist", (90, 30, 150), 8), 256: ("moving-on-rails", (255, 0, 0), 5), 257: ("moving-bus", (250, 80, 100), 5),
    258: ("moving-truck", (180, 30, 80), 4), 259: ("moving-other-vehicle", (255, 0, 0), 5),
}  # fmt: skip
SEMANTIC_KITTI_LEARNING_MAP_INV = {0: 0, 1: 10, 2: 11, 3: 15, 4: 18, 5: 20, 6: 30, 7: 31, 8: 32, 9: 40, 10: 44, 11: 48, 12: 49, 13: 50, 14: 51, 15: 70, 16: 71,
                                   17: 72, 18: 80, 19: 81}  # fmt: skip
LABEL_SPACES = ("semantickitti", "project")


@lru_cache(maxsize=4)
def semantic_kitti_lut(path: Path = LABELS_PATH) -> np.ndarray:
    """``(65536,) uint16``: the SemanticKITTI raw id of each project raw id (labels.yaml ``semantickitti:``);
    ids outside the class table are unlabeled (0). ``InputError`` naming the file for an id SemanticKITTI lacks."""
    from ..labels import semantickitti_ids

    table = load_class_table(path)
    ids = semantickitti_ids(path)
    lut = np.zeros(1 << 16, np.uint16)
    for raw_id, name in table.names.items():
        if ids[name] not in SEMANTIC_KITTI:
            raise InputError(f"{path}: semantickitti.{name}: {ids[name]} is not a SemanticKITTI raw id; allowed: {', '.join(map(str, SEMANTIC_KITTI))}")
        lut[raw_id] = ids[name]
    return lut


@dataclass(frozen=True)
class TaskMap:
    """Training ids of a task (``output.class_map``): ``training`` (65536,) int32 over project raw ids, 0 ignored,
    1..K the task classes in ``names`` order."""

    training: np.ndarray
    names: tuple[str, ...]


def task_training(class_map: dict | None, path: Path = LABELS_PATH) -> TaskMap | None:
    """The :class:`TaskMap` of ``output.class_map`` (``None`` when empty: the class table's ``learning_map``).

    class_map : ``{task class: [project classes] | "rest", ignore: [project classes]}``; ``rest`` is every class
        named nowhere else that the table trains (not unlabeled nor reflection ghosts); a class named nowhere is
        ignored. ``InputError`` naming the key otherwise.
    """
    if not class_map:
        return None
    if not isinstance(class_map, dict):
        raise InputError(f"output.class_map: expected a mapping {{task class: [classes], ignore: [classes]}}, got {class_map!r}")
    table = load_class_table(path)
    owner: dict[int, str] = {}
    rest = None
    for key, value in class_map.items():
        where = f"output.class_map.{key}"
        if not isinstance(key, str) or not key.strip() or any(c.isspace() for c in key.strip()):
            raise InputError(f"output.class_map: a task class is one word, got {key!r}")
        if value == "rest":
            if rest is not None or key == "ignore":
                raise InputError(f"{where}: rest (every class named nowhere else) may be given to one task class, not ignore")
            rest = key
            continue
        if not isinstance(value, list) or not value:
            raise InputError(f"{where}: expected a list of class names from assets_manifest/labels.yaml, or rest")
        for name in value:
            raw_id = table.id_of(str(name), where)
            if raw_id in owner:
                raise InputError(f"{where}: {table.names[raw_id]} is already in output.class_map.{owner[raw_id]}")
            owner[raw_id] = key
    names = tuple(k for k in class_map if k != "ignore")
    if not names:
        raise InputError("output.class_map: name at least one task class besides ignore")
    training = np.zeros(1 << 16, np.int32)
    for raw_id in table.names:
        key = owner.get(raw_id, rest if table.learning_map[raw_id] else None)
        if key is not None and key != "ignore":
            training[raw_id] = names.index(key) + 1
    return TaskMap(training, names)


def maps_for(class_map: dict | None) -> ClassMaps:
    """The class table's maps with the training ids of ``output.class_map`` (the table's own when empty)."""
    import json

    return _maps_for(json.dumps(class_map or {}))


@lru_cache(maxsize=8)
def _maps_for(class_map_json: str) -> ClassMaps:
    import json

    maps = load_class_maps()
    task = task_training(json.loads(class_map_json))
    return maps if task is None else ClassMaps(task.training, maps.things, maps.asprs, maps.kitti_names)


def semantic_kitti_space_yaml(counts: np.ndarray | None = None, split: dict | None = None, class_map: dict | None = None) -> dict:
    """``semantic-kitti.yaml`` in SemanticKITTI's own raw ids (the devkit's file, so its tools and the stock
    loaders agree), ``content`` counted over the written labels (``counts`` per SemanticKITTI raw id).

    With ``class_map`` the ``learning_map`` gives the task's ids (``labels`` stay SemanticKITTI's); a SemanticKITTI
    id whose project classes go to different task classes trains as ignored, listed under ``class_map_conflicts``.
    ``project_classes`` names the SemanticKITTI id of each project class.
    """
    from ..labels import semantickitti_ids

    ids = sorted(SEMANTIC_KITTI)
    counts = np.ones(max(ids) + 1) if counts is None else np.asarray(counts, float)
    total = counts.sum()
    task = task_training(class_map)
    conflicts: dict[int, list[str]] = {}
    if task is None:
        learning = {i: SEMANTIC_KITTI[i][2] for i in ids}
        inverse = dict(SEMANTIC_KITTI_LEARNING_MAP_INV)
    else:
        table, lut = load_class_table(), semantic_kitti_lut()
        learning = {i: 0 for i in ids}
        classes: dict[int, list[str]] = {}
        for raw_id, name in sorted(table.names.items()):
            classes.setdefault(int(lut[raw_id]), []).append(name)
        for sk, names in classes.items():
            trains = {int(task.training[table.id_of(n)]) for n in names}
            if len(trains) == 1:
                learning[sk] = trains.pop()
            else:
                conflicts[sk] = names
        inverse = {0: 0}
        for raw_id in ids:
            inverse.setdefault(learning[raw_id], raw_id)
        inverse = {t: inverse.get(t, 0) for t in range(len(task.names) + 1)}
    return {
        "name": "bpy_pipeline (SemanticKITTI label space)",
        "labels": {i: SEMANTIC_KITTI[i][0] for i in ids},
        "color_map": {i: list(SEMANTIC_KITTI[i][1]) for i in ids},
        "content": {i: float(counts[i] / total) if total > 0 and i < len(counts) else 0.0 for i in ids},
        "learning_map": learning,
        "learning_map_inv": inverse,
        "learning_ignore": {t: t == 0 for t in inverse},
        "split": split or {"train": [], "valid": [], "test": []},
        "project_classes": dict(sorted(semantickitti_ids().items(), key=lambda kv: load_class_table().id_of(kv[0]))),
        **({"class_map_conflicts": conflicts} if conflicts else {}),
    }
