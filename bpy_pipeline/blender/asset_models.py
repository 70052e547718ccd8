"""Asset files in Blender (bpy): imported once, turned upright, normalised, posed per frame.

:func:`load_models` imports each entry of an asset set (``bpy_pipeline/assets.py`` checks the
manifest) with Blender's own importer (glTF, OBJ, FBX; a .blend's objects are appended), applies the
entry's up axis (checked: a file that does not stand upright is an ``InputError`` naming the entry),
and normalises it to height 1, feet on z = 0, centred on x = y = 0, facing +x as the file does.

* A mesh-only asset becomes one mesh per part: ``body`` and ``glass`` (the triangles of materials
  whose names match ``glass_materials``: a car's windows, labelled ``lidar_material: glass``).
* An asset with an armature keeps its imported objects as a hidden template; each frame a pose is
  drawn from the frame's generator: a random keyframe of a random animation when the file has any
  (the human-robot paper: 22 models x 9 animations), else random rotations within the bones'
  ``LIMIT_ROTATION`` constraints. The posed mesh (evaluated through the depsgraph) is what placement
  checks, and each slot gets its own armature object posed the same way.
"""

from __future__ import annotations

import re

import bpy
import numpy as np
from mathutils import Matrix

from ..assets import asset_set, auto_unit_scale, orientation_error, up_rotation
from ..errors import InputError
from .mesh_objects import mesh_data, tag

TEMPLATES = "LiDAR Asset Templates"
GLASS_REFLECTIVITY = 0.08
BODY_REFLECTIVITY = {"person": 0.35, "car": 0.45, "robot": 0.55}
MAX_CACHED_POSES = 256  # posed meshes kept per rigged asset (a keyframe's mesh is evaluated once; the cache only saves time)


def _matrix(m) -> Matrix:
    return Matrix(np.asarray(m, float).tolist())


def _import(entry) -> list:
    """The objects the file brings into the scene (a .blend's objects appended)."""
    before = set(bpy.data.objects)
    suffix = entry.path.suffix.lower()
    try:
        if suffix in (".glb", ".gltf"):
            bpy.ops.import_scene.gltf(filepath=str(entry.path))
        elif suffix == ".obj":
            bpy.ops.wm.obj_import(filepath=str(entry.path), up_axis="Y", forward_axis="NEGATIVE_Z")
        elif suffix == ".fbx":
            bpy.ops.import_scene.fbx(filepath=str(entry.path), axis_up="Y", axis_forward="-Z", use_manual_orientation=True)
        else:
            with bpy.data.libraries.load(str(entry.path), link=False) as (source, target):
                target.objects = list(source.objects)
            for obj in target.objects:
                if obj is not None:
                    bpy.context.scene.collection.objects.link(obj)
    except (RuntimeError, AttributeError) as err:
        raise InputError(
            f"{entry.where}.path: Blender cannot import {entry.path.name} ({str(err).strip().splitlines()[-1] if str(err).strip() else type(err).__name__})"
        ) from None
    shapes = {b.custom_shape for o in bpy.data.objects if o.type == "ARMATURE" and o.pose for b in o.pose.bones if b.custom_shape}
    return [o for o in bpy.data.objects if o not in before and o not in shapes and o.users_collection]


def world_arrays(obj, depsgraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(vertices (n, 3) world, triangles (m, 3), material index (m,))`` of an evaluated mesh object."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        mesh.calc_loop_triangles()
        v = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", v)
        t = np.empty(len(mesh.loop_triangles) * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", t)
        m = np.empty(len(mesh.loop_triangles), np.int32)
        mesh.loop_triangles.foreach_get("material_index", m)
    finally:
        evaluated.to_mesh_clear()
    world = np.array(evaluated.matrix_world)
    return v.reshape(-1, 3).astype(float) @ world[:3, :3].T + world[:3, 3], t.reshape(-1, 3), m


class AssetModel:
    """One imported asset: ``shape(rng) -> (vertices (n, 3) unit height, triangles, detail)`` and its parts to show.

    normal : (4, 4) imported world -> unit frame (turn upright, centre, scale to height 1)
    """

    def __init__(self, entry):
        self.entry = entry
        self.kind = entry.kind
        actions_before = set(bpy.data.actions)
        objects = _import(entry)
        self.imported_actions = [a for a in bpy.data.actions if a not in actions_before]  # this import's, not an earlier one's
        meshes = [o for o in objects if o.type == "MESH"]
        if not meshes:
            raise InputError(f"{entry.where}.path: {entry.path.name} holds no mesh")
        self.armature = next((o for o in objects if o.type == "ARMATURE"), None)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        arrays = [world_arrays(o, depsgraph) for o in meshes]
        all_v = np.concatenate([a[0] for a in arrays])
        suffix = entry.path.suffix.lower()
        message = orientation_error(entry, all_v, suffix)
        if message:
            for obj in objects:
                bpy.data.objects.remove(obj, do_unlink=True)
            raise InputError(message)
        turn = np.eye(4)
        turn[:3, :3] = up_rotation(suffix, entry.up_axis)
        upright = all_v @ turn[:3, :3].T
        low, high = upright.min(axis=0), upright.max(axis=0)
        height = float(high[2] - low[2])
        if height <= 0:
            raise InputError(f"{entry.where}.path: {entry.path.name} is flat (no height)")
        self.file_height = height  # file units
        self.unit_scale = entry.unit_scale or auto_unit_scale(entry.kind, height)
        centre = np.eye(4)
        centre[:3, 3] = -np.array([(low[0] + high[0]) / 2, (low[1] + high[1]) / 2, low[2]])
        self.normal = np.diag([1 / height, 1 / height, 1 / height, 1.0]) @ centre @ turn
        self.objects = objects
        self.cache: dict = {}
        if self.armature is None:
            self._static_parts(meshes, arrays)
            for obj in objects:
                bpy.data.objects.remove(obj, do_unlink=True)
        else:
            self._template(objects, meshes)

    # -- mesh-only assets: one datablock per part
    def _static_parts(self, meshes, arrays) -> None:
        parts = {"body": [], "glass": []}
        for obj, (v, t, m) in zip(meshes, arrays):
            names = [(slot.material.name.lower() if slot.material else "") for slot in obj.material_slots]
            glass_slots = [k for k, n in enumerate(names) if any(g in n for g in self.entry.glass_materials)]
            is_glass = np.isin(m, glass_slots)
            unit = v @ self.normal[:3, :3].T + self.normal[:3, 3]
            for part, rows in (("body", ~is_glass), ("glass", is_glass)):
                if rows.any():
                    used, local = np.unique(t[rows], return_inverse=True)
                    parts[part].append((unit[used], local.reshape(-1, 3)))
        from ..geometry.primitives import merge

        self.parts = {}
        for part, items in parts.items():
            if items:
                v, t = merge(items)
                name = f"LiDAR Asset {self.entry.name} {part}"
                old = bpy.data.meshes.get(name)
                if old is not None:
                    bpy.data.meshes.remove(old)
                mesh = mesh_data(name, v, t)
                mesh.use_fake_user = True
                self.parts[part] = (mesh, v, t)
        v, t = merge([(p[1], p[2]) for p in self.parts.values()])
        self.unit_mesh = (v, t)

    # -- rigged assets: the imported objects stay as a hidden template, posed to draw shapes
    def _template(self, objects, meshes) -> None:
        collection = bpy.data.collections.get(TEMPLATES) or bpy.data.collections.new(TEMPLATES)
        if collection.name not in bpy.context.scene.collection.children:
            bpy.context.scene.collection.children.link(collection)
        for obj in objects:
            for c in list(obj.users_collection):
                c.objects.unlink(obj)
            collection.objects.link(obj)
            obj.hide_render = True  # never exported; still evaluated for its posed mesh
        self.meshes = meshes
        self.import_matrix = {o.name: np.array(o.matrix_world) for o in objects}
        self.actions = _actions_of(self.armature, self.imported_actions)
        self.limits = _rotation_limits(self.armature)
        self.parts = {}

    def shape(self, rng: np.random.Generator):
        """A mesh of this asset at unit height (feet on z = 0), the pose drawn from ``rng``: ``(vertices, triangles, detail)``."""
        if self.armature is None:
            return self.unit_mesh[0], self.unit_mesh[1], {"pose": "as modelled"}
        pose = draw_pose(self, rng)
        key = pose["key"]
        if key not in self.cache:
            apply_pose(self.armature, self, pose)
            bpy.context.view_layer.update()
            depsgraph = bpy.context.evaluated_depsgraph_get()
            from ..geometry.primitives import merge

            v, t = merge([world_arrays(o, depsgraph)[:2] for o in self.meshes])
            unit = v @ self.normal[:3, :3].T + self.normal[:3, 3]
            lift = -unit[:, 2].min()
            unit[:, 2] += lift
            if len(self.cache) >= MAX_CACHED_POSES:  # poses within limits are new every draw: bound the memory
                self.cache.pop(next(iter(self.cache)))
            self.cache[key] = (unit, t, lift)
        unit, t, lift = self.cache[key]
        return unit, t, {"pose": pose["name"], "pose_key": key, "lift": lift, "angles": pose.get("angles")}


def _fcurves(action):
    """The F-curves of an action (Blender 4.4+ keeps them in a layered action's channelbags)."""
    curves = []
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", ()):
                curves.extend(bag.fcurves)
    return curves or list(getattr(action, "fcurves", ()))


BONE_PATH = re.compile(r'pose\.bones\["(.+)"\]\.(rotation_quaternion|rotation_euler|location|scale)$')


def _actions_of(armature, actions) -> list:
    """``[(name, keyframe times, [(bone, property, index, fcurve)])]`` of the ``actions`` that move this armature's bones."""
    out = []
    bones = set(armature.pose.bones.keys())
    for action in sorted(actions, key=lambda a: a.name):
        channels, times = [], set()
        for fc in _fcurves(action):
            match = BONE_PATH.match(fc.data_path)
            if match and match.group(1) in bones:
                channels.append((match.group(1), match.group(2), fc.array_index, fc))
                times.update(round(k.co[0], 3) for k in fc.keyframe_points)
        if channels:  # named as in the file (Blender's .001 of a second import dropped)
            out.append((re.sub(r"\.\d{3}$", "", action.name), sorted(times), channels))
    return out


def _rotation_limits(armature) -> dict:
    """``{bone: (min (3,), max (3,)) rad}`` from the bones' Limit Rotation constraints (local Euler XYZ)."""
    limits = {}
    for bone in armature.pose.bones:
        for c in bone.constraints:
            if c.type == "LIMIT_ROTATION":
                lo = [c.min_x if c.use_limit_x else 0.0, c.min_y if c.use_limit_y else 0.0, c.min_z if c.use_limit_z else 0.0]
                hi = [c.max_x if c.use_limit_x else 0.0, c.max_y if c.use_limit_y else 0.0, c.max_z if c.use_limit_z else 0.0]
                limits[bone.name] = (np.array(lo), np.array(hi))
    return limits


def draw_pose(model: AssetModel, rng: np.random.Generator) -> dict:
    """A pose: a random keyframe of a random animation, else Euler angles uniform within each limited bone's limits."""
    if model.actions:
        k = int(rng.integers(len(model.actions)))
        name, times, _ = model.actions[k]
        t = float(times[int(rng.integers(len(times)))])
        return {"name": f"{name}@{t:g}", "key": (k, t), "action": k, "time": t}
    angles = {bone: rng.uniform(lo, hi) for bone, (lo, hi) in sorted(model.limits.items())}
    key = tuple((b, tuple(np.round(a, 9))) for b, a in angles.items())
    return {"name": "limits" if angles else "rest", "key": key, "angles": angles}


def apply_pose(armature, model: AssetModel, pose: dict) -> None:
    """Pose ``armature`` (the template or a slot's own) as ``pose`` (:func:`draw_pose`)."""
    if armature.pose is None:  # a new armature object gets its pose on the first evaluation
        bpy.context.view_layer.update()
    for bone in armature.pose.bones:
        bone.matrix_basis = Matrix.Identity(4)
    if "action" in pose:
        _, _, channels = model.actions[pose["action"]]
        for bone, prop, index, fc in channels:
            getattr(armature.pose.bones[bone], prop)[index] = fc.evaluate(pose["time"])
        return
    for bone, angles in pose["angles"].items():
        pb = armature.pose.bones[bone]
        pb.rotation_mode = "XYZ"
        pb.rotation_euler = tuple(float(a) for a in angles)


def load_models(set_name: str, kind: str, where: str, manifest=None) -> list[AssetModel]:
    """The models of asset set ``set_name`` of ``kind`` in ``manifest`` (default: assets_manifest/assets.yaml), imported once per population."""
    return [AssetModel(entry) for entry in asset_set(set_name, kind, where, manifest)]


class AssetSlot:
    """One placed asset: per model it has shown, its own objects (parts, or an armature and its meshes)."""

    def __init__(self, collection, name: str):
        self.collection, self.name = collection, name
        self.objects: dict[str, list] = {}  # model name -> objects
        self.armatures: dict[str, object] = {}

    def _objects_for(self, model: AssetModel) -> list:
        key = model.entry.name
        if key not in self.objects:
            objs = []
            if model.armature is None:
                for k, (part, (mesh, _, _)) in enumerate(model.parts.items()):
                    obj = bpy.data.objects.new(self.name if not objs else f"{self.name}_{part}", mesh)
                    self.collection.objects.link(obj)
                    if objs:
                        obj.parent = objs[0]
                    obj["part"] = part
                    objs.append(obj)
            else:
                rig = bpy.data.objects.new(f"{self.name}_rig", model.armature.data)
                self.collection.objects.link(rig)
                self.armatures[key] = rig
                objs.append(rig)
                for mesh_obj in model.meshes:
                    obj = bpy.data.objects.new(self.name if len(objs) == 1 else f"{self.name}_{mesh_obj.name}", mesh_obj.data)
                    self.collection.objects.link(obj)
                    obj.modifiers.new("Armature", "ARMATURE").object = rig
                    obj["part"] = "body"
                    obj["template"] = mesh_obj.name
                    objs.append(obj)
            self.objects[key] = objs
        return self.objects[key]

    def show(self, model: AssetModel, placed, class_name: str, instance: int, reflectivity: float | None) -> None:
        """Show ``model`` as ``placed`` (:class:`~bpy_pipeline.population.placer.Placed`), tagged ``class_name``."""
        objs = self._objects_for(model)
        for key, others in self.objects.items():
            if key != model.entry.name:
                for obj in others:
                    obj.hide_render = obj.hide_viewport = True
        d = placed.shape.detail
        body = BODY_REFLECTIVITY[model.kind] if reflectivity is None else reflectivity
        scale = np.diag([d["scale"], d["scale"], d["scale"], 1.0])
        if model.armature is None:
            objs[0].matrix_world = _matrix(placed.matrix @ scale)
        else:
            lift = np.eye(4)
            lift[2, 3] = d["lift"]
            frame = placed.matrix @ scale @ lift @ model.normal
            rig = self.armatures[model.entry.name]
            rig.matrix_world = _matrix(frame @ model.import_matrix[model.armature.name])
            pose = draw_pose_of(model, d)
            apply_pose(rig, model, pose)
            for obj in objs[1:]:
                obj.matrix_world = _matrix(frame @ model.import_matrix[obj["template"]])
        for obj in objs:
            if obj.type == "MESH":
                glass = obj.get("part") == "glass"
                tag(obj, class_name, "glass" if glass else "diffuse", GLASS_REFLECTIVITY if glass else body, instance)
            obj.hide_render = obj.hide_viewport = False

    def set_hidden(self, hidden: bool) -> None:
        for objs in self.objects.values():
            for obj in objs:
                obj.hide_render = obj.hide_viewport = hidden

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for objs in self.objects.values() for obj in objs)
        except ReferenceError:
            return False


def draw_pose_of(model: AssetModel, detail: dict) -> dict:
    """The pose a shape was drawn in, from its detail (``pose_key``)."""
    key = detail["pose_key"]
    if model.actions and isinstance(key, tuple) and len(key) == 2 and isinstance(key[0], int):
        return {"action": key[0], "time": key[1]}
    return {"angles": {b: np.array(a) for b, a in key}}
