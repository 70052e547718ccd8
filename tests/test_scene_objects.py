"""Blender objects from numpy arrays (``scenes/objects.py``): a mesh written through its attributes reads back as
the arrays it was made from, and objects removed in one batch take their orphaned data with them."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


@pytest.mark.parametrize("shape", [(850, 1632), (3, 1), (0, 0)], ids=["a body", "one triangle", "empty"])
def test_a_mesh_reads_back_as_the_arrays_it_was_made_from(shape):
    import bpy

    from bpy_pipeline.scenes.objects import mesh_data

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rng = np.random.default_rng(4)
    n, m = shape
    vertices = rng.normal(size=(n, 3)) * 10
    triangles = rng.integers(0, max(n, 1), (m, 3)).astype(np.int32)
    mesh = mesh_data("made", vertices, triangles)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    assert np.array_equal(co, vertices.astype(np.float32).ravel())
    assert np.array_equal(corners, triangles.ravel())
    assert len(mesh.polygons) == m and (sizes == 3).all()


def test_objects_removed_at_once_take_only_their_orphaned_meshes():
    import bpy

    from bpy_pipeline.scenes.objects import mesh_data, remove_objects

    bpy.ops.wm.read_factory_settings(use_empty=True)
    triangle = (np.eye(3), np.array([[0, 1, 2]]))
    own = [bpy.data.objects.new(f"own_{k}", mesh_data(f"own_{k}", *triangle)) for k in range(3)]
    shared = mesh_data("shared", *triangle)
    going, staying = bpy.data.objects.new("going", shared), bpy.data.objects.new("staying", shared)
    for obj in own + [going, staying]:
        bpy.context.scene.collection.objects.link(obj)
    remove_objects(own + [going])
    assert sorted(o.name for o in bpy.data.objects) == ["staying"]
    assert sorted(m.name for m in bpy.data.meshes) == ["shared"]  # still used by "staying"
