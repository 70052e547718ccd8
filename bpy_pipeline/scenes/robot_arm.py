"""A six-axis arm in Blender (bpy): a base and six link objects in a parent chain, one joint angle each.

The chain mirrors :mod:`~bpy_pipeline.geometry.kinematics`: link ``i`` is parented to link
``i - 1``, sits at its joint's ``origin`` (its ``location``) and turns about its joint's axis
(``rotation_axis_angle``), so Blender's evaluated world matrices are the forward kinematics and a
user can pose the arm joint by joint. Each link's mesh is the union of its capsules (inscribed),
and every object carries class ``robot arm`` and the robot's instance id.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from ..geometry.kinematics import ArmModel
from ..geometry.objects import link_meshes
from .objects import mesh_object, tag

REFLECTIVITY = 0.55  # painted metal (Staubli's melon-yellow; an assumption, not measured)


class RobotArm:
    """One arm: ``links[0]`` the base (placed on the floor), ``links[i]`` turned by joint ``i``."""

    def __init__(self, model: ArmModel, collection, index: int):
        self.model = model
        self.links = []
        meshes = link_meshes(model)
        for link, mesh in enumerate(meshes):
            name = f"robot_{index:02d}_" + ("base" if link == 0 else f"link_{link}")
            parent = self.links[-1] if self.links else None
            obj = mesh_object(name, mesh, collection, parent=parent)
            if link > 0:
                obj.location = model.origins[link - 1]
                obj.rotation_mode = "AXIS_ANGLE"
                obj["joint_limits_deg"] = [float(np.degrees(model.lower[link - 1])), float(np.degrees(model.upper[link - 1]))]
            self.links.append(obj)

    def show(self, base: np.ndarray, q: np.ndarray, instance: int) -> None:
        """Place the base at ``base`` (4, 4) and set joint angles ``q`` (radians)."""
        self.links[0].matrix_world = Matrix(np.asarray(base, float).tolist())
        for i, angle in enumerate(q):
            axis = self.model.axes[i]
            self.links[i + 1].rotation_axis_angle = (float(angle), float(axis[0]), float(axis[1]), float(axis[2]))
        for obj in self.links:
            tag(obj, "robot arm", "diffuse", REFLECTIVITY, instance)
        self.set_hidden(False)

    def set_hidden(self, hidden: bool) -> None:
        for obj in self.links:
            obj.hide_render = hidden
            obj.hide_viewport = hidden

    def world_frames(self) -> np.ndarray:
        """``(j + 1, 4, 4)`` evaluated world matrices of the links (call after a depsgraph update)."""
        return np.array([np.array(obj.matrix_world) for obj in self.links])

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for obj in self.links)
        except ReferenceError:
            return False
