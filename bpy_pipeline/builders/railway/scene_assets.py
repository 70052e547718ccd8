"""Support assets from files in Blender (bpy): ``scene.assets`` read once per build, split by class, placed at every support.

:data:`LOADERS` maps a file suffix to the function that reads it into :class:`Piece` arrays (Blender's own
importers for glTF/GLB, OBJ and PLY, their objects removed again once read; ifcopenshell's geometry
iterator for IFC). The pure :mod:`~bpy_pipeline.builders.railway.assets` says where each asset stands, what
it replaces and which class each part takes; :func:`place` turns that into tagged objects that share one
mesh datablock per slot and class, and removes the procedural objects they replace.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import bpy
import mathutils
import numpy as np

from ...errors import InputError
from ...blender.asset_models import world_arrays
from ...blender.mesh_objects import mesh_data, tag
from .assets import SLOTS, part_class, placements

DATA_KINDS = ("objects", "meshes", "materials", "images", "textures", "cameras", "lights", "actions", "armatures", "collections", "node_groups")


@dataclass(frozen=True)
class Piece:
    """One object of an asset file: ``vertices (n, 3)`` (file units, Blender's frame after its importer: Z up),
    ``triangles (m, 3)`` int, ``material (m,)`` int into ``materials`` (names; ``""`` unnamed)."""

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    materials: tuple[str, ...]


def _mesh_pieces(objects) -> list[Piece]:
    """The evaluated mesh objects among ``objects`` as world-space pieces."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    out = []
    for obj in objects:
        if obj.type != "MESH":
            continue
        vertices, triangles, material = world_arrays(obj, depsgraph)
        names = tuple(s.material.name if s.material else "" for s in obj.material_slots) or ("",)
        out.append(Piece(obj.name, vertices, triangles, np.clip(material, 0, len(names) - 1), names))
    return out


def _blender_import(operator):
    """A loader that runs Blender's importer ``operator(path)``, reads the new objects and removes everything the import added."""

    def load(path: Path, key: str) -> list[Piece]:
        before = {kind: set(getattr(bpy.data, kind)) for kind in DATA_KINDS}
        try:
            try:
                operator(str(path))
            except (RuntimeError, AttributeError) as err:
                last = str(err).strip().splitlines()[-1] if str(err).strip() else type(err).__name__
                raise InputError(f"{key}: Blender cannot import {path.name} ({last})") from None
            bpy.context.view_layer.update()
            return _mesh_pieces([o for o in bpy.data.objects if o not in before["objects"]])
        finally:
            for kind in DATA_KINDS:  # objects first: the data they use is freed after them
                data = getattr(bpy.data, kind)
                for block in [b for b in data if b not in before[kind]]:
                    data.remove(block)

    return load


def _ifc(path: Path, key: str) -> list[Piece]:
    """Every product with a body of an IFC file, in world coordinates (metres, Z up), named by its ``Name``."""
    try:
        import ifcopenshell
        import ifcopenshell.geom
    except ImportError:
        raise InputError(f"{key}: an .ifc asset needs ifcopenshell (pip install 'bpy-pipeline[ifc]')") from None
    try:
        model = ifcopenshell.open(str(path))
    except Exception as err:  # ifcopenshell raises its own and plain errors for an unreadable file
        raise InputError(f"{key}: ifcopenshell cannot read {path.name} ({str(err).strip() or type(err).__name__})") from None
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    out = []
    iterator = ifcopenshell.geom.iterator(settings, model)
    if not iterator.initialize():
        return out
    while True:
        shape = iterator.get()
        geometry = shape.geometry
        product = model.by_id(shape.id)
        faces = np.asarray(geometry.faces, np.int32).reshape(-1, 3)
        if len(faces):
            materials = tuple(getattr(m, "name", "") or "" for m in geometry.materials) or ("",)
            ids = np.asarray(geometry.material_ids, np.int32)
            ids = ids if len(ids) == len(faces) else np.zeros(len(faces), np.int32)
            out.append(Piece(product.Name or product.is_a(), np.asarray(geometry.verts, float).reshape(-1, 3), faces, np.clip(ids, 0, len(materials) - 1),
                             materials))
        if not iterator.next():
            return out


LOADERS = {
    ".glb": _blender_import(lambda p: bpy.ops.import_scene.gltf(filepath=p)),
    ".gltf": _blender_import(lambda p: bpy.ops.import_scene.gltf(filepath=p)),
    ".obj": _blender_import(lambda p: bpy.ops.wm.obj_import(filepath=p, up_axis="Y", forward_axis="NEGATIVE_Z")),
    ".ply": _blender_import(lambda p: bpy.ops.wm.ply_import(filepath=p)),
    ".ifc": _ifc,
}


def asset_parts(path: str, slot: str, unit_scale: float, rules: dict, key: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{class: (vertices (n, 3) m, triangles (m, 3))}`` of one asset file, in its own frame (origin the support's foot)."""
    file = Path(path)
    pieces = LOADERS[file.suffix.lower()](file, key)
    grouped: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for piece in pieces:
        for index, material in enumerate(piece.materials):
            chosen = piece.triangles[piece.material == index]
            if not len(chosen):
                continue
            used, remap = np.unique(chosen, return_inverse=True)
            grouped.setdefault(part_class([piece.name, material], slot, rules), []).append((piece.vertices[used] * unit_scale, remap.reshape(-1, 3)))
    if not grouped:
        raise InputError(f"{key}: {file.name} holds no mesh with faces")
    out = {}
    for class_name, parts in grouped.items():
        starts = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
        out[class_name] = (np.concatenate([v for v, _ in parts]), np.concatenate([t + s for (_, t), s in zip(parts, starts)]))
    return out


def place(params, layout, detail, collection, reflectivity: dict[str, float]) -> None:
    """Replace the procedural supports named by ``params.assets`` with the files' assets (nothing without assets).

    Each placement's parts become objects ``<support part name>`` (the slot's own class) and
    ``<support part name>.<class>`` (parts a name gave another class), each its own instance, sharing one mesh
    per slot and class; the procedural objects a placement replaces are removed (the masts are never built with a
    mast asset: the railway builder instances none, see :mod:`.support_nodes`).
    """
    assets = params.assets
    for slot in SLOTS:
        path = getattr(assets, slot)
        if not path:
            continue
        spots = placements(layout, slot, detail.supports, layout.section.offsets)
        if not spots:
            continue
        parts = asset_parts(path, slot, assets.unit_scale, assets.classes, f"scene.assets.{slot}")
        meshes = {c: mesh_data(f"asset.{slot}.{c.replace(' ', '_')}", v, t) for c, (v, t) in parts.items()}
        for spot in spots:
            for name in spot.replaces:
                obj = collection.objects.get(name)
                if obj is not None:
                    data = obj.data
                    bpy.data.objects.remove(obj, do_unlink=True)
                    if data is not None and data.users == 0:
                        bpy.data.meshes.remove(data)
            matrix = mathutils.Matrix(np.asarray(spot.pose, float).tolist())
            for class_name, mesh in meshes.items():
                name = spot.name if class_name == SLOTS[slot] else f"{spot.name}.{class_name.replace(' ', '_')}"
                obj = bpy.data.objects.new(name, mesh)
                obj.matrix_world = matrix
                collection.objects.link(obj)
                tag(obj, class_name, reflectivity=reflectivity.get(class_name, 0.5))
