"""The assets manifest (``assets_manifest/assets.yaml``): external meshes for ``scene.population``, checked. Pure.

An entry names one file (glTF/GLB, OBJ, FBX or .blend) and what it holds::

    - name: sedan                 kind: car (person | car | robot)
      set: project_cars           # population picks a set by this name (default: the entry's name)
      path: test_assets/car_sedan.glb      sha256: ...      licence: CC0-1.0     source: ...
      up_axis: auto               # the file's up axis: X, Y, Z, -X, -Y, -Z; auto: the format's (Y; .blend: Z)
      unit_scale: auto            # metres per file unit; auto: 1, 0.01, 0.001 or 0.0254, whichever gives the kind's usual size
      glass_materials: [glass, window, windshield, windscreen]   # material names (substrings) that become glass

Placed assets are scaled to a height drawn per object (the parking paper's rule: sample a height
from a range and scale to it), so ``unit_scale`` only reports the asset's own size. The orientation
is checked on import (a person stands taller than it is wide, a car is longer than it is tall): a
file that fails gets one line naming the entry and the ``up_axis`` that would fit.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .errors import InputError
from .yaml_text import load_yaml

MANIFEST = Path(__file__).resolve().parents[1] / "assets_manifest" / "assets.yaml"
FORMATS = (".glb", ".gltf", ".obj", ".fbx", ".blend")
AXES = {"X": (1, 0, 0), "Y": (0, 1, 0), "Z": (0, 0, 1), "-X": (-1, 0, 0), "-Y": (0, -1, 0), "-Z": (0, 0, -1)}
NATIVE_UP = {".glb": "Y", ".gltf": "Y", ".obj": "Y", ".fbx": "Y", ".blend": "Z"}
# file (x, y, z) -> Blender after the importer's own axis conversion (glTF, OBJ, FBX: Y up, -Z forward)
IMPORT_CONVERSION = {".blend": np.eye(3), **{s: np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]) for s in (".glb", ".gltf", ".obj", ".fbx")}}
NOMINAL_HEIGHT = {"person": 1.75, "car": 1.55, "robot": 1.2}  # m, for unit_scale: auto
UNIT_SCALES = (1.0, 0.01, 0.001, 0.0254, 0.1)
GLASS_MATERIALS = ("glass", "window", "windshield", "windscreen")
KINDS = tuple(NOMINAL_HEIGHT)


@dataclass(frozen=True)
class AssetEntry:
    """One checked manifest entry (``path`` resolved, its sha256 verified)."""

    name: str
    kind: str
    set: str  # "": an entry of no set (the industrial hall's own people, blender/people.py)
    path: Path
    sha256: str
    licence: str
    source: str = ""
    up_axis: str = "auto"
    unit_scale: float | None = None  # None: auto
    glass_materials: tuple[str, ...] = GLASS_MATERIALS
    where: str = ""  # "manifest: assets[i]" for messages


def read_manifest(path: str | Path | None = None) -> list[AssetEntry]:
    """Every entry of the manifest whose file is present, checked; ``InputError`` naming the file and entry otherwise.

    A missing file is skipped (the procedural models stand in); a file whose sha256 differs, an unknown
    format, kind or axis, or an entry without a licence is an error.
    """
    path = Path(path) if path else MANIFEST
    if not path.exists():
        raise InputError(f"{path}: the assets manifest does not exist")
    try:
        data = load_yaml(path.read_text()) or {}
    except yaml.YAMLError:
        raise InputError(f"{path}: not valid YAML") from None
    entries = data.get("assets", []) if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise InputError(f"{path}: assets: expected a list of {{name, kind, path, sha256, licence}}")
    out = []
    for i, entry in enumerate(entries):
        where = f"{path}: assets[{i}]"
        if not isinstance(entry, dict) or not all(isinstance(entry.get(k), str) and entry.get(k) for k in ("name", "kind", "path", "sha256", "licence")):
            raise InputError(f"{where}: needs name, kind, path, sha256 and licence (strings)")
        unknown = set(entry) - {"name", "kind", "set", "path", "sha256", "licence", "source", "up_axis", "unit_scale", "glass_materials"}
        if unknown:
            raise InputError(
                f"{where}.{sorted(unknown)[0]}: unknown key; allowed: name, kind, set, path, sha256, licence, source, up_axis, unit_scale, glass_materials"
            )
        if entry["kind"] not in KINDS:
            raise InputError(f"{where}.kind: expected one of {', '.join(KINDS)}, got {entry['kind']!r}")
        file = (path.parent / entry["path"]).resolve()
        if file.suffix.lower() not in FORMATS:
            raise InputError(f"{where}.path: expected a {', '.join(FORMATS)} file, got {entry['path']!r}")
        up = str(entry.get("up_axis", "auto")).upper()
        if up != "AUTO" and up not in AXES:
            raise InputError(f"{where}.up_axis: expected auto or one of {', '.join(AXES)}, got {entry.get('up_axis')!r}")
        scale = entry.get("unit_scale", "auto")
        if scale != "auto" and (isinstance(scale, bool) or not isinstance(scale, (int, float)) or scale <= 0):
            raise InputError(f"{where}.unit_scale: expected auto or a number > 0 (metres per file unit), got {scale!r}")
        glass = entry.get("glass_materials", list(GLASS_MATERIALS))
        if not isinstance(glass, list) or not all(isinstance(g, str) and g for g in glass):
            raise InputError(f"{where}.glass_materials: expected a list of material names, got {glass!r}")
        if not file.exists():
            continue
        digest = hashlib.sha256(file.read_bytes()).hexdigest()
        if digest != entry["sha256"].lower():
            raise InputError(f"{where}.sha256: {file.name} has sha256 {digest}, the manifest says {entry['sha256']}")
        out.append(AssetEntry(entry["name"], entry["kind"], str(entry.get("set", "")), file, digest, entry["licence"], str(entry.get("source", "")),
                              "auto" if up == "AUTO" else up, None if scale == "auto" else float(scale), tuple(g.lower() for g in glass), where))
    return out


def asset_set(name: str, kind: str, where: str, path: str | Path | None = None) -> list[AssetEntry]:
    """The entries of set ``name`` (or the entry named ``name``) of ``kind``; ``InputError`` naming ``where`` when none is present."""
    entries = [e for e in read_manifest(path) if e.set]
    chosen = [e for e in entries if e.kind == kind and name in (e.set, e.name)]
    if not chosen:
        sets = sorted({e.set for e in entries if e.kind == kind})
        raise InputError(
            f"{where}: no {kind} asset of set {name!r} is present in {Path(path) if path else MANIFEST}; sets of kind {kind}: {', '.join(sets) or 'none'}"
        )
    return chosen


def up_rotation(suffix: str, up_axis: str) -> np.ndarray:
    """``(3, 3)`` rotation that brings the file's up axis (after the importer's conversion) to Blender's +z."""
    axis = NATIVE_UP[suffix] if up_axis == "auto" else up_axis
    u = IMPORT_CONVERSION[suffix] @ np.array(AXES[axis], float)
    z = np.array([0.0, 0.0, 1.0])
    c = float(u @ z)
    if c > 1 - 1e-9:
        return np.eye(3)
    if c < -1 + 1e-9:
        return np.diag([1.0, -1.0, -1.0])  # half a turn about x
    k = np.cross(u, z)
    k /= np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    s = np.sqrt(1 - c * c)
    return np.eye(3) + s * K + (1 - c) * K @ K


def upright(kind: str, extent: np.ndarray) -> bool:
    """Whether a bounding box ``extent (3,)`` (m, x y z) looks upright for ``kind``.

    A person is at least 0.6 times as tall as its largest horizontal size (arms spread reach about
    its height); a car is longest along the ground and lower than 0.8 times its length; a robot any shape.
    """
    horizontal = float(max(extent[0], extent[1]))
    if kind == "person":
        return extent[2] >= 0.6 * horizontal
    if kind == "car":
        return extent[2] < 0.8 * horizontal
    return extent[2] > 0


def auto_unit_scale(kind: str, height: float) -> float:
    """The metres per unit of :data:`UNIT_SCALES` that brings ``height`` (file units) nearest the kind's usual height."""
    return min(UNIT_SCALES, key=lambda s: abs(np.log(max(height * s, 1e-12) / NOMINAL_HEIGHT[kind])))


def orientation_error(entry: AssetEntry, vertices_blender: np.ndarray, suffix: str) -> str | None:
    """``None`` when the imported vertices ``(n, 3)`` (Blender frame, after the importer) stand upright with the
    entry's ``up_axis``; else the one-line message, naming the axes that would fit."""
    turned = vertices_blender @ up_rotation(suffix, entry.up_axis).T
    extent = turned.max(axis=0) - turned.min(axis=0)
    if upright(entry.kind, extent):
        return None
    fits = [a for a in AXES if upright(entry.kind, np.ptp(vertices_blender @ up_rotation(suffix, a).T, axis=0))]
    axis = NATIVE_UP[suffix] + " (auto)" if entry.up_axis == "auto" else entry.up_axis
    return (
        f"{entry.where} ({entry.name}): {entry.path.name} does not stand upright as a {entry.kind} with up_axis {axis}"
        f" (extent x {extent[0]:.2f}, y {extent[1]:.2f}, z {extent[2]:.2f} file units); set up_axis to the file's up axis"
        + (f" ({' or '.join(fits)} would fit)" if fits else "")
    )
