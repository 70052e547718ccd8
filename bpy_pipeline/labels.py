"""The class table (``assets_manifest/labels.yaml``) and the name rules that label untagged objects.

Pure: no bpy. Class names are matched after normalisation (case-insensitive, ``_`` == `` ``),
so ``contact_wire``, ``Contact Wire`` and ``contact wire`` are one class.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml

from .errors import InputError
from .yaml_text import load_yaml

LABELS_PATH = Path(__file__).resolve().parent.parent / "assets_manifest" / "labels.yaml"


def normalise(name: str) -> str:
    """Canonical spelling of a class name: lower case, single spaces instead of ``_``."""
    return " ".join(str(name).replace("_", " ").lower().split())


@dataclass(frozen=True)
class NameRule:
    """Label an untagged object whose name (or an ancestor's) contains ``match``."""

    match: re.Pattern
    class_name: str
    exclude: re.Pattern | None = None

    def applies(self, names: list[str]) -> bool:
        """``names``: the object's name first, then its ancestors' names."""
        if self.exclude is not None and any(self.exclude.search(n) for n in names):
            return False
        return any(self.match.search(n) for n in names)


@dataclass(frozen=True)
class ClassTable:
    """Raw class ids, names, RGB colours and the training map, as in SemanticKITTI's yaml."""

    names: dict[int, str]
    colors: dict[int, tuple[int, int, int]]
    learning_map: dict[int, int]
    name_rules: tuple[NameRule, ...]

    def id_of(self, name: str, where: str = "class") -> int:
        """Raw id of a class name; ``InputError`` naming ``where`` and the allowed names otherwise."""
        wanted = normalise(name)
        for class_id, class_name in self.names.items():
            if class_name == wanted:
                return class_id
        allowed = ", ".join(self.names[i] for i in sorted(self.names))
        raise InputError(f"{where}: unknown class {name!r}; allowed: {allowed}")

    def classify(self, names: list[str]) -> str:
        """Class for an untagged object from the name rules (first match wins), else ``unlabeled``."""
        for rule in self.name_rules:
            if rule.applies(names):
                return rule.class_name
        return "unlabeled"

    def color_lut(self) -> np.ndarray:
        """``(max_id + 1, 3)`` uint8 RGB lookup table indexed by raw class id (unknown ids black)."""
        lut = np.zeros((max(self.names) + 1, 3), np.uint8)
        for class_id, rgb in self.colors.items():
            lut[class_id] = rgb
        return lut


def parse_rules(rules: list, where: str, names: dict[int, str]) -> tuple[NameRule, ...]:
    """Validate a list of ``{match, class, exclude}`` mappings into :class:`NameRule` objects."""
    if not isinstance(rules, list):
        raise InputError(f"{where}: expected a list of {{match, class, exclude}} mappings")
    known = set(names.values())
    parsed = []
    for i, rule in enumerate(rules):
        key = f"{where}[{i}]"
        if not isinstance(rule, dict) or not {"match", "class"} <= set(rule) or set(rule) - {"match", "class", "exclude"}:
            raise InputError(f"{key}: expected keys match, class and optionally exclude, got {rule!r}")
        class_name = normalise(rule["class"])
        if class_name not in known:
            raise InputError(f"{key}.class: unknown class {rule['class']!r}; allowed: {', '.join(sorted(known))}")
        try:
            match = re.compile(str(rule["match"]), re.IGNORECASE)
            exclude = re.compile(str(rule["exclude"]), re.IGNORECASE) if rule.get("exclude") else None
        except re.error as err:
            raise InputError(f"{key}: invalid regular expression ({err})") from None
        parsed.append(NameRule(match, class_name, exclude))
    return tuple(parsed)


@lru_cache(maxsize=4)
def _class_file(path: Path):
    """The parsed class table file ``path`` (read once per process and path; not to be changed by callers)."""
    return load_yaml(path.read_text())


def load_class_table(path: Path = LABELS_PATH) -> ClassTable:
    """Read and check the class table; ``InputError`` naming the file when it is missing or malformed."""
    return _class_table(Path(path))


@lru_cache(maxsize=4)
def _class_table(path: Path) -> ClassTable:
    """:func:`load_class_table` of ``path`` as a :class:`~pathlib.Path` (``load_class_table()`` and
    ``load_class_table(LABELS_PATH)`` are one cache entry, and one parse of the file)."""
    try:
        raw = _class_file(path)
    except (OSError, yaml.YAMLError) as err:
        raise InputError(f"{path}: cannot read the class table ({err})") from None
    try:
        names = {int(k): normalise(v) for k, v in raw["labels"].items()}
        colors = {int(k): tuple(int(c) for c in v) for k, v in raw["color_map"].items()}
        learning_map = {int(k): int(v) for k, v in raw["learning_map"].items()}
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise InputError(f"{path}: expected labels, color_map and learning_map keyed by class id ({err})") from None
    if set(colors) != set(names) or set(learning_map) != set(names):
        raise InputError(f"{path}: labels, color_map and learning_map must list the same class ids")
    if len(set(names.values())) != len(names):
        raise InputError(f"{path}: class names must be unique")
    rules = parse_rules(raw.get("name_rules", []), f"{path}: name_rules", names)
    return ClassTable(names, colors, learning_map, rules)


def semantickitti_ids(path: Path = LABELS_PATH) -> dict[str, int]:
    """``{project class name: SemanticKITTI raw id}`` from the ``semantickitti:`` section of the class table file
    (every class of the table listed; ``InputError`` naming the file when the section is missing, incomplete or not ids)."""
    return _semantickitti_ids(Path(path))


@lru_cache(maxsize=4)
def _semantickitti_ids(path: Path) -> dict[str, int]:
    table = _class_table(path)
    try:
        raw = _class_file(path).get("semantickitti")
        ids = {normalise(name): int(value) for name, value in raw.items()}
    except (OSError, yaml.YAMLError, AttributeError, TypeError, ValueError) as err:
        raise InputError(f"{path}: semantickitti: expected a mapping of class name to SemanticKITTI raw id ({err})") from None
    missing = sorted(set(table.names.values()) - set(ids))
    if missing:
        raise InputError(f"{path}: semantickitti: no SemanticKITTI id for {', '.join(missing)}")
    return ids
