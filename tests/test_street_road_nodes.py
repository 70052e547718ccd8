"""The street's carriageway, kerbs and sidewalks through the "Street Road" Geometry Nodes group
(builders/street/road_nodes.py), and its buildings through "Street Facade" (builders/street/facade_nodes.py).

One source of truth: each swept part, evaluated through the depsgraph, has the vertices of the pure
:func:`~bpy_pipeline.builders.street.layout.road_meshes` (every building: its pure box) for several
parameter sets; the built street labels them as the pure parts; and changing the road's ``Lane Width``
(a building's ``Height``) in its modifier moves the road (the building) to where the pure function
puts it, and nothing else.
"""

import dataclasses

import numpy as np
import pytest

from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.builders.street.params import StreetScene

EPS32 = float(np.finfo(np.float32).eps)
PARAMETER_SETS = [
    StreetScene(),
    StreetScene(lanes_per_direction=2, lane_width=3.25, parking_width=0.0, kerb_width=0.3, kerb_height=0.12, sidewalk_width=2.0, arm_length=60.0),
    StreetScene(lanes_per_direction=3, lane_width=3.0, parking_width=2.5, kerb_width=0.2, kerb_height=0.2, sidewalk_width=5.0, arm_length=150.0),
    StreetScene(junction_mix={"t_junction": 1.0}, layout_seed=0),  # the arm along -y
    StreetScene(junction_mix={"t_junction": 1.0}, layout_seed=1, lanes_per_direction=2, parking_width=0.0, arm_length=60.0),  # along +y
    StreetScene(junction_mix={"straight": 1.0}, sidewalk_width=2.0),
]


def _sorted(v: np.ndarray) -> np.ndarray:
    """``v`` (n, 3) in lexicographic order of its coordinates rounded to 0.1 mm (float32 rounding does not reorder ties)."""
    key = np.round(v, 4)
    return v[np.lexsort(key.T[::-1])]


def _excess(blender: np.ndarray, pure: np.ndarray, arm_length: float) -> float:
    """The largest excess (m) of the sorted vertices' difference over 1e-6 m plus the float32 limit of the group's
    arithmetic: Trim Curve interpolates along a centre line 2 arm_length long, so eps32 x 2 arm_length (2.4e-5 m at
    100 m); <= 0 when every vertex is within."""
    assert blender.shape == pure.shape
    allowed = 1e-6 + EPS32 * 2.0 * arm_length
    return float((np.abs(_sorted(blender) - _sorted(pure)) - allowed).max(initial=-1.0))


def _evaluated(obj) -> tuple[np.ndarray, int, float]:
    """World vertices (n, 3) of ``obj`` evaluated, its face count and its surface area (m2)."""
    import bpy

    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    faces, area = len(mesh.polygons), sum(p.area for p in mesh.polygons)
    evaluated.to_mesh_clear()
    return v.reshape(-1, 3).astype(np.float64), faces, area


def _area(mesh) -> float:
    v, t = mesh
    return float(0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum())


@pytest.mark.bpy
@pytest.mark.parametrize("k", range(len(PARAMETER_SETS)))
def test_group_vs_pure_vertices_for_several_parameter_sets(k):
    import bpy

    from bpy_pipeline.builders.street.road_nodes import PARTS, road_object

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = PARAMETER_SETS[k]
    pure = street.road_meshes(params)[:3]
    for part, mesh in zip(PARTS, pure):
        obj = road_object(f"street_{part}", part, params, bpy.context.scene.collection, 7)
        bpy.context.view_layer.update()
        v, faces, area = _evaluated(obj)
        assert _excess(v, mesh[0], params.arm_length) <= 0.0, part
        assert 2 * faces == len(mesh[1]), part  # a quad where the pure mesh has two triangles
        assert area == pytest.approx(_area(mesh), rel=1e-5), part


FACADE_SETS = [
    StreetScene(),
    StreetScene(layout_seed=3, building_depth=14.0, building_height=(3.0, 40.0), building_width=(6.0, 30.0), setback=(0.0, 2.0), arm_length=150.0),
    StreetScene(layout_seed=11, building_depth=6.5, building_height=(10.0, 12.0), open_share=0.0, sidewalk_width=5.0),
]


@pytest.mark.bpy
@pytest.mark.parametrize("k", range(len(FACADE_SETS)))
def test_facade_group_vs_pure_building_boxes_for_several_parameter_sets(k):
    import bpy

    from bpy_pipeline.builders.street.facade_nodes import facade_object

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = FACADE_SETS[k]
    buildings = [p for p in street.street_layout(params, np.random.default_rng(params.layout_seed)).parts if p.front is not None]
    assert len(buildings) >= 10
    for part in buildings:
        facade_object(part.name, part.front, bpy.context.scene.collection, part.instance)
    bpy.context.view_layer.update()
    worst = -1.0
    for part in buildings:
        v, faces, area = _evaluated(bpy.data.objects[part.name])
        worst = max(worst, _excess(v, part.mesh[0], params.arm_length))
        assert 2 * faces == len(part.mesh[1]) and area == pytest.approx(_area(part.mesh), rel=1e-5), part.name
    assert worst <= 0.0


@pytest.fixture(scope="module")
def street_frame():
    """The default street's first frame built with the bpy module: its layout."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config({"seed": 0, "frames": 1, "scene": {"builder": "street"}, "output": {"formats": ["ply"], "preview": False}})
    build_frame_scene(config, 0)
    params = config.scene.params
    return street.street_layout(params, np.random.default_rng(params.layout_seed)), params


SWEPT = ("street_road", "street_kerbs", "street_sidewalks")


def _buildings(layout) -> list:
    return [p for p in layout.parts if p.front is not None]


@pytest.mark.bpy
def test_the_street_has_live_road_and_scatter_groups(street_frame):
    import bpy

    from bpy_pipeline.blender.compat import get_modifier_input, interface_inputs

    layout, params = street_frame
    modifiers = [(obj.name, m) for obj in bpy.data.objects if obj.name.startswith("street_") for m in obj.modifiers if m.type == "NODES"]
    road = sorted(name for name, m in modifiers if m.node_group.name == "Street Road")
    assert road == sorted(SWEPT)
    facades = sorted(name for name, m in modifiers if m.node_group.name == "Street Facade")
    assert facades == sorted(p.name for p in _buildings(layout)) and all(name.startswith("street_building_") for name in facades)
    assert {m.node_group.name for _, m in modifiers} == {"Street Facade", "Street Planting", "Street Road", "Street Scatter"}
    assert len(modifiers) == 3 + 7 + len(facades) + 1 == 46  # the default layout's 35 buildings, the yards
    assert {"Part", "Lanes", "Lane Width", "Parking Width", "Kerb Width", "Kerb Height", "Sidewalk Width",
            "Instance"} <= set(interface_inputs(bpy.data.node_groups["Street Road"]))
    modifier = bpy.data.objects["street_road"].modifiers[0]
    assert get_modifier_input(modifier,
                              "Lane Width") == pytest.approx(params.lane_width) and get_modifier_input(modifier, "Lanes") == params.lanes_per_direction


@pytest.mark.bpy
def test_the_export_labels_the_swept_parts_as_the_pure_parts(street_frame):
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    layout, params = street_frame
    buffers = export_scene(load_class_table())
    objects = buffers.objects
    for part in (p for p in layout.parts if p.name in SWEPT or p.front is not None):
        assert objects.names.count(part.name) == 1, part.name  # the face attribute lidar_instance equals the tag: no split
        r = objects.names.index(part.name)
        assert (objects.class_names[r], int(objects.instance[r])) == (part.class_name, part.instance)
        t = buffers.triangles[buffers.triangle_object == r]
        assert len(t) == len(part.mesh[1]), part.name
        assert _excess(buffers.vertices[np.unique(t)], part.mesh[0], params.arm_length) <= 0.0, part.name


@pytest.mark.bpy
def test_a_wider_lane_in_the_modifier_moves_the_road_and_nothing_else(street_frame):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    _, params = street_frame
    table = load_class_table()

    def pieces():
        buffers = export_scene(table)
        names = buffers.objects.names
        return {name: buffers.vertices[buffers.triangles[buffers.triangle_object == r]] for r, name in enumerate(names)}

    road = bpy.data.objects["street_road"]

    def lane_width(value):
        set_modifier_input(road.modifiers[0], "Lane Width", value)  # what a user does in the modifier panel
        road.update_tag()
        bpy.context.view_layer.update()

    before = pieces()
    lane_width(params.lane_width + 1.0)
    try:
        after = pieces()
    finally:
        lane_width(params.lane_width)
    assert before.keys() == after.keys()
    wider = street.road_meshes(dataclasses.replace(params, lane_width=params.lane_width + 1.0))[0]
    moved = after["street_road"].reshape(-1, 3)
    assert not np.array_equal(before["street_road"], after["street_road"])
    assert _excess(np.unique(moved, axis=0), np.unique(wider[0], axis=0), params.arm_length) <= 0.0  # where the pure wider road is
    for name in before:
        if name != "street_road":
            assert np.array_equal(before[name], after[name]), name  # nothing else moved
    assert np.array_equal(pieces()["street_road"], before["street_road"])  # back as built


@pytest.mark.bpy
def test_a_taller_building_in_its_modifier_moves_its_roof_and_nothing_else(street_frame):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    layout, params = street_frame
    table = load_class_table()
    part = _buildings(layout)[0]
    obj = bpy.data.objects[part.name]

    def height(value):
        set_modifier_input(obj.modifiers[0], "Height", value)
        obj.update_tag()
        bpy.context.view_layer.update()

    def pieces():
        buffers = export_scene(table)
        return {name: buffers.vertices[buffers.triangles[buffers.triangle_object == r]] for r, name in enumerate(buffers.objects.names)}

    before = pieces()
    height(part.front[3] + 5.0)
    try:
        after = pieces()
    finally:
        height(part.front[3])
    taller = part.mesh[0].copy()
    taller[taller[:, 2] > taller[:, 2].min(), 2] += 5.0  # the pure box 5 m taller
    assert _excess(np.unique(after[part.name].reshape(-1, 3), axis=0), np.unique(taller, axis=0), params.arm_length) <= 0.0
    for name in before:
        if name != part.name:
            assert np.array_equal(before[name], after[name]), name


def test_every_road_input_the_config_sets_holds_its_keys_range():
    """The "Street Road" group's inputs from the scene's keys (:data:`road_nodes.FIELDS`)."""
    pytest.importorskip("bpy")
    from test_parking_nodes import inputs_cover_their_keys

    from bpy_pipeline.builders.street import road_nodes

    inputs_cover_their_keys(road_nodes.ROAD_INPUTS, road_nodes.FIELDS, StreetScene)
