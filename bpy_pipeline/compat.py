"""Differences between Blender versions, gated on ``bpy.app.version``, in one place."""

from __future__ import annotations

import bpy

VERSION = tuple(bpy.app.version)


def interface_inputs(group: bpy.types.NodeTree) -> dict:
    """Input sockets of a node group's interface, by name."""
    return {item.name: item for item in group.interface.items_tree if item.item_type == "SOCKET" and item.in_out == "INPUT"}


def set_modifier_input(modifier: bpy.types.Modifier, name: str, value) -> None:
    """Set the Geometry Nodes modifier input called ``name`` (its interface socket name).

    Up to 5.1 the inputs are ID properties of the modifier keyed by socket identifier
    (``modifier["Socket_2"] = 5``); from 5.2 they are RNA structs under
    ``modifier.properties.inputs.<identifier>.value`` and item assignment raises.
    """
    item = interface_inputs(modifier.node_group).get(name)
    if item is None:
        raise KeyError(f"node group {modifier.node_group.name!r} has no input {name!r}")
    if VERSION >= (5, 2, 0):
        getattr(modifier.properties.inputs, item.identifier).value = value
    else:
        modifier[item.identifier] = value


def get_modifier_input(modifier: bpy.types.Modifier, name: str):
    """The value of the Geometry Nodes modifier input called ``name``."""
    item = interface_inputs(modifier.node_group)[name]
    if VERSION >= (5, 2, 0):
        return getattr(modifier.properties.inputs, item.identifier).value
    return modifier[item.identifier]


def set_node_option(node: bpy.types.Node, name: str, value: str) -> None:
    """Set a node's enum option ``name`` (e.g. ``mode``) to ``value``, an RNA identifier such as ``"Z_UP"``.

    Up to 4.5 such options are node properties (``node.mode = "Z_UP"``); from 5.x many became menu
    input sockets (``node.inputs["Mode"]``) whose items are named ``"Z Up"``.
    """
    if name in node.bl_rna.properties:
        setattr(node, name, value)
        return
    socket = node.inputs.get(name.replace("_", " ").title())
    if socket is None or socket.type != "MENU":
        raise KeyError(f"node {node.bl_idname} has no option {name!r}")
    socket.default_value = value.replace("_", " ").title()
