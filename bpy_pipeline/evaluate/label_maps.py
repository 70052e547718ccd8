"""Label maps: every source's label space to the evaluation classes.

Evaluation classes are named with SemanticKITTI's 19 training class names (:data:`TRAINING_NAMES`
1..19). An evaluation picks some of them (``classes``, e.g. ``("car", "person")``); a point's
evaluation label is then

- ``i`` (0..C-1): the ``i``-th requested class,
- ``C`` (:func:`other_index`): labelled, but none of the requested classes ("other", the background),
- ``-1``: ignored (unlabelled, outlier, or a class the source cannot tell apart from a requested one).

One table per source space, each ending in SemanticKITTI training names:

- SemanticKITTI raw ids (``.label`` files, low 16 bits): :data:`SEMANTICKITTI_LEARNING_MAP`, the
  ``learning_map`` of SemanticKITTI's ``semantic-kitti.yaml`` (semantic-kitti-api, ``config/semantic-kitti.yaml``),
  raw id -> training id. Raw 0 (unlabeled) and 1 (outlier) are ignored; raw 52 (other-structure) and
  99 (other-object), which the official table sends to training id 0, are labelled points of no training
  class and count as "other" here.
- SemanticKITTI training ids (0..19, the ``.npy`` label files of the real scans): 0 is ignored.
- project classes (``semantic`` of generated data): ``assets_manifest/labels.yaml``'s ``semantickitti:``
  section (project name -> raw id, :func:`bpy_pipeline.labels.semantickitti_ids`), then the raw table.
  So ``rider`` -> 31 -> bicyclist, ``van`` -> 10 -> car, ``unlabeled`` -> ignored.
- KITTI object types (``label_2``): :data:`KITTI_TYPES`.
"""

from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from ..errors import InputError
from ..labels import load_class_table, normalise, semantickitti_ids

# SemanticKITTI's training classes, index = training id (semantic-kitti.yaml: learning_map_inv / labels).
TRAINING_NAMES = (
    "unlabeled", "car", "bicycle", "motorcycle", "truck", "other-vehicle", "person", "bicyclist", "motorcyclist",
    "road", "parking", "sidewalk", "other-ground", "building", "fence", "vegetation", "trunk", "terrain", "pole",
    "traffic-sign",
)  # fmt: skip
EVALUATION_CLASSES = TRAINING_NAMES[1:]

# SemanticKITTI raw id -> training id: `learning_map` of semantic-kitti.yaml (semantic-kitti-api, config/semantic-kitti.yaml).
SEMANTICKITTI_LEARNING_MAP = {
    0: 0,      # unlabeled
    1: 0,      # outlier -> unlabeled
    10: 1,     # car
    11: 2,     # bicycle
    13: 5,     # bus -> other-vehicle
    15: 3,     # motorcycle
    16: 5,     # on-rails -> other-vehicle
    18: 4,     # truck
    20: 5,     # other-vehicle
    30: 6,     # person
    31: 7,     # bicyclist
    32: 8,     # motorcyclist
    40: 9,     # road
    44: 10,    # parking
    48: 11,    # sidewalk
    49: 12,    # other-ground
    50: 13,    # building
    51: 14,    # fence
    52: 0,     # other-structure -> unlabeled
    60: 9,     # lane-marking -> road
    70: 15,    # vegetation
    71: 16,    # trunk
    72: 17,    # terrain
    80: 18,    # pole
    81: 19,    # traffic-sign
    99: 0,     # other-object -> unlabeled
    252: 1,    # moving-car -> car
    253: 7,    # moving-bicyclist -> bicyclist
    254: 6,    # moving-person -> person
    255: 8,    # moving-motorcyclist -> motorcyclist
    256: 5,    # moving-on-rails -> other-vehicle
    257: 5,    # moving-bus -> other-vehicle
    258: 4,    # moving-truck -> truck
    259: 5,    # moving-other-vehicle -> other-vehicle
}  # fmt: skip
RAW_IGNORED = (0, 1)  # unlabeled, outlier: no class at all
OTHER_TRAINING = -2  # pseudo training id: labelled, but of no training class (raw 52 other-structure, 99 other-object)

# KITTI object type (label_2) -> training name; None: ignored. Van is ignored as KITTI's own evaluation
# ignores vans for cars; Cyclist is a rider on a bicycle (SemanticKITTI's bicyclist).
KITTI_TYPES = {
    "Car": "car", "Pedestrian": "person", "Person_sitting": "person", "Cyclist": "bicyclist",
    "Van": None, "Truck": None, "Tram": None, "Misc": None, "DontCare": None,
}  # fmt: skip
KITTI_CLASSES = ("car", "person", "bicyclist")  # what KITTI's boxes can label; other classes cannot be tested on KITTI frames
# SqueezeSeg's samples (KITTI raw drives, labels from KITTI's tracklets): label id -> training name; 0 is labelled
# background (none of car, person, bicyclist). Files whose name starts with SQUEEZESEG_PREFIX use it.
SQUEEZESEG_NAMES = ("background", "car", "person", "bicyclist")
SQUEEZESEG_PREFIX = "squeezeseg_"


def parse_classes(classes: str | Iterable[str], where: str = "--classes") -> tuple[str, ...]:
    """Evaluation class names from ``"car,person"`` or a sequence; ``InputError`` naming ``where`` for an unknown
    or repeated name (spellings: ``traffic-sign``, ``traffic sign`` and ``traffic_sign`` are one)."""
    items = classes.split(",") if isinstance(classes, str) else list(classes)
    spelled = {normalise(n.replace("-", " ")): n for n in EVALUATION_CLASSES}
    out = []
    for item in items:
        name = spelled.get(normalise(str(item).replace("-", " ")))
        if name is None:
            raise InputError(f"{where}: unknown class {str(item).strip()!r}; allowed: {', '.join(EVALUATION_CLASSES)}")
        if name in out:
            raise InputError(f"{where}: class {name!r} given twice")
        out.append(name)
    if not out:
        raise InputError(f"{where}: no class given; allowed: {', '.join(EVALUATION_CLASSES)}")
    return tuple(out)


def other_index(classes: Sequence[str]) -> int:
    """The evaluation label of "other" (labelled, none of the requested classes): ``len(classes)``."""
    return len(classes)


def training_lut(classes: Sequence[str]) -> np.ndarray:
    """``(20,)`` int64: SemanticKITTI training id -> evaluation label (0 unlabeled -> -1)."""
    lut = np.full(len(TRAINING_NAMES), other_index(classes), np.int64)
    lut[0] = -1
    for i, name in enumerate(classes):
        lut[TRAINING_NAMES.index(name)] = i
    return lut


def raw_to_training_lut() -> np.ndarray:
    """``(65536,)`` int64: SemanticKITTI raw id -> training id; ignored raw ids (0, 1, and ids outside the table) -> 0,
    labelled raw ids of no training class (52, 99) -> :data:`OTHER_TRAINING`."""
    lut = np.zeros(1 << 16, np.int64)
    for raw, train in SEMANTICKITTI_LEARNING_MAP.items():
        lut[raw] = OTHER_TRAINING if train == 0 and raw not in RAW_IGNORED else train
    return lut


def training_to_eval(training: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    """``(n,)`` int64 evaluation labels of ``(n,)`` training ids (0..19, or :data:`OTHER_TRAINING`; others ignored)."""
    training = np.asarray(training, np.int64)
    out = np.full(training.shape, -1, np.int64)
    inside = (training >= 0) & (training < len(TRAINING_NAMES))
    out[inside] = training_lut(classes)[training[inside]]
    out[training == OTHER_TRAINING] = other_index(classes)
    return out


def raw_to_eval(raw: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    """``(n,)`` int64 evaluation labels of SemanticKITTI raw ids (``.label`` & 0xFFFF)."""
    return training_to_eval(raw_to_training_lut()[np.asarray(raw, np.int64) & 0xFFFF], classes)


def project_to_training_lut(class_names: dict[int, str] | None = None) -> np.ndarray:
    """``(max id + 1,)`` int64: project class id -> training id (or :data:`OTHER_TRAINING`, or 0 ignored).

    class_names : ``{project id: class name}`` (a dataset manifest's ``class_table``); ``None``: the project's table.
    """
    names = load_class_table().names if class_names is None else {int(k): normalise(v) for k, v in class_names.items()}
    to_raw = semantickitti_ids()
    raw_lut = raw_to_training_lut()
    lut = np.zeros(max(names) + 1, np.int64)
    for class_id, name in names.items():
        if name not in to_raw:
            raise InputError(f"assets_manifest/labels.yaml: semantickitti: no SemanticKITTI id for class {name!r}")
        lut[class_id] = raw_lut[to_raw[name]]
    return lut


def project_to_eval(semantic: np.ndarray, classes: Sequence[str], class_names: dict[int, str] | None = None) -> np.ndarray:
    """``(n,)`` int64 evaluation labels of project class ids (``semantic`` of generated points; ids outside the table ignored)."""
    lut = project_to_training_lut(class_names)
    semantic = np.asarray(semantic, np.int64)
    training = np.zeros(semantic.shape, np.int64)
    inside = (semantic >= 0) & (semantic < len(lut))
    training[inside] = lut[semantic[inside]]
    return training_to_eval(training, classes)


def kitti_type_to_eval(kitti_type: str, classes: Sequence[str]) -> int:
    """Evaluation label of a KITTI object type's points: a requested class, or -1 (ignored). A type whose
    training name is not requested is ignored too (a cyclist is never counted as "other")."""
    if kitti_type not in KITTI_TYPES:
        return -1  # an unknown type: ignored, as KITTI's Misc
    name = KITTI_TYPES[kitti_type]
    return classes.index(name) if name in classes else -1


def squeezeseg_to_eval(labels: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    """``(n,)`` int64 evaluation labels of SqueezeSeg label ids (0 background -> other; a class not requested -> ignored)."""
    lut = np.array([other_index(classes)] + [classes.index(n) if n in classes else -1 for n in SQUEEZESEG_NAMES[1:]], np.int64)
    return lut[np.asarray(labels, np.int64).reshape(-1)]


def check_kitti_classes(classes: Sequence[str], where: str) -> None:
    """``InputError`` when ``classes`` holds none of what KITTI boxes can label (car, person, bicyclist). With some of
    them, such a frame is scored on those only (``LabelledScan.known``)."""
    if not any(c in KITTI_CLASSES for c in classes):
        raise InputError(
            f"{where}: a KITTI object frame labels only {', '.join(KITTI_CLASSES)}; it cannot test {', '.join(classes)} (add one of those to --classes or drop "
            "it from --test)"
        )
