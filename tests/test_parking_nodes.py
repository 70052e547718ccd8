"""The car park's level through the "Parking Level" group (builders/parking/level_nodes.py).

One source of truth: each piece's object (floor, ceiling, walls, pillars, ramp), evaluated through
the depsgraph as the export reads it, gives the vertices and triangles of the pure
``parking_layout(...).meshes()`` (geometry/indoor.py) within 1e-6 m plus the float32 rounding of
the coordinate, for several parameter sets; and a bay width edited in the modifier moves the
pillars the export reads.
"""

import dataclasses

import numpy as np
import pytest

pytestmark = pytest.mark.bpy
EPS32 = float(np.finfo(np.float32).eps)


def excess(blender: np.ndarray, pure: np.ndarray) -> float:
    """The largest excess (m) of ``|blender - pure|`` over 1e-6 m plus two float32 steps of the coordinate; <= 0 when within."""
    assert blender.shape == pure.shape, (blender.shape, pure.shape)
    allowed = 1e-6 + 2 * EPS32 * np.abs(pure).max(axis=1, keepdims=True)
    return float((np.abs(blender - pure) - allowed).max(initial=-1.0))


def exported(names) -> dict:
    """``{name: (vertices (n, 3), triangles (m, 3))}`` of the objects ``names`` as the export reads them (unused vertices dropped)."""
    from bpy_pipeline.export import export_scene
    from bpy_pipeline.labels import load_class_table

    buffers = export_scene(load_class_table())
    out = {}
    for name in names:
        if name not in buffers.objects.names:
            out[name] = (np.zeros((0, 3)), np.zeros((0, 3), np.int32))
            continue
        t = buffers.triangles[buffers.triangle_object == buffers.objects.names.index(name)]
        used, inverse = np.unique(t, return_inverse=True)
        out[name] = (buffers.vertices[used], inverse.reshape(-1, 3))
    return out


def same_mesh(got, want) -> float:
    """The vertex excess of ``got`` over ``want`` (both (vertices, triangles)), after checking the triangles match one to one."""
    (gv, gt), (wv, wt) = got, want
    assert len(gt) == len(wt)
    return excess(gv[gt].reshape(-1, 3), np.asarray(wv, float)[wt].reshape(-1, 3))  # corner by corner, in triangle order


def build(**changes):
    import bpy

    from bpy_pipeline.builders.parking.params import ParkingScene
    from bpy_pipeline.geometry.indoor import parking_layout
    from bpy_pipeline.builders.parking.scene import ParkingGarage

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = dataclasses.replace(ParkingScene(), **changes)
    ParkingGarage(params)
    return params, parking_layout(params)


@pytest.mark.parametrize("changes", [
    {},
    {"ramp_length": 0.0},
    {"length": 83.7, "bay_width": 2.35, "bay_depth": 4.8, "pillar_every": 4, "pillar_size": 0.45, "driveway_width": 7.1, "ramp_length": 11.3},
    {"length": 25.0, "ceiling_height": 3.1, "slab_thickness": 0.25, "wall_thickness": 0.2, "pillar_every": 1, "ramp_length": 9.0},
])
def test_the_group_builds_the_pure_level(changes):
    import bpy

    _, layout = build(**changes)
    pure = layout.meshes()
    for name in ("floor", "ceiling", "wall", "pillar", "ramp"):
        modifiers = [m for m in bpy.data.objects[name].modifiers if m.type == "NODES"] if name in bpy.data.objects else []
        assert (name in pure) == bool(modifiers) and all(m.node_group.name == "Parking Level" for m in modifiers), name
    got = exported(pure)
    worst = max(same_mesh(got[name], pure[name]) for name in pure)
    assert worst <= 0.0


def test_labels_as_before_and_prototypes_unseen():
    from bpy_pipeline.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.builders.parking.scene import INSTANCE

    build()
    objects = export_scene(load_class_table()).objects
    assert "box prototype" not in objects.names and "wedge prototype" not in objects.names
    for name in ("floor", "ceiling", "wall", "pillar", "ramp"):
        r = objects.names.index(name)
        assert (objects.class_names[r], int(objects.instance[r])) == (name, INSTANCE[name])


def test_a_bay_width_edited_in_the_modifier_moves_the_pillars():
    import bpy

    from bpy_pipeline.compat import set_modifier_input
    from bpy_pipeline.geometry.indoor import parking_layout

    params, layout = build()
    pillar = bpy.data.objects["pillar"]
    set_modifier_input(pillar.modifiers[0], "Bay Width", 2.8)
    pillar.update_tag()
    bpy.context.view_layer.update()
    wider = parking_layout(dataclasses.replace(params, bay_width=2.8)).meshes()["pillar"]
    before = layout.meshes()["pillar"][0]
    assert len(wider[0]) != len(before) or not np.allclose(wider[0], before)  # the edit changes the grid
    assert same_mesh(exported(["pillar"])["pillar"], wider) <= 0.0
