"""Every exported triangle once: objects that are not meshes (a bevelled curve, an extruded text) are
listed by the depsgraph twice, as themselves and as an instance of their own evaluated mesh; the export
reads each once, so a user's .blend curves and texts are not in the scene twice."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


def _curve(name: str):
    import bpy

    data = bpy.data.curves.new(name, "CURVE")
    data.dimensions = "3D"
    spline = data.splines.new("POLY")
    spline.points.add(2)
    for point, co in zip(spline.points, [(0, 0, 0, 1), (5, 0, 1, 1), (5, 4, 1, 1)]):
        point.co = co
    data.bevel_depth = 0.1
    return data


def _text(name: str):
    import bpy

    data = bpy.data.curves.new(name, "FONT")
    data.body = "LiDAR"
    data.extrude = 0.05
    return data


@pytest.mark.parametrize("make", [_curve, _text], ids=["bevelled curve", "extruded text"])
def test_a_curve_or_text_object_is_exported_once(make):
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj = bpy.data.objects.new("thing", make("thing"))
    bpy.context.scene.collection.objects.link(obj)
    obj["lidar_class"] = "wall"
    depsgraph = bpy.context.evaluated_depsgraph_get()
    listed = [i for i in depsgraph.object_instances if i.object.original == obj or (i.is_instance and i.parent.original == obj)]
    mesh = obj.evaluated_get(depsgraph).to_mesh()
    mesh.calc_loop_triangles()
    expected = len(mesh.loop_triangles)
    obj.evaluated_get(depsgraph).to_mesh_clear()
    buffers = export_scene(load_class_table())
    assert expected > 0 and len(listed) == 2  # the depsgraph's two listings this guards against
    assert len(buffers.triangles) == expected
    corners = np.sort(buffers.vertices[buffers.triangles].round(6).reshape(len(buffers.triangles), -1), axis=1)
    assert len(np.unique(corners, axis=0)) == expected
