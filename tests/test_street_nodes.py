"""The street's scattered items through the "Street Scatter" Geometry Nodes group (builders/street/scatter_nodes.py).

One source of truth: each scattered kind's object, evaluated through the depsgraph, gives the
vertices of the pure ``Scatter.mesh`` (builders/street/dressing.py), in item order, whether its
instances are read as the export reads them or realized; its labels are the part's; a scan of
the exported scene equals a scan of the pure meshes; and the modifier's inputs edit the scene the
export reads.
"""

import dataclasses

import numpy as np
import pytest

from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.builders.street.dressing import Scatter

EPS32 = float(np.finfo(np.float32).eps)


def _within(blender: np.ndarray, pure: np.ndarray) -> float:
    """The largest excess (m) of ``|blender - pure|`` over 1e-6 m plus the float32 rounding of the coordinate
    (Blender stores vertices and matrices in float32: 7.6e-6 m at 100 m); <= 0 when every vertex is within."""
    assert blender.shape == pure.shape
    allowed = 1e-6 + EPS32 * np.abs(pure).max(axis=1, keepdims=True)
    return float((np.abs(blender - pure) - allowed).max(initial=-1.0))


def _instances_of(obj) -> np.ndarray:
    """World vertices of ``obj``'s instances as the export reads them (prototype mesh x instance matrix), in instance order."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    parts = []
    for instance in depsgraph.object_instances:
        if instance.is_instance and instance.parent.original == obj:
            mesh = instance.object.to_mesh()
            v = np.empty(len(mesh.vertices) * 3, np.float32)
            mesh.vertices.foreach_get("co", v)
            instance.object.to_mesh_clear()
            matrix = np.array(instance.matrix_world, np.float64)
            parts.append(v.reshape(-1, 3).astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3])
    return np.concatenate(parts) if parts else np.zeros((0, 3))


def _realized(obj) -> np.ndarray:
    import bpy

    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    evaluated.to_mesh_clear()
    return v.reshape(-1, 3).astype(np.float64)


def _set(obj, name, value):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input

    set_modifier_input(obj.modifiers[0], name, value)  # what a user does in the modifier panel
    obj.update_tag()
    bpy.context.view_layer.update()


@pytest.fixture(scope="module")
def street_frame():
    """The default street's first frame built with the bpy module: ``(layout, config)``."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config({"seed": 0, "frames": 1, "scene": {"builder": "street"}, "output": {"formats": ["ply"], "preview": False}})
    build_frame_scene(config, 0)

    params = config.scene.params
    return street.street_layout(params, np.random.default_rng(params.layout_seed)), config


def _scattered(layout):
    return [part for part in layout.parts if part.scatter is not None]


@pytest.mark.bpy
def test_every_scattered_kind_is_a_live_street_scatter_modifier(street_frame):
    import bpy

    from bpy_pipeline.blender.compat import get_modifier_input, interface_inputs

    layout, _ = street_frame
    scattered = _scattered(layout)
    assert {p.name for p in scattered} == {"street_trunks", "street_plants", "street_lamps_bollards", "street_bins", "street_bicycle_stands", "street_cones",
                                           "street_barriers"}
    street_objects = [obj for obj in bpy.data.objects if obj.name.startswith("street_") and ".prototype." not in obj.name]
    modifiers = [(obj.name, m) for obj in street_objects for m in obj.modifiers if m.type == "NODES" and m.node_group.name == "Street Scatter"]
    assert sorted(name for name, _ in modifiers) == sorted(p.name for p in scattered)  # one per scattered kind, none elsewhere
    others = {m.node_group.name for obj in street_objects for m in obj.modifiers if m.type == "NODES"} - {"Street Scatter"}
    # the carriageway, kerbs, sidewalks and buildings (tests/test_street_road_nodes.py), the yards (tests/test_planting_nodes.py)
    assert others == {"Street Road", "Street Facade", "Street Planting"}
    assert {"Prototypes", "Density", "Seed", "Scale", "Realize"} <= set(interface_inputs(bpy.data.node_groups["Street Scatter"]))
    for part in scattered:
        obj = bpy.data.objects[part.name]
        assert len(obj.data.vertices) == len(part.scatter.items) and len(obj.data.polygons) == 0  # the items as points
        kinds = get_modifier_input(obj.modifiers[0], "Prototypes")
        assert [o.name for o in sorted(kinds.objects, key=lambda o: o.name)] == [f"{part.name}.prototype.{k:02d}" for k in range(len(part.scatter.prototypes))]
        assert obj["lidar_class"] == part.class_name and obj["lidar_instance"] == part.instance


@pytest.mark.bpy
def test_the_group_places_the_prototypes_as_the_pure_function_does(street_frame):
    import bpy

    layout, _ = street_frame
    for part in _scattered(layout):
        obj = bpy.data.objects[part.name]
        pure = part.mesh[0]
        assert _within(_instances_of(obj), pure) <= 0.0, part.name  # as the export reads it: instances
        _set(obj, "Realize", True)
        try:
            assert _within(_realized(obj), pure) <= 0.0, part.name  # realized into one mesh
        finally:
            _set(obj, "Realize", False)
        # each item's own geometry, before its placement: the prototypes as Blender holds them
        for k, mesh in enumerate(part.scatter.prototypes):
            held = bpy.data.objects[f"{part.name}.prototype.{k:02d}"].data
            v = np.empty(len(held.vertices) * 3, np.float32)
            held.vertices.foreach_get("co", v)
            assert np.abs(v.reshape(-1, 3) - mesh[0]).max() <= 1e-6


@pytest.mark.bpy
def test_the_export_labels_instances_by_their_scatter_object_and_scans_as_the_pure_meshes(street_frame):
    from bpy_pipeline.buffers import SceneBuffers
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.lidar.cast.raycast import RayCaster

    layout, _ = street_frame
    buffers = export_scene(load_class_table())
    objects = buffers.objects
    row = {name: r for r, name in enumerate(objects.names)}
    assert not any(".prototype." in name for name in objects.names)  # prototypes are seen only where instanced
    static = [r for r in range(len(objects)) if objects.instance[r] < 1000]
    assert sorted(objects.names[r] for r in static) == sorted(p.name for p in layout.parts)
    for part in layout.parts:  # class, instance and triangle count of every static part, scattered or not
        r = row[part.name]
        assert (objects.class_names[r], int(objects.instance[r])) == (part.class_name, part.instance)
        assert int((buffers.triangle_object == r).sum()) == len(part.mesh[1]), part.name

    # the pure meshes in place of the instanced ones: same rows, same triangle order per object
    vertices, triangles, owner, offset = [], [], [], 0
    pure = {row[p.name]: p.mesh for p in _scattered(layout)}
    for r in range(len(objects)):
        if r in pure:
            v, t = pure[r]
        else:
            t = buffers.triangles[buffers.triangle_object == r]
            used, inverse = np.unique(t, return_inverse=True)
            v, t = buffers.vertices[used], inverse.reshape(-1, 3)
        vertices.append(v)
        triangles.append(t + offset)
        owner.append(np.full(len(t), r, np.int32))
        offset += len(v)
    reference = SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)

    elevation, azimuth = np.meshgrid(np.radians(np.linspace(-25.0, 15.0, 48)), np.radians(np.arange(0.0, 360.0, 0.25)), indexing="ij")
    directions = np.column_stack([(np.cos(elevation) * np.cos(azimuth)).ravel(), (np.cos(elevation) * np.sin(azimuth)).ravel(), np.sin(elevation).ravel()])
    classes = set()
    for station in ((-30.0, -1.75, 1.73), (20.0, 9.0, 1.8), (-9.0, 40.0, 1.8)):  # a lane, a sidewalk, the other road's sidewalk
        pose = np.eye(4)
        pose[:3, 3] = station
        scans = [RayCaster(b, frame=pose, kernel="numpy").intersect(np.zeros(3), directions) for b in (buffers, reference)]
        hit = [np.full(len(directions), -1) for _ in scans]
        distance = [np.full(len(directions), np.inf) for _ in scans]
        for h, d, s, b in zip(hit, distance, scans, (buffers, reference)):
            h[s.ray] = b.triangle_object[s.triangle]
            d[s.ray] = s.distance
        same = hit[0] == hit[1]
        assert same.mean() >= 0.9999, station  # a ray may graze a leaf card's edge within float32 rounding
        both = same & (hit[0] >= 0)
        close = np.abs(distance[0][both] - distance[1][both]) <= 1e-3
        assert close.mean() >= 0.9999, station
        classes |= {objects.class_names[r] for r in np.unique(hit[0][hit[0] >= 0])}
    assert {"vegetation", "trunk", "pole", "terrain", "building", "road", "sidewalk"} <= classes


@pytest.mark.bpy
def test_editing_an_input_or_a_point_edits_what_the_export_reads(street_frame):
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    layout, _ = street_frame
    table = load_class_table()
    parts = {p.name: p for p in _scattered(layout)}

    def exported(name):
        buffers = export_scene(table)
        if name not in buffers.objects.names:
            return np.zeros((0, 3))
        t = buffers.triangles[buffers.triangle_object == buffers.objects.names.index(name)]
        return buffers.vertices[np.unique(t)]

    bins = bpy.data.objects["street_bins"]
    _set(bins, "Scale", 2.0)  # every bin twice as large: the pure function with doubled scales
    try:
        doubled = Scatter(parts["street_bins"].scatter.prototypes)
        for k, position, yaw, scale in parts["street_bins"].scatter.items:
            doubled.add(k, position, yaw, np.multiply(scale, 2.0))
        got, want = exported("street_bins"), np.unique(doubled.mesh()[0].astype(np.float32).astype(np.float64), axis=0)
        assert len(got) == len(want) and _within(np.unique(got.astype(np.float32).astype(np.float64), axis=0), want) <= 0.0
    finally:
        _set(bins, "Scale", 1.0)

    plants = bpy.data.objects["street_plants"]
    items = len(parts["street_plants"].scatter.items)
    _set(plants, "Density", 0.5)
    try:
        kept = sum(1 for i in bpy.context.evaluated_depsgraph_get().object_instances if i.is_instance and i.parent.original == plants)
        assert 0.25 * items < kept < 0.75 * items  # thinned at random by Seed
        _set(plants, "Density", 0.0)
        assert len(exported("street_plants")) == 0  # no plants left to scan
    finally:
        _set(plants, "Density", 1.0)

    cones = bpy.data.objects["street_cones"]
    first = cones.data.vertices[0].co.copy()
    cones.data.vertices[0].co = (first.x, first.y, first.z + 5.0)  # a cone lifted in Edit Mode
    cones.data.update()
    bpy.context.view_layer.update()
    try:
        assert exported("street_cones")[:, 2].max() == pytest.approx(5.0 + 0.75, abs=1e-5)
    finally:
        cones.data.vertices[0].co = first
        cones.data.update()
        bpy.context.view_layer.update()
    assert _within(_instances_of(cones), parts["street_cones"].mesh[0]) <= 0.0  # back as built


def test_same_layout_seed_same_prototypes_and_transforms():
    from bpy_pipeline.builders.street.params import StreetScene

    params = StreetScene()
    first, again = (street.street_layout(params, np.random.default_rng(params.layout_seed)) for _ in range(2))
    other = street.street_layout(dataclasses.replace(params, layout_seed=1), np.random.default_rng(1))
    for a, b in zip(_scattered(first), _scattered(again)):
        assert a.scatter.items == b.scatter.items
        assert all(np.array_equal(p[0], q[0]) and np.array_equal(p[1], q[1]) for p, q in zip(a.scatter.prototypes, b.scatter.prototypes))
        assert np.array_equal(a.mesh[0], a.scatter.mesh()[0])  # the part's mesh is its prototypes placed
    plants = next(p for p in _scattered(other) if p.name == "street_plants")
    assert not np.array_equal(plants.scatter.prototypes[0][0], next(p for p in _scattered(first) if p.name == "street_plants").scatter.prototypes[0][0])
