"""The "Track" Geometry Nodes group: rails, sleepers, ballast, stones, embankment and ground along a curve.

A real node group a Blender user can open and edit: every dimension is an exposed input
(defaults: standard gauge, about 60 kg/m flat-bottom rails on concrete sleepers every 0.6 m),
and the track follows the curve object given as ``Centreline`` (the builder's
``track_centreline``), so editing that curve moves the track. ``Part`` picks what the group
outputs (0 everything, then one part each, so the builder can give each part its own object
and class); ``Track`` picks one track of the group (-1 all).

Sub-groups: "Track Centrelines" (the curve copied to each track's lateral offset), "Rail Profile"
(both rails of a track as three rectangles each), "Ballast Stones" (stones on the ballast bed
within a radius of the given centres). Profiles are drawn in (left, up) coordinates.
"""

from __future__ import annotations

import math

import bpy

from ...blender.nodes import GroupBuilder, current_group, new_group, stamp

PARTS = {"all": 0, "rails": 1, "sleepers": 2, "ballast": 3, "embankment": 4, "stones": 5, "ground": 6}
VERSION = 4  # bump when the groups change, so a file holding older groups gets new ones


def profile_to_frame(b: GroupBuilder, curve) -> bpy.types.NodeSocket:
    """A profile drawn in (left, up) coordinates, turned for Curve to Mesh on a curve with Z-up normals
    (whose profile x runs to the right and y downwards)."""
    return b.out(b.node("GeometryNodeTransform", {"Geometry": curve, "Rotation": (0.0, 0.0, math.pi)}, options={"mode": "COMPONENTS"}))


def centrelines_group() -> bpy.types.NodeTree:
    """"Track Centrelines": the curve copied to each track centreline, ``(k - (Tracks - 1) / 2) * Spacing`` to the left."""
    name = "Track Centrelines"
    group = current_group(name, VERSION)
    if group is not None:
        return group
    group = new_group(
        name,
        [("Curve", "NodeSocketGeometry"), ("Tracks", "NodeSocketInt", 1, "number of parallel tracks", 1, 5),
         ("Track Spacing", "NodeSocketFloat", 4.0, "m between neighbouring track centrelines"),
         ("Track", "NodeSocketInt", -1, "-1: every track; k: track k only (0 the rightmost)", -1, 4)],
        [("Curve", "NodeSocketGeometry")],
    )
    b = GroupBuilder(group)
    single = b.compare("GREATER_EQUAL", b.get("Track"), 0, "INT")
    amount = b.switch("INT", single, b.get("Tracks"), 1)
    copies = b.node("GeometryNodeDuplicateElements", {"Geometry": b.get("Curve"), "Amount": amount}, domain="SPLINE")
    index = b.switch("INT", single, b.out(copies, "Duplicate Index"), b.get("Track"))
    middle = b.math("MULTIPLY", b.math("SUBTRACT", b.get("Tracks"), 1.0), 0.5)
    offset = b.math("MULTIPLY", b.math("SUBTRACT", index, middle), b.get("Track Spacing"))
    tangent = b.out(b.node("GeometryNodeInputTangent"))
    left = b.vector_math("NORMALIZE", b.vector_math("CROSS_PRODUCT", (0.0, 0.0, 1.0), tangent))
    moved = b.node("GeometryNodeSetPosition", {"Geometry": b.out(copies, "Geometry"), "Offset": b.vector_math("SCALE", left, scale=offset)})
    b.links.new(b.out(moved), b.socket(b.outputs.inputs, "Curve"))
    return stamp(b.finish(), VERSION)


def rail_profile_group() -> bpy.types.NodeTree:
    """"Rail Profile": both rails of one track, foot on ``Base Height``, head inner faces ``Gauge`` apart."""
    name = "Rail Profile"
    group = current_group(name, VERSION)
    if group is not None:
        return group
    group = new_group(
        name,
        [("Gauge", "NodeSocketFloat", 1.435, "m between the inner faces of the rail heads"),
         ("Foot Width", "NodeSocketFloat", 0.150), ("Foot Height", "NodeSocketFloat", 0.018),
         ("Web Width", "NodeSocketFloat", 0.0165), ("Web Height", "NodeSocketFloat", 0.111),
         ("Head Width", "NodeSocketFloat", 0.072), ("Head Height", "NodeSocketFloat", 0.043),
         ("Base Height", "NodeSocketFloat", 0.57, "m from the centreline up to the rail foot")],
        [("Profile", "NodeSocketGeometry")],
    )
    b = GroupBuilder(group)
    half = b.math("ADD", b.math("MULTIPLY", b.get("Gauge"), 0.5), b.math("MULTIPLY", b.get("Head Width"), 0.5))
    join = b.node("GeometryNodeJoinGeometry")
    bottom = b.get("Base Height")
    for part in ("Foot", "Web", "Head"):
        width, height = b.get(f"{part} Width"), b.get(f"{part} Height")
        centre_z = b.math("ADD", bottom, b.math("MULTIPLY", height, 0.5))
        rectangle = b.out(b.node("GeometryNodeCurvePrimitiveQuadrilateral", {"Width": width, "Height": height}, mode="RECTANGLE"))
        for side in (-1.0, 1.0):
            lateral = b.math("MULTIPLY", half, side)
            placed = b.node("GeometryNodeTransform", {"Geometry": rectangle, "Translation": b.combine(lateral, centre_z, 0.0)}, options={"mode": "COMPONENTS"})
            b.links.new(b.out(placed), join.inputs[0])
        bottom = b.math("ADD", bottom, height)
    b.links.new(profile_to_frame(b, b.out(join)), b.socket(b.outputs.inputs, "Profile"))
    return stamp(b.finish(), VERSION)


def ballast_stones_group() -> bpy.types.NodeTree:
    """"Ballast Stones": stones of ``Stone Size`` on the upward faces of ``Bed``, within ``Radius`` of ``Centres``' points."""
    name = "Ballast Stones"
    group = current_group(name, VERSION)
    if group is not None:
        return group
    group = new_group(
        name,
        [("Bed", "NodeSocketGeometry"), ("Centres", "NodeSocketGeometry"),
         ("Radius", "NodeSocketFloat", 0.0, "m: stones only this close to a centre (0: none)"),
         ("Stone Size", "NodeSocketFloat", 0.045, "m, the stones' mean diameter"), ("Seed", "NodeSocketInt", 0)],
        [("Stones", "NodeSocketGeometry")],
    )
    b = GroupBuilder(group)
    position = b.out(b.node("GeometryNodeInputPosition"))
    distance = b.out(b.node("GeometryNodeProximity", {"Geometry": b.get("Centres"), "Sample Position": position}, target_element="POINTS"), "Distance")
    normal_z = b.out(b.node("ShaderNodeSeparateXYZ", {0: b.out(b.node("GeometryNodeInputNormal"))}), "Z")
    reach = b.math("ADD", b.get("Radius"), 2.0)
    near_face = b.out(b.node("FunctionNodeBooleanMath", {0: b.compare("LESS_THAN", distance, reach), 1: b.compare("GREATER_THAN", normal_z, 0.5)},
                             operation="AND"))
    faces = b.node("GeometryNodeDeleteGeometry", {"Geometry": b.get("Bed"),
                                                  "Selection": b.out(b.node("FunctionNodeBooleanMath", {0: near_face}, operation="NOT"))}, domain="FACE")
    size = b.get("Stone Size")
    points = b.node(
        "GeometryNodeDistributePointsOnFaces",
        {"Mesh": b.out(faces), "Distance Min": b.math("MULTIPLY", size, 0.9), "Density Max": b.math("DIVIDE", 1.5, b.math("MULTIPLY", size, size)),
         "Seed": b.get("Seed")},
        distribute_method="POISSON",
    )
    inside = b.node("GeometryNodeDeleteGeometry", {"Geometry": b.out(points, "Points"), "Selection": b.compare("GREATER_THAN", distance, b.get("Radius"))},
                    domain="POINT")
    stone = b.node("GeometryNodeMeshIcoSphere", {"Radius": b.math("MULTIPLY", size, 0.5), "Subdivisions": 1})
    seed = b.get("Seed")
    angles = b.out(b.node("FunctionNodeRandomValue", {"Min": (0.0, 0.0, 0.0), "Max": (2 * math.pi,) * 3, "Seed": b.math("ADD", seed, 1.0)},
                          data_type="FLOAT_VECTOR"))
    scales = b.out(b.node("FunctionNodeRandomValue", {"Min": (0.7, 0.7, 0.45), "Max": (1.3, 1.3, 0.8), "Seed": b.math("ADD", seed, 2.0)},
                          data_type="FLOAT_VECTOR"))
    rotation = b.out(b.node("FunctionNodeEulerToRotation", {"Euler": angles}))
    instances = b.node("GeometryNodeInstanceOnPoints", {"Points": b.out(inside), "Instance": b.out(stone, "Mesh"), "Rotation": rotation, "Scale": scales})
    real = b.node("GeometryNodeRealizeInstances", {"Geometry": b.out(instances)})
    enabled = b.compare("GREATER_THAN", b.get("Radius"), 0.0)
    b.links.new(b.switch("GEOMETRY", enabled, None, b.out(real)), b.socket(b.outputs.inputs, "Stones"))
    return stamp(b.finish(), VERSION)


TRACK_INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Centreline", "NodeSocketObject", None, "the curve the track follows (at formation level)"),
    ("Part", "NodeSocketInt", 0, "0 all, 1 rails, 2 sleepers, 3 ballast bed, 4 embankment, 5 ballast stones, 6 ground", 0, 6),
    ("Track", "NodeSocketInt", -1, "-1: every track; k: rails and sleepers of track k only (0 the rightmost)", -1, 4),
    ("Tracks", "NodeSocketInt", 1, "number of parallel tracks", 1, 5),
    ("Track Spacing", "NodeSocketFloat", 4.0, "m between neighbouring track centrelines"),
    ("Gauge", "NodeSocketFloat", 1.435, "m between the inner faces of the rail heads"),
    ("Rail Foot Width", "NodeSocketFloat", 0.150), ("Rail Foot Height", "NodeSocketFloat", 0.018),
    ("Rail Web Width", "NodeSocketFloat", 0.0165), ("Rail Web Height", "NodeSocketFloat", 0.111),
    ("Rail Head Width", "NodeSocketFloat", 0.072), ("Rail Head Height", "NodeSocketFloat", 0.043),
    ("Sleeper Spacing", "NodeSocketFloat", 0.6, "m between sleeper centres"),
    ("Sleeper Length", "NodeSocketFloat", 2.6, "m across the track"), ("Sleeper Width", "NodeSocketFloat", 0.26, "m along the track"),
    ("Sleeper Height", "NodeSocketFloat", 0.22),
    ("Ballast Height", "NodeSocketFloat", 0.35, "m of ballast under the sleepers"),
    ("Crib Height", "NodeSocketFloat", 0.17, "m of ballast between the sleepers, above their underside"),
    ("Ballast Shoulder", "NodeSocketFloat", 0.5, "m of flat ballast beyond the sleeper ends"),
    ("Ballast Slope", "NodeSocketFloat", 1.5, "horizontal per vertical"),
    ("Embankment Height", "NodeSocketFloat", 0.0, "m of formation above the ground"),
    ("Embankment Slope", "NodeSocketFloat", 1.5, "horizontal per vertical"),
    ("Embankment Berm", "NodeSocketFloat", 1.0, "m of flat formation beyond the ballast toe"),
    ("Ground Width", "NodeSocketFloat", 80.0, "m, the flat ground strip along the track"),
    ("Trim Start", "NodeSocketFloat", 0.0, "m along the centreline where the track starts"),
    ("Trim End", "NodeSocketFloat", 1.0e9, "m along the centreline where the track ends"),
    ("Stone Centres", "NodeSocketObject", None, "stones lie near this object's points (the scanner stations)"),
    ("Stone Radius", "NodeSocketFloat", 0.0, "m: stones within this distance of a centre (0: none)"),
    ("Stone Size", "NodeSocketFloat", 0.045, "m, the stones' mean diameter"),
    ("Seed", "NodeSocketInt", 0),
    ("Cant Angle", "NodeSocketFloat", 0.0, "radians of the full cant (0: a level track); rails and sleepers follow the centreline's tilt"),
]


def track_group() -> bpy.types.NodeTree:
    """The "Track" modifier group (see the module docstring); its inputs are :data:`TRACK_INPUTS`."""
    name = "Track"
    group = current_group(name, VERSION)
    if group is not None:
        return group
    group = new_group(name, TRACK_INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g = b.get
    source = b.node("GeometryNodeObjectInfo", {"Object": g("Centreline")}, transform_space="RELATIVE")
    trimmed = b.node("GeometryNodeTrimCurve", {"Curve": b.out(source, "Geometry"), "Start": g("Trim Start"), "End": g("Trim End")}, options={"mode": "LENGTH"})
    canted = b.out(b.node("GeometryNodeSetCurveNormal", {"Curve": b.out(trimmed)}, options={"mode": "Z_UP"}))
    # the centreline's tilt is the cant: rails and sleepers roll about each track's centre, raised by half
    # the cant so the inner rail keeps its height; bed, embankment and ground stay level
    centre = b.out(b.node("GeometryNodeSetCurveTilt", {"Curve": canted, "Tilt": 0.0}))

    lines = b.node("GeometryNodeGroup", {"Curve": canted, "Tracks": g("Tracks"), "Track Spacing": g("Track Spacing"), "Track": g("Track")},
                   node_tree=centrelines_group())
    tilt = b.out(b.node("GeometryNodeInputCurveTilt"))
    half_cant = b.math("MULTIPLY", b.math("ABSOLUTE", b.math("SINE", tilt)), b.math("MULTIPLY", b.math("ADD", g("Gauge"), g("Rail Head Width")), 0.5))
    tracks = b.out(b.node("GeometryNodeSetPosition", {"Geometry": b.out(lines), "Offset": b.combine(0.0, 0.0, half_cant)}))

    sleeper_top = b.math("ADD", g("Ballast Height"), g("Sleeper Height"))
    profile_inputs = {"Gauge": g("Gauge"), "Base Height": sleeper_top}
    for part in ("Foot", "Web", "Head"):
        profile_inputs |= {f"{part} Width": g(f"Rail {part} Width"), f"{part} Height": g(f"Rail {part} Height")}
    profile = b.node("GeometryNodeGroup", profile_inputs, node_tree=rail_profile_group())
    rails = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": tracks, "Profile Curve": b.out(profile), "Fill Caps": True}))

    stations = b.node("GeometryNodeCurveToPoints", {"Curve": tracks, "Length": g("Sleeper Spacing")}, options={"mode": "LENGTH"})
    along = b.out(b.node("FunctionNodeAlignRotationToVector", {"Vector": b.out(stations, "Tangent")}, axis="X", pivot_axis="Z"))
    # on a canted track, roll about the tangent until y (left) meets the curve's tilted normal (which points
    # to the right, as Curve to Mesh's profile x), point by point
    left = b.vector_math("SCALE", b.out(stations, "Normal"), scale=-1.0)
    rolled = b.out(b.node("FunctionNodeAlignRotationToVector", {"Rotation": along, "Vector": left}, axis="Y", pivot_axis="X"))
    facing = b.switch("ROTATION", b.compare("NOT_EQUAL", g("Cant Angle"), 0.0), along, rolled)
    block = b.node("GeometryNodeMeshCube", {"Size": b.combine(g("Sleeper Width"), g("Sleeper Length"), g("Sleeper Height"))})
    lifted = b.node("GeometryNodeTransform", {"Geometry": b.out(block, "Mesh"),
                                              "Translation": b.combine(0.0, 0.0,
                                                                       b.math("ADD", g("Ballast Height"), b.math("MULTIPLY", g("Sleeper Height"), 0.5)))},
                    options={"mode": "COMPONENTS"})
    placed = b.node("GeometryNodeInstanceOnPoints", {"Points": b.out(stations, "Points"), "Instance": b.out(lifted), "Rotation": facing})
    sleepers = b.out(b.node("GeometryNodeRealizeInstances", {"Geometry": b.out(placed)}))

    # the ballast bed under all tracks: a trapezoid, its top over the sleepers plus the shoulders
    extra_tracks = b.math("MULTIPLY", b.math("SUBTRACT", g("Tracks"), 1.0), g("Track Spacing"))
    top = b.math("ADD", b.math("ADD", extra_tracks, g("Sleeper Length")), b.math("MULTIPLY", g("Ballast Shoulder"), 2.0))
    bed_height = b.math("ADD", g("Ballast Height"), g("Crib Height"))  # the crib ballast fills between the sleepers
    toe = b.math("ADD", top, b.math("MULTIPLY", b.math("MULTIPLY", bed_height, g("Ballast Slope")), 2.0))

    def trapezoid(bottom_width, top_width, height, centre_height):
        shape = b.node("GeometryNodeCurvePrimitiveQuadrilateral", {"Bottom Width": bottom_width, "Top Width": top_width, "Height": height, "Offset": 0.0},
                       mode="TRAPEZOID")
        moved = b.node("GeometryNodeTransform", {"Geometry": b.out(shape), "Translation": b.combine(0.0, centre_height, 0.0)}, options={"mode": "COMPONENTS"})
        return profile_to_frame(b, b.out(moved))

    bed_profile = trapezoid(toe, top, bed_height, b.math("MULTIPLY", bed_height, 0.5))
    bed = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": centre, "Profile Curve": bed_profile, "Fill Caps": True}))

    berm = b.math("ADD", toe, b.math("MULTIPLY", g("Embankment Berm"), 2.0))
    foot = b.math("ADD", berm, b.math("MULTIPLY", b.math("MULTIPLY", g("Embankment Height"), g("Embankment Slope")), 2.0))
    bank_profile = trapezoid(foot, berm, g("Embankment Height"), b.math("MULTIPLY", g("Embankment Height"), -0.5))
    bank = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": centre, "Profile Curve": bank_profile, "Fill Caps": True}))
    bank = b.switch("GEOMETRY", b.compare("GREATER_THAN", g("Embankment Height"), 0.0), None, bank)

    half_ground = b.math("MULTIPLY", g("Ground Width"), 0.5)
    ground_z = b.math("MULTIPLY", g("Embankment Height"), -1.0)
    strip = b.node("GeometryNodeCurvePrimitiveLine", {"Start": b.combine(b.math("MULTIPLY", half_ground, -1.0), ground_z, 0.0),
                                                      "End": b.combine(half_ground, ground_z, 0.0)}, mode="POINTS")
    ground = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": centre, "Profile Curve": profile_to_frame(b, b.out(strip))}))

    # stones: the bed again on a finely resampled centreline, so faces far from every centre drop out early
    fine = b.node("GeometryNodeResampleCurve", {"Curve": centre, "Length": 2.0}, options={"mode": "LENGTH"})
    fine_bed = b.out(b.node("GeometryNodeCurveToMesh", {"Curve": b.out(fine), "Profile Curve": bed_profile}))
    centres = b.node("GeometryNodeObjectInfo", {"Object": g("Stone Centres")}, transform_space="RELATIVE")
    stones = b.out(b.node("GeometryNodeGroup", {"Bed": fine_bed, "Centres": b.out(centres, "Geometry"), "Radius": g("Stone Radius"),
                                                "Stone Size": g("Stone Size"), "Seed": g("Seed")}, node_tree=ballast_stones_group()))

    everything = b.node("GeometryNodeJoinGeometry")
    parts = [rails, sleepers, bed, bank, stones, ground]
    for socket in parts:
        b.links.new(socket, everything.inputs[0])
    pick = b.node("GeometryNodeIndexSwitch", data_type="GEOMETRY")
    while len([s for s in pick.inputs if s.type == "GEOMETRY"]) < len(parts) + 1:
        pick.index_switch_items.new()
    b.set_input(pick, "Index", g("Part"))
    choices = [s for s in pick.inputs if s.type == "GEOMETRY"]
    for socket, value in zip(choices, [b.out(everything), *parts]):
        b.links.new(value, socket)
    b.links.new(b.out(pick), b.socket(b.outputs.inputs, "Geometry"))
    return stamp(b.finish(), VERSION)
