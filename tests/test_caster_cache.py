"""The kept static part of a :class:`~bpy_pipeline.lidar.cast.raycast.CasterCache` found again at other buffer positions
(``moved_in_buffers``): no Blender."""

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.lidar.cast.raycast import CasterCache, RayCaster


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
