"""The kept static part of a :class:`~bpy_pipeline.lidar.cast.raycast.CasterCache` found again at other buffer positions
(``moved_in_buffers``): no Blender."""

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.lidar.cast.raycast import CasterCache, RayCaster, closed_surface


def box_mesh(centre, half, splits=1):
    """A closed box around ``centre`` of half-sizes ``half``: each face a ``splits`` x ``splits`` grid of quads, as
    ``(vertices (n, 3), triangles (m, 3))``."""
    vertices, triangles = [], []
    ticks = np.linspace(-1.0, 1.0, splits + 1)
    for axis in range(3):
        for side in (-1.0, 1.0):
            u, v = [a for a in range(3) if a != axis]
            start = len(vertices)
            for a in ticks:
                for b in ticks:
                    p = np.zeros(3)
                    p[axis], p[u], p[v] = side, a, b
                    vertices.append(np.asarray(centre) + p * half)
            for i in range(splits):
                for j in range(splits):
                    q = start + i * (splits + 1) + j
                    quad = [q, q + splits + 1, q + splits + 2, q + 1]
                    tri = [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
                    triangles += [t[::-1] for t in tri] if (side > 0) == (axis != 1) else tri
    return np.array(vertices), np.array(triangles)


def test_static_part_found_again_when_moving_objects_come_first_in_the_buffers():
    """The moving object is exported before the room and has more triangles in the second call, so every static
    triangle sits at another buffer position: the kept part is reused (its corners are the same) and traces as a
    fresh caster of the same buffers does. A room with one corner moved is built again."""
    room = box_mesh([0, 0, 2], np.array([12.0, 9.0, 4.0]), splits=3)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(20_000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    pose = np.eye(4)
    pose[:3, 3] = [0.5, -0.3, 1.0]
    cache = CasterCache(threads=2)
    for k, splits in enumerate((1, 2, 4)):
        buffers = SceneBuffers.from_meshes({"cart": box_mesh([3.0 + k, 1.0, 1.0], np.array([1.0, 0.6, 0.8]), splits), "room": room})
        moving = np.array([True, False])
        caster = cache.caster(buffers, pose, moving)
        fresh = RayCaster(buffers, pose, threads=2)
        a, b = caster.intersect(np.zeros(3), d), fresh.intersect(np.zeros(3), d)
        for field in ("ray", "distance", "triangle"):
            assert np.array_equal(getattr(a, field), getattr(b, field))
        assert (buffers.triangle_object[a.triangle] == 0).any() and (buffers.triangle_object[a.triangle] == 1).any()
    assert cache.builds == 1 and cache.reuses == 2
    moved = (room[0].copy(), room[1])
    moved[0][0] += 1e-9
    cache.caster(SceneBuffers.from_meshes({"cart": box_mesh([3.0, 1.0, 1.0], np.array([1.0, 0.6, 0.8])), "room": moved}), pose, np.array([True, False]))
    assert cache.builds == 2


def test_static_part_follows_a_sensor_that_moves_without_turning():
    """``follow``: the room's Embree scene is built once, in the poses' anchored frame (their origin snapped to the
    grid), and serves poses moved along a street (the same rotation): the rays' origins are shifted into it for Embree
    and every distance is solved in the new pose, so hits are a fresh caster's (same triangles here, distances within
    1e-9 m, the records' bytes equal), both through the compiled pass and the numpy path, and a pose gives the same
    records whichever pose came first. A turned pose or one in another grid cell builds again; without ``follow``
    every pose builds."""
    from bpy_pipeline.lidar.cast.raycast import FOLLOW_GRID
    from bpy_pipeline.lidar.sensor.rays import Pattern
    from bpy_pipeline.lidar.cast.scanner import scan

    room = box_mesh([20.0, 0, 2], np.array([60.0, 9.0, 4.0]), splits=6)
    rng = np.random.default_rng(5)
    d = rng.normal(size=(30_000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    pattern = Pattern(d, np.zeros(len(d), np.uint16), np.zeros(len(d)))
    poses = []
    for k in range(4):
        pose = np.eye(4)
        pose[:3, 3] = [-30.0 + 7.3 * k, -1.75, 1.73]
        poses.append(pose)

    def frame_buffers(pose):
        return SceneBuffers.from_meshes({"cart": box_mesh([pose[0, 3] + 6.0, 1.0, 1.0], np.array([2.0, 0.9, 0.8]), 2), "room": room})

    moving = np.array([True, False])
    for kernel in ("auto", "numpy"):
        cache, backwards, plain = (CasterCache(threads=2, kernel=kernel) for _ in range(3))
        records = {}
        for k, pose in enumerate(poses):
            buffers = frame_buffers(pose)
            caster = cache.caster(buffers, pose, moving, follow=True)
            plain.caster(buffers, pose, moving)
            fresh = RayCaster(buffers, pose, threads=2, kernel=kernel)
            a, b = caster.intersect(np.zeros(3), d), fresh.intersect(np.zeros(3), d)
            assert np.array_equal(a.ray, b.ray) and np.array_equal(a.triangle, b.triangle)
            assert np.abs(a.distance - b.distance).max() <= 1e-9
            assert (buffers.triangle_object[a.triangle] == 0).any()
            records[k] = scan(caster, buffers, pattern, pose, 0.1, 200.0)[0].tobytes()
            assert records[k] == scan(fresh, buffers, pattern, pose, 0.1, 200.0)[0].tobytes()
        assert (cache.builds, cache.reuses) == (1, 3) and (plain.builds, plain.reuses) == (4, 0)
        for k in reversed(range(4)):
            buffers = frame_buffers(poses[k])
            assert scan(backwards.caster(buffers, poses[k], moving, follow=True), buffers, pattern, poses[k], 0.1, 200.0)[0].tobytes() == records[k]
        assert backwards.builds == 1
    turned, far = np.eye(4), np.eye(4)
    turned[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    turned[:3, 3] = pose[:3, 3]
    far[:3, 3] = pose[:3, 3] + [FOLLOW_GRID, 0.0, 0.0]
    for other in (turned, far):
        cache.caster(buffers, other, moving, follow=True)
    assert cache.builds == 3


def test_rows_as_a_block_and_their_complement():
    """``as_block`` gives consecutive sorted rows as a slice, anything else as given; ``complement`` the other rows."""
    from bpy_pipeline.lidar.cast.raycast import as_block, complement

    assert as_block(np.arange(3, 8)) == slice(3, 8)
    gaps = np.array([1, 2, 4])
    assert as_block(gaps) is gaps
    assert complement(np.arange(0, 5), 9) == slice(5, 9)
    assert complement(np.arange(4, 9), 9) == slice(0, 4)
    assert complement(np.arange(0, 9), 9) == slice(9, 9)
    assert complement(np.zeros(0, np.int64), 9) == slice(0, 9)
    assert np.array_equal(complement(np.arange(2, 5), 9), [0, 1, 5, 6, 7, 8])
    assert np.array_equal(complement(gaps, 6), [0, 3, 5])


def test_kept_static_part_keeps_its_objects_closedness_and_planes():
    """The static room first in the buffers (a block of rows) and a moving cart after it, poses moved along x
    (``follow``): every caster's planes are a fresh caster's bit for bit, and the room's closedness is worked out
    once for the run (kept in the static part) while the cart's stays each caster's own."""
    room = box_mesh([20.0, 0, 2], np.array([60.0, 9.0, 4.0]), splits=4)
    cache = CasterCache(threads=2)
    for k in range(3):
        buffers = SceneBuffers.from_meshes({"room": room, "cart": box_mesh([3.0 + k, 1.0, 1.0], np.array([1.0, 0.6, 0.8]), 1 + k)})
        pose = np.eye(4)
        pose[:3, 3] = [-30.0 + 7.3 * k, -1.75, 1.73]
        caster = cache.caster(buffers, pose, np.array([False, True]), key="room", follow=True)
        fresh = RayCaster(buffers, pose, threads=2)
        assert np.array_equal(caster.plane_normal.view(np.int64), fresh.plane_normal.view(np.int64))
        assert np.array_equal(caster.plane_offset.view(np.int64), fresh.plane_offset.view(np.int64))
        assert [caster.closed(row) for row in (0, 1)] == [closed_surface(buffers.triangles[buffers.triangle_object == row]) for row in (0, 1)]
        assert list(cache.kept.closed) == [0]  # the cart's row is not the static part's
    assert cache.builds == 1 and cache.reuses == 2
    cache.kept.closed[0] = "kept"  # what the part keeps is what the next caster answers
    assert cache.caster(buffers, pose, np.array([False, True]), key="room", follow=True).closed(0) == "kept"
