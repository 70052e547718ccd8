"""Re-traced rays are bounded by their own first hit (the query's limit where they missed), and the caller's arrays
stay untouched.

embreex's ``EmbreeScene.run(..., dists=far)`` writes each hit's distance back into ``far``. The
caster re-traces suspect rays (a back face of an object the same query also hit from the
front: raycast.py, module notes); a moved ray wins only when strictly nearer than the ray's own
hit, so each re-trace is asked no farther than that hit (from the first trace's answer, a copy),
and the caller's limits keep their values.
"""

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.lidar.cast.raycast import RayCaster


def test_retraced_rays_keep_the_querys_range_and_the_callers_arrays_stay_untouched():
    # One open quad in the plane x = 0 (normal +x), seen from both sides in one query: the rays
    # from x < 0 meet its back face while others meet its front, so they are re-traced.
    quad = (np.array([[0.0, -5, -5], [0, 5, -5], [0, 5, 5], [0, -5, 5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    buffers = SceneBuffers.from_meshes({"quad": quad})
    caster = RayCaster(buffers, frame=np.eye(4), threads=1)
    rng = np.random.default_rng(0)
    n = 64
    side = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)  # even rays from +x (front), odd from -x (back)
    origins = np.column_stack([side * rng.uniform(1.0, 3.0, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])
    directions = np.column_stack([-side, rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    limits = np.full(n, 40.0)

    seen, answers = [], []  # the distance limits every Embree call was given, as it was given them, and its answers
    embree = caster._embree

    def spy(o32, d32, far):
        seen.append(np.array(far, np.float64))
        answers.append(tuple(np.array(a) for a in embree(o32, d32, far)))
        return answers[-1]

    caster._embree = spy
    hits = caster.intersect(origins, directions, limits)
    assert len(seen) == 2, "the back-face rays were not re-traced (one first trace, then the moved ones in one query)"
    assert len(seen[1]) == 4 * (n // 2), "each back-face ray is moved four ways"
    np.testing.assert_array_equal(seen[0], 40.0)
    back = np.arange(1, n, 2)
    first_hit = answers[0][0][back].astype(np.float64)
    assert (answers[0][1][back] >= 0).all() and (first_hit < 40.0).all()
    np.testing.assert_array_equal(seen[1], np.tile(first_hit, 4))  # every re-trace is bounded by its ray's own hit
    np.testing.assert_array_equal(limits, 40.0)
    # and the answer is the quad itself for every ray, at the exact distance
    assert np.array_equal(hits.ray, np.arange(n))
    np.testing.assert_allclose(hits.distance, np.abs(origins[:, 0] / directions[:, 0]), rtol=0, atol=1e-9)
