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
from .mesh_objects import mesh_object, tag

REFLECTIVITY = 0.55  # painted metal (Staubli's melon-yellow; an assumption, not measured)


class RobotArm:
    """One arm: ``links[0]`` the base (placed on the floor), ``links[i]`` turned by joint ``i``."""

    def __init__(self, model: ArmModel, collection, index: int, meshes: list | None = None):
        """``meshes``: per link ``(vertices, triangles)`` in its frame (a URDF's own meshes); default its capsules."""
        self.model = model
        self.links = []
        meshes = link_meshes(model) if meshes is None else meshes
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
            if self.model.fixed is not None:  # a URDF joint: its fixed turn (rpy), then the joint's
                from ..geometry.kinematics import axis_rotations

                local = np.eye(4)
                local[:3, :3] = self.model.fixed[i] @ axis_rotations(axis, np.array(angle))
                local[:3, 3] = self.model.origins[i]
                self.links[i + 1].matrix_basis = Matrix(local.tolist())
                continue
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


def _import_mesh(path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3), triangles (m, 3))`` of a link mesh file in its own coordinates (STL, OBJ, DAE, glTF)."""
    from ..errors import InputError
    from ..geometry.primitives import merge

    before = set(bpy.data.objects)
    suffix = path.suffix.lower()
    try:
        if suffix == ".stl":
            bpy.ops.wm.stl_import(filepath=str(path))
        elif suffix == ".obj":
            bpy.ops.wm.obj_import(filepath=str(path), up_axis="Z", forward_axis="Y")  # the file's own axes
        elif suffix == ".dae":
            bpy.ops.wm.collada_import(filepath=str(path))
        elif suffix in (".glb", ".gltf"):
            bpy.ops.import_scene.gltf(filepath=str(path))
        else:
            raise InputError(f"{where}: mesh {path.name}: expected .stl, .obj, .dae, .glb or .gltf")
    except (RuntimeError, AttributeError) as err:
        raise InputError(
            f"{where}: Blender cannot import {path.name} ({str(err).strip().splitlines()[-1] if str(err).strip() else type(err).__name__})"
        ) from None
    objects = [o for o in bpy.data.objects if o not in before]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    parts = []
    for obj in objects:
        if obj.type != "MESH":
            continue
        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        mesh.calc_loop_triangles()
        v = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", v)
        t = np.empty(len(mesh.loop_triangles) * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", t)
        world = np.array(evaluated.matrix_world)
        parts.append((v.reshape(-1, 3).astype(float) @ world[:3, :3].T + world[:3, 3], t.reshape(-1, 3)))
        evaluated.to_mesh_clear()
    for obj in objects:
        bpy.data.objects.remove(obj, do_unlink=True)
    if not parts:
        raise InputError(f"{where}: mesh {path.name} holds no triangles")
    return merge(parts)


def load_urdf_arm(path: str):
    """A :class:`~bpy_pipeline.geometry.urdf.MeshedArm` from a URDF: its chain and its links' visual meshes (link frames)."""
    from pathlib import Path

    from ..geometry.primitives import merge
    from ..geometry.urdf import MeshedArm, arm_from_urdf, read_urdf

    urdf = read_urdf(path)
    meshes = []
    for link, visuals in zip(urdf.links, urdf.visuals):
        parts = []
        for file, origin, scale in visuals:
            v, t = _import_mesh(Path(file), f"{path}: link {link!r}")
            parts.append(((v * scale) @ origin[:3, :3].T + origin[:3, 3], t))
        meshes.append(merge(parts) if parts else (np.zeros((0, 3)), np.zeros((0, 3), np.int32)))
    return MeshedArm(arm_from_urdf(urdf, [m[0] for m in meshes]), meshes)
