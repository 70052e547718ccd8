"""The "Street Facade" Geometry Nodes group: each building swept from its facade line along the plot.

A real node group a Blender user can open and edit. Every ``street_building_<k>`` object is a mesh of
one edge: the building's facade line along its plot's frontage (``dressing.Dressing.fronts``; at the
box's bottom, under the ground, the building to the line's left, away from the road). Its "Street
Facade" modifier sweeps a ``Depth`` x ``Height`` rectangle along that line (Mesh to Curve, normals Z
up, Curve to Mesh with caps filled): from the line ``Depth`` metres to its left and ``Height`` metres
up, the pure building box of :func:`~bpy_pipeline.builders.street.dressing.dress` (same 8 vertices
within float32 rounding; a quad where the box has two triangles). A user changes a building's height
or depth in the modifier panel, or moves its line's ends in Edit Mode, and rescans.

Labels: the objects keep their ``lidar_*`` tags (class ``building``, one instance each); ``Instance``
is stored on every face as the named attribute ``lidar_instance`` (0: the object's).
"""

from __future__ import annotations

import bpy
import numpy as np

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp

GROUP = "Street Facade"
VERSION = 1  # bump when the group changes, so a file holding an older one gets the new one

FACADE_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Depth", "NodeSocketFloat", 12.0, "m, the building from its facade line back (to the line's left)", 0.1, 1000.0),
    ("Height", "NodeSocketFloat", 10.0, "m, the building's top above its facade line (the line lies 0.3 m under the lowest ground)", 0.1, 1000.0),
    ("Instance", "NodeSocketInt", 0,
     "instance id of what the group makes, stored as the named attribute lidar_instance the export reads (0: the object's lidar_instance)", 0, 2**31 - 1),
]


def facade_group() -> bpy.types.NodeTree:
    """The "Street Facade" modifier group (see the module docstring); its inputs are :data:`FACADE_INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, FACADE_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get
    lines = b.out(b.node("GeometryNodeMeshToCurve", {"Mesh": g("Geometry")}))
    curves = b.out(b.node("GeometryNodeSetCurveNormal", {"Curve": lines}, options={"mode": "Z_UP"}))
    rectangle = b.out(b.node("GeometryNodeCurvePrimitiveQuadrilateral", {"Width": g("Depth"), "Height": g("Height")}, options={"mode": "RECTANGLE"}))
    # Curve to Mesh with Z-up normals turns the profile's x to the line's right and its y down
    offset = b.combine(b.math("MULTIPLY", g("Depth"), -0.5), b.math("MULTIPLY", g("Height"), -0.5), 0.0)
    profile = b.out(b.node("GeometryNodeTransform", {"Geometry": rectangle, "Translation": offset}))
    swept = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": curves, "Profile Curve": profile, "Fill Caps": True}))
    labelled = b.node("GeometryNodeStoreNamedAttribute", {"Geometry": swept, "Name": "lidar_instance", "Value": g("Instance")},
                      options={"data_type": "INT", "domain": "FACE"})
    b.links.new(b.out(labelled), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def facade_object(name: str, front, collection: bpy.types.Collection, instance: int = 0) -> bpy.types.Object:
    """A mesh object ``name`` of one edge, the facade line of ``front`` (``(start (3,), end (3,), depth, height)``, m),
    its "Street Facade" modifier sweeping the building along it."""
    start, end, depth, height = front
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.stack([start, end]).tolist(), [(0, 1)], [])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    add_group_modifier(obj, facade_group(), {"Depth": float(depth), "Height": float(height), "Instance": int(instance)})
    return obj
