"""Geometry Nodes groups the builders use. Real node groups a Blender user can open and edit."""

from __future__ import annotations

import bpy

from ..compat import set_modifier_input


def _socket(group, name, in_out, socket_type, default=None):
    item = group.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)
    if default is not None:
        item.default_value = default
    return item


def boxes_along_line_group(name: str = "Boxes Along Line") -> bpy.types.NodeTree:
    """``Count`` boxes of ``Size`` (m) instanced at ``Start`` + i * ``Offset``, joined to the input geometry.

    Used for sleepers (and anything else spaced along a straight line); the boxes stay
    instances, which export reads through the depsgraph's instance list.
    """
    group = bpy.data.node_groups.get(name)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    if hasattr(group, "is_modifier"):
        group.is_modifier = True
    _socket(group, "Geometry", "INPUT", "NodeSocketGeometry")
    _socket(group, "Count", "INPUT", "NodeSocketInt", 10)
    _socket(group, "Start", "INPUT", "NodeSocketVector", (0.0, 0.0, 0.0))
    _socket(group, "Offset", "INPUT", "NodeSocketVector", (0.6, 0.0, 0.0))
    _socket(group, "Size", "INPUT", "NodeSocketVector", (0.26, 2.6, 0.22))
    _socket(group, "Geometry", "OUTPUT", "NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    group_in = nodes.new("NodeGroupInput")
    group_out = nodes.new("NodeGroupOutput")
    line = nodes.new("GeometryNodeMeshLine")
    line.mode = "OFFSET"
    cube = nodes.new("GeometryNodeMeshCube")
    instance = nodes.new("GeometryNodeInstanceOnPoints")
    join = nodes.new("GeometryNodeJoinGeometry")
    links.new(group_in.outputs["Count"], line.inputs["Count"])
    links.new(group_in.outputs["Start"], line.inputs["Start Location"])
    links.new(group_in.outputs["Offset"], line.inputs["Offset"])
    links.new(group_in.outputs["Size"], cube.inputs["Size"])
    links.new(line.outputs["Mesh"], instance.inputs["Points"])
    links.new(cube.outputs["Mesh"], instance.inputs["Instance"])
    links.new(group_in.outputs["Geometry"], join.inputs["Geometry"])
    links.new(instance.outputs["Instances"], join.inputs["Geometry"])
    links.new(join.outputs["Geometry"], group_out.inputs["Geometry"])
    for i, node in enumerate((group_in, line, cube, instance, join, group_out)):
        node.location = (200 * i, 0)
    return group


def add_group_modifier(obj: bpy.types.Object, group: bpy.types.NodeTree, inputs: dict) -> bpy.types.Modifier:
    """Add a Geometry Nodes modifier running ``group`` on ``obj``; ``inputs`` maps socket names to values."""
    modifier = obj.modifiers.new(group.name, "NODES")
    modifier.node_group = group
    for name, value in inputs.items():
        set_modifier_input(modifier, name, value)
    return modifier
