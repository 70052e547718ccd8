"""Embree reading the caster's buffers in place (lidar/cast/embree.py) gives embreex's own hits.

The shared-buffer scene and embreex's ``TriangleMesh`` (the fallback) are built from the same
vertices and triangles and traced with the same rays: same triangle, same float32 distance for
every ray. The caster keeps the buffers Embree reads alive with the scene.
"""

import gc
import os

import numpy as np
import pytest
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.lidar.cast import embree
from bpy_pipeline.lidar.cast.raycast import RayCaster, default_threads


def terrain(n: int = 120, seed: int = 0):
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(-20, 20, n), np.linspace(-20, 20, n), indexing="ij"), -1).reshape(-1, 2)
    vertices = np.column_stack([g, rng.normal(0, 0.3, len(g))])
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.int32)


def rays(count: int = 20000, seed: int = 1):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d[:, 2] = -np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.tile(np.float32([0.5, -0.3, 4.0]), (count, 1)), d.astype(np.float32)


def test_shared_buffers_give_triangle_meshs_hits():
    vertices, triangles = terrain()
    origins, directions = rays()
    copied = rtcore_scene.EmbreeScene()
    TriangleMesh(copied, vertices.astype(np.float32), triangles)
    shared = rtcore_scene.EmbreeScene()
    keep = embree.attach_triangles(shared, vertices, triangles)
    assert bool(keep) == embree.shared_buffers_supported()
    a, b = copied.run(origins, directions, output=1), shared.run(origins, directions, output=1)
    assert (a["primID"] >= 0).mean() > 0.5
    np.testing.assert_array_equal(a["primID"], b["primID"])
    np.testing.assert_array_equal(a["tfar"], b["tfar"])


def test_the_fallback_gives_the_same_caster(monkeypatch):
    vertices, triangles = terrain(40)
    buffers = SceneBuffers.from_meshes({"terrain": (vertices, triangles)})
    origins, directions = rays(5000)
    pose = np.eye(4)
    shared = RayCaster(buffers, frame=pose, kernel="numpy").intersect(origins[0].astype(np.float64), directions.astype(np.float64))
    monkeypatch.setattr(embree, "shared_buffers_supported", lambda: False)
    copied = RayCaster(buffers, frame=pose, kernel="numpy")
    assert copied.parts[0].keep == ()
    fallback = copied.intersect(origins[0].astype(np.float64), directions.astype(np.float64))
    for field in ("ray", "distance", "triangle"):
        np.testing.assert_array_equal(getattr(shared, field), getattr(fallback, field))


def test_the_caster_keeps_the_buffers_embree_reads():
    vertices, triangles = terrain(60)
    buffers = SceneBuffers.from_meshes({"terrain": (vertices, triangles)})
    caster = RayCaster(buffers, frame=np.eye(4), kernel="numpy")
    origins, directions = rays(3000)
    before = caster.intersect(origins[0].astype(np.float64), directions.astype(np.float64))
    del buffers, vertices, triangles
    gc.collect()
    np.zeros((4000, 4000))  # reuse freed memory, were the buffers freed
    after = caster.intersect(origins[0].astype(np.float64), directions.astype(np.float64))
    np.testing.assert_array_equal(before.distance, after.distance)


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="no os.sched_getaffinity on this system")
def test_threads_default_to_the_cores_this_process_may_use():
    assert default_threads() == len(os.sched_getaffinity(0))
    assert RayCaster(SceneBuffers.from_meshes({"t": terrain(4)}), frame=np.eye(4), threads=3).threads == 3


def test_a_low_build_gives_the_default_builds_hits():
    """``build="low"`` (Embree's Morton build, for the per-frame scenes few rays meet: visibility's AloneCaster) changes the
    hierarchy, not the nearest hit of any ray."""
    vertices, triangles = terrain()
    origins, directions = rays(50000)
    buffers = SceneBuffers.from_meshes({"terrain": (vertices, triangles)})
    pose = np.eye(4)
    hits = [RayCaster(buffers, frame=pose, build=build).intersect(origins[0].astype(np.float64), directions.astype(np.float64))
            for build in ("medium", "low")]
    assert len(hits[0].ray) > len(directions) // 2
    for field in ("ray", "distance", "triangle", "normal"):
        np.testing.assert_array_equal(getattr(hits[0], field), getattr(hits[1], field))


def test_a_low_build_is_asked_of_the_scene_and_its_geometry(monkeypatch):
    """Embree builds its fast hierarchy only when both the scene's and the geometry's quality are low."""
    if not embree.shared_buffers_supported():
        pytest.skip("this embreex's layout is not the checked one: its TriangleMesh builds at Embree's default")
    lib = embree._library()
    asked = []
    for name in ("rtcSetSceneBuildQuality", "rtcSetGeometryBuildQuality"):
        real = getattr(lib, name)
        monkeypatch.setattr(lib, name, lambda handle, quality, name=name, real=real: (asked.append((name, quality)), real(handle, quality))[1])
    vertices, triangles = terrain(20)
    embree.attach_triangles(rtcore_scene.EmbreeScene(), vertices, triangles)
    assert asked == []  # Embree's default
    embree.attach_triangles(rtcore_scene.EmbreeScene(), vertices, triangles, build="low")
    assert sorted(asked) == [("rtcSetGeometryBuildQuality", 0), ("rtcSetSceneBuildQuality", 0)]
