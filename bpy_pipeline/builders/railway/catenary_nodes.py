"""The catenary's Geometry Nodes groups: "Catenary Wire" and "Catenary Droppers" (the railway thesis's catenary in nodes).

Real node groups a Blender user can open and edit, run by the modifiers of the railway's span
objects (``span.<run>.<k>.<wire>`` and ``span.<run>.<k>.droppers``, see :mod:`.railway`):

- "Catenary Wire": the object's curve holds the wire between its two registration points (its
  first and last points are the attachment points; the builder also keeps the pure samples
  between them, which the group ignores). The group hangs ``Samples`` points between the two
  ends on the thesis's parabola, z(t) = z_line(t) - 4 Sag t (1 - t) at t = i / (Samples - 1)
  (:func:`~bpy_pipeline.builders.railway.catenary.parabolic_sag`), and sweeps a ``Sides``-gon of
  ``Radius`` along it (``Sweep`` off: the centreline only). Moving an end point in Edit Mode or
  changing ``Sag`` in the modifier panel re-hangs the wire.
- "Catenary Droppers": each dropper hangs between the contact wire and the wire above it (the
  messenger, or the auxiliary messenger) at span parameter t. ``Spacing`` 0 keeps the droppers the
  builder drew (the object's curve: one two-point spline per dropper, at the thesis's spacing
  with its seeded jitter; t is read from the dropper's lower end projected on the contact chord);
  ``Spacing`` > 0 places n = max(1, floor(L / Spacing)) droppers at t_k = (k + Stagger) / (n + 1),
  k = 1..n, kept a quarter step clear of the supports and ``Clearance`` metres from mid-span
  (a section insulator's), as :func:`~bpy_pipeline.builders.railway.catenary.dropper_positions` does
  without jitter; ``Stagger`` is -1/4 and +1/4 on the two wires of a doubled contact wire. Both
  ends follow the wires' ``Contact Sag`` and ``Upper Sag``, so a sag edited on both moves both.

Labels: the objects keep their ``lidar_*`` tags; the swept mesh is theirs.
"""

from __future__ import annotations

import bpy

from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp

WIRE = "Catenary Wire"
DROPPERS = "Catenary Droppers"
VERSION = 1  # bump when the groups change, so a file holding older ones gets the new ones

WIRE_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Sag", "NodeSocketFloat", 0.0, "m the wire hangs below the chord at mid-span (the thesis's parabola)", 0.0, 10.0),
    ("Samples", "NodeSocketInt", 3, "points along the wire (the thesis: max(3, floor(max(2, L / 10 m) x points per 10 m)))", 3, 100000),
    ("Radius", "NodeSocketFloat", 0.006, "m, circumradius of the swept section", 0.0, 1.0),
    ("Sides", "NodeSocketInt", 6, "sides of the swept section", 3, 64),
    ("Sweep", "NodeSocketBool", True, "sweep the section along the wire (off: the centreline only)"),
]

DROPPER_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Contact Start", "NodeSocketVector", (0.0, 0.0, 0.0), "m, the contact wire's attachment at the span's first support"),
    ("Contact End", "NodeSocketVector", (0.0, 0.0, 0.0), "m, the contact wire's attachment at the span's second support"),
    ("Contact Sag", "NodeSocketFloat", 0.0, "m, the contact wire's mid-span sag", 0.0, 10.0),
    ("Upper Start", "NodeSocketVector", (0.0, 0.0, 0.0), "m, the messenger's (or auxiliary messenger's) attachment at the first support"),
    ("Upper End", "NodeSocketVector", (0.0, 0.0, 0.0), "m, the messenger's attachment at the second support"),
    ("Upper Sag", "NodeSocketFloat", 0.0, "m, the messenger's mid-span sag", 0.0, 10.0),
    ("Spacing", "NodeSocketFloat", 0.0, "m between droppers (0: keep the droppers the builder drew, with their jitter)", 0.0, 100.0),
    ("Stagger", "NodeSocketFloat", 0.0, "shift of the droppers in steps (-0.25 / +0.25 on a doubled contact wire's two wires)", -0.5, 0.5),
    ("Clearance", "NodeSocketFloat", 0.0, "m kept free of droppers either side of mid-span (a section insulator's)", 0.0, 100.0),
    ("Radius", "NodeSocketFloat", 0.006, "m, circumradius of the swept section", 0.0, 1.0),
    ("Sides", "NodeSocketInt", 6, "sides of the swept section", 3, 64),
    ("Sweep", "NodeSocketBool", True, "sweep the section along the droppers (off: their centrelines only)"),
]


def _hang(b: GroupBuilder, start, end, sag, t) -> bpy.types.NodeSocket:
    """The point of the thesis's parabola at span parameter ``t``: start + t (end - start) - (0, 0, 4 sag t (1 - t))."""
    along = b.vector_math("ADD", start, b.vector_math("SCALE", b.vector_math("SUBTRACT", end, start), scale=t))
    drop = b.math("MULTIPLY", b.math("MULTIPLY", 4.0, sag), b.math("MULTIPLY", t, b.math("SUBTRACT", 1.0, t)))
    return b.vector_math("SUBTRACT", along, b.combine(0.0, 0.0, drop))


def _sweep(b: GroupBuilder, curve, radius, sides, sweep) -> bpy.types.NodeSocket:
    """``curve`` swept by a ``sides``-gon of circumradius ``radius``, caps filled, when ``sweep`` holds."""
    profile = b.node("GeometryNodeCurvePrimitiveCircle", {"Resolution": sides, "Radius": radius}, options={"mode": "RADIUS"})
    tube = b.node("GeometryNodeCurveToMesh", {"Curve": curve, "Profile Curve": b.out(profile), "Fill Caps": True})
    return b.switch("GEOMETRY", sweep, curve, b.out(tube))


def _position(b: GroupBuilder, geometry, index) -> bpy.types.NodeSocket:
    """The position of point ``index`` of ``geometry``'s curves."""
    sample = b.node("GeometryNodeSampleIndex", {"Geometry": geometry, "Value": b.out(b.node("GeometryNodeInputPosition")), "Index": index},
                    options={"data_type": "FLOAT_VECTOR", "domain": "POINT"})
    return b.out(sample)


def wire_group() -> bpy.types.NodeTree:
    """The "Catenary Wire" modifier group (see the module docstring); inputs :data:`WIRE_INPUTS`."""
    group = current_group(WIRE, VERSION)
    if group is not None:
        return group
    group = new_group(WIRE, WIRE_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get
    count = b.out(b.node("GeometryNodeAttributeDomainSize", {"Geometry": g("Geometry")}, options={"component": "CURVE"}), "Point Count")
    start = _position(b, g("Geometry"), 0)
    end = _position(b, g("Geometry"), b.math("SUBTRACT", count, 1.0))
    line = b.node("GeometryNodeCurvePrimitiveLine", {"Start": start, "End": end})
    resampled = b.node("GeometryNodeResampleCurve", {"Curve": b.out(line), "Count": g("Samples")}, options={"mode": "COUNT"})
    index = b.out(b.node("GeometryNodeInputIndex"))
    t = b.math("DIVIDE", index, b.math("SUBTRACT", g("Samples"), 1.0))
    hung = b.node("GeometryNodeSetPosition", {"Geometry": b.out(resampled), "Position": _hang(b, start, end, g("Sag"), t)})
    b.links.new(_sweep(b, b.out(hung), g("Radius"), g("Sides"), g("Sweep")), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def droppers_group() -> bpy.types.NodeTree:
    """The "Catenary Droppers" modifier group (see the module docstring); inputs :data:`DROPPER_INPUTS`."""
    group = current_group(DROPPERS, VERSION)
    if group is not None:
        return group
    group = new_group(DROPPERS, DROPPER_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get
    cs, ce, us, ue = g("Contact Start"), g("Contact End"), g("Upper Start"), g("Upper End")
    chord = b.vector_math("MULTIPLY", b.vector_math("SUBTRACT", ce, cs), (1.0, 1.0, 0.0))  # the contact wire's chord in plan
    span = b.vector_math("LENGTH", chord)

    # built droppers: t from each point projected on the contact chord; the first point of a spline is the lower end
    position = b.out(b.node("GeometryNodeInputPosition"))
    projected = b.vector_math("DOT_PRODUCT", b.vector_math("SUBTRACT", position, cs), chord)
    t_point = b.math("DIVIDE", projected, b.vector_math("DOT_PRODUCT", chord, chord))
    lower = b.out(b.node("GeometryNodeCurveEndpointSelection", {"Start Size": 1, "End Size": 0}))
    # both ends take the t of the lower end (a dropper is a two-point spline; the upper wire's chord need not be parallel)
    first = b.math("SUBTRACT", b.math("ADD", b.out(b.node("GeometryNodeInputIndex")), lower), 1.0)
    t_built = b.out(b.node("GeometryNodeFieldAtIndex", {"Index": first, "Value": t_point}, options={"data_type": "FLOAT", "domain": "POINT"}))
    rehung = b.vector_math("ADD", b.vector_math("SCALE", _hang(b, cs, ce, g("Contact Sag"), t_built), scale=lower),  # 1 at the lower end, else 0
                           b.vector_math("SCALE", _hang(b, us, ue, g("Upper Sag"), t_built), scale=b.math("SUBTRACT", 1.0, lower)))
    built = b.out(b.node("GeometryNodeSetPosition", {"Geometry": g("Geometry"), "Position": rehung}))

    # even droppers at the thesis's spacing: n = max(1, floor(L / spacing)), t_k = (k + stagger) / (n + 1)
    n = b.math("MAXIMUM", 1.0, b.math("FLOOR", b.math("DIVIDE", span, b.math("MAXIMUM", g("Spacing"), 1e-6))))
    step = b.math("DIVIDE", 1.0, b.math("ADD", n, 1.0))
    index = b.out(b.node("GeometryNodeInputIndex"))
    t_even = b.math("MULTIPLY", b.math("ADD", b.math("ADD", index, 1.0), g("Stagger")), step)
    t_even = b.math("MINIMUM", b.math("MAXIMUM", t_even, b.math("MULTIPLY", 0.25, step)), b.math("SUBTRACT", 1.0, b.math("MULTIPLY", 0.25, step)))
    points = b.node("GeometryNodePoints", {"Count": n, "Position": _hang(b, cs, ce, g("Contact Sag"), t_even)})
    vertices = b.node("GeometryNodePointsToVertices", {"Points": b.out(points)})
    # a point stores its t so the clearance and the upper end read the clipped value
    stored = b.node("GeometryNodeStoreNamedAttribute", {"Geometry": b.out(vertices), "Name": "t", "Value": t_even},
                    options={"data_type": "FLOAT", "domain": "POINT"})
    t_stored = b.out(b.node("GeometryNodeInputNamedAttribute", {"Name": "t"}, options={"data_type": "FLOAT"}), "Attribute")
    near_middle = b.compare("LESS_THAN", b.math("MULTIPLY", b.math("ABSOLUTE", b.math("SUBTRACT", t_stored, 0.5)), span), g("Clearance"))
    kept = b.node("GeometryNodeDeleteGeometry", {"Geometry": b.out(stored), "Selection": near_middle}, options={"domain": "POINT", "mode": "ALL"})
    offset = b.vector_math("SUBTRACT", _hang(b, us, ue, g("Upper Sag"), t_stored), position)
    extruded = b.node("GeometryNodeExtrudeMesh", {"Mesh": b.out(kept), "Offset": offset, "Offset Scale": 1.0}, options={"mode": "VERTICES"})
    curves = b.node("GeometryNodeMeshToCurve", {"Mesh": b.out(b.node("GeometryNodeRemoveAttribute", {"Geometry": b.out(extruded, "Mesh"), "Name": "t"}))})
    even = b.out(curves)

    placed = b.switch("GEOMETRY", b.compare("GREATER_THAN", g("Spacing"), 0.0), built, even)
    b.links.new(_sweep(b, placed, g("Radius"), g("Sides"), g("Sweep")), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)


def curve_object(name: str, polylines, collection) -> bpy.types.Object:
    """A curve object of poly splines through ``(k, 3)`` points (m), without bevel: the group sweeps it."""
    import numpy as np

    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    for points in polylines:
        spline = curve.splines.new("POLY")
        spline.points.add(len(points) - 1)
        spline.points.foreach_set("co", np.column_stack([points, np.ones(len(points))]).astype(np.float32).ravel())
    obj = bpy.data.objects.new(name, curve)
    collection.objects.link(obj)
    return obj


def wire_object(name: str, points, sag: float, radius: float, sides: int, collection) -> bpy.types.Object:
    """A wire: a curve through ``points`` ((k, 3) m, the pure samples; its ends the registration points) run by "Catenary Wire"."""
    obj = curve_object(name, [points], collection)
    add_group_modifier(obj, wire_group(), {"Sag": float(sag), "Samples": len(points), "Radius": float(radius), "Sides": int(sides)})
    return obj


def droppers_object(name: str, droppers, contact, upper, radius: float, sides: int, collection) -> bpy.types.Object:
    """The droppers of one contact wire over one span (``Droppers``), one spline each, run by "Catenary Droppers";
    ``contact`` and ``upper`` are the :class:`~bpy_pipeline.builders.railway.layout.Wire` s they hang between."""
    import numpy as np

    obj = curve_object(name, [np.stack([a, b]) for a, b in zip(droppers.lower, droppers.upper)], collection)
    inputs = {"Contact Start": tuple(map(float, contact.start)), "Contact End": tuple(map(float, contact.end)), "Contact Sag": float(contact.sag),
              "Upper Start": tuple(map(float, upper.start)), "Upper End": tuple(map(float, upper.end)), "Upper Sag": float(upper.sag),
              "Radius": float(radius), "Sides": int(sides)}
    add_group_modifier(obj, droppers_group(), inputs)
    return obj
