"""Export the project's own procedural models as asset files: the small, freely licensed test assets.

    python examples/assets/make_assets.py [OUT_DIR]     # default: assets_manifest/test_assets

Writes (all CC0-1.0, made by this project, no download):

* ``car_sedan.glb``: the procedural sedan (geometry/objects.py) as one mesh with four materials,
  ``paint``, ``window_glass``, ``interior`` and ``tyre`` (the window material becomes ``glass``);
* ``person_rigged.glb``: the procedural person (blender/people.py), 1.75 m, its body skinned to its
  skeleton, with four animations (standing, walking, sitting, crouching: three keyframes each, poses
  drawn within the joint limits of geometry/human.py from a fixed seed);
* ``robot_arm.obj``: the default six-axis arm in one pose (Y up, as OBJ files usually are).

It prints the sha256 of each file for assets_manifest/assets.yaml.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bpy_pipeline.geometry import human, kinematics  # noqa: E402
from bpy_pipeline.geometry.objects import STYLES, arm_mesh, car_parts  # noqa: E402
from bpy_pipeline.blender.mesh_objects import mesh_data  # noqa: E402
from bpy_pipeline.blender.people import body_data, pose_bases, rest_matrices, skeleton  # noqa: E402

CAR_MATERIALS = {"body": "paint", "windows": "window_glass", "interior": "interior", "tyres": "tyre"}
PERSON_HEIGHT = 1.75  # m
SEED = 14


def _only(objects) -> None:
    bpy.ops.object.select_all(action="DESELECT")
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]


def make_car(path: Path) -> None:
    parts = car_parts(STYLES[0])
    vertices, triangles, material, offset = [], [], [], 0
    for k, (part, (v, t)) in enumerate(parts.items()):
        vertices.append(v)
        triangles.append(t + offset)
        material.append(np.full(len(t), k, np.int32))
        offset += len(v)
    mesh = mesh_data("car_sedan", np.concatenate(vertices), np.concatenate(triangles))
    for part in parts:
        mesh.materials.append(bpy.data.materials.new(CAR_MATERIALS[part]))
    mesh.polygons.foreach_set("material_index", np.concatenate(material))
    mesh.update()
    obj = bpy.data.objects.new("car_sedan", mesh)
    bpy.context.scene.collection.objects.link(obj)
    _only([obj])
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", use_selection=True, export_animations=False)


def make_person(path: Path) -> None:
    data = skeleton()
    armature = bpy.data.objects.new("person_rig", data)
    bpy.context.scene.collection.objects.link(armature)
    body = bpy.data.objects.new("person_body", body_data("medium"))
    bpy.context.scene.collection.objects.link(body)
    body.parent = armature
    body.modifiers.new("Armature", "ARMATURE").object = armature
    armature.scale = (PERSON_HEIGHT,) * 3
    bpy.context.view_layer.update()
    rest = rest_matrices(data)
    rng = np.random.default_rng(SEED)
    armature.animation_data_create()
    for pose in human.POSES:
        action = bpy.data.actions.new(pose)
        action.use_fake_user = True
        armature.animation_data.action = action
        for frame in (1, 10, 20):
            bases = pose_bases(human.segment_frames(human.sample_pose(pose, rng), 1.0), rest)
            for name, basis in zip(human.SEGMENT_NAMES, bases):
                bone = armature.pose.bones[name]
                bone.matrix_basis = Matrix(basis.tolist())
                bone.keyframe_insert("rotation_quaternion", frame=frame)
                bone.keyframe_insert("location", frame=frame)
        track = armature.animation_data.nla_tracks.new()
        track.name = pose
        track.strips.new(pose, 1, action)
        armature.animation_data.action = None
    _only([armature, body])
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", use_selection=True, export_animations=True, export_animation_mode="NLA_TRACKS")


def make_robot(path: Path) -> None:
    model = kinematics.load_arm()
    q = kinematics.random_configuration(model, np.random.default_rng(SEED), np.eye(4), floor_z=0.0)
    obj = bpy.data.objects.new("robot_arm", mesh_data("robot_arm", *arm_mesh(model, q)))
    bpy.context.scene.collection.objects.link(obj)
    _only([obj])
    bpy.ops.wm.obj_export(filepath=str(path), export_selected_objects=True, export_materials=False, export_uv=False, export_normals=False, up_axis="Y",
                          forward_axis="NEGATIVE_Z")


def main(out: Path) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    digests = {}
    for name, make in (("car_sedan.glb", make_car), ("person_rigged.glb", make_person), ("robot_arm.obj", make_robot)):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        make(out / name)
        digests[name] = hashlib.sha256((out / name).read_bytes()).hexdigest()
        print(f"{name}: {digests[name]} ({(out / name).stat().st_size} bytes)")
    return digests


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    main(Path(args[0]) if args else ROOT / "assets_manifest" / "test_assets")
