"""Blender-side modules no other test imports by name: the blend and primitives builders' scenes, the shared box
prototypes (blender/box_nodes.py), the hall's, the street's scatter and planting groups called directly, and the
population's standing places (population/scene.py). Every mesh is read as the export reads it (the depsgraph)."""

import os

import numpy as np
import pytest

from bpy_pipeline.errors import InputError

pytestmark = pytest.mark.bpy


@pytest.fixture
def empty(bpy_scene):
    bpy_scene.ops.wm.read_factory_settings(use_empty=True)
    return bpy_scene


def exported(names):
    from test_parking_nodes import exported as read

    return read(names)


def test_blend_builder_opens_the_file_once_and_knows_when_it_changed(empty, tmp_path):
    from bpy_pipeline.builders.blend import params as blend_params
    from bpy_pipeline.builders.blend import scene as blend_scene
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection

    bpy = empty
    mesh_object("users_cube", primitives.box(1.0, 1.0, 1.0), scene_collection())
    path = tmp_path / "mine.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert "users_cube" not in bpy.data.objects
    opened = blend_scene.OpenedBlend(blend_params.BlendScene(str(path)))
    assert "users_cube" in bpy.data.objects and opened.alive()
    os.utime(path, ns=(opened.stamp + 10**9, opened.stamp + 10**9))
    assert not opened.alive()
    with pytest.raises(InputError, match="^scene.path: the blend builder needs the path"):
        blend_params.check(blend_params.BlendScene(), "scene")
    (tmp_path / "scene.obj").write_text("")
    with pytest.raises(InputError, match=r"^scene.path: .*scene\.obj is not a \.blend file"):
        blend_scene.build(blend_params.BlendScene(str(tmp_path / "scene.obj")))


def test_primitives_builder_places_each_shape_with_its_labels(empty):
    from bpy_pipeline.builders.primitives import scene as primitives_scene
    from bpy_pipeline.config import load_config

    shapes = [{"type": "box", "size": [2.0, 1.0, 0.5], "position": [5.0, 1.0, 0.25], "class": "car", "name": "crate"},
              {"type": "sphere", "size": 0.5, "position": [0.0, 4.0, 1.0], "class": "person"}]
    params = load_config({"scene": {"builder": "primitives", "shapes": shapes}}).scene.params
    primitives_scene.build(params)
    got = exported(["crate", "sphere_1"])
    v = got["crate"][0]
    assert np.allclose(v.min(0), [4.0, 0.5, 0.0]) and np.allclose(v.max(0), [6.0, 1.5, 0.5])
    assert np.allclose(np.linalg.norm(got["sphere_1"][0] - [0.0, 4.0, 1.0], axis=1), 0.5, atol=1e-5)
    assert empty.data.objects["crate"]["lidar_class"] == "car"


def test_the_hall_group_builds_a_desk_on_the_shared_unit_box_as_the_pure_desk(empty):
    from test_parking_nodes import same_mesh

    from bpy_pipeline.builders.industrial_hall import hall_nodes
    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene
    from bpy_pipeline.geometry.indoor import desk
    from bpy_pipeline.blender import box_nodes
    from bpy_pipeline.blender.mesh_objects import scene_collection

    collection = scene_collection()
    prototypes = box_nodes.prototypes(collection)
    assert set(prototypes) == {"box", "wedge"} and all(not obj.visible_get() for obj in prototypes.values())
    params = IndustrialHallScene()
    hall_nodes.hall_object("desk_a", "desk", params, collection, prototypes, Centre=(3.0, -2.0, 0.0), Size=(1.6, 0.8, 0.75))
    got = exported(["desk_a"])["desk_a"]
    assert same_mesh(got, desk("desk_a", (3.0, -2.0), (1.6, 0.8), 0.75).mesh()) <= 0.0


def triangle_set(mesh) -> np.ndarray:
    """``(m, 9)`` each triangle's corners (rounded to 0.1 mm, sorted within the triangle), the triangles sorted."""
    v, t = mesh
    corners = np.round(np.asarray(v, float)[np.asarray(t)], 4)  # (m, 3, 3)
    corners = np.array([c[np.lexsort(c.T[::-1])] for c in corners]).reshape(len(t), 9)
    return corners[np.lexsort(corners.T[::-1])]


def test_scatter_points_carry_each_items_transform_and_the_group_places_the_pure_mesh(empty):
    from bpy_pipeline.builders.street import scatter_nodes
    from bpy_pipeline.builders.street.dressing import Scatter
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.blender.mesh_objects import scene_collection

    scatter = Scatter([primitives.box(0.4, 0.4, 1.0), primitives.cylinder(0.2, 2.0, 8)])
    scatter.add(0, (1.0, 2.0, 0.0), 0.3, (1.0, 2.0, 1.0))
    scatter.add(1, (-4.0, 0.5, 0.1), -1.2)
    scatter.add(0, (0.0, -3.0, 0.0), 2.0, (0.5, 0.5, 0.5))
    mesh = scatter_nodes.points_mesh("pts", scatter)
    assert np.allclose([v.co[:] for v in mesh.vertices], scatter.positions)
    assert [d.value for d in mesh.attributes["prototype"].data] == [0, 1, 0]
    assert np.allclose([d.value for d in mesh.attributes["yaw"].data], [0.3, -1.2, 2.0])
    collection = scene_collection()
    scatter_nodes.scatter_object("bins", scatter, collection, scatter_nodes.prototypes_collection(collection))
    assert np.allclose(triangle_set(exported(["bins"])["bins"]), triangle_set(scatter.mesh()), atol=1e-5)  # the same triangles, in any order


def test_the_planting_group_has_its_documented_inputs_and_is_made_once(empty):
    from bpy_pipeline.builders.street import planting_nodes

    group = planting_nodes.planting_group()
    inputs = [item for item in group.interface.items_tree if getattr(item, "in_out", "") == "INPUT"]
    assert [(i.name, i.socket_type) for i in inputs] == [(row[0], row[1]) for row in planting_nodes.PLANTING_INPUTS]
    density = next(i for i in inputs if i.name == "Density")
    assert (density.default_value, density.min_value, density.max_value) == (0.0, 0.0, 100.0)
    assert planting_nodes.planting_group() == group and group.name == planting_nodes.GROUP


def test_standing_places_prefer_walkable_classes_and_else_detect_floors():
    from bpy_pipeline.buffers import ObjectTable, SceneBuffers
    from bpy_pipeline.population.params import PlacementRules
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.population.scene import find_places

    table = load_class_table()
    floor = primitives.plane(10.0, 10.0)
    table_top = primitives.translated(primitives.box(2.0, 1.0, 0.05), (0.0, 0.0, 0.5))

    def buffers(classes):
        meshes = [floor, table_top]
        v = np.concatenate([m[0] for m in meshes])
        t = np.concatenate([meshes[0][1], meshes[1][1] + len(meshes[0][0])]).astype(np.int32)
        owner = np.concatenate([np.zeros(len(meshes[0][1]), np.int32), np.ones(len(meshes[1][1]), np.int32)])
        objects = ObjectTable(["f", "t"], ["", ""], classes, np.array([table.id_of(c) for c in classes], np.uint16), np.array([1, 2], np.uint32),
                              np.zeros(2, np.uint8), np.full(2, 0.5, np.float32))
        return SceneBuffers(v, t, owner, objects)

    rules = PlacementRules(seat_classes=["table"] if "table" in table.names else [])
    detected = find_places(buffers(["wall", "wall"]), PlacementRules(walkable_classes=[]))
    assert detected.source == "detected" and len(detected.floors) >= 1 and abs(detected.floors[0].z) < 1e-9
    named = find_places(buffers(["floor", "wall"]), rules)
    assert named.source == "walkable_classes" and [round(s.z, 6) for s in named.floors] == [0.0]
    assert abs(sum(s.area for s in named.floors) - 100.0) < 1e-6
