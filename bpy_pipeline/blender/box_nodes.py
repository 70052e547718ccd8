"""Boxes and wedges placed by Geometry Nodes: the prototypes and node helpers the parking and hall groups share.

A box is the pure :func:`~bpy_pipeline.geometry.primitives.box` of size 1 (corners at +-0.5, the
same twelve triangles) instanced at its centre and scaled to its size; a wedge is the parking
ramp's unit prism (``geometry.indoor._prism_along_y`` of the unit profile) scaled
from its corner. So a group's boxes have the pure meshes' triangles, in the same order.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..geometry import primitives
from ..geometry.indoor import _prism_along_y
from .nodes import GroupBuilder, excluded_collection
from .mesh_objects import mesh_object

PROTOTYPES = "LiDAR Box Prototypes"
BOX = "box prototype"
WEDGE = "wedge prototype"
UNIT_WEDGE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])  # (x, z): the ramp's profile, rising along +x


def prototypes(parent: bpy.types.Collection) -> dict:
    """The unit box and wedge as objects of an excluded :data:`PROTOTYPES` collection under ``parent``: ``{"box": obj, "wedge": obj}``."""
    collection = excluded_collection(parent, PROTOTYPES)
    box = mesh_object(BOX, primitives.box(1.0, 1.0, 1.0), collection)
    wedge = mesh_object(WEDGE, _prism_along_y(UNIT_WEDGE, 0.0, 1.0), collection)
    return {"box": box, "wedge": wedge}


def place(b: GroupBuilder, count, position, scale, prototype, selection=None) -> bpy.types.NodeSocket:
    """``count`` instances of the object ``prototype`` at ``position`` scaled by ``scale`` (fields of the point Index);
    points where ``selection`` holds are dropped first."""
    points = b.out(b.node("GeometryNodePoints", {"Count": count, "Position": position}))
    if selection is not None:
        points = b.out(b.node("GeometryNodeDeleteGeometry", {"Geometry": points, "Selection": selection}, options={"domain": "POINT", "mode": "ALL"}))
    instance = b.out(b.node("GeometryNodeObjectInfo", {"Object": prototype, "As Instance": True}, options={"transform_space": "ORIGINAL"}), "Geometry")
    return b.out(b.node("GeometryNodeInstanceOnPoints", {"Points": points, "Instance": instance, "Scale": scale}))


def index(b: GroupBuilder) -> bpy.types.NodeSocket:
    return b.out(b.node("GeometryNodeInputIndex"))


def pick(b: GroupBuilder, part, choices: list) -> bpy.types.NodeSocket:
    """The geometry of ``choices[k - 1]`` where the integer ``part`` is k (nothing for other values)."""
    out = None
    for k, geometry in enumerate(choices, start=1):
        empty = out if out is not None else b.out(b.node("GeometryNodeJoinGeometry"))
        out = b.switch("GEOMETRY", b.compare("EQUAL", part, k, data_type="INT"), empty, geometry)
    return out


def select(b: GroupBuilder, condition, false, true) -> bpy.types.NodeSocket:
    """A float: ``true`` where ``condition`` holds, else ``false``."""
    return b.switch("FLOAT", condition, false, true)


def label(b: GroupBuilder, geometry, instance) -> bpy.types.NodeSocket:
    """``geometry``'s instances with the named attribute ``lidar_instance`` (INT) set to ``instance``: the export
    labels each instance by it (and, realized, each face: Realize Instances carries it to the faces)."""
    return b.out(b.node("GeometryNodeStoreNamedAttribute", {"Geometry": geometry, "Name": "lidar_instance", "Value": instance},
                        options={"data_type": "INT", "domain": "INSTANCE"}))


FINISH_INPUTS = [  # the interface rows of what :func:`finish` reads, for a group's INPUTS
    ("Instance", "NodeSocketInt", 0,
     "instance id of what the group makes, stored as the named attribute lidar_instance the export reads (0: the object's lidar_instance)", 0, 2**31 - 1),
    ("Realize", "NodeSocketBool", False, "realize the instances into one mesh (the export reads instances as they are)"),
]


def finish(b: GroupBuilder, geometry, realize, instance=None) -> None:
    """Link ``geometry`` (instances; labelled ``instance`` when given) to the group's output, realized when the bool ``realize`` holds."""
    if instance is not None:
        geometry = label(b, geometry, instance)
    real = b.out(b.node("GeometryNodeRealizeInstances", {"Geometry": geometry}))
    b.links.new(b.switch("GEOMETRY", realize, geometry, real), b.socket(b.outputs.inputs, "Geometry"))
