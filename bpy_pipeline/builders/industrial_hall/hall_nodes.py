"""The "Industrial Hall" Geometry Nodes group: the hall's slabs and walls, its desks and shelf racks from their dimensions.

A real node group a Blender user can open and edit. It computes in nodes what
:func:`~bpy_pipeline.geometry.indoor.hall_layout`, :func:`~bpy_pipeline.geometry.indoor.desk` and
:func:`~bpy_pipeline.geometry.indoor.shelf` compute in numpy, and instances the unit box
(:mod:`.box_nodes`) for every board, leg and slab, so the pieces have the pure meshes' triangles
in the same order. ``Part`` picks the output:

- 1 floor, 2 ceiling (0.3 m slabs, ``Length`` x ``Width``), 3 walls (four, ``Wall Thickness``
  thick, ``Height`` high, inside ``Length`` x ``Width``);
- 4 a desk at ``Centre``: a 4 cm top ``Size`` x, y and ``Size`` z high, four 5 cm legs inset 5 cm;
- 5 a shelf rack at ``Centre``: four 6 cm uprights and ``Levels`` 3 cm boards from 0.1 m to the
  top of a ``Size`` rack.

Each desk and rack keeps its own object (and so its class and instance, the object's ``lidar_*``
tags, and ``Instance`` stored as the named attribute ``lidar_instance`` the export reads first); changing ``Levels`` or ``Size`` in a rack's modifier
rebuilds that rack. People and robots
still avoid the furniture of the YAML's hall (the placement reads the pure layout).
"""

from __future__ import annotations

import bpy

from ...blender import box_nodes
from ...blender.box_nodes import select
from ...blender.nodes import GroupBuilder, add_group_modifier, current_group, new_group, stamp

GROUP = "Industrial Hall"
VERSION = 2  # 2: the Instance input, stored as lidar_instance
PARTS = {"floor": 1, "ceiling": 2, "walls": 3, "desk": 4, "shelf": 5}
SLAB = 0.3  # m, as geometry.indoor.hall_layout

INPUTS = [
    ("Geometry", "NodeSocketGeometry"),
    ("Part", "NodeSocketInt", 0, "1 floor, 2 ceiling, 3 walls, 4 desk, 5 shelf rack", 0, 5),
    ("Length", "NodeSocketFloat", 16.0, "m, the hall along x", 0.1, 10000.0),
    ("Width", "NodeSocketFloat", 12.0, "m, the hall along y", 0.1, 10000.0),
    ("Height", "NodeSocketFloat", 5.0, "m, floor to ceiling", 0.1, 1000.0),
    ("Wall Thickness", "NodeSocketFloat", 0.3, "m", 0.0, 10.0),
    ("Centre", "NodeSocketVector", (0.0, 0.0, 0.0), "m, a desk's or rack's centre on the floor"),
    ("Size", "NodeSocketVector", (2.0, 0.6, 2.2), "m, a desk's or rack's length, depth and height"),
    ("Levels", "NodeSocketInt", 4, "boards of a rack", 1, 100),
    ("Box", "NodeSocketObject", None, "the unit box instanced for every piece"),
    *box_nodes.FINISH_INPUTS,
]


# input -> IndustrialHallScene field, the hall's own inputs of every piece (a rack's Levels: shelf_levels; Centre, Size: per piece)
FIELDS = {"Length": "length", "Width": "width", "Height": "height", "Wall Thickness": "wall_thickness"}


def hall_group() -> bpy.types.NodeTree:
    """The "Industrial Hall" modifier group (see the module docstring); inputs :data:`INPUTS`."""
    group = current_group(GROUP, VERSION)
    if group is not None:
        return group
    group = new_group(GROUP, INPUTS, [("Geometry", "NodeSocketGeometry")], modifier=True)
    b = GroupBuilder(group)
    g, m, xyz = b.get, b.math, b.combine
    box, t, h = g("Box"), g("Wall Thickness"), g("Height")
    half_x, half_y = m("MULTIPLY", g("Length"), 0.5), m("MULTIPLY", g("Width"), 0.5)
    i = box_nodes.index(b)

    def parity(k):  # -1, +1, -1, ... over k
        return m("SUBTRACT", m("MULTIPLY", m("MODULO", k, 2.0), 2.0), 1.0)

    slab_size = xyz(g("Length"), g("Width"), SLAB)
    floor = box_nodes.place(b, 1, xyz(0.0, 0.0, -SLAB / 2), slab_size, box)
    ceiling = box_nodes.place(b, 1, xyz(0.0, 0.0, m("ADD", h, SLAB / 2)), slab_size, box)

    along_x = b.compare("LESS_THAN", i, 1.5)  # two walls along x at y = +-(half_y - t / 2), then two along y
    side = parity(i)
    wall_centre = xyz(select(b, along_x, m("MULTIPLY", side, m("SUBTRACT", half_x, m("MULTIPLY", t, 0.5))), 0.0),
                      select(b, along_x, 0.0, m("MULTIPLY", side, m("SUBTRACT", half_y, m("MULTIPLY", t, 0.5)))), m("MULTIPLY", h, 0.5))
    wall_size = xyz(select(b, along_x, t, g("Length")), select(b, along_x, m("MULTIPLY", m("SUBTRACT", half_y, t), 2.0), t), h)
    walls = box_nodes.place(b, 4, wall_centre, wall_size, box)

    sep = b.node("ShaderNodeSeparateXYZ", {"Vector": g("Size")})
    length, depth, top = b.out(sep, "X"), b.out(sep, "Y"), b.out(sep, "Z")
    centre = b.node("ShaderNodeSeparateXYZ", {"Vector": g("Centre")})
    cx, cy = b.out(centre, "X"), b.out(centre, "Y")

    def corners(k, inset):
        """x, y of the k-th of four legs or uprights (x -1 then +1, each y -1 then +1), ``inset`` from the edges."""
        sx, sy = m("SUBTRACT", m("MULTIPLY", m("FLOOR", m("DIVIDE", k, 2.0)), 2.0), 1.0), parity(k)
        return (m("ADD", cx, m("MULTIPLY", sx, m("SUBTRACT", m("MULTIPLY", length, 0.5), inset))),
                m("ADD", cy, m("MULTIPLY", sy, m("SUBTRACT", m("MULTIPLY", depth, 0.5), inset))))

    # a desk: the top, then four legs
    is_top = b.compare("LESS_THAN", i, 0.5)
    lx, ly = corners(m("SUBTRACT", i, 1.0), 0.075)
    leg_height = m("SUBTRACT", top, 0.04)
    desk = box_nodes.place(b, 5, xyz(select(b, is_top, lx, cx), select(b, is_top, ly, cy),
                                     select(b, is_top, m("MULTIPLY", leg_height, 0.5), m("SUBTRACT", top, 0.02))),
                           xyz(select(b, is_top, 0.05, length), select(b, is_top, 0.05, depth), select(b, is_top, leg_height, 0.04)), box)

    # a rack: four uprights, then the boards at linspace(0.1, height - 0.015, levels)
    upright = b.compare("LESS_THAN", i, 3.5)
    ux, uy = corners(i, 0.03)
    levels = m("MAXIMUM", g("Levels"), 1.0)
    board_z = m("ADD", 0.1, m("MULTIPLY", m("SUBTRACT", i, 4.0), m("DIVIDE", m("SUBTRACT", top, 0.115), m("MAXIMUM", m("SUBTRACT", levels, 1.0), 1.0))))
    shelf = box_nodes.place(b, m("ADD", levels, 4.0), xyz(select(b, upright, cx, ux), select(b, upright, cy, uy),
                                                          select(b, upright, board_z, m("MULTIPLY", top, 0.5))),
                            xyz(select(b, upright, length, 0.06), select(b, upright, depth, 0.06), select(b, upright, 0.03, top)), box)

    box_nodes.finish(b, box_nodes.pick(b, g("Part"), [floor, ceiling, walls, desk, shelf]), g("Realize"), g("Instance"))
    return stamp(b.finish(), VERSION)


def hall_object(name: str, part: str, params, collection, prototypes: dict, instance: int = 0, **inputs) -> bpy.types.Object:
    """An object whose "Industrial Hall" modifier outputs ``part`` (a key of :data:`PARTS`) of the hall of ``params``
    (an ``IndustrialHallScene``); ``inputs`` sets ``Centre``, ``Size``, ``Levels`` of a desk or rack."""
    obj = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    collection.objects.link(obj)
    hall = {name: getattr(params, key) for name, key in FIELDS.items()}
    add_group_modifier(obj, hall_group(), hall | inputs | {"Part": PARTS[part], "Box": prototypes["box"], "Instance": int(instance)})
    return obj


def furniture_object(item, params, collection, prototypes: dict, instance: int = 0) -> bpy.types.Object:
    """The object of one desk or rack of ``hall_layout(params).furniture``, its dimensions read from ``params``."""
    board = item.parts[0 if item.class_name == "desk" else 4][0]  # the desk's top, the rack's first board: centred on the item
    centre = (float(board[0]), float(board[1]), 0.0)
    if item.class_name == "desk":
        return hall_object(item.name, "desk", params, collection, prototypes, instance, Centre=centre, Size=(*params.desk_size, params.desk_height))
    return hall_object(item.name, "shelf", params, collection, prototypes, instance, Centre=centre, Size=tuple(params.shelf_size), Levels=params.shelf_levels)
