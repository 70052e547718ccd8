"""No two elements of a railway's overhead line pass through each other, measured on the exported meshes.

Two objects intersect when an edge of a triangle of one crosses a triangle of the other. Only the
joints a line is built with may touch: a cantilever with its own registration arm, insulators, mast
or gantry and the messenger it carries; a registration arm with its contact wires; droppers with
their own wires; a wire with itself in the next span; a feeder or earth wire with its mast's
bracket and insulator. Everything else (one track's fittings against another's, a wire against
another track's arm, a mast against a wire) must stay clear.
"""

import re

import numpy as np
import pytest

from bpy_pipeline.config import load_config

pytestmark = pytest.mark.bpy

CASES = [("single", 1), ("single", 2), ("both_sides", 1), ("both_sides", 2), ("both_sides", 3), ("both_sides", 4),
         ("gantry", 2), ("gantry", 3), ("gantry", 4), ("gantry", 5)]
AUXILIARY = {2: True, 3: True}  # track counts also built with an auxiliary messenger (PA)


def segment_hits(a, b, triangles) -> bool:
    """Whether any segment ``a[i]``-``b[i]`` ((e, 3) each, m) crosses any of ``triangles`` ((t, 3, 3)), traced by Embree."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    origin = triangles.reshape(-1, 3).min(0)  # a local origin: float32 keeps sub-millimetre detail
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, (triangles - origin).astype(np.float32))
    d = b - a
    length = np.linalg.norm(d, axis=1)
    keep = length > 1e-9
    a, d, length = a[keep] - origin, d[keep] / length[keep, None], length[keep]
    out = scene.run(a.astype(np.float32), d.astype(np.float32), dists=(length * (1 - 1e-4)).astype(np.float32), output=1)
    return bool(((out["primID"] >= 0) & (out["tfar"] > 1e-4 * length)).any())


def meshes_intersect(va, ta, vb, tb, margin=0.01) -> bool:
    """Whether two triangle meshes ((n, 3) vertices, (m, 3) indices each) pass through each other:
    an edge of a triangle of one crosses a triangle of the other."""
    lo, hi = np.maximum(va[ta].reshape(-1, 3).min(0),
                        vb[tb].reshape(-1, 3).min(0)) - margin, np.minimum(va[ta].reshape(-1, 3).max(0), vb[tb].reshape(-1, 3).max(0)) + margin
    if (lo > hi).any():
        return False

    def near(v, t):
        tri = v[t]
        keep = ((tri.max(1) >= lo) & (tri.min(1) <= hi)).all(1)
        return tri[keep]

    A, B = near(va, ta), near(vb, tb)
    if not len(A) or not len(B):
        return False
    edges = lambda tri: (np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]]), np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]]))  # noqa: E731
    return segment_hits(*edges(A), B) or segment_hits(*edges(B), A)


def element(name: str):
    """(kind, support or span, track or run or side) of an overhead-line object name, ``None`` for track parts."""
    m = re.fullmatch(r"support\.(\d+)\.(mast|gantry|cantilever|registration_arm|steady_arm|insulators|anchor|tensioning_weight)(?:\.(\w+))?", name)
    if m:
        return m[2], int(m[1]), m[3]
    m = re.fullmatch(r"span\.(\w+)\.(\d+)\.(\w+)", name)
    if m:
        return m[3], int(m[2]), m[1]
    return None


def joint(a, b) -> bool:
    """Whether elements ``a`` and ``b`` (from :func:`element`) are built touching."""
    (ka, ia, ra), (kb, ib, rb) = sorted([a, b])
    wire = {"contact_wire", "messenger_wire", "auxiliary_messenger", "feeder", "earth_wire", "droppers", "section_insulator"}
    if ka not in wire and kb not in wire:  # two fittings: one support, one track, or a mast with its fittings
        if ia != ib:
            return False
        if {ka, kb} == {"anchor", "tensioning_weight"}:  # the rope holds its weight
            return ra == rb
        if "mast" in (ka, kb) or "gantry" in (ka, kb):
            other = rb if ka in ("mast", "gantry") else ra
            if "tensioning_weight" in (ka, kb):
                return False
            return other is None or other.startswith("t") or other in ("right", "left")
        return ra == rb and "anchor" not in (ka, kb) and "tensioning_weight" not in (ka, kb)
    if ka in wire and kb in wire:  # wires: the same run in neighbouring spans, droppers on their own wires
        track = lambda run: run.rstrip("bp")  # noqa: E731  (t0b: a second contact wire; t0p: the droppers above a PA; t0s1: tension section 1)
        if ka == kb:
            return ra == rb and abs(ia - ib) <= 1
        if "section_insulator" in (ka, kb):  # it clamps its own contact wire
            return {ka, kb} == {"section_insulator", "contact_wire"} and ia == ib and track(ra) == track(rb)
        return ("droppers" in (ka, kb) and ia == ib and track(ra) == track(rb)
                and {ka, kb} <= {"droppers", "contact_wire", "messenger_wire", "auxiliary_messenger"})
    fitting, wire_ = (a, b) if a[0] not in wire else (b, a)
    (kf, support, who), (kw, span, run) = fitting, wire_
    if support not in (span, span + 1):
        return False
    if kw in ("feeder", "earth_wire"):
        return kf in ("mast", "gantry") or (kf == "insulators" and who == run)
    if kf == "anchor":  # an overlap's ropes pull its runs' raised ends off to the anchor
        return kw in ("contact_wire", "messenger_wire", "auxiliary_messenger")
    track = re.sub(r"s\d+$", "", run.rstrip("bp"))  # the track whose fittings carry every tension section's wires
    if kf in ("registration_arm", "steady_arm"):
        return kw == "contact_wire" and who == track
    if kf in ("cantilever", "insulators"):
        return kw == "messenger_wire" and who == track
    return False


def clashes(overrides: list[str]) -> list[tuple[str, str]]:
    """The pairs of overhead-line objects of the railway built from ``overrides`` that pass through each other
    without being a joint."""
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.blender import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.detail.mode=fixed", "scene.catenary.points_per_10m=10", "scene.supports.mast_type=mixed", *overrides])
    build_scene(config.scene, frame_rng(3, 0), None)
    buffers = export_scene(load_class_table())
    objects, bounds = {}, {}
    for row, name in enumerate(buffers.objects.names):
        kind = element(name)
        if kind is None:
            continue
        tri = buffers.triangles[buffers.triangle_object == row]
        objects[name] = (kind, buffers.vertices, tri)
        bounds[name] = (buffers.vertices[tri].reshape(-1, 3).min(0), buffers.vertices[tri].reshape(-1, 3).max(0))
    names = sorted(objects)
    assert any(".registration_arm." in n for n in names) and any(".contact_wire" in n for n in names)
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            (ka, va, ta), (kb, vb, tb) = objects[a], objects[b]
            if (bounds[a][0] > bounds[b][1] + 0.01).any() or (bounds[b][0] > bounds[a][1] + 0.01).any():
                continue
            if not joint(ka, kb) and meshes_intersect(va, ta, vb, tb):
                out.append((a, b))
    return out


@pytest.mark.parametrize("layout,tracks", CASES)
def test_no_two_elements_intersect(layout, tracks):
    curve = "[0, 3, 0]" if tracks % 2 else "[0, 0, 0]"  # odd track counts on a 260 m curve (pulled-off wires)
    found = clashes([f"scene.supports.layout={layout}", f"scene.track.tracks={tracks}", "scene.track.start=[-55, 0, 0]",
                     f"scene.track.mid={curve}", "scene.track.end=[55, 0, 0]", "scene.catenary.double_contact_probability=0.5",
                     f"scene.catenary.auxiliary_messenger={str(AUXILIARY.get(tracks, False)).lower()}",
                     "scene.catenary.anchors=true", "scene.catenary.section_insulator_every=2"])
    assert not found, found[:10]


@pytest.mark.parametrize("layout,tracks", CASES)
def test_overlaps_and_steady_arms_stay_clear(layout, tracks):
    # 200 m, 40 m spans, tension sections of 80 m: an overlap over span 2 (two runs side by side, the ending one
    # rising 0.5 m to its anchor at support 3, the starting one anchored at support 2), steady arms apart
    curve = "[0, 6, 0]" if tracks % 2 else "[0, 0, 0]"
    overrides = [f"scene.supports.layout={layout}", f"scene.track.tracks={tracks}", "scene.track.start=[-100, 0, 0]", f"scene.track.mid={curve}",
                 "scene.track.end=[100, 0, 0]", "scene.supports.span=40", "scene.supports.span_jitter=1", "scene.catenary.tension_length=80",
                 "scene.catenary.steady_arms=true", "scene.catenary.double_contact_probability=0.5",
                 f"scene.catenary.auxiliary_messenger={str(AUXILIARY.get(tracks, False)).lower()}"]
    import bpy

    found = clashes(overrides)
    names = {o.name for o in bpy.data.objects}
    assert {"span.t0.02.contact_wire", "span.t0s1.02.contact_wire", "span.t0s1.03.contact_wire"} <= names
    assert any(".steady_arm." in n for n in names)
    if layout != "gantry":  # the ending run's raised end is roped to its anchor at support 3 (a gantry carries no anchors)
        end = np.array(bpy.data.objects["span.t0.02.contact_wire"].data.splines[0].points[-1].co[:3])
        anchors = [o for o in bpy.data.objects if o.name.startswith("support.03.anchor.")]
        vertices = np.concatenate([np.array([o.matrix_world @ v.co for v in o.data.vertices]) for o in anchors])
        assert np.linalg.norm(vertices - end, axis=1).min() < 0.02
    assert not found, found[:10]


def test_registration_arms_are_about_a_metre_long():
    import bpy

    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.blender import build_scene

    for layout, tracks in (("single", 2), ("both_sides", 4), ("gantry", 3)):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        config = load_config(None, [f"scene.supports.layout={layout}", f"scene.track.tracks={tracks}", "scene.detail.mode=fixed"])
        build_scene(config.scene, frame_rng(0, 0), None)
        arms = [o for o in bpy.data.objects if ".registration_arm." in o.name]
        assert arms
        for arm in arms:
            v = np.array([vert.co for vert in arm.data.vertices])
            length = np.linalg.norm(v.max(0) - v.min(0))  # its box's diagonal: length plus the tube's width
            assert 1.0 <= length <= 1.5 + 0.06, (arm.name, length)


def test_the_joint_rules_catch_a_clash():
    # a registration arm through another track's main tube, as the old two-track single-mast layout had
    from bpy_pipeline.builders.railway import parts as railway_parts

    near = railway_parts.cantilever(-3.05, 0.2, 6.2, 7.6, 0.3, arm_length=2.1)  # the old 2.1 m arm
    far = railway_parts.cantilever(-3.05, 4.2, 6.2, 7.6, 0.3)  # rooted at the mast face, under the near track's
    assert meshes_intersect(*near["registration arm"], *far["cantilever"])
    assert not meshes_intersect(*near["registration arm"], *near["insulator"])
    assert not joint(("registration_arm", 1, "t0"), ("cantilever", 1, "t1"))
    assert joint(("registration_arm", 1, "t0"), ("contact_wire", 0, "t0"))
    assert not joint(("registration_arm", 1, "t0"), ("contact_wire", 1, "t1"))
