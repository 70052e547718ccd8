"""The railway's "Railway Supports" Geometry Nodes group: the masts instanced at the track's stations (bpy).

Identical masts (same side, kind, height, base and lateral offset: the same mesh with the brackets of
its feeder and earth wire, in its support's level frame) are one prototype object (``mast.<side>.<kind>.<n>``,
in the excluded collection :data:`PROTOTYPES`, never scanned itself). A points object
``supports.mast.<side>.<n>`` holds one vertex per support that carries that mast: its position is the
origin of the support's level frame (:attr:`~bpy_pipeline.builders.railway.layout.Support.frame`, from the pure
layout) and its point attributes are

- ``rotation`` (FLOAT_VECTOR): the frame's Euler angles (0, 0, yaw), rad; the frames are level;
- ``lidar_part`` (INT): k + 1 for the k-th name of the object's ``lidar_parts`` list
  (``support.<k>.mast.<side>``, today's object names).

The group instances the prototype's geometry (``Prototype``) on those points with their rotations and
realizes the instances: the point attributes become attributes of the realized geometry, so every
realized vertex carries its support's ``lidar_part``, and the export labels each support's faces as
the row named after it, with the object's class and an automatic instance id by that name: the same
rows, classes and instance ids as one object per mast gave. Moving a point in Edit Mode moves its
mast; editing the prototype's mesh edits every mast of that kind.

Cantilevers, registration and steady arms, the tracks' insulators (their lengths follow each support's
stagger and offsets), the feeders' insulators, gantries and anchors stay one object each.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, excluded_collection, new_group, stamp

SUPPORTS = "Railway Supports"
VERSION = 1  # bump when the group changes, so a file holding an older one gets the new one
PROTOTYPES = "railway_prototypes"  # the excluded collection of the prototype meshes
PART_ATTRIBUTE = "lidar_part"  # the export's PART_ATTRIBUTE
ROTATION = "rotation"

SUPPORT_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Prototype", "NodeSocketObject", None, "the mesh instanced at every point (in its support's level frame: x along the track, y left, z up)"),
]


def supports_group() -> bpy.types.NodeTree:
    """The "Railway Supports" modifier group (see the module docstring); inputs :data:`SUPPORT_INPUTS`."""
    group = current_group(SUPPORTS, VERSION)
    if group is not None:
        return group
    group = new_group(SUPPORTS, SUPPORT_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    prototype = b.node("GeometryNodeObjectInfo", {"Object": b.get("Prototype")}, transform_space="ORIGINAL")
    euler = b.out(b.node("GeometryNodeInputNamedAttribute", {"Name": ROTATION}, options={"data_type": "FLOAT_VECTOR"}), "Attribute")
    rotation = b.out(b.node("FunctionNodeEulerToRotation", {"Euler": euler}))
    instances = b.node("GeometryNodeInstanceOnPoints", {"Points": b.get("Geometry"), "Instance": b.out(prototype, "Geometry"), "Rotation": rotation})
    real = b.node("GeometryNodeRealizeInstances", {"Geometry": b.out(instances)})
    b.links.new(b.out(real), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def prototype_object(name: str, mesh: bpy.types.Mesh, parent: bpy.types.Collection) -> bpy.types.Object:
    """A prototype object of ``mesh`` in the excluded :data:`PROTOTYPES` collection under ``parent`` (made when missing)."""
    collection = bpy.data.collections.get(PROTOTYPES)
    if collection is None or collection.name not in parent.children:
        collection = excluded_collection(parent, PROTOTYPES)
    obj = bpy.data.objects.new(name, mesh)
    obj.hide_render = True  # seen only where the group instances it
    collection.objects.link(obj)
    return obj


def supports_object(name: str, prototype: bpy.types.Object, frames: np.ndarray, parts: list[str], collection) -> bpy.types.Object:
    """A points object at the origins of ``frames`` ((n, 4, 4) level frames, m) run by "Railway Supports" on ``prototype``;
    point k carries ``rotation`` (the frame's yaw) and ``lidar_part`` k + 1, naming ``parts[k]`` (its ``lidar_parts``)."""
    frames = np.asarray(frames, float).reshape(-1, 4, 4)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(frames))
    mesh.vertices.foreach_set("co", frames[:, :3, 3].astype(np.float32).ravel())
    yaw = np.arctan2(frames[:, 1, 0], frames[:, 0, 0])
    euler = np.column_stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw])
    mesh.attributes.new(ROTATION, "FLOAT_VECTOR", "POINT").data.foreach_set("vector", euler.astype(np.float32).ravel())
    mesh.attributes.new(PART_ATTRIBUTE, "INT", "POINT").data.foreach_set("value", np.arange(1, len(frames) + 1, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    obj["lidar_parts"] = list(parts)
    add_group_modifier(obj, supports_group(), {"Prototype": prototype})
    return obj


def support_frames(obj: bpy.types.Object) -> np.ndarray:
    """``(n, 4, 4)`` the level frames a supports object's points stand for (position and ``rotation`` yaw), float64."""
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    euler = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes[ROTATION].data.foreach_get("vector", euler)
    yaw = euler.reshape(-1, 3)[:, 2].astype(float)
    out = np.zeros((len(yaw), 4, 4))
    out[:, 0, 0], out[:, 1, 0], out[:, 0, 1], out[:, 1, 1] = np.cos(yaw), np.sin(yaw), -np.sin(yaw), np.cos(yaw)
    out[:, 2, 2] = out[:, 3, 3] = 1.0
    out[:, :3, 3] = co.reshape(-1, 3)
    return out


def realized_parts(obj: bpy.types.Object) -> dict[str, np.ndarray]:
    """``{part name: (n, 3) world vertices (float64 of Blender's float32)}`` of a supports object's evaluated geometry."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        attribute = mesh.attributes[PART_ATTRIBUTE]
        values = np.empty(len(attribute.data), np.int32)
        attribute.data.foreach_get("value", values)
        if attribute.domain != "POINT":
            raise ValueError(f"{obj.name}: {PART_ATTRIBUTE} on {attribute.domain}, expected POINT")
    finally:
        evaluated.to_mesh_clear()
    matrix = np.array(obj.matrix_world, float)
    world = co.reshape(-1, 3).astype(float) @ matrix[:3, :3].T + matrix[:3, 3]
    names = list(obj["lidar_parts"])
    return {names[v - 1]: world[values == v] for v in np.unique(values).tolist() if v > 0}
