"""A scanned frame in the viewport: point-cloud objects coloured by class, ghost points apart.

Direct returns go to one object, ghost points (``bounces > 0``: seen through a mirror) to a
second one drawn with larger, paler points, so they stand out and can be hidden on their own.
Both carry the point record as attributes (``semantic``, ``instance``, ``intensity``,
``bounces``) and the class colour as the colour attribute ``Col`` (linear RGBA), which a
material shows in Material Preview and Rendered mode and Solid mode shows with
Color: Attribute. Each object sits at the sensor pose, holding the points in the sensor frame.

A ``PointCloud`` datablock where Blender can fill one from Python (5.0 and newer); otherwise a
mesh of vertices only, drawn as points by a Geometry Nodes "Mesh to Points" modifier.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from .bpy_pipeline.compat import set_modifier_input

COLLECTION = "LiDAR Clouds"
COLOR = "Col"
MATERIAL = "LiDAR class colour"
POINTS_GROUP = "LiDAR Points"
GHOST_PALENESS = 0.5  # ghost colours move this far from the class colour towards white
GHOST_SCALE = 1.6  # ghost points are drawn this much larger


def native_point_clouds() -> bool:
    """Whether this Blender can fill a ``PointCloud`` from Python (``PointCloud.resize``)."""
    return hasattr(bpy.data, "pointclouds") and "resize" in bpy.types.PointCloud.bl_rna.functions


def linear_rgba(rgb8: np.ndarray) -> np.ndarray:
    """``(n, 3)`` uint8 sRGB -> ``(n, 4)`` float32 linear RGBA (what a colour attribute holds)."""
    c = rgb8.astype(np.float32) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.column_stack([linear, np.ones(len(c), np.float32)]).astype(np.float32)


def _collection() -> bpy.types.Collection:
    """The clouds' collection, emptied (previous clouds and their data removed)."""
    collection = bpy.data.collections.get(COLLECTION)
    if collection is None:
        collection = bpy.data.collections.new(COLLECTION)
        bpy.context.scene.collection.children.link(collection)
    for obj in list(collection.objects):
        data = obj.data
        bpy.data.objects.remove(obj, do_unlink=True)
        if data is not None and data.users == 0:
            (bpy.data.meshes if isinstance(data, bpy.types.Mesh) else bpy.data.pointclouds).remove(data)
    return collection


def _material() -> bpy.types.Material:
    material = bpy.data.materials.get(MATERIAL)
    if material is not None:
        return material
    material = bpy.data.materials.new(MATERIAL)
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = COLOR
    emission = nodes.new("ShaderNodeEmission")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(attribute.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for i, node in enumerate((attribute, emission, output)):
        node.location = (250 * i, 0)
    return material


def _points_group() -> bpy.types.NodeTree:
    """Geometry Nodes: a vertices-only mesh -> points of ``Radius`` (m) with ``Material``."""
    group = bpy.data.node_groups.get(POINTS_GROUP)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(POINTS_GROUP, "GeometryNodeTree")
    if hasattr(group, "is_modifier"):
        group.is_modifier = True
    group.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket(name="Radius", in_out="INPUT", socket_type="NodeSocketFloat").default_value = 0.02
    group.interface.new_socket(name="Material", in_out="INPUT", socket_type="NodeSocketMaterial")
    group.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    group_in, group_out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    to_points = nodes.new("GeometryNodeMeshToPoints")
    set_material = nodes.new("GeometryNodeSetMaterial")
    links.new(group_in.outputs["Geometry"], to_points.inputs["Mesh"])
    links.new(group_in.outputs["Radius"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], set_material.inputs["Geometry"])
    links.new(group_in.outputs["Material"], set_material.inputs["Material"])
    links.new(set_material.outputs["Geometry"], group_out.inputs["Geometry"])
    for i, node in enumerate((group_in, to_points, set_material, group_out)):
        node.location = (220 * i, 0)
    return group


def _attributes(data, points: np.ndarray, rgba: np.ndarray) -> None:
    color = data.attributes.new(COLOR, "FLOAT_COLOR", "POINT")
    color.data.foreach_set("color", rgba.ravel())
    for name, kind, key, values in (
        ("semantic", "INT", "value", points["semantic"].astype(np.int32)),
        ("instance", "INT", "value", np.minimum(points["instance"], np.iinfo(np.int32).max).astype(np.int32)),
        ("intensity", "FLOAT", "value", points["intensity"].astype(np.float32)),
        ("bounces", "INT", "value", points["bounces"].astype(np.int32)),
    ):
        data.attributes.new(name, kind, "POINT").data.foreach_set(key, values)


def cloud_object(name: str, points: np.ndarray, rgba: np.ndarray, radius: float, collection, pose: np.ndarray) -> bpy.types.Object:
    """One point-cloud object of ``points`` ((p,) POINT_DTYPE, in the frame of ``pose`` (4, 4)) coloured ``rgba`` (p, 4)."""
    xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float32)
    material = _material()
    if native_point_clouds():
        data = bpy.data.pointclouds.new(name)
        data.resize(len(points))
        data.attributes["position"].data.foreach_set("vector", xyz.ravel())
        size = data.attributes.get("radius") or data.attributes.new("radius", "FLOAT", "POINT")
        size.data.foreach_set("value", np.full(len(points), radius, np.float32))
        data.materials.append(material)
    else:
        data = bpy.data.meshes.new(name)
        data.vertices.add(len(points))
        data.vertices.foreach_set("co", xyz.ravel())
        data.materials.append(material)
    _attributes(data, points, rgba)
    if isinstance(data, bpy.types.Mesh):  # what Solid mode's Color: Attribute shows
        data.color_attributes.active_color = data.color_attributes[COLOR]
    obj = bpy.data.objects.new(name, data)
    obj.matrix_world = Matrix(np.asarray(pose, np.float64).tolist())
    collection.objects.link(obj)
    if obj.type == "MESH":
        modifier = obj.modifiers.new(POINTS_GROUP, "NODES")
        modifier.node_group = _points_group()
        set_modifier_input(modifier, "Radius", radius)
        set_modifier_input(modifier, "Material", material)
    return obj


def show_frame(points: np.ndarray, pose: np.ndarray, color_lut: np.ndarray, name: str = "LiDAR cloud", radius: float = 0.02) -> list[bpy.types.Object]:
    """Replace the clouds in the viewport by this frame's: ``[direct]`` or ``[direct, ghosts]``.

    points : (p,) POINT_DTYPE records; pose : (4, 4) the frame they are in (the sensor pose, or
    the identity for world-frame output); color_lut : (k, 3) uint8 RGB by class id
    """
    collection = _collection()
    rgba = linear_rgba(color_lut[points["semantic"]])
    ghost = points["bounces"] > 0
    objects = [cloud_object(name, points[~ghost], rgba[~ghost], radius, collection, pose)]
    if ghost.any():
        pale = rgba[ghost].copy()
        pale[:, :3] += GHOST_PALENESS * (1.0 - pale[:, :3])
        objects.append(cloud_object(f"{name} ghosts", points[ghost], pale, radius * GHOST_SCALE, collection, pose))
    return objects
