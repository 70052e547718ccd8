"""Differences between Blender versions, gated on ``bpy.app.version``, in one place."""

from __future__ import annotations

from collections.abc import Callable

import bpy
import numpy as np

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
    return get_modifier_inputs(modifier, [name])[name]


def get_modifier_inputs(modifier: bpy.types.Modifier, names) -> dict:
    """``{name: value}`` of the Geometry Nodes modifier inputs called ``names`` (the group's interface read once)."""
    items = interface_inputs(modifier.node_group)
    return {name: _input_value(modifier, items[name]) for name in names}


def _input_value(modifier: bpy.types.Modifier, item):
    """The value of the Geometry Nodes modifier input of interface socket ``item``."""
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


def instance_attribute(instancer, attribute: str, modifier_input: str) -> Callable[[int], int] | None:
    """The INT named attribute ``attribute`` of an evaluated instancer's instances, as a function of the
    instance's index in the depsgraph's order (0 where it has no value); None where it has none.

    From 5.3 each instance's own value is read (``instances_pointcloud()`` of its evaluated geometry).
    In 4.5 that point cloud is never freed (Blender prints "Not freed memory blocks" when it exits; 5.3
    frees it; the releases between are not checked), so before 5.3 every instance takes the value of the
    instancer's last Geometry Nodes modifier input named ``modifier_input``: exact for groups that store
    that input on every instance, as the builders' groups do; per-instance values need 5.3.
    """
    modifiers = [m for m in instancer.original.modifiers if m.type == "NODES" and m.node_group is not None]
    if not modifiers:
        return None  # only Geometry Nodes store attributes on instances
    if VERSION < (5, 3, 0):
        # each interface read once
        given = [(m, items[modifier_input]) for m in modifiers for items in [interface_inputs(m.node_group)] if modifier_input in items]
        value = int(_input_value(*given[-1])) if given else 0
        return (lambda index: value) if value > 0 else None
    geometry = instancer.evaluated_geometry()  # held while read
    points = geometry.instances_pointcloud()
    found = points.attributes.get(attribute) if points is not None else None
    if found is None or found.data_type != "INT":
        return None
    ids = np.empty(len(found.data), np.int32)
    found.data.foreach_get("value", ids)
    return lambda index: int(ids[index]) if index < len(ids) else 0
