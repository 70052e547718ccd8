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
        raw = yaml.safe_load(Path(path).read_text()) or {}
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


def semantic_kitti_yaml(counts: np.ndarray | None = None, split: dict | None = None) -> dict:
    """The dataset's ``semantic-kitti.yaml`` (the SemanticKITTI devkit's layout) from the class table.

    counts : (k,) points per raw id over the dataset, for ``content`` (fractions); uniform when ``None``
    split : ``{train: [...], valid: [...], test: [...]}`` sequence numbers
    ``color_map`` is BGR, as the devkit's files are (the project's table is RGB); ``learning_map_inv``
    maps each training id to the first raw id that trains as it; ``learning_ignore`` marks training id 0.
    """
    table = load_class_table()
    ids = sorted(table.names)
    counts = np.ones(max(ids) + 1) if counts is None else np.asarray(counts, float)
    total = counts.sum()
    inverse: dict[int, int] = {}
    for raw_id in ids:
        inverse.setdefault(table.learning_map[raw_id], raw_id)
    return {
        "name": "bpy_pipeline",
        "labels": {i: table.names[i] for i in ids},
        "color_map": {i: [int(c) for c in table.colors[i][::-1]] for i in ids},
        "content": {i: float(counts[i] / total) if total > 0 and i < len(counts) else 0.0 for i in ids},
        "learning_map": {i: table.learning_map[i] for i in ids},
        "learning_map_inv": dict(sorted(inverse.items())),
        "learning_ignore": {t: t == 0 for t in sorted(inverse)},
        "split": split or {"train": [], "valid": [], "test": []},
    }
