"""The railway's catenary through the "Catenary Wire" and "Catenary Droppers" groups (builders/railway/catenary_nodes.py).

One source of truth: each wire's and dropper set's object, evaluated through the depsgraph, gives
the points of the pure functions (``builders/railway/catenary.py``: the thesis's parabola and dropper
rule; the layout's jittered droppers), within 1e-6 m plus the float32 rounding of the coordinate,
for several parameter sets; the swept tubes lie their radius from the pure centrelines; and the
modifier inputs edit what the export reads.
"""

import math

import numpy as np
import pytest

from bpy_pipeline.builders.railway import catenary

pytestmark = pytest.mark.bpy
EPS32 = float(np.finfo(np.float32).eps)
ULPS = 4  # measured: 3.7 at most (the ends stored in float32, then lerp and sag each rounded)


def excess(blender: np.ndarray, pure: np.ndarray) -> float:
    """The largest excess (m) of ``|blender - pure|`` over 1e-6 m plus ULPS float32 steps of the coordinate
    (Blender holds the ends and evaluates fields in float32); <= 0 when every point is within."""
    assert blender.shape == pure.shape, (blender.shape, pure.shape)
    allowed = 1e-6 + ULPS * EPS32 * np.abs(pure).max(axis=1, keepdims=True)
    print(
        f"max |blender - pure| {np.abs(blender - pure).max(initial=0):.3g} m, in float32 steps of the coordinate "
        f"{(np.abs(blender - pure) / (EPS32 * np.abs(pure).max(axis=1, keepdims=True))).max(initial=0):.2f}"
    )
    return float((np.abs(blender - pure) - allowed).max(initial=-1.0))


def evaluated(obj) -> tuple[np.ndarray, np.ndarray]:
    """World vertices (n, 3) float64 and edges (e, 2) of ``obj`` evaluated."""
    import bpy

    e = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = e.to_mesh()
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    edges = np.empty(len(mesh.edges) * 2, np.int32)
    mesh.edges.foreach_get("vertices", edges)
    e.to_mesh_clear()
    matrix = np.array(obj.matrix_world, np.float64)
    return v.reshape(-1, 3).astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3], edges.reshape(-1, 2)


def set_input(obj, name, value):
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input

    set_modifier_input(obj.modifiers[0], name, value)  # what a user does in the modifier panel
    obj.update_tag()
    bpy.context.view_layer.update()


@pytest.fixture(scope="module")
def railway():
    """The default railway's first frame, every wire and dropper built: ``layout``."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.blender import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=railway", "scene.catenary.double_contact_probability=1", "scene.catenary.feeders=true",
                                "scene.catenary.earth_wire=true"])
    return build_scene(config.scene, frame_rng(0, 0), None).scene


def test_every_wire_and_dropper_set_is_a_live_catenary_modifier(railway):
    import bpy

    from bpy_pipeline.blender.compat import get_modifier_input

    spans = [o for o in bpy.data.objects if o.name.startswith("span.") and not o.name.endswith("section_insulator")]
    assert len(spans) == len(railway.wires) + len(railway.droppers)
    groups = {o.name: [m.node_group.name for m in o.modifiers if m.type == "NODES"] for o in spans}
    assert {tuple(g) for g in groups.values()} == {("Catenary Wire",), ("Catenary Droppers",)}
    kinds = {w.kind for w in railway.wires}
    assert {"contact_wire", "messenger_wire", "feeder", "earth_wire"} <= kinds and any(d.run.endswith("b") for d in railway.droppers)
    for wire in railway.wires:
        obj = bpy.data.objects[f"span.{wire.run}.{wire.span:02d}.{wire.kind}"]
        assert get_modifier_input(obj.modifiers[0], "Sag") == pytest.approx(wire.sag, rel=1e-6)
        assert obj["lidar_class"] == wire.class_name


def test_the_wire_group_hangs_the_thesis_parabola(railway):
    import bpy

    worst = -1.0
    for wire in railway.wires:
        obj = bpy.data.objects[f"span.{wire.run}.{wire.span:02d}.{wire.kind}"]
        samples = len(obj.data.splines[0].points)
        pure = catenary.parabolic_sag(wire.start, wire.end, wire.sag, samples)
        set_input(obj, "Sweep", False)
        try:
            points, edges = evaluated(obj)
        finally:
            set_input(obj, "Sweep", True)
        assert len(edges) == samples - 1
        worst = max(worst, excess(points, pure))
        # the swept tube: every vertex its radius from the pure centreline (the ring's plane bisects the bend)
        from bpy_pipeline.blender.compat import get_modifier_input

        radius = get_modifier_input(obj.modifiers[0], "Radius")
        tube, _ = evaluated(obj)
        a, b = pure[:-1], pure[1:]
        ab = b - a
        t = np.clip(np.einsum("vsk,sk->vs", tube[:, None] - a, ab) / np.einsum("sk,sk->s", ab, ab), 0, 1)
        distance = np.linalg.norm(tube[:, None] - (a + t[..., None] * ab), axis=2).min(axis=1)
        assert np.abs(distance - radius).max() <= 1e-5 + 1e-4 * radius, obj.name
    assert worst <= 0.0


@pytest.mark.parametrize("start, end, sag, samples", [
    ((0.0, 0.0, 5.6), (60.0, 0.0, 5.6), 0.0, 3),
    ((-30.0, 1.2, 5.3), (35.0, -1.1, 5.5), 0.12, 41),
    ((100.0, 50.0, 6.8), (140.0, 85.0, 7.4), 0.9, 200),
    ((-512.0, 3.0, 7.0), (-470.0, 2.6, 6.9), 0.35, 17),
])
def test_wire_group_against_the_pure_parabola(start, end, sag, samples):
    import bpy

    from bpy_pipeline.builders.railway import catenary_nodes
    from bpy_pipeline.blender.mesh_objects import scene_collection

    collection = scene_collection("catenary test")
    pure = catenary.parabolic_sag(start, end, sag, samples)
    obj = catenary_nodes.wire_object("wire under test", np.array([start, end]), sag, 0.01, 6, collection)
    set_input(obj, "Samples", samples)
    set_input(obj, "Sweep", False)
    assert excess(evaluated(obj)[0], pure) <= 0.0
    bpy.data.objects.remove(obj, do_unlink=True)


def test_the_droppers_group_hangs_the_layouts_droppers_and_places_the_thesis_spacing(railway):
    import bpy

    wires = {(w.run, w.span, w.kind): w for w in railway.wires}
    worst = -1.0
    checked_even = 0
    for droppers in railway.droppers:
        obj = bpy.data.objects[f"span.{droppers.run}.{droppers.span:02d}.droppers"]
        set_input(obj, "Sweep", False)
        try:
            built, edges = evaluated(obj)
            pure = np.stack([droppers.lower, droppers.upper], axis=1).reshape(-1, 3)  # lower, upper per dropper
            assert len(edges) == len(droppers.t)
            worst = max(worst, excess(built, pure))
            contact = wires[(droppers.run, droppers.span, "contact_wire")] if not droppers.run.endswith("p") else None
            if contact is None:
                continue
            upper = wires[(droppers.run.rstrip("b"), droppers.span, "messenger_wire")]
            shift = {"b": 0.25}.get(droppers.run[-1], -0.25 if (droppers.run + "b", droppers.span, "contact_wire") in wires else 0.0)
            for spacing in (5.0, 7.5, 11.0):
                set_input(obj, "Spacing", spacing)
                set_input(obj, "Stagger", shift)
                even, edges = evaluated(obj)
                t = catenary.dropper_positions(contact.length, spacing, 0.0, np.random.default_rng(0), shift)
                want = np.stack([contact.points_at(t), upper.points_at(t)], axis=1).reshape(-1, 3)
                assert len(edges) == len(t) == catenary.dropper_count(contact.length, spacing)
                worst = max(worst, excess(even, want))
                checked_even += 1
        finally:
            set_input(obj, "Spacing", 0.0)
            set_input(obj, "Stagger", 0.0)
            set_input(obj, "Sweep", True)
    assert checked_even >= 3 and worst <= 0.0


def test_a_sag_edited_in_the_modifier_moves_what_the_export_reads(railway):
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    wire = next(w for w in railway.wires if w.kind == "contact_wire")
    name = f"span.{wire.run}.{wire.span:02d}.contact_wire"
    obj = bpy.data.objects[name]

    def lowest():
        buffers = export_scene(load_class_table())
        row = buffers.objects.names.index(name)
        return buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == row])][:, 2].min()

    before = lowest()
    set_input(obj, "Sag", wire.sag + 0.5)
    try:
        assert lowest() == pytest.approx(before - 0.5, abs=0.02)  # half a metre lower at mid-span (the sampled tube's lowest ring)
    finally:
        set_input(obj, "Sag", wire.sag)
    assert lowest() == pytest.approx(before, abs=1e-6)
    assert math.isfinite(before)


def test_a_wire_is_in_the_exported_scene_once(railway):
    """A curve with a Geometry Nodes modifier is listed by the depsgraph as itself and as an instance of its own
    mesh; the export reads it once: each wire's triangles equal its evaluated mesh's, and no triangle repeats."""
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    buffers = export_scene(load_class_table())
    for wire in railway.wires[:6]:
        name = f"span.{wire.run}.{wire.span:02d}.{wire.kind}"
        obj = bpy.data.objects[name]
        mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
        expected = sum(len(p.vertices) - 2 for p in mesh.polygons)
        obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
        rows = [k for k, n in enumerate(buffers.objects.names) if n == name]
        assert expected > 0 and int(np.isin(buffers.triangle_object, rows).sum()) == expected, name
    corners = np.sort(buffers.vertices[buffers.triangles].round(6).reshape(len(buffers.triangles), -1), axis=1)
    assert len(np.unique(corners, axis=0)) == len(corners)
