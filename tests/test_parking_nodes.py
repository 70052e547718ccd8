"""The car park's level through the "Parking Level" group (builders/parking/level_nodes.py).

One source of truth: each piece's object (floor, ceiling, walls, pillars, ramp), evaluated through
the depsgraph as the export reads it, gives the vertices and triangles of the pure
``level_layout(...).meshes()`` (builders/parking/layout.py: geometry/indoor.py's level with doorways) within 1e-6 m plus the float32 rounding of
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
    from bpy_pipeline.blender.export import export_scene
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

    from bpy_pipeline.builders.parking.layout import level_layout
    from bpy_pipeline.builders.parking.params import ParkingScene
    from bpy_pipeline.builders.parking.scene import ParkingGarage

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = dataclasses.replace(ParkingScene(), **changes)
    ParkingGarage(params)
    return params, level_layout(params)


@pytest.mark.parametrize("changes", [
    {},
    {"ramp_length": 0.0},
    {"length": 83.7, "bay_width": 2.35, "bay_depth": 4.8, "pillar_every": 4, "pillar_size": 0.45, "driveway_width": 7.1, "ramp_length": 11.3},
    {"length": 25.0, "ceiling_height": 3.1, "slab_thickness": 0.25, "wall_thickness": 0.2, "pillar_every": 1, "ramp_length": 9.0},
    {"wall_openings": 1},
    {"wall_openings": 3, "opening_width": 2.4, "opening_height": 2.3, "length": 71.0, "wall_thickness": 0.35, "driveway_width": 7.1},
    {"wall_openings": 7, "opening_width": 0.9, "opening_height": 1.95, "length": 25.0, "ceiling_height": 3.1, "ramp_length": 0.0},
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
    from bpy_pipeline.blender.export import export_scene
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

    from bpy_pipeline.blender.compat import set_modifier_input
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


def garage_with_cars_in_bays():
    """A kept garage (as a run keeps it across frames) whose cars snap to bays, eight wanted a frame."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=parking", "scene.placement=bays", "scene.cars={kind: normal, mean: 8, std: 0, min: 0, max: 40}"])
    keep = {}
    build_frame_scene(config, 0, keep=keep)
    return config, keep


def car_centres(garage) -> np.ndarray:
    """(n, 2) the placed cars' box centres, checked against their body objects' locations (what the export reads)."""
    import bpy

    centres = np.array([box.centre[:2] for _, box in garage.last.placed]).reshape(-1, 2)
    bodies = np.array([bpy.data.objects[f"car_{k:03d}"].location[:2] for k in range(len(centres))]).reshape(-1, 2)
    np.testing.assert_allclose(bodies, centres, atol=1e-5)  # float32 locations
    return centres


def in_bays(centres: np.ndarray, bays: np.ndarray) -> np.ndarray:
    """Whether each centre is (within 1e-9 m) the centre of one of ``bays``."""
    return np.array([np.linalg.norm(bays[:, :2] - c, axis=1).min() <= 1e-9 for c in centres], bool)


def test_a_bay_width_edited_in_the_modifier_moves_the_cars_to_the_new_bays():
    """The pillar piece's Bay Width set to 2.8 m from Python, then the kept garage's next frame: every car in a bay
    of the pure level with 2.8 m bays (built from the values read back from the modifier), not in the old ones."""
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.geometry.indoor import parking_layout
    from bpy_pipeline.stages.scene import build_frame_scene

    config, keep = garage_with_cars_in_bays()
    garage = keep["parking"][1]
    old = parking_layout(config.scene.params).bays
    assert garage.params is config.scene.params and in_bays(car_centres(garage), old).all()  # unedited: the YAML's level itself
    set_modifier_input(bpy.data.objects["pillar"].modifiers[0], "Bay Width", 2.8)
    build_frame_scene(config, 1, keep=keep)
    assert keep["parking"][1] is garage  # the same level, edited, not rebuilt
    assert garage.params == dataclasses.replace(config.scene.params, bay_width=2.8)
    new = parking_layout(garage.params).bays
    centres = car_centres(garage)
    assert len(centres) >= 4 and in_bays(centres, new).all() and not in_bays(centres, old).all(), centres


def test_an_unedited_level_keeps_the_yaml_values_despite_float32_inputs():
    """2.35 m bays read back from the modifier as float32 (2.3499999) are not an edit: the garage keeps the YAML's floats."""
    import bpy

    from bpy_pipeline.builders.parking.level_nodes import edited_params

    params, _ = build(bay_width=2.35, length=83.7, pillar_every=4)
    pieces = [bpy.data.objects[n] for n in ("floor", "ceiling", "wall", "pillar", "ramp")]
    assert edited_params(pieces, params) is params


def test_an_impossible_edit_is_one_line_naming_the_input():
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.stages.scene import build_frame_scene

    config, keep = garage_with_cars_in_bays()
    set_modifier_input(bpy.data.objects["ramp"].modifiers[0], "Ramp Length", 55.0)
    with pytest.raises(InputError, match=r"ramp_length: must leave at least 8 m") as error:
        build_frame_scene(config, 1, keep=keep)
    assert "\n" not in str(error.value)


def test_the_group_is_laid_out_in_columns_by_depth():
    """``GroupBuilder.finish`` lays the nodes out (set all at once): the group input in the first column, the output
    in the last, every linked node right of each node it reads, no two nodes at one place."""
    import bpy

    from bpy_pipeline.builders.parking.level_nodes import level_group

    bpy.ops.wm.read_factory_settings(use_empty=True)
    group = level_group()
    x = {node.name: node.location[0] for node in group.nodes}
    places = {(node.location[0], node.location[1]) for node in group.nodes}
    inputs, outputs = (next(n for n in group.nodes if n.bl_idname == kind) for kind in ("NodeGroupInput", "NodeGroupOutput"))
    assert x[inputs.name] == 0.0 and x[outputs.name] == max(x.values()) and len(places) == len(group.nodes)
    assert all(x[link.to_node.name] > x[link.from_node.name] for link in group.links)


def inputs_cover_their_keys(inputs, fields: dict, params) -> None:
    """Each group input of ``fields`` ({input name: params field}) declares a range (``inputs``' rows: name, type, default,
    description, min, max) holding its key's whole range (the field's metadata): a value the config takes is one the
    group's modifier panel offers when the user edits the built scene, and none overflows a 32-bit integer input (Blender
    refuses that with a traceback; a float beyond its input's range Blender takes as it is)."""
    metadata = {f.name: f.metadata for f in dataclasses.fields(params)}
    rows = {row[0]: row for row in inputs}
    for name, key in fields.items():
        low, high = rows[name][4], rows[name][5]
        assert metadata[key]["low"] is not None and metadata[key]["high"] is not None, key
        assert low <= metadata[key]["low"] and metadata[key]["high"] <= high, (key, metadata[key]["low"], metadata[key]["high"], low, high)


def test_every_level_input_the_config_sets_holds_its_keys_range():
    """The "Parking Level" group's inputs from the scene's keys (a 10^12 m level ran until killed, a pillar_every of 2^31
    overflowed the group's integer input)."""
    from bpy_pipeline.builders.parking import level_nodes
    from bpy_pipeline.builders.parking.params import ParkingScene

    inputs_cover_their_keys(level_nodes.INPUTS, level_nodes.FIELDS, ParkingScene)
