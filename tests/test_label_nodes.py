"""Labels through Geometry Nodes: the named attribute ``lidar_instance`` the export reads (export.INSTANCE_ATTRIBUTE).

The groups store their ``Instance`` input on every instance they make; the export labels an
instance, or a realized face, by it (its class stays its owner's), so the scan labels instanced
and realized geometry as the builder tagged it, and one object may carry many instances.
"""

import numpy as np
import pytest

from test_hall_nodes import build

pytestmark = pytest.mark.bpy


def rows(buffers) -> dict:
    """``{row name: (class, instance, triangles)}`` of an export."""
    objects = buffers.objects
    counts = np.bincount(buffers.triangle_object, minlength=len(objects))
    return {name: (objects.class_names[r], int(objects.instance[r]), int(counts[r])) for r, name in enumerate(objects.names)}


def export():
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    return export_scene(load_class_table())


def set_input(obj, name, value):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input

    set_modifier_input(obj.modifiers[0], name, value)
    obj.update_tag()
    bpy.context.view_layer.update()


def test_the_groups_store_the_tagged_instance_and_an_edit_relabels_instances_and_realized_faces():
    import bpy

    if not hasattr(bpy.types, "GeometrySet"):
        pytest.skip(f"Blender {bpy.app.version_string} cannot read instance attributes (GeometrySet came with 4.3)")
    _, layout = build()
    desk = layout.furniture[0]
    before = rows(export())
    assert before[desk.name] == ("desk", 10, 12 * 5)  # the named attribute agrees with the tag: one row, as before
    obj = bpy.data.objects[desk.name]
    set_input(obj, "Instance", 77)
    labelled = rows(export())
    assert desk.name not in labelled and labelled[f"{desk.name}#77"] == ("desk", 77, 12 * 5)
    set_input(obj, "Realize", True)  # one mesh: the faces carry the attribute
    assert rows(export())[f"{desk.name}#77"] == ("desk", 77, 12 * 5)
    set_input(obj, "Realize", False)
    set_input(obj, "Instance", 10)
    assert rows(export()) == before


def test_a_mesh_whose_faces_carry_instances_exports_one_row_per_instance():
    import bpy

    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection, tag

    bpy.ops.wm.read_factory_settings(use_empty=True)
    two = primitives.merge([primitives.box(1, 1, 1), primitives.translated(primitives.box(1, 1, 1), (3, 0, 0))])
    obj = tag(mesh_object("crates", two, scene_collection()), "wall")
    ids = obj.data.attributes.new("lidar_instance", "INT", "FACE")
    ids.data.foreach_set("value", np.repeat([5, 9], 12).astype(np.int32))
    buffers = export()
    assert rows(buffers) == {"crates#5": ("wall", 5, 12), "crates#9": ("wall", 9, 12)}
    r = buffers.objects.names.index("crates#9")
    assert buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == r])][:, 0].min() == pytest.approx(2.5)  # the second box
