"""A scanned frame in the viewport: point-cloud objects coloured by class, ghost points apart.

One object per class and kind of return: ``LiDAR cloud <class>`` for direct returns and
``LiDAR cloud ghosts <class>`` for ghost points (``bounces > 0``: seen through a mirror), drawn
with larger, paler points so they stand out and can be hidden on their own. Each object's colour
is its class colour (Solid mode, Color: Object, draws it in any Blender: per-point colours of
Geometry Nodes points are not drawn by Solid mode in Blender 4.x) and its material, the class's
(``LiDAR class colour NN name``), has that viewport colour and emits the points' ``Col`` in
Material Preview and Rendered mode. Every object carries the point record as attributes
(``semantic``, ``instance``, ``intensity``, ``bounces``), the colour as ``Col`` (linear RGBA),
and sits at the sensor pose, holding the points in the sensor frame.

A ``PointCloud`` datablock where Blender can fill one from Python (5.0 and newer); otherwise a
mesh of vertices only, drawn as points by a Geometry Nodes "Mesh to Points" modifier.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from .bpy_pipeline.blender.compat import set_modifier_input

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


def _class_material(class_id: int, name: str, rgb8) -> bpy.types.Material:
    """The material of one class: viewport colour = the class colour (linear), nodes emit the point's ``Col``."""
    title = f"{MATERIAL} {class_id:02d} {name}"
    material = bpy.data.materials.get(title) or bpy.data.materials.new(title)
    material.diffuse_color = tuple(linear_rgba(np.asarray([rgb8], np.uint8))[0].tolist())
    if material.node_tree is not None and material.node_tree.nodes.get("LiDAR colour"):
        return material
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.name = "LiDAR colour"
    attribute.attribute_name = COLOR
    emission = nodes.new("ShaderNodeEmission")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(attribute.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for i, node in enumerate((attribute, emission, output)):
        node.location = (250 * i, 0)
    return material


def class_materials(color_lut: np.ndarray, names: dict[int, str]) -> list[bpy.types.Material]:
    """One material per class id ``0 .. len(color_lut) - 1`` (index = class id)."""
    return [_class_material(i, names.get(i, f"class {i}"), color_lut[i]) for i in range(len(color_lut))]


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


def cloud_object(name: str, points: np.ndarray, rgba: np.ndarray, radius: float, collection, pose: np.ndarray, material, color) -> bpy.types.Object:
    """One point-cloud object of ``points`` ((p,) POINT_DTYPE, in the frame of ``pose`` (4, 4)) coloured ``rgba`` (p, 4);
    ``material`` its class's, ``color`` (4,) linear RGBA the object's colour."""
    xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float32)
    if native_point_clouds():
        data = bpy.data.pointclouds.new(name)
        data.resize(len(points))
        data.attributes["position"].data.foreach_set("vector", xyz.ravel())
        size = data.attributes.get("radius") or data.attributes.new("radius", "FLOAT", "POINT")
        size.data.foreach_set("value", np.full(len(points), radius, np.float32))
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
    obj.color = tuple(float(c) for c in color)
    collection.objects.link(obj)
    if obj.type == "MESH":
        modifier = obj.modifiers.new(POINTS_GROUP, "NODES")
        modifier.node_group = _points_group()
        set_modifier_input(modifier, "Radius", radius)
        set_modifier_input(modifier, "Material", material)
    return obj


def show_frame(points: np.ndarray, pose: np.ndarray, color_lut: np.ndarray, names: dict[int, str] | None = None, name: str = "LiDAR cloud",
               radius: float = 0.02) -> list[bpy.types.Object]:
    """Replace the clouds in the viewport by this frame's: one object per class of direct returns, then per class of ghosts.

    points : (p,) POINT_DTYPE records; pose : (4, 4) the frame they are in (the sensor pose, or
    the identity for world-frame output); color_lut : (k, 3) uint8 RGB by class id; names : class names by id
    """
    names = names or {}
    collection = _collection()
    materials = class_materials(color_lut, names)
    rgba = linear_rgba(color_lut[points["semantic"]])
    ghost = points["bounces"] > 0
    rgba[ghost, :3] += GHOST_PALENESS * (1.0 - rgba[ghost, :3])
    objects = []
    for kind, mask, size in (("", ~ghost, radius), ("ghosts ", ghost, radius * GHOST_SCALE)):
        for class_id in np.unique(points["semantic"][mask]).tolist():
            keep = mask & (points["semantic"] == class_id)
            label = f"{name} {kind}{names.get(class_id, f'class {class_id}')}"
            objects.append(cloud_object(label, points[keep], rgba[keep], size, collection, pose, materials[class_id], rgba[keep][0]))
    return objects
