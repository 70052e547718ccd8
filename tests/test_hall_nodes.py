"""The industrial hall's slabs, walls, desks and racks through the "Industrial Hall" group (builders/industrial_hall/hall_nodes.py).

One source of truth: every piece's object, evaluated through the depsgraph as the export reads it,
gives the vertices and triangles of the pure ``hall_layout`` boxes (geometry/indoor.py) within
1e-6 m plus the float32 rounding of the coordinate, for several parameter sets; labels are as
before; and a rack's levels edited in its modifier change what the export reads.
"""

import dataclasses

import pytest

from test_parking_nodes import exported, inputs_cover_their_keys, same_mesh

pytestmark = pytest.mark.bpy


def build(**changes):
    import bpy

    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene
    from bpy_pipeline.geometry.indoor import hall_layout
    from bpy_pipeline.builders.industrial_hall.scene import IndustrialHall

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = dataclasses.replace(IndustrialHallScene(), robots=0, **changes)
    IndustrialHall(params)
    return params, hall_layout(params)


def pure_meshes(layout) -> dict:
    from bpy_pipeline.geometry.indoor import boxes_mesh

    return {"floor": boxes_mesh(layout.floor), "ceiling": boxes_mesh(layout.ceiling),
            "walls": boxes_mesh(layout.walls)} | {f.name: f.mesh() for f in layout.furniture}


@pytest.mark.parametrize("changes", [
    {},
    {"length": 23.4, "width": 9.7, "height": 6.2, "wall_thickness": 0.25, "desk_rows": 3, "desks_per_row": 2, "desk_size": (1.4, 0.7), "desk_height": 0.76},
    {"shelves": 5, "shelf_size": (2.7, 0.8, 3.1), "shelf_levels": 6, "desk_rows": 0},
    {"shelves": 1, "shelf_levels": 1, "desks_per_row": 1},
])
def test_the_group_builds_the_pure_hall(changes):
    import bpy

    _, layout = build(**changes)
    pure = pure_meshes(layout)
    for name in pure:
        assert [m.node_group.name for m in bpy.data.objects[name].modifiers] == ["Industrial Hall"], name
    got = exported(pure)
    assert max(same_mesh(got[name], pure[name]) for name in pure) <= 0.0


def test_labels_as_before():
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.builders.industrial_hall.scene import INSTANCE

    _, layout = build()
    objects = export_scene(load_class_table()).objects
    for name, class_name, instance in [("floor", "floor", 1), ("ceiling", "ceiling", 3), ("walls", "wall", 2)] + [
            (f.name, f.class_name, INSTANCE[f.class_name] + k) for k, f in enumerate(layout.furniture)]:
        r = objects.names.index(name)
        assert (objects.class_names[r], int(objects.instance[r])) == (class_name, instance), name


def test_a_racks_levels_edited_in_its_modifier_change_what_the_export_reads():
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.geometry.indoor import shelf

    params, layout = build()
    item = next(f for f in layout.furniture if f.class_name == "shelf")
    obj = bpy.data.objects[item.name]
    set_modifier_input(obj.modifiers[0], "Levels", 7)
    obj.update_tag()
    bpy.context.view_layer.update()
    seven = shelf(item.name, item.parts[4][0][:2], params.shelf_size, 7).mesh()
    got = exported([item.name])[item.name]
    assert len(got[1]) == len(seven[1]) == 12 * (4 + 7) and same_mesh(got, seven) <= 0.0


def test_every_hall_input_the_config_sets_holds_its_keys_range():
    """The "Industrial Hall" group's inputs from the scene's keys, a rack's Levels among them (2^31 boards ran out of memory)."""
    from bpy_pipeline.builders.industrial_hall import hall_nodes
    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene

    inputs_cover_their_keys(hall_nodes.INPUTS, hall_nodes.FIELDS | {"Levels": "shelf_levels"}, IndustrialHallScene)
