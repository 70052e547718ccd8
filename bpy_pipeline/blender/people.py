"""Articulated procedural people in Blender (bpy): an armature per person, a body mesh skinned to it.

One armature datablock holds the skeleton of :mod:`~bpy_pipeline.geometry.human` at height 1
(bones at the joints, each bone's tail at its child's joint); every person is an armature
*object* sharing it, scaled by its height and placed by its ``placement``, with a body mesh child
deformed by an Armature modifier. The body is the union of the skeleton's capsules (three builds:
slim, medium, broad), each vertex weighted 1 to its segment's bone, so limbs move rigidly and
the evaluated mesh equals the capsule meshes of :func:`~bpy_pipeline.geometry.human.body_mesh`.

A new frame re-poses the people already built (pose bones' ``matrix_basis``) and hides the
unused ones; nothing is rebuilt. External person meshes listed in an assets manifest
(``assets_manifest/assets.yaml``: glTF or OBJ, with sha256 and licence) replace the procedural
bodies when the manifest lists any: they are imported once and placed standing in their own pose.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..assets import MANIFEST, AssetEntry, read_manifest
from ..errors import InputError
from ..geometry import human
from .mesh_objects import mesh_data, tag

BONE_TAILS = {"head": (0.0, 0.0, 1.0), "forearm_l": (0.0, 0.135, 0.38), "forearm_r": (0.0, -0.135, 0.38), "foot_l": (0.12, 0.085, 0.02),
              "foot_r": (0.12, -0.085, 0.02)}
BONE_CHILD = {"pelvis": "spine", "spine": "head", "upper_arm_l": "forearm_l", "upper_arm_r": "forearm_r", "thigh_l": "shank_l", "shank_l": "foot_l",
              "thigh_r": "shank_r", "shank_r": "foot_r"}
SKELETON = "LiDAR Person Skeleton"


def skeleton() -> bpy.types.Armature:
    """The shared armature datablock (created once per Blender session): one bone per segment, height 1."""
    data = bpy.data.armatures.get(SKELETON)
    if data is not None:
        return data
    data = bpy.data.armatures.new(SKELETON)
    holder = bpy.data.objects.new(SKELETON + " (edit)", data)
    bpy.context.scene.collection.objects.link(holder)
    view_layer = bpy.context.view_layer
    previous = view_layer.objects.active
    view_layer.objects.active = holder
    bpy.ops.object.mode_set(mode="EDIT")
    bones = {}
    for s, name in enumerate(human.SEGMENT_NAMES):
        bone = data.edit_bones.new(name)
        bone.head = human.JOINT[s]
        child = BONE_CHILD.get(name)
        bone.tail = human.JOINT[human.SEGMENT_INDEX[child]] if child else np.asarray(BONE_TAILS[name])
        bone.roll = 0.0
        parent = human.PARENT[s]
        if parent >= 0:
            bone.parent = bones[human.SEGMENT_NAMES[parent]]
        bones[name] = bone
    bpy.ops.object.mode_set(mode="OBJECT")
    for segment, dof, _, limits in human.DOFS:  # the joint ranges the poses keep to, for anyone posing by hand
        data.bones[segment][f"limit_{dof}_deg"] = list(limits)
    view_layer.objects.active = previous
    bpy.data.objects.remove(holder)
    data.use_fake_user = True  # outlives its edit holder; every person shares it
    return data


def rest_matrices(data: bpy.types.Armature) -> np.ndarray:
    """``(s, 4, 4)`` armature-space rest matrices of the bones, in segment order (as Blender stores them)."""
    return np.array([np.array(data.bones[name].matrix_local) for name in human.SEGMENT_NAMES])


def pose_bases(frames: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """``(s, 4, 4)`` pose-bone ``matrix_basis`` that put each bone on its segment frame.

    frames : (s, 4, 4) segment frames in the person's frame at height 1 (translations in units
    of the height); rest : the bones' rest matrices. Blender poses a bone as
    ``pose = pose_parent @ rest_parent^-1 @ rest @ basis`` (root: ``rest @ basis``), and a bone
    follows its segment when ``pose = frame @ rotation(rest)``.
    """
    rotation = np.repeat(np.eye(4)[None], len(rest), axis=0)
    rotation[:, :3, :3] = rest[:, :3, :3]
    pose = frames @ rotation
    bases = np.empty_like(pose)
    for s, parent in enumerate(human.PARENT):
        start = rest[s] if parent < 0 else pose[parent] @ np.linalg.inv(rest[parent]) @ rest[s]
        bases[s] = np.linalg.inv(start) @ pose[s]
    return bases


def body_data(build: str) -> bpy.types.Mesh:
    """The body mesh of a build (``slim``, ``medium``, ``broad``) at height 1 in the rest pose, with one vertex group per segment."""
    name = f"LiDAR Person Body ({build})"
    mesh = bpy.data.meshes.get(name)
    if mesh is not None:
        return mesh
    frames = human.segment_frames(np.zeros(len(human.DOFS)), 1.0)
    a, b, r = human.capsules(frames, 1.0, human.BUILDS[build])
    vertices, triangles, owner = human.body_mesh(a, b, r)
    mesh = mesh_data(name, vertices, triangles)
    holder = bpy.data.objects.new(name + " (groups)", mesh)
    segment = human.CAPSULE_SEGMENT[owner]
    for s, seg_name in enumerate(human.SEGMENT_NAMES):
        group = holder.vertex_groups.new(name=seg_name)
        group.add(np.flatnonzero(segment == s).tolist(), 1.0, "REPLACE")
    bpy.data.objects.remove(holder)
    mesh.use_fake_user = True
    return mesh


class PersonRig:
    """One person in the scene: an armature object and its skinned body mesh child, tagged ``person``."""

    def __init__(self, collection, index: int):
        self.armature = bpy.data.objects.new(f"person_{index:03d}_rig", skeleton())
        collection.objects.link(self.armature)
        self.body = bpy.data.objects.new(f"person_{index:03d}", body_data("medium"))
        collection.objects.link(self.body)
        self.body.parent = self.armature  # its vertex groups (one per bone) come with the mesh
        modifier = self.body.modifiers.new("Armature", "ARMATURE")
        modifier.object = self.armature
        self.rest = rest_matrices(self.armature.data)

    def show(self, person: human.Person, build: str, instance: int, reflectivity: float) -> None:
        """Pose, scale and place the rig as ``person``."""
        local = np.linalg.inv(person.placement) @ person.frames  # segment frames in the person's frame
        local[:, :3, 3] /= person.height
        bases = pose_bases(local, self.rest)
        if self.armature.pose is None:  # a new armature object gets its pose on the first evaluation
            bpy.context.view_layer.update()
        for name, basis in zip(human.SEGMENT_NAMES, bases):
            self.armature.pose.bones[name].matrix_basis = Matrix(basis.tolist())
        world = person.placement.copy()
        world[:3, :3] *= person.height
        self.armature.matrix_world = Matrix(world.tolist())
        self.body.data = body_data(build)
        tag(self.body, "person", "diffuse", reflectivity, instance)
        self.set_hidden(False)

    def set_hidden(self, hidden: bool) -> None:
        for obj in (self.armature, self.body):
            obj.hide_render = hidden
            obj.hide_viewport = hidden

    def alive(self) -> bool:
        try:
            return self.body.name in bpy.data.objects and self.armature.name in bpy.data.objects
        except ReferenceError:
            return False


IMPORTABLE = (".gltf", ".glb", ".obj")  # what import_asset reads


def load_assets(path: str | Path | None = None, kind: str = "person") -> list[AssetEntry]:
    """The entries of ``kind`` and no set in an assets manifest whose file is present and matches its sha256.

    Read and checked by :func:`bpy_pipeline.assets.read_manifest` (entries of a named set are for
    ``scene.population``); an absent manifest gives none (the procedural models stand in), and so
    does an entry whose file is missing. A file that is not glTF/GLB or OBJ is an ``InputError``.
    """
    path = Path(path) if path else MANIFEST
    if not path.exists():
        return []
    chosen = [e for e in read_manifest(path) if e.kind == kind and not e.set]
    for entry in chosen:
        if entry.path.suffix.lower() not in IMPORTABLE:
            raise InputError(f"{entry.where}.path: expected a .gltf, .glb or .obj file for the hall's people, got {entry.path.name!r}")
    return chosen


def import_asset(asset: AssetEntry) -> tuple[bpy.types.Mesh, np.ndarray]:
    """The asset as one mesh datablock, feet on z = 0, centred on x = y = 0, height 1; and its capsule.

    Returns ``(mesh, capsule)`` where ``capsule`` is ``(a (3,), b (3,), radius)`` at height 1:
    a vertical capsule around the mesh (its collision shape).
    """
    name = f"LiDAR Asset {asset.name}"
    mesh = bpy.data.meshes.get(name)
    if mesh is None:
        before = set(bpy.data.objects)
        if asset.path.suffix.lower() == ".obj":
            bpy.ops.wm.obj_import(filepath=str(asset.path))
        else:
            bpy.ops.import_scene.gltf(filepath=str(asset.path))
        imported = [o for o in bpy.data.objects if o not in before]
        parts = []
        for obj in imported:
            if obj.type == "MESH":
                m = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
                m.calc_loop_triangles()
                v = np.empty(len(m.vertices) * 3, np.float32)
                m.vertices.foreach_get("co", v)
                t = np.empty(len(m.loop_triangles) * 3, np.int32)
                m.loop_triangles.foreach_get("vertices", t)
                world = np.array(obj.matrix_world)
                parts.append((v.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3], t.reshape(-1, 3)))
                obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
        for obj in imported:
            bpy.data.objects.remove(obj)
        if not parts:
            raise InputError(f"asset {asset.name!r}: {asset.path.name} holds no mesh")
        from ..geometry.primitives import merge

        vertices, triangles = merge(parts)
        low, high = vertices.min(axis=0), vertices.max(axis=0)
        from ..assets import upright

        if not upright("person", high - low):  # a lying person would fit nowhere: say so instead of placing none
            extent = ", ".join(f"{k} {v:.2f}" for k, v in zip("xyz", high - low))
            raise InputError(
                f"asset {asset.name!r}: {asset.path.name} does not stand upright as a person when read Y up as glTF and OBJ are (extent {extent}); re-export "
                "it Y up, or give it a set and its up_axis in the manifest and place it with scene.population"
            )
        vertices = (vertices - [(low[0] + high[0]) / 2, (low[1] + high[1]) / 2, low[2]]) / (high[2] - low[2])
        mesh = mesh_data(name, vertices, triangles)
        mesh.use_fake_user = True
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    v = v.reshape(-1, 3).astype(float)
    radius = float(np.linalg.norm(v[:, :2], axis=1).max())
    return mesh, (np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), radius)


class AssetPerson:
    """An external person mesh placed standing: one object, collision by a vertical capsule."""

    def __init__(self, collection, index: int):
        self.body = bpy.data.objects.new(f"person_{index:03d}", bpy.data.meshes.new(f"person_{index:03d}_empty"))
        collection.objects.link(self.body)

    def show(self, mesh, height: float, position, yaw: float, instance: int, reflectivity: float) -> None:
        self.body.data = mesh
        self.body.location = (position[0], position[1], 0.0)
        self.body.rotation_euler = (0.0, 0.0, yaw)
        self.body.scale = (height, height, height)
        tag(self.body, "person", "diffuse", reflectivity, instance)
        self.body.hide_render = self.body.hide_viewport = False

    def set_hidden(self, hidden: bool) -> None:
        self.body.hide_render = self.body.hide_viewport = hidden
