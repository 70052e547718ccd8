"""The "Street Road" Geometry Nodes group: carriageway, kerbs and sidewalks swept along the road centre curves.

A real node group a Blender user can open and edit. The street's ``street_road``, ``street_kerbs``
and ``street_sidewalks`` objects are meshes whose edges are the roads' centre lines (z = 0, one
edge per road, made curves by Mesh to Curve: the first runs through the junction; with ``Junction`` 0
(four arms) every further one crosses it at its middle, with 1 (a T-junction) every further one is an arm
from the junction's centre out, with 2 (a straight street) there is none); each runs the group, which builds
what ``Part`` asks for as the pure :func:`~bpy_pipeline.builders.street.layout.road_meshes` does:

- the cross-section from the inputs: half road ``R = Lanes x Lane Width + Parking Width``, the kerb
  a ``Kerb Width`` x ``Kerb Height`` rectangle at ``|across|`` from ``R``, the sidewalk a ``Sidewalk
  Width`` x ``Kerb Height`` rectangle beyond it (both sides of the centre line);
- each road cut into its two arms at its middle, the through road's by a gap of ``0`` (the
  carriageway), ``R`` (kerbs) or ``R + Kerb Width`` (sidewalks), a crossing road's by ``R``,
  ``R + Kerb Width`` and ``R + Kerb Width + Sidewalk Width`` (Trim Curve by length);
- the profile swept along the arms (Curve to Mesh, normals Z up, caps filled): a line ``2 R`` wide
  for the carriageway, the two rectangles for the kerbs and the sidewalks;
- a T-junction's arm trimmed from its start by the same gaps; the through road's kerb and sidewalk are
  cut only on the arm's side (the side its points' mean lies on), and run whole on the other; a
  straight street's run whole on both.

Same surfaces as the pure function: the same vertices (within float32 rounding at their
coordinates), quads where it has two triangles (the export splits them on the same plane).
Moving a centre line's points in Edit Mode moves the road; changing ``Lane Width`` widens it.

Labels: the objects keep their ``lidar_*`` tags; ``Instance`` is stored on every face as the named
attribute ``lidar_instance`` (0: the object's), which the export reads first.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp
from .layout import FOUR_ARMS, JUNCTIONS, Junction, junction

GROUP = "Street Road"
VERSION = 2  # bump when the group changes, so a file holding an older one gets the new one
PARTS = ("road", "kerbs", "sidewalks")  # the Part input's values, in order

ROAD_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Part", "NodeSocketInt", 0, "what to build: 0 the carriageway, 1 the kerbs, 2 the sidewalks", 0, 2),
    ("Junction", "NodeSocketInt", 0, "0 four arms (every further edge crosses the first), 1 a T-junction (every further edge an arm from the centre out), "
     "2 a straight road (the first edge alone)", 0, 2),
    ("Lanes", "NodeSocketInt", 1, "drive lanes per direction", 1, 16),
    ("Lane Width", "NodeSocketFloat", 3.5, "m, one drive lane", 0.5, 10.0),
    ("Parking Width", "NodeSocketFloat", 2.2, "m, the parking strip by each kerb (0: none)", 0.0, 10.0),
    ("Kerb Width", "NodeSocketFloat", 0.15, "m, the kerb across", 0.01, 2.0),
    ("Kerb Height", "NodeSocketFloat", 0.15, "m, the kerb's and the sidewalk's top above the road", 0.0, 1.0),
    ("Sidewalk Width", "NodeSocketFloat", 3.5, "m, the sidewalk beyond the kerb", 0.1, 50.0),
    ("Instance", "NodeSocketInt", 0,
     "instance id of what the group makes, stored as the named attribute lidar_instance the export reads (0: the object's lidar_instance)", 0, 2**31 - 1),
]


def _arms(b: GroupBuilder, curve, gap) -> bpy.types.NodeSocket:
    """``curve``'s splines without ``gap`` metres either side of their middles: two arms each (Trim Curve by length)."""
    length = b.out(b.node("GeometryNodeSplineLength"), "Length")
    half = b.math("MULTIPLY", length, 0.5)
    first = b.node("GeometryNodeTrimCurve", {"Curve": curve, "Start": 0.0, "End": b.math("SUBTRACT", half, gap)}, options={"mode": "LENGTH"})
    second = b.node("GeometryNodeTrimCurve", {"Curve": curve, "Start": b.math("ADD", half, gap), "End": length}, options={"mode": "LENGTH"})
    return _join(b, b.out(first), b.out(second))


def _from(b: GroupBuilder, curve, gap) -> bpy.types.NodeSocket:
    """``curve``'s splines without their first ``gap`` metres (a T-junction's arm beyond the road it meets)."""
    length = b.out(b.node("GeometryNodeSplineLength"), "Length")
    return b.out(b.node("GeometryNodeTrimCurve", {"Curve": curve, "Start": gap, "End": length}, options={"mode": "LENGTH"}))


def _sides(b: GroupBuilder, geometry, side) -> tuple[bpy.types.NodeSocket, bpy.types.NodeSocket]:
    """``geometry``'s faces on the ``side`` (a number whose sign is the side's, along y) and those on the other side."""
    y = b.out(b.node("ShaderNodeSeparateXYZ", {0: b.out(b.node("GeometryNodeInputPosition"))}), "Y")
    split = b.node("GeometryNodeSeparateGeometry", {"Geometry": geometry, "Selection": b.compare("GREATER_THAN", b.math("MULTIPLY", y, side), 0.0)},
                   options={"domain": "FACE"})
    return b.out(split, "Selection"), b.out(split, "Inverted")


def _join(b: GroupBuilder, *geometries) -> bpy.types.NodeSocket:
    node = b.node("GeometryNodeJoinGeometry")
    for geometry in geometries:
        b.links.new(geometry, node.inputs[0])
    return b.out(node)


def _rectangles(b: GroupBuilder, inner, width, height) -> bpy.types.NodeSocket:
    """Two ``width`` x ``height`` rectangles (the profile's x across, y down) from ``|x| = inner`` outwards, on z = 0 .. height."""
    rectangle = b.out(b.node("GeometryNodeCurvePrimitiveQuadrilateral", {"Width": width, "Height": height}, options={"mode": "RECTANGLE"}))
    centre = b.math("ADD", inner, b.math("MULTIPLY", width, 0.5))
    lift = b.math("MULTIPLY", height, -0.5)  # Curve to Mesh with Z-up normals turns the profile's y down
    sides = [b.out(b.node("GeometryNodeTransform", {"Geometry": rectangle, "Translation": b.combine(b.math("MULTIPLY", centre, sign), lift, 0.0)}))
             for sign in (-1.0, 1.0)]
    return _join(b, *sides)


def road_group() -> bpy.types.NodeTree:
    """The "Street Road" modifier group (see the module docstring); its inputs are :data:`ROAD_INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, ROAD_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get
    half_road = b.math("ADD", b.math("MULTIPLY", g("Lanes"), g("Lane Width")), g("Parking Width"))
    inner = b.math("ADD", half_road, g("Kerb Width"))
    outer = b.math("ADD", inner, g("Sidewalk Width"))

    lines = b.out(b.node("GeometryNodeMeshToCurve", {"Mesh": g("Geometry")}))
    curves = b.out(b.node("GeometryNodeSetCurveNormal", {"Curve": lines}, options={"mode": "Z_UP"}))
    first = b.compare("EQUAL", b.out(b.node("GeometryNodeInputIndex")), 0, data_type="INT")
    split = b.node("GeometryNodeSeparateGeometry", {"Geometry": curves, "Selection": first}, options={"domain": "CURVE"})
    through, crossing = b.out(split, "Selection"), b.out(split, "Inverted")

    def sweep(curve, profile):
        return b.out(b.node("GeometryNodeCurveToMesh", {"Curve": curve, "Profile Curve": profile, "Fill Caps": True}))

    line = b.out(b.node("GeometryNodeCurvePrimitiveLine",
                        {"Start": b.combine(b.math("MULTIPLY", half_road, -1.0), 0.0, 0.0), "End": b.combine(half_road, 0.0, 0.0)}))
    kerb = _rectangles(b, half_road, g("Kerb Width"), g("Kerb Height"))
    walk = _rectangles(b, inner, g("Sidewalk Width"), g("Kerb Height"))
    # four arms: the crossing road cut at its middle
    cross = (_join(b, sweep(through, line), sweep(_arms(b, crossing, half_road), line)),
             _join(b, sweep(_arms(b, through, half_road), kerb), sweep(_arms(b, crossing, inner), kerb)),
             _join(b, sweep(_arms(b, through, inner), walk), sweep(_arms(b, crossing, outer), walk)))
    # a T-junction: the arm from the centre out; the through road's kerb and sidewalk cut on the arm's side only
    y = b.out(b.node("ShaderNodeSeparateXYZ", {0: b.out(b.node("GeometryNodeInputPosition"))}), "Y")
    side = b.out(b.node("GeometryNodeAttributeStatistic", {"Geometry": crossing, "Attribute": y}, options={"data_type": "FLOAT", "domain": "POINT"}), "Mean")
    t_junction = [_join(b, sweep(through, line), sweep(_from(b, crossing, half_road), line))]
    for profile, through_gap, arm_gap in ((kerb, half_road, inner), (walk, inner, outer)):
        cut, _ = _sides(b, sweep(_arms(b, through, through_gap), profile), side)
        _, whole = _sides(b, sweep(through, profile), side)
        t_junction.append(_join(b, cut, whole, sweep(_from(b, crossing, arm_gap), profile)))
    # a straight road: the through road alone, whole
    straight = (sweep(through, line), sweep(through, kerb), sweep(through, walk))

    chosen = b.node("GeometryNodeIndexSwitch", {"Index": g("Part")}, data_type="GEOMETRY")
    chosen.index_switch_items.new()  # two items by default
    for k, geometries in enumerate(zip(cross, t_junction, straight)):
        by_junction = b.node("GeometryNodeIndexSwitch", {"Index": g("Junction")}, data_type="GEOMETRY")
        by_junction.index_switch_items.new()
        for kind, geometry in enumerate(geometries):
            b.links.new(geometry, by_junction.inputs[kind + 1])
        b.links.new(b.out(by_junction), chosen.inputs[k + 1])
    labelled = b.node("GeometryNodeStoreNamedAttribute", {"Geometry": b.out(chosen), "Name": "lidar_instance", "Value": g("Instance")},
                      options={"data_type": "INT", "domain": "FACE"})
    b.links.new(b.out(labelled), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def centre_lines(arm_length: float, j: Junction = FOUR_ARMS) -> list[np.ndarray]:
    """The roads' centre lines ((2, 3) m each) of junction ``j``: the road along x (through), then the road along y
    (crossing) with four arms, its arm from the centre out at a T-junction, nothing more on a straight street."""
    a = float(arm_length)
    through = np.array([[-a, 0.0, 0.0], [a, 0.0, 0.0]])
    if len(j.arms) == 2:
        return [through, np.array([[0.0, -a, 0.0], [0.0, a, 0.0]])]
    return [through] + [np.array([[0.0, 0.0, 0.0], [0.0, sign * a, 0.0]]) for sign in j.arms]


# input -> StreetScene field (:func:`road_inputs`)
FIELDS = {"Lanes": "lanes_per_direction", "Lane Width": "lane_width", "Parking Width": "parking_width", "Kerb Width": "kerb_width",
          "Kerb Height": "kerb_height", "Sidewalk Width": "sidewalk_width"}


def road_inputs(params) -> dict:
    """The group's inputs for :class:`~bpy_pipeline.builders.street.StreetScene` ``params`` (Part and Instance aside)."""
    return {name: (int if name == "Lanes" else float)(getattr(params, key)) for name, key in FIELDS.items()}


def road_object(name: str, part: str, params, collection: bpy.types.Collection, instance: int = 0) -> bpy.types.Object:
    """A mesh object ``name`` whose edges are the roads' centre lines, its "Street Road" modifier building ``part`` (one of :data:`PARTS`).

    A mesh, not a curve object: the depsgraph gives a curve object's Geometry Nodes mesh both as the
    object and as an instance of it, which the export would read twice."""
    j = junction(params)
    lines = centre_lines(params.arm_length, j)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.concatenate(lines).tolist(), [(2 * k, 2 * k + 1) for k in range(len(lines))], [])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    add_group_modifier(obj, road_group(),
                       {"Part": PARTS.index(part), "Junction": list(JUNCTIONS).index(j.kind), "Instance": int(instance)} | road_inputs(params))
    return obj
