"""``scene.builder: primitives``: planes, boxes, spheres and cylinders at poses, for tests and calibration."""

from __future__ import annotations

import numpy as np

from ...geometry import primitives
from ...blender.mesh_objects import mesh_object, scene_collection, tag


def shape_mesh(shape):
    """``(vertices, triangles)`` of a :class:`~bpy_pipeline.builders.primitives.Shape` in its own frame."""
    size = shape.size if isinstance(shape.size, list) else [shape.size]
    if shape.type == "plane":
        return primitives.plane(size[0], size[-1])
    if shape.type == "box":
        return primitives.box(*(size * 3 if len(size) == 1 else size))
    if shape.type == "sphere":
        return primitives.uv_sphere(size[0], shape.segments)
    return primitives.cylinder(size[0], size[1], shape.segments)


def build(params) -> None:
    """One object per shape, tagged with its class, material and reflectivity."""
    collection = scene_collection()
    for i, shape in enumerate(params.shapes):
        obj = mesh_object(shape.name or f"{shape.type}_{i}", shape_mesh(shape), collection, shape.position, np.radians(shape.rotation_deg))
        tag(obj, shape.class_name, shape.material, shape.reflectivity)
