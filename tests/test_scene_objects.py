"""Blender objects from numpy arrays (``blender/mesh_objects.py``): a mesh written through its attributes reads back as
the arrays it was made from, and objects removed in one batch take their orphaned data with them."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


@pytest.mark.parametrize("shape", [(850, 1632), (3, 1), (0, 0)], ids=["a body", "one triangle", "empty"])
def test_a_mesh_reads_back_as_the_arrays_it_was_made_from(shape):
    import bpy

    from bpy_pipeline.blender.mesh_objects import mesh_data

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rng = np.random.default_rng(4)
    n, m = shape
    vertices = rng.normal(size=(n, 3)) * 10
    triangles = rng.integers(0, max(n, 1), (m, 3)).astype(np.int32)
    mesh = mesh_data("made", vertices, triangles)
    co, corners = _read(mesh.vertices, "co", np.float32, 3), _read(mesh.loops, "vertex_index", np.int32)
    sizes = _read(mesh.polygons, "loop_total", np.int32)
    assert np.array_equal(co, vertices.astype(np.float32).ravel())
    assert np.array_equal(corners, triangles.ravel())
    assert len(mesh.polygons) == m and (sizes == 3).all()


def test_objects_removed_at_once_take_only_their_orphaned_meshes():
    import bpy

    from bpy_pipeline.blender.mesh_objects import mesh_data, remove_objects

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


@pytest.mark.parametrize("faces", ["triangles", "quads"])
def test_export_gives_blenders_loop_triangles_and_their_faces_ids(faces):
    """The export reads an all-triangle mesh's corners as its tessellation, and tessellates others through Blender:
    either way the triangles (world), and a FACE attribute's ids per triangle, are Blender's loop triangles'."""
    import bpy

    from bpy_pipeline.blender.export import INSTANCE_ATTRIBUTE, export_scene
    from bpy_pipeline.labels import load_class_table

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, location=(1.0, 2.0, 3.0))
    obj = bpy.context.active_object
    if faces == "triangles":
        modifier = obj.modifiers.new("tri", "TRIANGULATE")
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    mesh = obj.data
    ids = mesh.attributes.new(INSTANCE_ATTRIBUTE, "INT", "FACE")
    ids.data.foreach_set("value", np.arange(len(mesh.polygons), dtype=np.int32) % 3 + 1)
    obj["lidar_class"] = "wall"
    mesh.calc_loop_triangles()
    expected = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", expected)
    face = np.empty(len(mesh.loop_triangles), np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", face)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    corners = (co.reshape(-1, 3).astype(np.float64) + [1.0, 2.0, 3.0])[expected.reshape(-1, 3)]  # (m, 3, 3) world
    assert (len(mesh.loops) == 3 * len(mesh.polygons)) == (faces == "triangles")

    buffers = export_scene(load_class_table())
    got = buffers.vertices[buffers.triangles]
    instance = buffers.objects.instance[buffers.triangle_object]
    order = np.lexsort(corners.reshape(len(corners), -1).T)
    got_order = np.lexsort(got.reshape(len(got), -1).T)
    np.testing.assert_allclose(got[got_order], corners[order], atol=1e-6)
    assert np.array_equal(instance[got_order], (face % 3 + 1)[order])


def _read(items, name: str, dtype, width: int = 1) -> np.ndarray:
    """``(len(items) * width,)`` array of attribute ``name`` of a Blender collection (``foreach_get``)."""
    out = np.empty(len(items) * width, dtype)
    items.foreach_get(name, out)
    return out


def _mesh_state(bpy, obj) -> tuple:
    """What a mesh object holds: its positions, corners, polygons, edges, evaluated bounds and a ray's hit."""
    mesh = obj.data
    co, corners = _read(mesh.vertices, "co", np.float32, 3), _read(mesh.loops, "vertex_index", np.int32)
    starts, edges = _read(mesh.polygons, "loop_start", np.int32), _read(mesh.edges, "vertices", np.int32, 2)
    graph = bpy.context.evaluated_depsgraph_get()
    bounds = np.array([list(c) for c in obj.evaluated_get(graph).bound_box])
    hit = obj.ray_cast((0.1, 0.1, 50.0), (0.0, 0.0, -1.0))
    return co.tobytes(), corners.tobytes(), starts.tobytes(), np.sort(edges.reshape(-1, 2), 0).tobytes(), bounds.tobytes(), hit[0], tuple(hit[1])


def test_a_mesh_refilled_with_its_own_triangles_is_the_mesh_filled_anew():
    """fill_mesh keeps the triangles (and edges) a mesh has already and writes its positions only: its bounds, its BVH (a
    ray cast) and everything read back are those of a mesh filled from nothing with the same arrays; other triangles, or
    none, refill it whole."""
    import bpy

    from bpy_pipeline.blender.mesh_objects import fill_mesh, mesh_object
    from bpy_pipeline.geometry import human
    from bpy_pipeline.geometry.primitives import box_mesh

    bpy.ops.wm.read_factory_settings(use_empty=True)
    collection = bpy.context.scene.collection
    a, b, r = human.capsules(human.segment_frames(human.neutral_angles(), 1.7), 1.7)
    body = human.body_mesh(a, b, r, 8, 2)[:2]
    moved = (body[0] * 1.3 + (0.4, -0.2, 0.5), body[1])
    box = box_mesh(-1.0, 1.0, -1.0, 1.0, 0.0, 2.0)
    kept = mesh_object("kept", body, collection)
    for mesh in (moved, box, (np.zeros((0, 3)), np.zeros((0, 3), np.int32)), moved, body):
        _mesh_state(bpy, kept)  # its bounds and BVH made before the refill
        fill_mesh(kept.data, *mesh)
        fresh = mesh_object("fresh", mesh, collection)
        assert _mesh_state(bpy, kept) == _mesh_state(bpy, fresh)
        bpy.data.objects.remove(fresh)
