"""The "Street Scatter" Geometry Nodes group: the street's scattered items instanced on points.

A real node group a Blender user can open and edit. Each scattered kind of the street's dressing
(trunks, crowns and bushes, lamps and bollards, bins, bicycle stands, cones, barriers;
``builders/street/dressing.py``'s :class:`~bpy_pipeline.builders.street.dressing.Scatter`) is one
object whose mesh is a point cloud: one vertex per item where it stands, with point attributes
``yaw`` (float, radians about z), ``scale`` (vector, along the prototype's axes) and ``prototype``
(int). Its "Street Scatter" modifier instances the kind's prototype meshes (the objects of a
collection, picked by ``prototype`` in the order of their names) on those points: Instance on
Points, turned by ``yaw`` and scaled by ``scale``, which places the prototypes exactly as the pure
:meth:`~bpy_pipeline.builders.street.dressing.Scatter.mesh` does.

Inputs a user edits in the modifier panel: ``Density`` (the share of items kept, drawn by
``Seed``), ``Scale`` (every item's scale times it), ``Realize`` (one mesh instead of instances).
Moving, adding or deleting the points in Edit Mode moves, adds or removes items. The export reads
instances as they are (each prototype's mesh once, every placement a matrix), so ``Realize`` is
off by default; labels are the object's ``lidar_*`` tags (the prototypes are untagged, so their
instances take the scatter object's class), and ``Instance`` (the part's instance id) is stored on
every instance as the named attribute ``lidar_instance``, which the export reads first: realized or
joined into another object, the items keep their instance id.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, excluded_collection, new_group, stamp
from ...blender.mesh_objects import mesh_object

GROUP = "Street Scatter"
PROTOTYPES = "LiDAR Street Prototypes"  # the collection (excluded from the view layer) holding each kind's prototypes
VERSION = 2  # 2: the Instance input, stored as lidar_instance; bump when the group changes, so a file holding an older one gets the new one

SCATTER_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Prototypes", "NodeSocketCollection", None, "the kind's prototype meshes, picked by each point's `prototype` attribute (in name order)"),
    ("Density", "NodeSocketFloat", 1.0, "share of the items kept (1: every item; less thins them at random)", 0.0, 1.0),
    ("Seed", "NodeSocketInt", 0, "which items Density keeps"),
    ("Scale", "NodeSocketFloat", 1.0, "every item's scale times this", 0.0, 100.0),
    ("Instance", "NodeSocketInt", 0,
     "instance id of what the group makes, stored as the named attribute lidar_instance the export reads (0: the object's lidar_instance)", 0, 2**31 - 1),
    ("Realize", "NodeSocketBool", False, "realize the instances into one mesh (the export reads instances as they are)"),
]


def scatter_group() -> bpy.types.NodeTree:
    """The "Street Scatter" modifier group (see the module docstring); its inputs are :data:`SCATTER_INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, SCATTER_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get

    def attribute(name: str, data_type: str) -> bpy.types.NodeSocket:
        return b.out(b.node("GeometryNodeInputNamedAttribute", {"Name": name}, data_type=data_type), "Attribute")

    prototypes = b.node("GeometryNodeCollectionInfo", {"Collection": g("Prototypes"), "Separate Children": True, "Reset Children": True},
                        options={"transform_space": "ORIGINAL"})
    # the available (boolean) one
    keep = b.out(b.node("FunctionNodeRandomValue", {"Probability": g("Density"), "Seed": g("Seed")}, data_type="BOOLEAN"), "Value")
    rotation = b.out(b.node("FunctionNodeEulerToRotation", {"Euler": b.combine(0.0, 0.0, attribute("yaw", "FLOAT"))}))
    scale = b.vector_math("SCALE", attribute("scale", "FLOAT_VECTOR"), scale=g("Scale"))
    instances = b.node(
        "GeometryNodeInstanceOnPoints",
        {"Points": g("Geometry"), "Selection": keep, "Instance": b.out(prototypes), "Pick Instance": True,
         "Instance Index": attribute("prototype", "INT"), "Rotation": rotation, "Scale": scale},
    )
    labelled = b.out(b.node("GeometryNodeStoreNamedAttribute", {"Geometry": b.out(instances), "Name": "lidar_instance", "Value": g("Instance")},
                            options={"data_type": "INT", "domain": "INSTANCE"}))
    real = b.node("GeometryNodeRealizeInstances", {"Geometry": labelled})
    b.links.new(b.switch("GEOMETRY", g("Realize"), labelled, b.out(real)), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def prototypes_collection(parent: bpy.types.Collection, name: str = PROTOTYPES) -> bpy.types.Collection:
    """A new, empty collection ``name`` under ``parent``, excluded from the view layer (its objects are
    seen only where a group instances them); a stale one, its objects and its kinds are removed first
    (:func:`~bpy_pipeline.blender.nodes.excluded_collection`)."""
    return excluded_collection(parent, name)


def points_mesh(name: str, scatter) -> bpy.types.Mesh:
    """A mesh of one vertex per item of ``scatter`` at its position, with point attributes ``yaw``, ``scale``, ``prototype``."""
    mesh = bpy.data.meshes.new(name)
    positions = np.ascontiguousarray(scatter.positions, np.float32)
    mesh.vertices.add(len(positions))
    mesh.vertices.foreach_set("co", positions.reshape(-1))
    mesh.attributes.new("yaw", "FLOAT", "POINT").data.foreach_set("value", np.ascontiguousarray(scatter.yaw, np.float32))
    mesh.attributes.new("scale", "FLOAT_VECTOR", "POINT").data.foreach_set("vector", np.ascontiguousarray(scatter.scale, np.float32).reshape(-1))
    mesh.attributes.new("prototype", "INT", "POINT").data.foreach_set("value", np.ascontiguousarray(scatter.prototype, np.int32))
    mesh.update()
    return mesh


def scatter_object(name: str, scatter, collection: bpy.types.Collection, prototypes: bpy.types.Collection, instance: int = 0) -> bpy.types.Object:
    """The object of one scattered kind: ``scatter``'s items as points, its prototypes as the objects of a new
    collection ``"<name> prototypes"`` under ``prototypes``, and a live "Street Scatter" modifier instancing them."""
    kinds = bpy.data.collections.new(f"{name} prototypes")
    prototypes.children.link(kinds)
    for k, mesh in enumerate(scatter.prototypes):
        mesh_object(f"{name}.prototype.{k:02d}", mesh, kinds)  # zero-padded: Collection Info orders children by name
    obj = bpy.data.objects.new(name, points_mesh(name, scatter))
    collection.objects.link(obj)
    add_group_modifier(obj, scatter_group(), {"Prototypes": kinds, "Instance": int(instance)})
    return obj
