"""The "Street Planting" Geometry Nodes group: trees distributed over the street's yards.

A real node group a Blender user can open and edit. The ``street_yard_trees`` object is the ground of
the yards and open plots (``dressing.Yards``: each 1 m inside its plot, at the terrain's height;
:func:`~bpy_pipeline.builders.street.dressing.yard_ground`). Its "Street Planting" modifier
distributes points over that ground (Distribute Points on Faces, Poisson disk: ``Density`` trees per
100 m^2, none closer than ``Clearance``, drawn by ``Seed``; none within ``Clearance`` of ``Keep Clear Of``'s
geometry, the layout's trunks) and stands a tree on each: a trunk (the
``Trunk`` object, a unit cylinder, from 0.2 m under the ground into the crown's middle, radius
max(0.08 m, 4 % of the height)) and a round leaf-card crown (one of the ``Crowns`` collection, turned at
random), the tree ``Height Min``..``Height Max`` tall with a crown radius ``Crown Radius Min``..``Max``
and the round crown's height: min(2.2 radius, 0.8 height, height - 1.5 m), as
:func:`~bpy_pipeline.builders.street.vegetation.crown_size` gives it. The ground itself is not output.

``scene.yard_trees`` (default 0: the group plants nothing, and the street is the one the layout's
generator dresses) sets ``Density``; a user raises it in the modifier panel and rescans. The trees
are Blender's own draw (Distribute Points on Faces' generator), so no pure function reproduces them
point for point; the tests check what the inputs promise: count, spacing, where they stand, sizes.

Labels: the trunk and crown prototypes carry their ``lidar_*`` tags (``trunk`` and ``vegetation``,
one instance id each), which their instances take (``blender/export.py``).
"""

from __future__ import annotations

import math

import bpy

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp
from ...blender.mesh_objects import mesh_object, tag
from .dressing import REFLECTIVITY, yard_ground

GROUP = "Street Planting"
VERSION = 1  # bump when the group changes, so a file holding an older one gets the new one
OBJECT = "street_yard_trees"

PLANTING_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Trunk", "NodeSocketObject", None, "the trunk prototype: a cylinder of radius 1 from z 0 to 1"),
    ("Crowns", "NodeSocketCollection", None, "crown prototypes of radius 1 and height 1 centred on their origin, picked at random"),
    ("Density", "NodeSocketFloat", 0.0, "trees per 100 m^2 of the ground before Clearance thins them (0: none)", 0.0, 100.0),
    ("Seed", "NodeSocketInt", 0, "which trees: their places, sizes, turns and crowns"),
    ("Clearance", "NodeSocketFloat", 4.0, "m, the least distance between two trees, and from the trees of Keep Clear Of", 0.5, 50.0),
    ("Keep Clear Of", "NodeSocketObject", None, "an object whose evaluated geometry (realized) no tree stands within Clearance of (the layout's trunks)"),
    ("Height Min", "NodeSocketFloat", 4.0, "m, the shortest tree", 2.0, 60.0),
    ("Height Max", "NodeSocketFloat", 14.0, "m, the tallest tree", 2.0, 60.0),
    ("Crown Radius Min", "NodeSocketFloat", 1.5, "m", 0.1, 20.0),
    ("Crown Radius Max", "NodeSocketFloat", 3.5, "m", 0.1, 20.0),
]


def planting_group() -> bpy.types.NodeTree:
    """The "Street Planting" modifier group (see the module docstring); its inputs are :data:`PLANTING_INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, PLANTING_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get

    def uniform(low, high, offset: int) -> bpy.types.NodeSocket:
        """A per-point random float in [low, high], the ``offset``-th draw of ``Seed``."""
        seed = b.math("ADD", g("Seed"), float(offset))
        return b.out(b.node("FunctionNodeRandomValue", {"Min": low, "Max": high, "Seed": seed}, data_type="FLOAT"), "Value")

    distribute = b.node("GeometryNodeDistributePointsOnFaces",
                        {"Mesh": g("Geometry"), "Distance Min": g("Clearance"), "Density Max": b.math("MULTIPLY", g("Density"), 0.01), "Seed": g("Seed")},
                        options={"distribute_method": "POISSON"})
    others = b.out(b.node("GeometryNodeRealizeInstances", {"Geometry": b.out(b.node("GeometryNodeObjectInfo", {"Object": g("Keep Clear Of")},
                                                                                        options={"transform_space": "RELATIVE"}), "Geometry")}))
    near = b.out(b.node("GeometryNodeProximity", {"Geometry": others}, options={"target_element": "POINTS"}), "Distance")
    any_other = b.compare("GREATER_THAN", b.out(b.node("GeometryNodeAttributeDomainSize", {"Geometry": others}, options={"component": "MESH"}), "Point Count"),
                          0, data_type="INT")
    # no geometry: nothing near
    too_near = b.out(b.node("FunctionNodeBooleanMath", {0: any_other, 1: b.compare("LESS_THAN", near, g("Clearance"))}, operation="AND"))
    points = b.out(b.node("GeometryNodeDeleteGeometry", {"Geometry": b.out(distribute, "Points"), "Selection": too_near},
                          options={"domain": "POINT"}))
    height = uniform(g("Height Min"), g("Height Max"), 1)
    radius = uniform(g("Crown Radius Min"), g("Crown Radius Max"), 2)
    yaw = uniform(0.0, 2 * math.pi, 3)
    pick = b.out(b.node("FunctionNodeRandomValue", {"Min": 0, "Max": 1 << 20, "Seed": b.math("ADD", g("Seed"), 4.0)}, data_type="INT"), "Value")
    crown_height = b.math("MINIMUM", b.math("MINIMUM", b.math("MULTIPLY", radius, 2.2), b.math("MULTIPLY", height, 0.8)), b.math("SUBTRACT", height, 1.5))
    centre = b.math("SUBTRACT", height, b.math("MULTIPLY", crown_height, 0.5))  # the crown's centre above the ground
    trunk_radius = b.math("MAXIMUM", b.math("MULTIPLY", height, 0.04), 0.08)

    crowns = b.out(b.node("GeometryNodeCollectionInfo", {"Collection": g("Crowns"), "Separate Children": True, "Reset Children": True},
                          options={"transform_space": "ORIGINAL"}))
    raised = b.out(b.node("GeometryNodeSetPosition", {"Geometry": points, "Offset": b.combine(0.0, 0.0, centre)}))
    crown_instances = b.node("GeometryNodeInstanceOnPoints", {
        "Points": raised, "Instance": crowns, "Pick Instance": True, "Instance Index": pick,
        "Rotation": b.out(b.node("FunctionNodeEulerToRotation", {"Euler": b.combine(0.0, 0.0, yaw)})),
        "Scale": b.combine(radius, radius, crown_height)})
    trunk = b.node("GeometryNodeObjectInfo", {"Object": g("Trunk"), "As Instance": True}, options={"transform_space": "ORIGINAL"})
    sunk = b.out(b.node("GeometryNodeSetPosition", {"Geometry": points, "Offset": b.combine(0.0, 0.0, -0.2)}))
    trunk_instances = b.node("GeometryNodeInstanceOnPoints", {
        "Points": sunk, "Instance": b.out(trunk, "Geometry"), "Scale": b.combine(trunk_radius, trunk_radius, b.math("ADD", centre, 0.2))})
    joined = b.node("GeometryNodeJoinGeometry")
    b.links.new(b.out(trunk_instances), b.socket(joined.inputs, "Geometry"))
    b.links.new(b.out(crown_instances), b.socket(joined.inputs, "Geometry"))
    b.links.new(b.out(joined), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def planting_object(yards, params, collection: bpy.types.Collection, prototypes: bpy.types.Collection, instance: int,
                    keep_clear_of: bpy.types.Object | None = None) -> bpy.types.Object:
    """The ``street_yard_trees`` object: the ground of ``yards`` (``dressing.Yards``) with a live "Street Planting"
    modifier set from ``params`` (``StreetScene``: ``yard_trees``, ``yard_tree_clearance``, ``yard_tree_height``,
    ``layout_seed``); its trunk (class ``trunk``, instance id ``instance``) and crowns (``vegetation``, ``instance + 1``)
    are prototypes in a new collection under ``prototypes``; the object itself is tagged ``terrain`` (``instance + 2``),
    which its ground would take with the modifier turned off. No tree stands within the clearance of ``keep_clear_of``
    (the layout's trunks). Reflectivities: ``dressing.REFLECTIVITY``."""
    kinds = bpy.data.collections.new(f"{OBJECT} prototypes")
    prototypes.children.link(kinds)
    trunk = tag(mesh_object(f"{OBJECT}.trunk", yards.trunk, kinds), "trunk", "diffuse", REFLECTIVITY["trunk"], instance)
    crowns = bpy.data.collections.new(f"{OBJECT} crowns")
    kinds.children.link(crowns)
    for k, mesh in enumerate(yards.crowns):
        tag(mesh_object(f"{OBJECT}.crown.{k:02d}", mesh, crowns), "vegetation", "diffuse", REFLECTIVITY["vegetation"], instance + 1)
    obj = tag(mesh_object(OBJECT, yard_ground(yards.terrain, yards.rects), collection), "terrain", "diffuse", REFLECTIVITY["terrain"], instance + 2)
    low, high = params.yard_tree_height
    add_group_modifier(obj, planting_group(), {
        "Trunk": trunk, "Crowns": crowns, "Keep Clear Of": keep_clear_of, "Density": float(params.yard_trees), "Seed": int(params.layout_seed),
        "Clearance": float(params.yard_tree_clearance), "Height Min": float(low), "Height Max": float(high)})
    return obj

