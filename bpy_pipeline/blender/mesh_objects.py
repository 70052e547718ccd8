"""Blender objects from numpy arrays, label tags, and the collection builders write into."""

from __future__ import annotations

import bpy
import numpy as np

COLLECTION = "LiDAR Scene"


def scene_collection(name: str = COLLECTION) -> bpy.types.Collection:
    """An empty collection ``name`` linked to the current scene (emptied if it exists, orphans purged)."""
    collection = bpy.data.collections.get(name)
    if collection is None:
        collection = bpy.data.collections.new(name)
        bpy.context.scene.collection.children.link(collection)
    remove_objects(list(collection.all_objects))
    for child in list(collection.children):
        bpy.data.collections.remove(child)
    return collection


def remove_objects(objects: list) -> None:
    """Remove ``objects``, then their mesh and curve data that no other object uses, in one pass each.

    ``bpy.data.batch_remove`` looks through the file's IDs once for the whole list, where removing one
    object at a time looks through them once per object (150 road users of a street: 57 ms -> 6 ms).
    """
    data = {obj.data for obj in objects if obj.data is not None and obj.type in ("MESH", "CURVE")}
    bpy.data.batch_remove(objects)
    bpy.data.batch_remove([d for d in data if d.users == 0])


def tag(obj: bpy.types.Object, class_name: str | None = None, material: str = "diffuse", reflectivity: float = 0.5, instance: int | None = None):
    """Set the ``lidar_*`` custom properties export reads (docs/builders.md; the classes are assets_manifest/labels.yaml)."""
    if class_name is not None:
        obj["lidar_class"] = class_name
    obj["lidar_material"] = material
    obj["lidar_reflectivity"] = float(reflectivity)
    if instance is not None:
        obj["lidar_instance"] = int(instance)
    return obj


def mesh_data(name: str, vertices: np.ndarray, triangles: np.ndarray) -> bpy.types.Mesh:
    """A mesh datablock from ``(n, 3)`` vertices and ``(m, 3)`` triangles (:func:`fill_mesh`)."""
    return fill_mesh(bpy.data.meshes.new(name), vertices, triangles)


def fill_mesh(mesh: bpy.types.Mesh, vertices: np.ndarray, triangles: np.ndarray) -> bpy.types.Mesh:
    """``mesh`` given ``(n, 3)`` vertices and ``(m, 3)`` triangles, filled with foreach_set; returns it.

    The positions and corners are written through their attributes (``position``, ``.corner_vert``), whose
    arrays take the numpy buffer in one copy; ``vertices.co`` and ``loops.vertex_index`` go value by value
    (the same mesh, 3x slower: a street frame makes about 150 meshes). Refilling a mesh an object already
    uses changes its geometry only, where a new object or mesh makes Blender rebuild the scene's relations.
    A mesh holding these triangles already (:func:`has_triangles`: a road user's part where the last frame had the
    same kind of part) keeps them and its edges and takes the new positions only; emptied and filled anew it costs
    50 times as much for a pedestrian's body (the polygons' ``loop_start`` go value by value, the edges are found again).
    """
    vertices = np.ascontiguousarray(vertices, np.float32).reshape(-1)
    triangles = np.ascontiguousarray(triangles, np.int32).reshape(-1)
    if has_triangles(mesh, len(vertices) // 3, triangles):
        if len(vertices):
            mesh.attributes["position"].data.foreach_set("vector", vertices)
            mesh.vertices[0].co = vertices[:3]  # through MeshVertex: tags the positions changed (bounds, normals, BVH)
        mesh.update()
        return mesh
    mesh.clear_geometry()
    if len(vertices):  # an empty mesh has no attributes to write
        mesh.vertices.add(len(vertices) // 3)
        mesh.attributes["position"].data.foreach_set("vector", vertices)
    if len(triangles):
        mesh.loops.add(len(triangles))
        mesh.attributes[".corner_vert"].data.foreach_set("value", triangles)
    mesh.polygons.add(len(triangles) // 3)
    mesh.polygons.foreach_set("loop_start", np.arange(0, len(triangles), 3, dtype=np.int32))
    mesh.update()
    return mesh


def has_triangles(mesh: bpy.types.Mesh, count: int, corners: np.ndarray) -> bool:
    """True when ``mesh`` has ``count`` vertices and only triangles, whose corners are ``corners`` (3 m,) int32 in order.

    As many polygons as a third of its corners means every polygon is a triangle, one after the other.
    """
    if len(mesh.vertices) != count or len(mesh.loops) != len(corners) or 3 * len(mesh.polygons) != len(corners):
        return False
    if not len(corners):
        return True
    held = np.empty(len(corners), np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", held)
    return bool(np.array_equal(held, corners))


def mesh_object(name, mesh, collection, location=(0, 0, 0), rotation=(0, 0, 0), parent=None) -> bpy.types.Object:
    """A mesh object for ``mesh`` (a datablock or a ``(vertices, triangles)`` pair) at a pose (m, radians)."""
    if isinstance(mesh, tuple):
        mesh = mesh_data(name, *mesh)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.rotation_euler = rotation
    collection.objects.link(obj)
    if parent is not None:
        obj.parent = parent
    return obj


def wire_object(name: str, polylines: list[np.ndarray], radius: float, collection, sides: int = 6) -> bpy.types.Object:
    """A curve object of poly splines through ``(k, 3)`` points, bevelled to a round wire of ``radius``.

    Blender turns it into a mesh at evaluation; export reads that mesh through the depsgraph.
    """
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = radius
    curve.bevel_resolution = max(0, (sides - 4) // 2)
    curve.use_fill_caps = True
    for points in polylines:
        spline = curve.splines.new("POLY")
        spline.points.add(len(points) - 1)
        co = np.column_stack([points, np.ones(len(points))]).astype(np.float32)
        spline.points.foreach_set("co", co.ravel())
    obj = bpy.data.objects.new(name, curve)
    collection.objects.link(obj)
    return obj
