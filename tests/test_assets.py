"""Asset sets of the assets manifest: checked entries, upright imports, the parking paper's height scaling,
glass windows, rigged people posed by their animations, a wrongly oriented file named in one line."""

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from bpy_pipeline.assets import AXES, asset_set, auto_unit_scale, read_manifest, up_rotation, upright
from bpy_pipeline.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
TEST_ASSETS = ROOT / "assets_manifest" / "test_assets"


def _manifest(tmp_path, entries):
    path = tmp_path / "assets.yaml"
    path.write_text(yaml.safe_dump({"assets": entries}))
    return path


def _entry(file: Path, **more):
    return {"name": file.stem, "kind": "person", "set": "mine", "path": file.name, "sha256": hashlib.sha256(file.read_bytes()).hexdigest(),
            "licence": "CC0-1.0", **more}


# ----------------------------------------------------------------------------- pure: the manifest
def test_the_shipped_manifest_lists_the_projects_own_assets_with_matching_digests():
    entries = read_manifest()
    assert {(e.kind, e.set) for e in entries} == {("car", "project_cars"), ("person", "project_people"), ("robot", "project_robots")}
    for e in entries:
        assert e.path.is_file() and e.path.stat().st_size < 200_000 and e.licence == "CC0-1.0"
        assert hashlib.sha256(e.path.read_bytes()).hexdigest() == e.sha256
    assert asset_set("project_cars", "car", "x")[0].glass_materials == ("window_glass",)
    with pytest.raises(InputError, match=r"^scene.population.car.assets: no car asset of set 'nope' is present in .*; sets of kind car: project_cars$"):
        asset_set("nope", "car", "scene.population.car.assets")


def test_bad_entries_are_named(tmp_path):
    file = tmp_path / "body.obj"
    file.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    cases = [
        (_entry(file, sha256="0" * 64), r"assets\[0\]\.sha256: body.obj has sha256 [0-9a-f]{64}, the manifest says 0{64}"),
        (_entry(file, up_axis="up"), r"assets\[0\]\.up_axis: expected auto or one of X, Y, Z, -X, -Y, -Z"),
        (_entry(file, unit_scale=-1), r"assets\[0\]\.unit_scale: expected auto or a number > 0"),
        (_entry(file, kind="tree"), r"assets\[0\]\.kind: expected one of person, car, robot"),
        (_entry(file, colour="red"), r"assets\[0\]\.colour: unknown key"),
        ({**_entry(file), "path": "body.stl"}, r"assets\[0\]\.path: expected a .glb, .gltf, .obj, .fbx, .blend file"),
        ({k: v for k, v in _entry(file).items() if k != "licence"}, r"assets\[0\]: needs name, kind, path, sha256 and licence"),
    ]
    for entry, message in cases:
        with pytest.raises(InputError, match=message):
            read_manifest(_manifest(tmp_path, [entry]))
    assert read_manifest(_manifest(tmp_path, [{**_entry(file), "path": "absent.obj"}])) == []  # absent: skipped


def test_up_axes_turn_the_declared_axis_to_blenders_z():
    z = np.array([0.0, 0.0, 1.0])
    conversion = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # glTF/OBJ importers: file Y up -> Blender Z
    for suffix in (".glb", ".obj", ".blend"):
        for axis, vector in AXES.items():
            r = up_rotation(suffix, axis)
            np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
            imported = (np.eye(3) if suffix == ".blend" else conversion) @ np.array(vector, float)
            np.testing.assert_allclose(r @ imported, z, atol=1e-12)
    np.testing.assert_allclose(up_rotation(".glb", "auto"), np.eye(3))
    assert upright("person", np.array([0.6, 0.5, 1.8])) and not upright("person", np.array([0.6, 1.8, 0.5]))
    assert upright("car", np.array([4.5, 1.8, 1.5])) and not upright("car", np.array([1.5, 1.8, 4.5]))
    assert auto_unit_scale("person", 175.0) == 0.01 and auto_unit_scale("car", 1550.0) == 0.001 and auto_unit_scale("person", 1.7) == 1.0


# ----------------------------------------------------------------------------- in Blender
def _hall(tmp_path):
    sys.path.insert(0, str(ROOT / "examples" / "hall_twin"))
    try:
        from make_hall import build_hall
    finally:
        sys.path.pop(0)
    return build_hall(tmp_path / "hall.blend")


def _instances(buffers):
    out = {}
    inst = buffers.objects.instance[buffers.triangle_object]
    for i in np.unique(inst):
        rows = inst == i
        tri = buffers.triangles[rows]
        used, local = np.unique(tri, return_inverse=True)
        out[int(i)] = (buffers.vertices[used], local.reshape(-1, 3), buffers.objects.material[buffers.triangle_object[rows]])
    return out


@pytest.mark.bpy
def test_asset_sets_stand_upright_at_drawn_heights_with_glass_windows_and_animated_poses(bpy_scene, tmp_path):
    import bpy

    from bpy_pipeline.buffers import MATERIAL_ID
    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.population.placer import meshes_cross
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    population = {  # the car first: it needs the most room
        "car": {"count": 1, "assets": "project_cars"},
        "person": {"count": 3, "assets": "project_people", "height": {"kind": "uniform", "min": 1.6, "max": 1.9}},
        "robot_arm": {"count": 1, "assets": "project_robots"},
    }
    config = load_config({"seed": 4, "scene": {"builder": "blend", "path": str(_hall(tmp_path)), "population": population},
                          "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}})
    keep, poses = {}, set()
    for frame in range(3):
        result = build_frame_scene(config, frame, keep=keep)
        info = result.info["population"]
        assert [info[k]["placed"] for k in ("person", "car", "robot_arm")] == [3, 1, 1], result.warnings
        poses.update(info["person"]["poses"])
        buffers = export_scene(load_class_table())
        parts = _instances(buffers)
        static = buffers.triangles[(buffers.objects.instance < 10000)[buffers.triangle_object]]
        placed = keep["population"][1].last
        for i, p in placed.items():
            v, t, material = parts[i]
            extent = v.max(axis=0) - v.min(axis=0)
            assert not meshes_cross(v, t, buffers.vertices, static)
            assert v[:, 2].min() == pytest.approx(0.01, abs=1e-4)  # on the floor (the placement gap above it)
            if p.kind == "person":  # scaled to the drawn height (the posed mesh, re-floored)
                assert 1.0 < extent[2] <= 1.9 + 1e-6 and p.shape.detail["scale"] == pytest.approx(p.shape.detail["height"])
            if p.kind == "car":  # the parking paper's 1.55-1.70 m, and the window material is glass
                assert 1.55 - 1e-6 <= extent[2] <= 1.70 + 1e-6 and extent[0] > 2 * extent[2] or extent[1] > 2 * extent[2]
                assert (material == MATERIAL_ID["glass"]).sum() > 0 and (material == MATERIAL_ID["diffuse"]).sum() > 0
            if p.kind == "robot_arm":  # its own size: the file's metres
                assert extent[2] == pytest.approx(p.shape.detail["scale"], rel=1e-4)
        # a placed person's bones hold the drawn animation's values at the drawn keyframe
        model = keep["population"][1].sides["person"].models[0]
        rig = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o.name.startswith("person_000") and not o.hide_render)
        first = min(i for i, p in placed.items() if p.kind == "person")
        action, time = placed[first].shape.detail["pose_key"]
        name, times, channels = model.actions[action]
        assert time in times
        for bone, prop, index, fc in channels[:40]:
            assert getattr(rig.pose.bones[bone], prop)[index] == pytest.approx(fc.evaluate(time), abs=1e-6)
    assert len(poses) >= 4 and {p.split("@")[0] for p in poses} <= {"standing", "walking", "sitting", "crouching"}


def _lying_person(tmp_path) -> Path:
    """A procedural person exported as OBJ with Z up (the file's own axes): a Y-up importer lays it down."""
    import bpy

    from bpy_pipeline.geometry import human
    from bpy_pipeline.geometry.objects import person_mesh
    from bpy_pipeline.blender.mesh_objects import mesh_data

    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj = bpy.data.objects.new("walker", mesh_data("walker", *person_mesh(human.neutral_angles(), 1.8)))
    bpy.context.scene.collection.objects.link(obj)
    obj.select_set(True)
    path = tmp_path / "walker_zup.obj"
    bpy.ops.wm.obj_export(filepath=str(path), export_selected_objects=True, export_materials=False, up_axis="Z", forward_axis="Y")
    return path


@pytest.mark.bpy
def test_a_wrongly_oriented_asset_is_named_in_one_line_and_its_declared_up_axis_fixes_it(bpy_scene, tmp_path):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    file = _lying_person(tmp_path)
    hall = _hall(tmp_path)
    manifest = _manifest(tmp_path, [_entry(file)])
    population = {"person": {"count": 2, "assets": "mine"}, "placement": {"manifest": str(manifest)}}
    config = load_config({"scene": {"builder": "blend", "path": str(hall), "population": population}, "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}})
    with pytest.raises(InputError) as error:
        build_frame_scene(config, 0, keep={})
    message = str(error.value)
    assert "\n" not in message and "assets[0] (walker_zup): walker_zup.obj does not stand upright as a person with up_axis Y (auto)" in message
    assert "set up_axis to the file's up axis (Z or -Z would fit)" in message
    # the same file with its up axis declared stands upright, its people on the floor
    _manifest(tmp_path, [_entry(file, up_axis="Z")])
    result = build_frame_scene(config, 0, keep={})
    assert result.info["population"]["person"]["placed"] == 2
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    buffers = export_scene(load_class_table())
    people = buffers.vertices[np.unique(buffers.triangles[(buffers.objects.instance >= 10000)[buffers.triangle_object]])]
    assert people[:, 2].max() > 1.4 and people[:, 2].min() == pytest.approx(0.01, abs=1e-4)
    # from the command line: exit 2 and the one line, no frame written
    out = tmp_path / "out"
    _manifest(tmp_path, [_entry(file)])
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"scene": {"builder": "blend", "path": str(hall), "population": population},
                                   "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}}))
    run = subprocess.run([sys.executable, str(ROOT / "run.py"), "--config", str(cfg), "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 2
    lines = [line for line in run.stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1 and "does not stand upright" in lines[0], run.stderr
    assert not list(out.glob("ply/*.ply"))


def test_a_missing_set_is_a_config_error_before_blender(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(tmp_path / "o"), "--set", "scene.builder=primitives", "--set",
                             "scene.population={car: {count: 1, assets: sports_cars}}"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert (
        result.stderr.strip().startswith("error: scene.population.car.assets: no car asset of set 'sports_cars'")
        and len(result.stderr.strip().splitlines()) == 1
    )


@pytest.mark.bpy
def test_a_rig_without_animations_is_posed_within_its_bones_rotation_limits(bpy_scene):
    from bpy_pipeline.blender.asset_models import apply_pose, draw_pose, load_models, _rotation_limits

    model = load_models("project_people", "person", "test")[0]
    rig = model.armature
    limits = {"upper_arm_l": (-0.8, 0.3), "thigh_r": (-0.5, 0.9), "spine": (-0.2, 0.2)}
    for bone, (lo, hi) in limits.items():
        c = rig.pose.bones[bone].constraints.new("LIMIT_ROTATION")
        c.use_limit_x = c.use_limit_y = c.use_limit_z = True
        c.min_x, c.max_x, c.min_y, c.max_y, c.min_z, c.max_z = lo, hi, lo / 2, hi / 2, lo / 3, hi / 3
    model.actions, model.limits = [], _rotation_limits(rig)  # as a file without animations
    rng = np.random.default_rng(0)
    seen = []
    for _ in range(20):
        pose = draw_pose(model, rng)
        assert pose["name"] == "limits" and set(pose["angles"]) == set(limits)
        apply_pose(rig, model, pose)
        for bone, (lo, hi) in limits.items():
            angles = np.array(rig.pose.bones[bone].rotation_euler)
            assert (angles >= np.array([lo, lo / 2, lo / 3]) - 1e-6).all() and (angles <= np.array([hi, hi / 2, hi / 3]) + 1e-6).all()
            seen.append(angles)
        assert all(np.allclose(np.array(b.matrix_basis), np.eye(4)) for b in rig.pose.bones if b.name not in limits)
    assert np.ptp(np.array(seen), axis=0).max() > 0.3  # the draws spread over the ranges
    v1 = model.shape(np.random.default_rng(1))[0]
    v2 = model.shape(np.random.default_rng(2))[0]
    assert v1.shape == v2.shape and not np.allclose(v1, v2)  # the evaluated mesh follows the pose


@pytest.mark.bpy
@pytest.mark.parametrize("suffix", [".fbx", ".blend"])
def test_fbx_and_blend_car_files_import_upright_with_their_glass(bpy_scene, tmp_path, suffix):
    """The shipped sedan re-saved as FBX (Blender's exporter, Y up) and as a .blend (Z up), both with up_axis auto."""
    import bpy

    from bpy_pipeline.blender.asset_models import load_models

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=str(TEST_ASSETS / "car_sedan.glb"))
    file = tmp_path / f"sedan{suffix}"
    if suffix == ".fbx":
        bpy.ops.export_scene.fbx(filepath=str(file), axis_up="Y", axis_forward="-Z")
    else:
        bpy.ops.wm.save_as_mainfile(filepath=str(file))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    manifest = _manifest(tmp_path, [_entry(file, kind="car", set="saved")])
    (model,) = load_models("saved", "car", "test", manifest)
    v, t, _ = model.shape(np.random.default_rng(0))
    extent = v.max(axis=0) - v.min(axis=0)
    assert extent[2] == pytest.approx(1.0) and extent[0] / extent[2] == pytest.approx(4.631 / 1.625, rel=0.01)  # nose along x, upright
    assert set(model.parts) == {"body", "glass"} and len(model.parts["glass"][2]) == 10  # the windows' ten triangles
    assert model.unit_scale == 1.0


@pytest.mark.bpy
def test_asset_frames_are_the_same_whatever_came_before(bpy_scene, tmp_path):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames

    population = {"car": {"count": 1, "assets": "project_cars"}, "person": {"count": {"min": 1, "max": 4}, "assets": "project_people"}}
    data = {"seed": 9, "frames": 4, "scene": {"builder": "blend", "path": str(_hall(tmp_path)), "population": population},
            "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}, "output": {"formats": ["ply"], "preview": False}}
    config = load_config(data)
    for _ in run_frames(config, tmp_path / "all"):
        pass
    for _ in run_frames(config, tmp_path / "alone", frames=[3]):
        pass
    for name in ("ply/000003.ply", "openpcdet/labels/000003.txt"):
        assert (tmp_path / "all" / name).read_bytes() == (tmp_path / "alone" / name).read_bytes(), name
    assert (tmp_path / "all" / "ply/000002.ply").read_bytes() != (tmp_path / "all" / "ply/000003.ply").read_bytes()
