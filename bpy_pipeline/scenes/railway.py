"""``scene.builder: railway``: a straight single track with ballast, sleepers, rails, two masts and wires.

The track runs along +x, centred on the origin; ground at z = 0. Sleepers come from the
"Boxes Along Line" Geometry Nodes group; wires are bevelled curves. Every object is tagged
with its class from assets_manifest/labels.yaml.
"""

from __future__ import annotations

import math

import bpy
import numpy as np

from ..geometry import primitives
from ..geometry.catenary import parabolic_sag
from .nodes import add_group_modifier, boxes_along_line_group
from .objects import mesh_object, scene_collection, tag, wire_object

SLEEPER = (0.26, 2.6, 0.22)  # m: width along the track, length across, height (B70 concrete)
RAIL_PARTS = ((0.150, 0.0115), (0.0165, 0.1225), (0.072, 0.038))  # m: (width, height) of foot, web, head
RAIL_HEIGHT = sum(h for _, h in RAIL_PARTS)
MAST_SECTION = (0.3, 0.3, 0.02)  # m: flange width, depth, thickness of the H-section


def rail_mesh(length: float):
    """A simplified flat-bottom rail (foot, web, head boxes) along x, foot on z = 0."""
    parts, z = [], 0.0
    for width, height in RAIL_PARTS:
        parts.append(primitives.translated(primitives.box(length, width, height), (0, 0, z + height / 2)))
        z += height
    return primitives.merge(parts)


def h_section_mesh(height: float):
    """An H-section mast standing on z = 0 (flanges across y)."""
    width, depth, t = MAST_SECTION
    return primitives.merge(
        [
            primitives.translated(primitives.box(t, width, height), (-depth / 2 + t / 2, 0, height / 2)),
            primitives.translated(primitives.box(t, width, height), (depth / 2 - t / 2, 0, height / 2)),
            primitives.translated(primitives.box(depth - 2 * t, t, height), (0, 0, height / 2)),
        ]
    )


def arm_mesh(y0: float, y1: float, z: float, thickness: float = 0.06):
    """A horizontal bar across the track from y0 to y1 at height z."""
    return primitives.translated(primitives.box(thickness, abs(y1 - y0), thickness), (0, (y0 + y1) / 2, z))


def build(params, rng: np.random.Generator) -> None:
    collection = scene_collection()
    half = params.length / 2
    sleeper_top = params.ballast_height + SLEEPER[2]
    rail_top = sleeper_top + RAIL_HEIGHT

    ground = mesh_object("ground", primitives.plane(params.length + 40, 40), collection)
    tag(ground, "ground", reflectivity=0.3)

    top = SLEEPER[1] / 2 + params.ballast_shoulder
    bottom = top + params.ballast_height * 1.5  # 1:1.5 slope
    ballast_profile = np.array([[-bottom, 0.0], [bottom, 0.0], [top, params.ballast_height], [-top, params.ballast_height]])
    tag(mesh_object("ballast", primitives.prism(ballast_profile, -half, half), collection), "ballast", reflectivity=0.35)

    count = int(params.length // params.sleeper_spacing)
    start = -(count - 1) * params.sleeper_spacing / 2
    sleepers = mesh_object("sleepers", (np.zeros((0, 3)), np.zeros((0, 3), np.int32)), collection)
    add_group_modifier(
        sleepers,
        boxes_along_line_group(),
        {"Count": count, "Start": (start, 0.0, params.ballast_height + SLEEPER[2] / 2), "Offset": (params.sleeper_spacing, 0.0, 0.0), "Size": SLEEPER},
    )
    tag(sleepers, "sleeper", reflectivity=0.4)

    rail_offset = params.gauge / 2 + RAIL_PARTS[2][0] / 2
    rail = rail_mesh(params.length)
    for side, y in (("left", rail_offset), ("right", -rail_offset)):
        tag(mesh_object(f"rail_{side}", rail, collection, (0, y, sleeper_top)), "rail", reflectivity=0.6)

    contact_z = rail_top + params.contact_wire_height
    messenger_z = contact_z + params.system_height
    mast_x = (-params.span / 2, params.span / 2)
    mast_y = -params.mast_offset
    stagger = (params.stagger, -params.stagger)
    for i, (x, y_wire) in enumerate(zip(mast_x, stagger)):
        tag(mesh_object(f"mast_{i}", h_section_mesh(params.mast_height), collection, (x, mast_y, 0)), "mast", reflectivity=0.5)
        tag(mesh_object(f"cantilever_{i}", arm_mesh(mast_y, y_wire, messenger_z), collection, (x, 0, 0)), "cantilever", reflectivity=0.5)
        tag(mesh_object(f"registration_arm_{i}", arm_mesh(mast_y, y_wire, contact_z, 0.04), collection, (x, 0, 0)), "registration arm", reflectivity=0.5)

    samples = max(3, math.ceil(params.span / 0.5) + 1)
    ends = [(mast_x[0], stagger[0]), (mast_x[1], stagger[1])]
    contact = parabolic_sag([*ends[0], contact_z], [*ends[1], contact_z], params.contact_wire_sag, samples)
    messenger = parabolic_sag([*ends[0], messenger_z], [*ends[1], messenger_z], params.messenger_wire_sag, samples)
    tag(wire_object("contact_wire", [contact], params.contact_wire_diameter / 2, collection), "contact wire", reflectivity=0.7)
    tag(wire_object("messenger_wire", [messenger], params.messenger_wire_diameter / 2, collection), "messenger wire", reflectivity=0.7)

    droppers = max(1, math.floor(params.span / params.dropper_spacing))
    u = (np.arange(droppers) + 0.5) / droppers
    lower = np.array([np.interp(u, np.linspace(0, 1, samples), contact[:, k]) for k in range(3)]).T
    upper = np.array([np.interp(u, np.linspace(0, 1, samples), messenger[:, k]) for k in range(3)]).T
    tag(wire_object("droppers", [np.stack([a, b]) for a, b in zip(lower, upper)], 0.004, collection), "dropper", reflectivity=0.6)
    bpy.context.view_layer.update()
