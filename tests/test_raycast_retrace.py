"""Re-traced rays are bounded by their own first hit (the query's limit where they missed), and the caller's arrays
stay untouched; an open surface seen from both sides is not re-traced.

embreex's ``EmbreeScene.run(..., dists=far)`` writes each hit's distance back into ``far``. The
caster re-traces suspect rays (a back face of a closed object the same query also hit from the
front: raycast.py, module notes); a moved ray wins only when strictly nearer than the ray's own
hit, so each re-trace is asked no farther than that hit (from the first trace's answer, a copy),
and the caller's limits keep their values.
"""

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.lidar.cast.raycast import RayCaster


def rays_from_both_sides(n: int, rng: np.random.Generator, plane_x: float) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 3)`` origins and unit directions towards the plane x = ``plane_x``: even rays from 1..3 m before it (larger x),
    odd ones from 1..3 m behind it."""
    side = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    origins = np.column_stack([side * rng.uniform(1.0, 3.0, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])
    directions = np.column_stack([-side, rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins[:, 0] += plane_x
    return origins, directions


def spied(caster: RayCaster) -> tuple[list, list]:
    """The distance limits every Embree call of ``caster`` is given, as it was given them, and its answers."""
    seen, answers = [], []
    embree = caster._embree

    def spy(o32, d32, far):
        seen.append(np.array(far, np.float64))
        answers.append(tuple(np.array(a) for a in embree(o32, d32, far)))
        return answers[-1]

    caster._embree = spy
    return seen, answers


def test_retraced_rays_keep_the_querys_range_and_the_callers_arrays_stay_untouched():
    # A closed box from x = -5 to 5 (its faces outwards), its face x = 5 seen in one query from outside (even rays: its
    # front) and from inside the box (odd rays: its back): the odd rays are re-traced.
    box = primitives.box(10.0, 10.0, 10.0)
    buffers = SceneBuffers.from_meshes({"box": box})
    caster = RayCaster(buffers, frame=np.eye(4), threads=1)
    n = 64
    origins, directions = rays_from_both_sides(n, np.random.default_rng(0), 5.0)
    limits = np.full(n, 40.0)
    seen, answers = spied(caster)
    hits = caster.intersect(origins, directions, limits)
    assert len(seen) == 2, "the back-face rays were not re-traced (one first trace, then the moved ones in one query)"
    assert len(seen[1]) == 4 * (n // 2), "each back-face ray is moved four ways"
    np.testing.assert_array_equal(seen[0], 40.0)
    back = np.arange(1, n, 2)
    first_hit = answers[0][0][back].astype(np.float64)
    assert (answers[0][1][back] >= 0).all() and (first_hit < 40.0).all()
    np.testing.assert_array_equal(seen[1], np.tile(first_hit, 4))  # every re-trace is bounded by its ray's own hit
    np.testing.assert_array_equal(limits, 40.0)
    # and every ray meets the face x = 5, at the exact distance
    assert np.array_equal(hits.ray, np.arange(n))
    np.testing.assert_allclose(hits.distance, np.abs((origins[:, 0] - 5.0) / directions[:, 0]), rtol=0, atol=1e-9)


def test_an_open_surface_seen_from_both_sides_is_not_traced_again():
    """A pane, a leaf or a fence is seen from behind by rays that slipped nowhere: only a closed object's back faces
    tell of a slip. Each ray keeps its own first hit."""
    quad = (np.array([[0.0, -5, -5], [0, 5, -5], [0, 5, 5], [0, -5, 5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    caster = RayCaster(SceneBuffers.from_meshes({"quad": quad}), frame=np.eye(4), threads=1)
    n = 64
    origins, directions = rays_from_both_sides(n, np.random.default_rng(0), 0.0)
    seen, _ = spied(caster)
    hits = caster.intersect(origins, directions, np.full(n, 40.0))
    assert len(seen) == 1, "rays at the back of an open quad were traced again"
    assert np.array_equal(hits.ray, np.arange(n))
    np.testing.assert_allclose(hits.distance, np.abs(origins[:, 0] / directions[:, 0]), rtol=0, atol=1e-9)
