"""Support assets from files (``scene.assets``): where each asset stands, what it replaces, which class each part takes. Pure.

The railway thesis imported BIM assemblies of its supports; ``scene.assets`` does the same: a file per slot
(:data:`SLOTS`: ``mast``, ``cantilever``, ``gantry``) replaces the procedural part at every support the
level of detail builds. The convention (docs/railway.md, "Support assets from files"):

* the asset's origin is the **foot of its support** (the mast's foot; a gantry's right leg's), on the
  ground beside the track, and after Blender's importer (Z up) its **+Y faces the track**, +Z up,
  metres (``unit_scale`` metres per file unit for OBJ and PLY files drawn in other units);
* ``mast`` replaces every mast (with its feeder and earth-wire brackets) of a ``single`` or
  ``both_sides`` layout, ``gantry`` every portal of a ``gantry`` layout;
* ``cantilever`` replaces the mast-face cantilever assembly of each mast (cantilever, registration arm,
  its insulators, steady arm), placed at that mast's foot like the mast: a BIM assembly is drawn for the
  nearest track ``supports.mast_offset`` m along +Y. The drop-tube cantilevers of farther tracks and of
  gantries, the feeder insulators and every wire stay procedural, at the layout's positions.

Each part of an asset takes the slot's class, unless a name says otherwise (:func:`part_class`).
"""

from __future__ import annotations

import fnmatch
import json
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...labels import normalise

SLOTS = {"mast": "mast", "cantilever": "cantilever", "gantry": "gantry"}  # scene.assets key -> the class its parts take by default
FORMATS = (".glb", ".gltf", ".obj", ".ply", ".ifc")
# classes an object or material name may give a part by its beginning (``insulator_3`` -> insulator), longest first
NAMED_CLASSES = ("section insulator", "tensioning weight", "registration arm", "steady arm", "cantilever", "insulator", "gantry", "anchor", "mast")
CANTILEVER_PARTS = ("cantilever", "registration_arm", "insulators", "steady_arm")  # the procedural objects a mast-face cantilever asset replaces, per track


@dataclass(frozen=True)
class AssetPlacement:
    """One asset to place: ``name`` of its objects, ``pose`` ``(4, 4)`` world (the asset's origin and axes),
    ``replaces`` the names of the procedural objects it stands in for."""

    name: str
    pose: np.ndarray
    replaces: tuple[str, ...]


def foot_pose(support_frame: np.ndarray, lateral: float, base: float, outward: float) -> np.ndarray:
    """``(4, 4)`` world pose of a mast foot: ``lateral`` (m) and ``base`` (m) in the support's level frame
    (x along the track, y left, z up), turned so that +Y points back to the track (away from ``outward``)."""
    turn = math.pi if outward > 0 else 0.0  # a right mast (outward -1) sees the track along the frame's +y
    c, s = math.cos(turn), math.sin(turn)
    local = np.array([[c, -s, 0, 0], [s, c, 0, lateral], [0, 0, 1, base], [0, 0, 0, 1]], float)
    return np.asarray(support_frame, float) @ local


def placements(layout, slot: str, supports, offsets) -> list[AssetPlacement]:
    """Where the ``slot`` asset stands at each support index of ``supports`` (the ones the level of detail builds).

    layout : a :class:`~.railway_layout.RailwayLayout`; offsets : ``(n,)`` track centre laterals (m, the cross-section's).
    """
    out = []
    for k in supports:
        support = layout.supports[k]
        frame = support.frame
        if slot == "gantry":
            if support.gantry:
                right = next(m for m in support.masts if m.side == "right")
                out.append(AssetPlacement(f"support.{k:02d}.gantry", foot_pose(frame, right.lateral, right.base, -1.0), (f"support.{k:02d}.gantry",)))
            continue
        if support.gantry:
            continue
        for mast in support.masts:
            pose = foot_pose(frame, mast.lateral, mast.base, mast.outward)
            if slot == "mast":
                out.append(AssetPlacement(f"support.{k:02d}.mast.{mast.side}", pose, (f"support.{k:02d}.mast.{mast.side}",)))
            elif slot == "cantilever" and mast.tracks:
                i = min(mast.tracks, key=lambda t: abs(float(offsets[t]) - mast.lateral))  # the mast-face cantilever's track
                out.append(AssetPlacement(f"support.{k:02d}.cantilever.t{i}", pose, tuple(f"support.{k:02d}.{p}.t{i}" for p in CANTILEVER_PARTS)))
    return out


def part_class(names: list[str], slot: str, rules: dict[str, str]) -> str:
    """The class of an asset's part, from its names (the object's, then its material's; either may be empty).

    ``rules`` (``scene.assets.classes``): ``{glob: class}`` tried first, in order, case-insensitive on each name;
    then a name beginning with one of :data:`NAMED_CLASSES` (``_`` and ``-`` read as spaces: ``Insulator_02``,
    ``registration-arm.001``) takes that class; else the slot's class.
    """
    for pattern, class_name in rules.items():
        if any(name and fnmatch.fnmatch(name.lower(), pattern.lower()) for name in names):
            return normalise(class_name)
    for name in names:
        spoken = normalise(name.replace("-", " "))
        for class_name in NAMED_CLASSES:
            if spoken.startswith(class_name):
                return class_name
    return SLOTS[slot]


def sniff(path: Path) -> str | None:
    """``None`` when the file's first bytes look like its suffix's format; else what is wrong (one phrase)."""
    suffix = path.suffix.lower()
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError as err:
        return f"cannot read it ({err.strerror})"
    if not head:
        return "empty"
    if suffix == ".glb":
        if len(head) < 12 or head[:4] != b"glTF" or struct.unpack("<I", head[4:8])[0] != 2:
            return "not a binary glTF 2.0 file (no 'glTF' version 2 header)"
        declared, size = struct.unpack("<I", head[8:12])[0], path.stat().st_size
        if declared != size:
            return f"a damaged binary glTF file (its header says {declared} bytes, the file has {size})"
    elif suffix == ".gltf":
        try:
            data = json.loads(path.read_text())
        except (UnicodeDecodeError, ValueError):
            return "not a glTF JSON file"
        if not isinstance(data, dict) or "asset" not in data:
            return "not a glTF JSON file (no 'asset' key)"
    elif suffix == ".ply":
        if not head.startswith(b"ply"):
            return "not a PLY file (no 'ply' header)"
    elif suffix == ".ifc":
        if not head.lstrip().startswith(b"ISO-10303-21"):
            return "not an IFC STEP file (no 'ISO-10303-21' header)"
    elif suffix == ".obj":
        if b"\0" in head or not any(line.strip().startswith(b"v ") for line in head.splitlines()):
            return "not a Wavefront OBJ text file (no 'v' vertex line at its start)"
    return None


def check_assets(assets, where: str, known_classes) -> None:
    """One ``InputError`` naming the key (``scene.assets.mast``) when a path is missing, of another format, not
    what its suffix says, or an IFC file without ifcopenshell; a ``classes`` rule naming an unknown class."""
    for slot in SLOTS:
        given = getattr(assets, slot)
        if not given:
            continue
        key = f"{where}.{slot}"
        path = Path(given)
        if path.suffix.lower() not in FORMATS:
            raise InputError(f"{key}: expected a {', '.join(FORMATS)} file, got {given!r}")
        if not path.is_file():
            raise InputError(f"{key}: no such file {given!r}")
        wrong = sniff(path)
        if wrong:
            raise InputError(f"{key}: {given!r} is {wrong}; allowed: {', '.join(FORMATS)}")
        if path.suffix.lower() == ".ifc":
            try:
                import ifcopenshell  # noqa: F401
            except ImportError:
                raise InputError(f"{key}: an .ifc asset needs ifcopenshell (pip install 'bpy-pipeline[ifc]'); or give a .glb, .gltf, .obj or .ply") from None
    known = {normalise(c) for c in known_classes}
    for pattern, class_name in assets.classes.items():
        if not isinstance(pattern, str) or not isinstance(class_name, str):
            raise InputError(f"{where}.classes: expected {{name glob: class}} strings, got {pattern!r}: {class_name!r}")
        if normalise(class_name) not in known:
            raise InputError(f"{where}.classes.{pattern}: unknown class {class_name!r}; allowed: {', '.join(sorted(known))}")
