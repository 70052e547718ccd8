"""The "Parking Level" Geometry Nodes group: a car-park level's slabs, walls, pillar grid and ramp from its dimensions.

A real node group a Blender user can open and edit. It computes in nodes what
:func:`~bpy_pipeline.geometry.indoor.parking_layout` computes in numpy, and instances the unit
box (or the ramp's unit wedge; :mod:`.box_nodes`) for each piece, so the pieces have the pure
meshes' triangles in the same order:

- floor: one slab of ``Slab Thickness`` under the floor, the walls' outer size;
- ceiling: one slab above ``Ceiling Height``, open above the ramp (two slabs when there is one);
- walls: four, ``Wall Thickness`` thick, around the driveway (``Driveway Width``) and a bay depth
  (``Bay Depth``) plus 0.5 m on either side, ``Length`` long; the two long walls cut by
  ``Wall Openings`` doorways each (``Opening Width`` by ``Opening Height``, evenly spaced; segments
  and lintels in :func:`.layout.level_layout`'s order);
- pillars: between every ``Pillar Every`` bays of ``Bay Width`` along both bay rows' front lines,
  ``Pillar Size`` square, in groups of bays as many as fit in ``Length`` (a pillar gap
  ``Pillar Size`` + 0.2 m); none where the ramp is;
- ramp: ``Ramp Length`` long in the +y bay row at the +x end, rising to the next level.

``Part`` picks what the group outputs (1 floor, 2 ceiling, 3 walls, 4 pillars, 5 ramp), so each
piece keeps its own object and labels (the object's ``lidar_*`` tags; ``Instance`` stores the instance id as
the named attribute ``lidar_instance`` on the instances, which the export reads first). Changing ``Bay Width`` in
the modifier panel moves the pillars; :func:`edited_params` reads the pieces' inputs back, so the builder's
next car placement uses the bays, pillars and ramp of the edited level (the pure layout of those values).
"""

from __future__ import annotations

import dataclasses

import bpy
import numpy as np

from ...blender.compat import get_modifier_inputs
from ...blender import box_nodes
from ...blender.box_nodes import select
from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp

GROUP = "Parking Level"
VERSION = 3  # 2: the Instance input, stored as lidar_instance; 3: doorways in the long walls
PARTS = {"floor": 1, "ceiling": 2, "wall": 3, "pillar": 4, "ramp": 5}

INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Part", "NodeSocketInt", 0, "1 floor, 2 ceiling, 3 walls, 4 pillars, 5 ramp", 0, 5),
    ("Length", "NodeSocketFloat", 60.0, "m along the driveway (x), inside the walls", 1.0, 10000.0),
    ("Driveway Width", "NodeSocketFloat", 6.5, "m", 0.0, 100.0),
    ("Bay Width", "NodeSocketFloat", 2.5, "m along the driveway", 0.1, 100.0),
    ("Bay Depth", "NodeSocketFloat", 5.0, "m across the driveway", 0.0, 100.0),
    ("Ceiling Height", "NodeSocketFloat", 2.6, "m, floor to ceiling", 0.1, 100.0),
    ("Slab Thickness", "NodeSocketFloat", 0.3, "m, floor and ceiling slabs", 0.0, 10.0),
    ("Wall Thickness", "NodeSocketFloat", 0.3, "m", 0.0, 10.0),
    ("Pillar Size", "NodeSocketFloat", 0.6, "m, the square pillars' side", 0.0, 10.0),
    ("Pillar Every", "NodeSocketInt", 3, "bays between two pillars", 1, 1000),
    ("Ramp Length", "NodeSocketFloat", 16.0, "m (0: no ramp)", 0.0, 1000.0),
    ("Wall Openings", "NodeSocketInt", 0, "doorways in each long wall, evenly spaced (0: none)", 0, 1000),
    ("Opening Width", "NodeSocketFloat", 1.2, "m, a doorway's width", 0.0, 100.0),
    ("Opening Height", "NodeSocketFloat", 2.1, "m, a doorway's height (a lintel above it up to the ceiling)", 0.0, 100.0),
    ("Box", "NodeSocketObject", None, "the unit box instanced for slabs, walls and pillars"),
    ("Wedge", "NodeSocketObject", None, "the ramp's unit wedge"),
    *box_nodes.FINISH_INPUTS,
]


def level_group() -> bpy.types.NodeTree:
    """The "Parking Level" modifier group (see the module docstring); inputs :data:`INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g, m, xyz = b.get, b.math, b.combine
    t, slab, h = g("Wall Thickness"), g("Slab Thickness"), g("Ceiling Height")
    half_x = m("MULTIPLY", g("Length"), 0.5)
    front = m("MULTIPLY", g("Driveway Width"), 0.5)
    half_y = m("ADD", m("ADD", front, g("Bay Depth")), 0.5)
    outer_x, outer_y = m("ADD", half_x, t), m("ADD", half_y, t)
    ramp = b.compare("GREATER_THAN", g("Ramp Length"), 0.0)
    ramp_x0 = m("SUBTRACT", half_x, g("Ramp Length"))
    i = box_nodes.index(b)
    side = m("SUBTRACT", m("MULTIPLY", m("MODULO", i, 2.0), 2.0), 1.0)  # -1, +1, -1, ...
    box = g("Box")

    floor = box_nodes.place(b, 1, xyz(0.0, 0.0, m("MULTIPLY", slab, -0.5)), xyz(m("MULTIPLY", outer_x, 2.0), m("MULTIPLY", outer_y, 2.0), slab), box)

    # walls: the long walls' segments at y = +-(half_y + t / 2) (k doorways: k + 1 segments a wall, segment j of
    # both walls in turn), the end walls at x = +-(half_x + t / 2), then a lintel over each doorway (both walls in turn)
    k, half_w, top = g("Wall Openings"), m("MULTIPLY", g("Opening Width"), 0.5), g("Opening Height")
    segments = m("MULTIPLY", m("ADD", k, 1.0), 2.0)
    is_segment, is_end = b.compare("LESS_THAN", i, m("SUBTRACT", segments, 0.5)), b.compare("LESS_THAN", i, m("ADD", segments, 1.5))
    j = m("FLOOR", m("DIVIDE", i, 2.0))  # a segment's number along its wall
    j_lintel = m("FLOOR", m("DIVIDE", m("SUBTRACT", i, m("ADD", segments, 2.0)), 2.0))
    step = m("DIVIDE", g("Length"), m("MULTIPLY", m("ADD", k, 1.0), 2.0))  # half the doorways' spacing
    doorway = lambda n: m("MULTIPLY", m("SUBTRACT", m("ADD", m("MULTIPLY", n, 2.0), 1.0), k), step)  # noqa: E731 - doorway n's centre x: (2 n + 1 - k) L / (2 (k + 1)), no cancellation
    start = select(b, b.compare("LESS_THAN", j, 0.5), m("ADD", doorway(m("SUBTRACT", j, 1.0)), half_w), m("MULTIPLY", outer_x, -1.0))
    end = select(b, b.compare("GREATER_THAN", j, m("SUBTRACT", k, 0.5)), m("SUBTRACT", doorway(j), half_w), outer_x)

    def three(segment, end_wall, lintel):
        return select(b, is_segment, select(b, is_end, lintel, end_wall), segment)

    long_y = m("MULTIPLY", side, m("ADD", half_y, m("MULTIPLY", t, 0.5)))
    wall_centre = xyz(three(m("MULTIPLY", m("ADD", start, end), 0.5), m("MULTIPLY", side, m("ADD", half_x, m("MULTIPLY", t, 0.5))), doorway(j_lintel)),
                      three(long_y, 0.0, long_y), three(m("MULTIPLY", h, 0.5), m("MULTIPLY", h, 0.5), m("MULTIPLY", m("ADD", top, h), 0.5)))
    wall_size = xyz(three(m("SUBTRACT", end, start), t, g("Opening Width")), three(t, m("MULTIPLY", half_y, 2.0), t), three(h, h, m("SUBTRACT", h, top)))
    walls = box_nodes.place(b, m("MULTIPLY", segments, 2.0), wall_centre, wall_size, box)  # 2 (k + 1) + 2 + 2 k

    # ceiling: west of the ramp over the full width, then beside the ramp (one slab without a ramp)
    x0 = select(b, ramp, outer_x, ramp_x0)
    first = b.compare("LESS_THAN", i, 0.5)
    ceiling_centre = xyz(select(b, first, m("MULTIPLY", m("ADD", x0, outer_x), 0.5), m("MULTIPLY", m("SUBTRACT", x0, outer_x), 0.5)),
                         select(b, first, m("MULTIPLY", m("SUBTRACT", front, outer_y), 0.5), 0.0), m("ADD", h, m("MULTIPLY", slab, 0.5)))
    ceiling_size = xyz(select(b, first, m("SUBTRACT", outer_x, x0), m("ADD", x0, outer_x)),
                       select(b, first, m("ADD", front, outer_y), m("MULTIPLY", outer_y, 2.0)), slab)
    ceiling = box_nodes.place(b, b.switch("INT", ramp, 1, 2), ceiling_centre, ceiling_size, box)

    # pillars: [gap][group of bays][gap]... both sides of the driveway, none in the ramp's row past its start
    gap = m("ADD", g("Pillar Size"), 0.2)
    bays = m("MULTIPLY", g("Pillar Every"), g("Bay Width"))
    pitch = m("ADD", bays, gap)
    groups = m("FLOOR", m("DIVIDE", m("SUBTRACT", g("Length"), gap), pitch))
    start = m("MULTIPLY", m("ADD", m("MULTIPLY", groups, pitch), gap), -0.5)
    x = m("ADD", m("ADD", start, m("MULTIPLY", m("FLOOR", m("DIVIDE", i, 2.0)), pitch)), m("MULTIPLY", gap, 0.5))
    half_pillar = m("MULTIPLY", g("Pillar Size"), 0.5)
    in_ramp = b.out(b.node("FunctionNodeBooleanMath", {0: b.compare("GREATER_THAN", side, 0.0),
                                                       1: b.compare("GREATER_THAN", m("ADD", x, half_pillar), ramp_x0)}, operation="AND"))
    in_ramp = b.out(b.node("FunctionNodeBooleanMath", {0: in_ramp, 1: ramp}, operation="AND"))
    pillars = box_nodes.place(b, m("MULTIPLY", m("ADD", groups, 1.0), 2.0), xyz(x, m("MULTIPLY", side, m("ADD", front, half_pillar)), m("MULTIPLY", h, 0.5)),
                              xyz(g("Pillar Size"), g("Pillar Size"), h), box, selection=in_ramp)

    # the ramp: the unit wedge from (ramp_x0, front, 0), ramp length by bay row depth by a storey
    ramp_geometry = box_nodes.place(b, b.switch("INT", ramp, 0, 1), xyz(ramp_x0, front, 0.0),
                                    xyz(g("Ramp Length"), m("SUBTRACT", half_y, front), m("ADD", h, slab)), g("Wedge"))

    box_nodes.finish(b, box_nodes.pick(b, g("Part"), [floor, ceiling, walls, pillars, ramp_geometry]), g("Realize"), g("Instance"))
    return stamp(b.finish(), VERSION)


# input -> ParkingScene field (:func:`inputs_of`)
FIELDS = {"Length": "length", "Driveway Width": "driveway_width", "Bay Width": "bay_width", "Bay Depth": "bay_depth",
          "Ceiling Height": "ceiling_height", "Slab Thickness": "slab_thickness", "Wall Thickness": "wall_thickness",
          "Pillar Size": "pillar_size", "Pillar Every": "pillar_every", "Ramp Length": "ramp_length",
          "Wall Openings": "wall_openings", "Opening Width": "opening_width", "Opening Height": "opening_height"}

INTS = {"pillar_every", "wall_openings"}


def inputs_of(p) -> dict:
    """The group's dimension inputs from a ``ParkingScene`` ``p``."""
    return {name: getattr(p, field) for name, field in FIELDS.items()}


def _same(a, b) -> bool:
    """Whether a modifier's value ``a`` is the built value ``b``: ints exactly, floats after float32 rounding
    (Blender stores float inputs in single precision, so 2.35 reads back as 2.3499999)."""
    if isinstance(b, (int, np.integer)) and not isinstance(b, bool):
        return int(a) == int(b)
    return np.float32(a) == np.float32(b)


def edited_params(objects, params):
    """``params`` (a ``ParkingScene``) with every dimension a piece's "Parking Level" modifier holds changed
    from its built value; where pieces disagree, the first of ``objects`` whose value changed wins.

    ``objects`` : the level's pieces (any order; those without the group are skipped). A value equal to
    the built one after float32 rounding is not an edit, so an unedited level gives ``params`` itself
    (the same floats, the same bytes); an edited float is the shortest decimal its float32 reads as
    (typed 2.8, stored 2.7999999523, read 2.8).
    """
    changes = {}
    for obj in objects:
        for modifier in obj.modifiers:
            if modifier.type != "NODES" or modifier.node_group is None or modifier.node_group.name != GROUP:
                continue
            values = get_modifier_inputs(modifier, [name for name, field in FIELDS.items() if field not in changes])
            for name, value in values.items():
                field = FIELDS[name]
                if not _same(value, getattr(params, field)):
                    changes[field] = int(value) if field in INTS else float(str(np.float32(value)))  # the shortest decimal: 2.8, not 2.7999999523
    return dataclasses.replace(params, **changes) if changes else params


def level_object(name: str, part: str, params, collection, prototypes: dict, instance: int = 0) -> bpy.types.Object:
    """An object whose "Parking Level" modifier outputs ``part`` (a key of :data:`PARTS`) of the level of ``params``,
    its instances labelled ``instance``."""
    mesh = bpy.data.meshes.new(name)
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    add_group_modifier(obj, level_group(), inputs_of(params) | {"Part": PARTS[part], "Box": prototypes["box"], "Wedge": prototypes["wedge"],
                                                                "Instance": int(instance)})
    return obj
