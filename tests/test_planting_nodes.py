"""Trees distributed over the street's yards by the "Street Planting" group (builders/street/planting_nodes.py).

The group draws its trees with Blender's own generator (Distribute Points on Faces), so no pure
function gives them point for point; these tests check what its inputs promise, with the bpy module:
how many trees for the density, none closer than the clearance (to each other and to the layout's trunks), each standing on the yards' ground
inside a yard, sizes within their ranges and built by the pure crown rule, labels from the
prototypes' tags, the same trees for the same seed, none at density 0 (the default street's bytes),
and an edited density in the modifier panel scanned as trunks and crowns.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


def _street(**scene):
    """The street's first frame built with the bpy module; ``(layout, config)``."""
    import bpy

    from bpy_pipeline.builders.street import layout as street
    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config({"seed": 0, "frames": 1, "scene": {"builder": "street", **scene}, "effects": {"ideal": True},
                          "sensor": {"preset": "hdl64e", "position": [30.0, 30.0, 1.73]}, "output": {"formats": ["ply"], "preview": False}})
    build_frame_scene(config, 0)
    params = config.scene.params
    return street.street_layout(params, np.random.default_rng(params.layout_seed)), config


def _trees(obj) -> tuple[np.ndarray, np.ndarray]:
    """``(trunks (k, 4, 4), crowns (k, 4, 4))``: the world matrices of a "Street Planting" object's instances, ordered by x then y."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    found = {"trunk": [], "crown": []}
    for instance in depsgraph.object_instances:
        if instance.is_instance and instance.parent.original == obj:
            found[instance.object.original.name.split(".")[1]].append(np.array(instance.matrix_world, np.float64))
    ordered = [np.array(sorted(m, key=lambda a: (round(a[0, 3], 3), round(a[1, 3], 3)))).reshape(-1, 4, 4) for m in (found["trunk"], found["crown"])]
    return ordered[0], ordered[1]


def _set(obj, name, value):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input

    set_modifier_input(obj.modifiers["Street Planting"], name, value)  # what a user does in the modifier panel
    obj.update_tag()
    bpy.context.view_layer.update()


def test_the_trees_keep_the_density_clearance_yards_and_sizes_they_are_given():
    import bpy

    layout, config = _street(yard_trees=3.0, yard_tree_clearance=3.0, yard_tree_height=[5.0, 12.0])
    yards = layout.yards
    trunks, crowns = _trees(bpy.data.objects["street_yard_trees"])
    area = sum((x1 - x0) * (y1 - y0) for x0, x1, y0, y1 in yards.rects)
    assert 0.3 * 3.0 * area / 100 <= len(trunks) <= 3.0 * area / 100  # Poisson disk thins the drawn density, never adds
    assert len(crowns) == len(trunks)
    base = trunks[:, :3, 3] + (0.0, 0.0, 0.2)  # a trunk starts 0.2 m under the ground
    np.testing.assert_allclose(crowns[:, :2, 3], base[:, :2], atol=1e-4)  # each crown on its trunk
    rects = np.array(yards.rects)
    inside = (
        (base[:, None, 0] >= rects[None, :, 0] - 1e-3)
        & (base[:, None, 0] <= rects[None, :, 1] + 1e-3)
        & (base[:, None, 1] >= rects[None, :, 2] - 1e-3)
        & (base[:, None, 1] <= rects[None, :, 3] + 1e-3)
    )
    assert inside.any(axis=1).all()
    assert np.abs(base[:, 2] - yards.terrain.z(base[:, 0], base[:, 1])).max() < 0.02  # on the ground (sampled every 2 m)
    gaps = np.linalg.norm(base[:, None, :2] - base[None, :, :2], axis=2) + np.eye(len(base)) * 1e9
    assert gaps.min() >= 3.0 - 1e-3
    # and clear of the layout's own trees (Keep Clear Of: the trunks' cylinders)
    layout_trunks = next(part for part in layout.parts if part.name == "street_trunks").mesh[0]
    assert np.linalg.norm(base[:, None, :] - layout_trunks[None, :, :], axis=2).min() >= 3.0 - 1e-3
    # sizes: the crown's radius and height are its scale (unit prototypes), the height follows the pure crown rule
    from bpy_pipeline.builders.street.vegetation import crown_size

    radius, crown_height = np.linalg.norm(crowns[:, :3, 0], axis=1), np.linalg.norm(crowns[:, :3, 2], axis=1)
    height = crowns[:, 2, 3] - base[:, 2] + crown_height / 2
    assert radius.min() >= 1.5 - 1e-4 and radius.max() <= 3.5 + 1e-4
    assert height.min() >= 5.0 - 1e-3 and height.max() <= 12.0 + 1e-3
    for r, h, c in zip(radius, height, crown_height):
        assert c == pytest.approx(crown_size("round", float(h), float(r))[1], abs=1e-3)
    trunk_length = np.linalg.norm(trunks[:, :3, 2], axis=1)
    np.testing.assert_allclose(trunk_length, crowns[:, 2, 3] - base[:, 2] + 0.2, atol=1e-3)  # from under the ground into the crown's middle
    np.testing.assert_allclose(np.linalg.norm(trunks[:, :3, 0], axis=1), np.maximum(0.08, 0.04 * height), atol=1e-4)


def test_the_trees_are_labelled_trunk_and_vegetation_and_scanned():
    import bpy  # noqa: F401  (the test needs Blender's module loaded)

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.plan import run_frames

    layout, config = _street(yard_trees=4.0)
    table = load_class_table()
    buffers = export_scene(table)
    rows = {name: (buffers.objects.class_names[k], int(buffers.objects.instance[k])) for k,
            name in enumerate(buffers.objects.names) if name.startswith("street_yard_trees")}
    top = max(part.instance for part in layout.parts)
    assert rows == {"street_yard_trees.trunk": ("trunk", top + 1), **{f"street_yard_trees.crown.{k:02d}": ("vegetation", top + 2) for k in range(3)}}
    # the scan: points on the new trees carry their labels
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        for _ in run_frames(config, Path(folder), build=False, mode="overwrite"):
            pass
        points = read_ply(Path(folder) / "ply" / "000000.ply")
    assert ((points["instance"] == top + 1) & (points["semantic"] == table.id_of("trunk", "test"))).sum() > 0
    assert ((points["instance"] == top + 2) & (points["semantic"] == table.id_of("vegetation", "test"))).sum() > 0


def test_same_seed_same_trees_and_none_at_density_zero():
    import bpy

    _street(yard_trees=2.0)
    first = _trees(bpy.data.objects["street_yard_trees"])
    _street(yard_trees=2.0)
    again = _trees(bpy.data.objects["street_yard_trees"])
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    _street(yard_trees=2.0, layout_seed=1)
    other = _trees(bpy.data.objects["street_yard_trees"])
    assert len(other[0]) != len(first[0]) or not np.array_equal(other[0], first[0])
    _street(yard_trees=2.0, yard_plants=0, street_trees=0)  # no layout trunks to keep clear of: the trees stand all the same
    assert len(_trees(bpy.data.objects["street_yard_trees"])[0]) > len(first[0])
    _street()  # the default: the group plants nothing, and the ground it would plant on is no geometry of the scene
    assert all(len(m) == 0 for m in _trees(bpy.data.objects["street_yard_trees"]))
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    assert not any(name.startswith("street_yard_trees") for name in export_scene(load_class_table()).objects.names)


def test_a_density_edited_in_the_modifier_panel_is_what_the_export_reads():
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    _street()
    obj = bpy.data.objects["street_yard_trees"]
    _set(obj, "Density", 3.0)
    trunks, _ = _trees(obj)
    assert len(trunks) > 0
    names = export_scene(load_class_table()).objects.names
    assert "street_yard_trees.trunk" in names
    _set(obj, "Clearance", 8.0)  # fewer trees, farther apart
    fewer, _ = _trees(obj)
    assert 0 < len(fewer) < len(trunks)
