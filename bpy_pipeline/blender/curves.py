"""Curve objects of the scene as world-space polylines (bpy), for trajectories along them.

The curve is read from the evaluated depsgraph, so its resolution, modifiers and parents
apply: the polyline is the one Blender draws. A bevelled or extruded curve (a wire, a rail)
is read through a temporary copy without bevel or extrusion, so the result is always its
centreline; the user's object is never changed.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..errors import InputError

SHAPE_KEYS = ("bevel_depth", "extrude")  # curve settings that turn the line into a surface


def curve_polyline(name: str, depsgraph=None, where: str = "sensor.trajectory.curve") -> np.ndarray:
    """``(k, 3)`` float64 world points along the curve object ``name``, in spline order.

    A cyclic spline repeats its first point at the end. ``InputError`` naming ``where`` when the
    object is missing, is not a curve, has no points, or holds more than one spline.
    """
    obj = bpy.data.objects.get(name)
    if obj is None:
        curves = sorted(o.name for o in bpy.data.objects if o.type == "CURVE")
        raise InputError(f"{where}: no object {name!r} in the scene; curve objects: {', '.join(curves) or 'none'}")
    if obj.type != "CURVE":
        raise InputError(f"{where}: object {name!r} is a {obj.type.lower()}, not a curve")
    if len(obj.data.splines) != 1:
        raise InputError(f"{where}: curve {name!r} holds {len(obj.data.splines)} splines; a trajectory follows exactly one")
    if any(getattr(obj.data, key) for key in SHAPE_KEYS) or obj.data.bevel_object is not None:
        return _centreline_of_copy(obj, where)
    return _evaluated_polyline(obj, depsgraph or bpy.context.evaluated_depsgraph_get(), where)


def _evaluated_polyline(obj, depsgraph, where: str) -> np.ndarray:
    """World points of the evaluated curve's single chain of edges."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        vertices = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", vertices)
        edges = np.empty(len(mesh.edges) * 2, np.int32)
        mesh.edges.foreach_get("vertices", edges)
        faces = len(mesh.polygons)
    finally:
        evaluated.to_mesh_clear()
    vertices, edges = vertices.reshape(-1, 3).astype(np.float64), edges.reshape(-1, 2)
    if faces or len(vertices) < 2:
        raise InputError(f"{where}: curve {obj.name!r} evaluates to {len(vertices)} points and {faces} faces, not a line")
    chain = np.arange(len(vertices) - 1)
    if len(edges) == len(vertices) and (edges[-1] == [len(vertices) - 1, 0]).all():
        vertices = np.vstack([vertices, vertices[:1]])  # cyclic: close the loop
        edges = edges[:-1]
    if not (len(edges) == len(chain) and (edges[:, 0] == chain).all() and (edges[:, 1] == chain + 1).all()):
        raise InputError(f"{where}: curve {obj.name!r} does not evaluate to one chain of points (its modifiers split or reorder it)")
    matrix = np.array(evaluated.matrix_world, np.float64)
    return vertices @ matrix[:3, :3].T + matrix[:3, 3]


def _centreline_of_copy(obj, where: str) -> np.ndarray:
    """The polyline of a temporary copy of ``obj`` with bevel and extrusion off."""
    data = obj.data.copy()
    for key in SHAPE_KEYS:
        setattr(data, key, 0.0)
    data.bevel_object = None
    copy = obj.copy()
    copy.data = data
    bpy.context.scene.collection.objects.link(copy)
    try:
        bpy.context.view_layer.update()
        return _evaluated_polyline(copy, bpy.context.evaluated_depsgraph_get(), where)
    finally:
        bpy.data.objects.remove(copy, do_unlink=True)
        bpy.data.curves.remove(data)
