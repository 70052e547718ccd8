"""The railway's masts instanced at the stations by the "Railway Supports" group (builders/railway/support_nodes.py).

One source of truth: each support's realized mast, evaluated through the depsgraph, gives the pure
layout's mast (``_mast_mesh`` in the support's frame, float64) within 1e-6 m plus ULPS float32 steps of
the coordinate (Blender holds the station and the prototype in float32 and realizes in float32), for
several parameter sets; the points stand at the pure frames; the export labels every support's faces
with the row, class and automatic instance id that one object per mast gave.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy
EPS32 = float(np.finfo(np.float32).eps)
ULPS = 2  # measured: 0.7 at most (one rounding of the rotated prototype, one of the sum)

PARAMETER_SETS = [
    ["scene.catenary.feeders=true", "scene.catenary.earth_wire=true"],
    ["scene.supports.layout=both_sides", "scene.track.tracks=2"],
    ["scene.track.mid=[0, 10, 0]", "scene.supports.mast_type=mixed", "scene.catenary.feeders=true"],
]


def build(overrides):
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.blender import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=railway", "scene.detail.mode=fixed", "scene.detail.stones=false", *overrides])
    return config.scene.params, build_scene(config.scene, frame_rng(0, 0), None).scene


def supports_objects():
    import bpy

    return [o for o in bpy.data.objects if o.name.startswith("supports.mast.")]


@pytest.mark.parametrize("overrides", PARAMETER_SETS, ids=["feeders", "both_sides", "curved_lattice"])
def test_every_mast_is_the_pure_mast_at_its_station(overrides):
    from bpy_pipeline.builders.railway import support_nodes
    from bpy_pipeline.builders.railway.scene import _mast_mesh

    params, layout = build(overrides)
    objects = supports_objects()
    assert objects and all([m.node_group.name for m in o.modifiers] == ["Railway Supports"] for o in objects)
    expected = {f"support.{s.index:02d}.mast.{m.side}" for s in layout.supports if not s.gantry for m in s.masts}
    seen, worst, steps = set(), 0.0, 0.0
    for obj in objects:
        frames = support_nodes.support_frames(obj)
        names = list(obj["lidar_parts"])
        for name, frame in zip(names, frames):  # the points stand at the pure frames
            support = layout.supports[int(name.split(".")[1])]
            np.testing.assert_allclose(frame, support.frame, atol=1e-6 + 2 * EPS32 * np.abs(support.frame[:3, 3]).max())
        for name, vertices in support_nodes.realized_parts(obj).items():
            support = layout.supports[int(name.split(".")[1])]
            mast = next(m for m in support.masts if m.side == name.split(".")[3])
            local = _mast_mesh(mast, params.catenary)[0]
            pure = local @ support.frame[:3, :3].T + support.frame[:3, 3]
            assert vertices.shape == pure.shape, name
            scale = EPS32 * np.maximum(np.abs(pure).max(axis=1, keepdims=True), 1.0)
            difference = np.abs(vertices - pure)
            assert (difference <= 1e-6 + ULPS * scale).all(), (name, float(difference.max()))
            worst, steps = max(worst, float(difference.max())), max(steps, float((difference / scale).max()))
            seen.add(name)
    print(f"max |group - pure| {worst:.3g} m, {steps:.2f} float32 steps of the coordinate")
    assert seen == expected  # every mast once, none else


def test_the_export_labels_each_instanced_mast_as_its_own_object():
    import bpy

    from bpy_pipeline.builders.railway import support_nodes
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    _, layout = build(PARAMETER_SETS[1])
    buffers = export_scene(load_class_table())
    objects = buffers.objects
    rows = {n: r for r, n in enumerate(objects.names)}
    parts = {}
    for obj in supports_objects():
        parts |= support_nodes.realized_parts(obj)
    assert len(parts) == 2 * len(layout.supports)
    for name, vertices in parts.items():
        row = rows[name]
        assert objects.class_names[row] == "mast"
        hit = buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == row])]
        assert hit.shape == vertices.shape and np.abs(hit - vertices).max() <= 1e-9  # exactly the part's realized faces
    # the automatic instance ids follow the names, as if every mast were an object of that name
    named = sorted(n for n in objects.names)
    auto = sorted(int(i) for i in objects.instance)
    assert [int(objects.instance[rows[n]]) for n in named] == auto
    assert len(set(objects.instance.tolist())) == len(objects.names)
    # the points carry the part numbers; moving one moves its mast only (a user in Edit Mode)
    obj = supports_objects()[0]
    before = support_nodes.realized_parts(obj)
    first = list(obj["lidar_parts"])[0]
    obj.data.vertices[0].co.z += 0.5
    obj.data.update()
    bpy.context.view_layer.update()
    after = support_nodes.realized_parts(obj)
    for name in before:
        moved = after[name] - before[name]
        assert np.allclose(moved, [0.0, 0.0, 0.5 if name == first else 0.0], atol=1e-4), name


def test_mast_assets_replace_the_instanced_masts(tmp_path):
    """With ``scene.assets.mast`` no mast is instanced: the files' masts stand in their place (tests/test_railway_assets.py)."""
    import bpy

    from test_railway_assets import MAST, write_glb

    glb = write_glb(tmp_path / "mast.glb", MAST)
    _, layout = build([f"scene.assets.mast={glb}"])
    assert not supports_objects() and not bpy.data.objects.get("mast.right.h_section.0")
    masts = {o.name for o in bpy.data.objects if o.get("lidar_class") == "mast"}
    assert masts == {f"support.{s.index:02d}.mast.{m.side}" for s in layout.supports for m in s.masts}
