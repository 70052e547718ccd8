"""The faster ways of the boxes stage and the parking placement give the bits of the ways they replace.

- truncation's coverage of every object at once (:func:`covered_by_owner`, each object's window of cells, in numpy and
  compiled) against one :class:`Coverage` per object;
- :func:`surface_samples` written in place against level by level, and given the triangles' areas against computing them;
- whether a box has area, from its first triangle, against the sum of all its triangles' areas;
- the vertices an object set uses, without a sort, against ``np.unique``; the boxes' triangles found by a search of
  exported buffers' ordered objects against a pass over every triangle;
- the placer's slab test against :func:`~bpy_pipeline.geometry.collision.ray_box_distance`, rays along the box's
  faces and axes included (the whole visibility against its per-object reference: tests/test_boxes.py);
- a capsule's mesh (every body segment of every person, every frame) built at once against ring by ring, and a
  body's capsules all at once against one by one;
- the street's and the garage's free-space prefilter against testing every rectangle;
- a wheel from its cached cylinder against the cylinder made anew;
- rows' lengths (:func:`~bpy_pipeline.lidar.cast.raycast.row_norms`) against ``np.linalg.norm``, and the suspect rays
  moved four ways in one Embree query against one query a way;
- the placer's occlusion tests of every placed box at once against one box at a time;
- the insertion rule's turn of a candidate, the rectangles' separating axes and the placer's region and keep-out
  tests in Python floats against the numpy forms they replace.
"""

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.geometry.boxes import fit_boxes, object_triangles
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.collision import box_axes, capsule_mesh, capsule_meshes, ray_box_distance, rectangles_near, rectangles_overlap
from bpy_pipeline.geometry.placement import FloorBoxPlacer, PlacedBox, _slab_distance, facing_samples
from bpy_pipeline.lidar.cast.raycast import JITTER, RayCaster, choose_kernels, row_norms
from bpy_pipeline.lidar.cast.visibility import (Coverage, _centroids, _used_vertices, compiled_passes, covered_by_owner, have_area, surface_samples,
                                                triangle_areas)

COMPILED = [passes for passes in [compiled_passes(choose_kernels("auto"))] if passes is not None]  # the compiled windows too, where numba is


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _each_objects_coverage(points, owner, samples, sample_owner, count, cell):
    expected = np.zeros(len(samples), bool)
    for k in range(count):
        mine = sample_owner == k
        if (owner == k).any():
            expected[mine] = Coverage(points[owner == k], cell).covers(samples[mine])
    return expected


def test_coverage_of_all_objects_at_once_is_each_objects_coverage():
    rng = np.random.default_rng(4)
    count = 70
    # objects spread over the whole sphere: every window is every cell
    points = _unit(rng.normal(size=(3000, 3))) * rng.uniform(1, 30, (3000, 1))
    points[:200, 2] = np.abs(points[:200, 2]) + 50  # near the pole: rows clamp there
    owner = rng.integers(0, count - 5, len(points))  # the last objects pass no ray
    samples = _unit(rng.normal(size=(20000, 3))) * rng.uniform(1, 30, (20000, 1))
    sample_owner = rng.integers(0, count, len(samples))
    where = rng.random(len(samples)) < 0.7
    for cell in (1.0, 0.7, 2.0):
        expected = _each_objects_coverage(points, owner, samples, sample_owner, count, cell)
        assert expected.any() and not expected.all()
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell), expected)
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=where), expected & where)
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=where, distance=np.linalg.norm(samples, axis=1)),
                              expected & where)
        every = np.ones(len(samples), bool)  # a mask of all True takes the way of no mask
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=every, distance=np.linalg.norm(samples, axis=1)),
                              expected)
        for passes in COMPILED:
            assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, passes=passes), expected)
            assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=where, passes=passes), expected & where)


def test_coverage_of_small_objects_across_the_seam_and_at_a_pole():
    """Objects as a street's are, each a few cells wide: one across azimuth 180 deg, where columns wrap, one
    over the sensor, where rows clamp, one beside a single point, and objects no ray passes."""
    rng = np.random.default_rng(6)
    count = 40
    centres = _unit(rng.normal(size=(count, 3)))
    centres[0], centres[1] = [-1, 0, 0.01], [0.01, 0, 1]
    spread = rng.uniform(0.01, 0.3, count)
    spread[2] = 0.0
    owner = rng.integers(0, count - 3, 5000)
    owner[owner == 2] = 3
    owner[0] = 2  # object 2: one point
    sample_owner = rng.integers(0, count, 30000)
    points = (centres[owner] + rng.normal(size=(5000, 3)) * spread[owner, None]) * rng.uniform(1, 40, (5000, 1))
    samples = (centres[sample_owner] + rng.normal(size=(30000, 3)) * np.maximum(spread, 0.002)[sample_owner, None]) * rng.uniform(1, 40, (30000, 1))
    where = rng.random(len(samples)) < 0.8
    azimuth = np.degrees(np.arctan2(samples[sample_owner == 0, 1], samples[sample_owner == 0, 0]))
    assert (azimuth > 170).any() and (azimuth < -170).any()  # object 0 straddles the seam
    for cell in (0.2, 0.35, 1.0):
        expected = _each_objects_coverage(points, owner, samples, sample_owner, count, cell)
        assert expected[sample_owner == 0].any() and expected[sample_owner == 1].any() and expected[sample_owner == 2].any()
        assert not expected[sample_owner >= count - 3].any()
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell), expected)
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=where, distance=np.linalg.norm(samples, axis=1)),
                              expected & where)
        every = np.ones(len(samples), bool)  # a mask of all True takes the way of no mask
        assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=every, distance=np.linalg.norm(samples, axis=1)),
                              expected)
        for passes in COMPILED:
            assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, passes=passes), expected)
            assert np.array_equal(covered_by_owner(points, owner, samples, sample_owner, count, cell, where=where, passes=passes), expected & where)


def _surface_samples_level_by_level(triangles, spacing):
    """The way :func:`surface_samples` sampled before it wrote in place: each level's rows found by a scan, its
    blocks joined at the end (the reference for its bits)."""
    first, edge1, edge2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    area = np.linalg.norm(np.cross(edge1, edge2), axis=1) / 2
    edge = np.minimum(np.maximum(np.linalg.norm(edge1, axis=1), np.linalg.norm(edge2, axis=1)), np.sqrt(2.0 * area))
    level = np.clip(np.ceil(edge / spacing), 1, 24).astype(int)
    points, weights, owners = [], [], []
    for n in np.unique(level):
        rows = np.flatnonzero(level == n)
        u, v = _centroids(int(n))
        block = np.multiply(u[None, :, None], edge1[rows][:, None])
        block += first[rows][:, None]
        block += np.multiply(v[None, :, None], edge2[rows][:, None])
        points.append(block.reshape(-1, 3))
        weights.append(np.repeat(area[rows] / n**2, len(u)))
        owners.append(np.repeat(rows, len(u)))
    return np.concatenate(points), np.concatenate(weights), np.concatenate(owners)


def test_surface_samples_written_in_place_are_the_bits_of_level_by_level():
    rng = np.random.default_rng(7)
    triangles = rng.normal(size=(3000, 3, 3)) * rng.uniform(0.005, 4, (3000, 1, 1))  # levels 1 to 24
    spacing = rng.uniform(0.05, 0.5, 3000)
    new = surface_samples(triangles, spacing, return_triangle=True, area_bound=True)
    assert len(np.unique(np.bincount(new[2]))) > 20  # many levels, each n^2 samples a triangle
    for x, y in zip(new, _surface_samples_level_by_level(triangles, spacing)):
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()
    empty = surface_samples(np.zeros((0, 3, 3)), 0.1, return_triangle=True)
    assert [a.shape for a in empty] == [(0, 3), (0,), (0,)]


def test_surface_samples_with_given_areas_are_the_same_bits():
    rng = np.random.default_rng(5)
    triangles = rng.normal(size=(500, 3, 3)) * rng.uniform(0.01, 3, (500, 1, 1))
    area = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1) / 2
    spacing = rng.uniform(0.05, 0.5, 500)
    a = surface_samples(triangles, spacing, return_triangle=True, area_bound=True)
    b = surface_samples(triangles, spacing, return_triangle=True, area_bound=True, area=area)
    for x, y in zip(a, b):
        assert x.tobytes() == y.tobytes()
    # the centroids of a cut triangle: n^2 of them, their areas adding up to the triangle's
    points, weights, owner = a
    assert np.allclose(np.bincount(owner, weights, minlength=500), area)


def test_used_vertices_is_unique_with_inverse():
    rng = np.random.default_rng(6)
    triangles = rng.integers(0, 5000, (3000, 3)).astype(np.int32)
    used, inverse = np.unique(triangles, return_inverse=True)
    used2, inverse2 = _used_vertices(triangles, 6000)
    assert np.array_equal(used, used2) and np.array_equal(inverse.ravel(), inverse2)
    used3, inverse3 = _used_vertices(triangles + 900, 6000)  # the table starts at the lowest vertex used
    assert np.array_equal(used + 900, used3) and np.array_equal(inverse.ravel(), inverse3)
    assert all(len(a) == 0 for a in _used_vertices(np.zeros((0, 3), np.int32), 10))


def _objects(rng, count, ordered):
    """Buffers of ``count`` small random objects (each its own vertices, two of them unused), two objects an instance,
    classes car or wall; triangles in object order, or shuffled."""
    vertices, triangles, owner = [], [], []
    for row in range(count):
        vertices.append(rng.uniform(-1, 1, (12, 3)) + rng.uniform(-50, 50, 3))
        triangles.append(rng.integers(0, 10, (int(rng.integers(1, 9)), 3)) + 12 * row)
        owner.append(np.full(len(triangles[-1]), row, np.int32))
    triangles, owner = np.concatenate(triangles).astype(np.int32), np.concatenate(owner)
    if not ordered:
        order = rng.permutation(len(owner))
        triangles, owner = triangles[order], owner[order]
    objects = ObjectTable([f"o{r}" for r in range(count)], [""] * count, [["car", "wall"][r % 3 == 0] for r in range(count)], np.zeros(count, np.uint16),
                          (np.arange(count) // 2 + 1).astype(np.uint32), np.zeros(count, np.uint8), np.full(count, 0.5, np.float32))
    return SceneBuffers(np.concatenate(vertices), triangles, owner, objects)


def test_boxes_triangles_found_by_a_search_of_ordered_objects_are_the_pass_over_every_triangle():
    for ordered in (True, False):
        buffers = _objects(np.random.default_rng(11), 40, ordered)
        box_of_row = np.where(np.asarray(buffers.objects.class_names) == "car", buffers.objects.instance.astype(np.int64), -1)
        triangle, box = object_triangles(buffers, box_of_row)
        expected = np.flatnonzero(box_of_row[buffers.triangle_object] >= 0)
        assert len(expected) > 50 and np.array_equal(triangle, expected) and np.array_equal(box, box_of_row[buffers.triangle_object[expected]])
    # the same objects with their triangles in another order: the same boxes
    headings = {1: 0.3, 4: -2.0}
    boxes = [fit_boxes(_objects(np.random.default_rng(11), 40, ordered), ["car"], headings) for ordered in (True, False)]
    assert len(boxes[0]) == 20 and boxes[0].tobytes() == boxes[1].tobytes()


def _ray_box_distance(origin, directions, centre, axes, half):
    """The placer's slab test of one box: its rays turned into the box's axes, then :func:`_slab_distance`."""
    return _slab_distance((origin - centre) @ axes, directions @ axes, half)


def test_placer_slab_test_is_ray_box_distance():
    rng = np.random.default_rng(7)
    for trial in range(200):
        yaw = float(rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)]))
        axes = box_axes(yaw)
        centre = rng.uniform(-5, 5, 3)
        half = rng.uniform(0.2, 2.5, 3)
        sensor = rng.uniform(-5, 5, 3) if trial % 3 else centre + rng.uniform(-0.1, 0.1, 3)  # some start inside
        directions = _unit(rng.normal(size=(64, 3)))
        directions[:8] = axes.T[rng.integers(0, 3, 8)] * rng.choice([-1.0, 1.0], (8, 1))  # along the box's axes
        directions[8:12] = _unit(facing_samples(sensor, centre, half, yaw)[:4] - sensor) if len(facing_samples(sensor, centre, half, yaw)) else directions[8:12]
        with np.errstate(divide="ignore", invalid="ignore"):
            fast = _ray_box_distance(sensor, directions, centre, axes, half)
        assert fast.tobytes() == ray_box_distance(sensor, directions, centre, axes, half).tobytes()


def test_the_placers_occlusion_tests_of_every_box_at_once_are_one_box_at_a_time():
    """A candidate's samples against every placed box, and every placed box's samples against the candidate, in one
    slab test each: the bits of :func:`_ray_box_distance` one box at a time (boxes in front, behind, around the
    sensor, and rays along their axes)."""
    rng = np.random.default_rng(21)
    for trial in range(40):
        placer = FloorBoxPlacer(rng.uniform(-1, 1, 3), ((-30.0, -30.0), (30.0, 30.0)))
        for _ in range(int(rng.integers(0, 7))):
            half = rng.uniform(0.3, 2.5, 3)
            centre = np.array([*rng.uniform(-12, 12, 2), half[2]])
            yaw = float(rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)]))
            samples = facing_samples(placer.sensor, centre, half, yaw)
            placer.boxes.append(PlacedBox(centre, half, yaw, samples, rng.random(len(samples)) < 0.8))
        half = rng.uniform(0.3, 2.5, 3)
        candidate = PlacedBox(np.array([*rng.uniform(-12, 12, 2), half[2]]), half, float(rng.uniform(-np.pi, np.pi)), np.zeros((0, 3)), np.zeros(0, bool))
        directions = _unit(rng.normal(size=(48, 3)))
        directions[:6] = box_axes(candidate.yaw).T[rng.integers(0, 3, 6)]  # along a box's axes: divisions by zero
        distance = rng.uniform(0.5, 30, 48)
        expected = np.zeros(48, bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            for box in placer.boxes:
                expected |= _ray_box_distance(placer.sensor, directions, box.centre, box_axes(box.yaw), box.half) < distance - 1e-6
            hidden = [_ray_box_distance(placer.sensor, _rays(placer, box)[0], candidate.centre, box_axes(candidate.yaw),
                                        candidate.half) < _rays(placer, box)[1] - 1e-6 for box in placer.boxes]
        assert np.array_equal(placer._blocked(directions, distance, placer.boxes), expected)
        got = placer._hidden_by(candidate)
        assert len(got) == len(placer.boxes) and all(np.array_equal(a, b) for a, b in zip(got, hidden))
        if trial == 39:
            assert expected.any() and any(h.any() for h in hidden)


def _rays(placer, box):
    """A placed box's samples' directions and distances from the sensor, as the placer computes them."""
    offset = box.samples - placer.sensor
    distance = np.linalg.norm(offset, axis=1)
    return offset / np.maximum(distance, 1e-12)[:, None], distance


def _capsule_ring_by_ring(a, b, radius, segments=10, rings=3, flat_start=False):
    """The capsule mesh as it was built before, a ring and a band at a time with ``np.cross``: the reference."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    w = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(w, helper)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    circle = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
    rows = [(a, 0.0, radius)] if flat_start else [(a, -radius * np.cos(np.pi / 2 * k / (rings + 1)),
                                                   radius * np.sin(np.pi / 2 * k / (rings + 1))) for k in range(1, rings + 1)] + [(a, 0.0, radius)]
    rows += [(b, 0.0, radius)] + [(b, radius * np.cos(np.pi / 2 * k / (rings + 1)), radius * np.sin(np.pi / 2 * k / (rings + 1))) for k in range(rings, 0, -1)]
    vertices = np.concatenate([[a if flat_start else a - radius * w], *[c + o * w + r * circle for c, o, r in rows], [b + radius * w]])
    j = np.arange(segments)
    k = (j + 1) % segments
    tris = [np.stack([np.zeros(segments, int), 1 + k, 1 + j], 1)]
    for r in range(len(rows) - 1):
        lo, hi = 1 + r * segments, 1 + (r + 1) * segments
        tris += [np.stack([lo + j, lo + k, hi + k], 1), np.stack([lo + j, hi + k, hi + j], 1)]
    last = 1 + (len(rows) - 1) * segments
    tris.append(np.stack([np.full(segments, len(vertices) - 1), last + j, last + k], 1))
    return vertices, np.concatenate(tris).astype(np.int32)


def test_a_capsule_built_at_once_is_the_same_bits_as_ring_by_ring():
    rng = np.random.default_rng(6)
    for i in range(600):
        a, b = rng.normal(size=3) * rng.uniform(0.1, 100), rng.normal(size=3)
        if i % 10 == 0:
            b = a.copy()  # a sphere
        options = {"segments": int(rng.integers(3, 16)), "rings": int(rng.integers(1, 5)), "flat_start": bool(rng.random() < 0.3)}
        radius = float(rng.uniform(0.01, 1.0))
        vertices, triangles = capsule_mesh(a, b, radius, **options)
        want_vertices, want_triangles = _capsule_ring_by_ring(a, b, radius, **options)
        assert vertices.dtype == want_vertices.dtype and vertices.tobytes() == want_vertices.tobytes(), (i, options)
        assert triangles.dtype == want_triangles.dtype and triangles.tobytes() == want_triangles.tobytes(), (i, options)


def test_a_bodys_capsules_built_at_once_are_each_capsules_bits():
    from bpy_pipeline.geometry import human

    rng = np.random.default_rng(7)
    for i in range(40):
        person = human.pose_person(human.sample_pose(human.POSES[i % len(human.POSES)], rng), float(rng.uniform(1.4, 2.0)), 1.0,
                                   "walking", rng.normal(size=2) * 20, float(rng.uniform(-3, 3)))
        a, b, radius = person.a.copy(), person.b.copy(), person.radius
        a[0] = b[0]  # a zero-length axis (a sphere) among them
        vertices, triangles = capsule_meshes(a, b, radius, 8, 2)
        for k in range(len(radius)):
            want_vertices, want_triangles = capsule_mesh(a[k], b[k], float(radius[k]), 8, 2)
            assert vertices[k].tobytes() == want_vertices.tobytes() and triangles.tobytes() == want_triangles.tobytes(), (i, k)
        body_vertices, body_triangles, owner = human.body_mesh(a, b, radius, 8, 2)
        assert body_vertices.tobytes() == vertices.reshape(-1, 3).tobytes()
        assert np.array_equal(body_triangles, (triangles[None] + (np.arange(len(radius)) * vertices.shape[1])[:, None, None]).reshape(-1, 3))
        assert np.array_equal(owner, np.repeat(np.arange(len(radius)), vertices.shape[1]))


def test_the_free_space_prefilter_keeps_every_overlapping_rectangle():
    rng = np.random.default_rng(8)
    for clearance in (0.0, 0.3):
        centres = rng.uniform(-20, 20, (300, 2))
        halves = rng.uniform(0.1, 3.0, (300, 2))
        yaws = rng.uniform(-np.pi, np.pi, 300)
        radii = np.hypot(halves[:, 0] + clearance / 2, halves[:, 1] + clearance / 2)
        for _ in range(300):
            centre, half, yaw = rng.uniform(-20, 20, 2), rng.uniform(0.1, 3.0, 2), float(rng.uniform(-np.pi, np.pi))
            near = set(rectangles_near(centre, half, clearance, centres, radii).tolist())
            overlapping = {k for k in range(len(centres)) if rectangles_overlap(centre, half, yaw, centres[k], halves[k], yaws[k], clearance)}
            assert overlapping <= near
            assert len(near) < len(centres)  # it does filter


def test_a_wheel_from_its_cached_cylinder_is_the_cylinder_made_anew():
    from bpy_pipeline.geometry.primitives import cylinder, wheel_mesh

    rng = np.random.default_rng(9)
    for _ in range(50):
        x, y, radius, width, sides = *rng.normal(size=2), float(rng.choice([0.31, 0.5])), float(rng.choice([0.2, 0.3])), int(rng.choice([8, 12]))
        v, t = cylinder(radius, width, sides)
        want = (v[:, [0, 2, 1]] + [x, y, radius], t[:, ::-1].copy())
        got = wheel_mesh(x, y, radius, width, sides)
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
        got[0][:] = 0.0  # a caller may change its wheel: the next one is unchanged
        got[1][:] = 0
        again = wheel_mesh(x, y, radius, width, sides)
        assert again[0].tobytes() == want[0].tobytes() and again[1].tobytes() == want[1].tobytes()


def test_boxes_fitted_from_triangles_grouped_once_are_the_per_instance_isin_boxes():
    """fit_boxes groups the wanted objects' triangles by object row once; the reference looks each instance's up
    over every triangle (np.isin). Objects of one instance spread over the table, some classes unwanted, a heading
    given for some: the same bits."""
    from bpy_pipeline.buffers import SceneBuffers
    from bpy_pipeline.geometry.boxes import BOX_DTYPE, fit_boxes, footprint_heading, wrap_angle

    rng = np.random.default_rng(11)
    meshes = {}
    for k in range(40):
        centre = rng.uniform(-50, 50, 3)
        vertices = centre + rng.normal(size=(30, 3)) * rng.uniform(0.2, 2.0, 3)
        meshes[f"part{k}"] = (vertices, rng.integers(0, 30, (25, 3)))
    buffers = SceneBuffers.from_meshes(meshes)
    names = np.array(["car", "person", "building", "car", "pole"])[rng.integers(0, 5, 40)]
    buffers.objects.class_names[:] = list(names)
    buffers.objects.instance[:] = rng.integers(1, 12, 40)  # several rows an instance, in any order
    classes = ["car", "person"]
    headings = {2: 0.3, 5: -1.2}
    got = fit_boxes(buffers, classes, headings)

    objects = buffers.objects
    by_instance = {}
    for r in range(len(objects)):
        if objects.class_names[r] in classes:
            by_instance.setdefault(int(objects.instance[r]), []).append(r)
    expected = np.zeros(len(by_instance), BOX_DTYPE)
    for k, (instance, members) in enumerate(sorted(by_instance.items())):
        vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, members)])]
        yaw = headings.get(instance, None)
        yaw = footprint_heading(vertices[:, :2]) if yaw is None else yaw
        c, s = np.cos(yaw), np.sin(yaw)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        local = vertices @ rotation
        low, high = local.min(axis=0), local.max(axis=0)
        expected[k]["class_name"], expected[k]["instance"] = objects.class_names[members[0]], instance
        expected[k]["centre"], expected[k]["size"], expected[k]["heading"] = rotation @ ((low + high) / 2), high - low, wrap_angle(yaw)
    assert len(got) >= 8 and got.tobytes() == expected.tobytes()


def test_the_cone_prefilter_keeps_every_pair_of_the_full_matrix_compiled_or_numpy():
    """cone_pairs: ray-major pairs, compiled or numpy in blocks, the same pairs; every pair the full (n, k) matrix
    test lets through is among them (the margin covers rounding), rays on a cone's edge included."""
    from bpy_pipeline.lidar.cast.kernels import compiled
    from bpy_pipeline.lidar.cast.visibility import CONE_BLOCK, cone_pairs

    rng = np.random.default_rng(12)
    directions = _unit(rng.normal(size=(2 * CONE_BLOCK + 777, 3)))  # blocks and a remainder
    centres = rng.normal(size=(30, 3)) * 20
    distance = np.linalg.norm(centres, axis=1)
    axes = centres / distance[:, None]
    radius = rng.uniform(0.5, 4.0, len(centres))
    cos_limit = np.sqrt(1 - (radius / distance) ** 2)
    edge = np.sqrt(1 - cos_limit[:5] ** 2)  # rays on the edges of the first five cones
    side = _unit(np.cross(axes[:5], [0.0, 0.0, 1.0]))
    directions[:5] = axes[:5] * cos_limit[:5, None] + side * edge[:, None]
    full = np.nonzero(directions @ axes.T >= cos_limit[None])
    numpy_pairs = cone_pairs(directions, axes, cos_limit)
    assert np.all(np.diff(numpy_pairs[0]) >= 0)  # ray-major
    pair_set = set(zip(*(a.tolist() for a in numpy_pairs)))
    assert set(zip(*(a.tolist() for a in full))) <= pair_set and {(j, j) for j in range(5)} <= pair_set
    assert len(pair_set) - len(full[0]) <= 5  # the margin adds rounding-close pairs, no more
    kernels = compiled()
    if kernels is not None:
        compiled_pairs = cone_pairs(directions, axes, cos_limit, kernels)
        assert all(np.array_equal(a, b) for a, b in zip(compiled_pairs, numpy_pairs))


def test_the_compiled_cone_test_skips_only_boxes_no_ray_of_a_block_can_reach():
    """cone_blocks prunes (block of consecutive rays, box) pairs by the blocks' bounding cones: on a spinning
    pattern most pairs go, yet every pair the full matrix keeps is in a kept block, the pairs are numpy's, rays on a
    cone's edge included; a box around the sensor keeps every block, rays all round the sphere keep every box, and so
    does a block with a ray that is not unit."""
    from bpy_pipeline.lidar.cast.kernels import compiled
    from bpy_pipeline.lidar.cast.numba_kernels import CONE_RAYS
    from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern
    from bpy_pipeline.lidar.cast.visibility import CONE_MARGIN, cone_pairs

    kernels = compiled()
    if kernels is None:
        pytest.skip("numba is not installed: the numpy cone test has no blocks")
    directions = np.ascontiguousarray(sensor_pattern(resolve_sensor({"preset": "hdl64e"})).directions, np.float64)
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(60, 3)) * [25.0, 25.0, 1.0]
    centres[-1] = [0.3, 0.2, 0.1]  # the sensor inside this one's sphere: every ray may pass it
    distance = np.linalg.norm(centres, axis=1)
    axes = centres / distance[:, None]
    radius = rng.uniform(0.5, 3.0, len(centres))
    cos_limit = np.where(distance > radius, np.sqrt(np.clip(1 - (radius / distance) ** 2, 0, 1)), -2.0)
    # the first ten cones' edges through a ray each: a ray of a block right on a box's boundary
    for j, i in enumerate(rng.choice(len(directions), 10, replace=False)):
        cos_limit[j] = directions[i] @ axes[j]
    limit = cos_limit - CONE_MARGIN
    keep = kernels.cone_blocks(directions, np.ascontiguousarray(axes), limit)
    full = np.nonzero(directions @ axes.T >= limit[None])
    assert keep[full[0] // CONE_RAYS, full[1]].all()
    assert keep[:, -1].all() and keep[:, :-1].mean() < 0.3
    compiled_pairs = cone_pairs(directions, axes, cos_limit, kernels)
    numpy_pairs = cone_pairs(directions, axes, cos_limit)
    assert all(np.array_equal(a, b) for a, b in zip(compiled_pairs, numpy_pairs)) and len(compiled_pairs[0]) > 1000
    everywhere = _unit(rng.normal(size=(4 * CONE_RAYS, 3)))
    assert kernels.cone_blocks(everywhere, np.ascontiguousarray(axes), limit).all()
    longer = directions[: 4 * CONE_RAYS].copy()
    longer[CONE_RAYS + 7] *= 1.0 + 1e-9  # not unit: its block is never pruned, the others are
    pruned = kernels.cone_blocks(longer, np.ascontiguousarray(axes), limit)
    assert pruned[1].all() and not pruned[[0, 2, 3]].all()


def _turn_about_numpy(pivot_xy, position_xy, yaw, angle_deg):
    """turn_about as numpy scalars computed it before (the reference)."""
    angle = np.radians(angle_deg)
    c, s = np.cos(angle), np.sin(angle)
    offset = np.asarray(position_xy, float) - np.asarray(pivot_xy, float)
    turned = np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]]) + pivot_xy
    return turned, float(np.angle(np.exp(1j * (yaw + angle))))


def test_a_candidate_turned_in_python_floats_is_numpys_bits():
    """The insertion rule's turn (every candidate of every car, every frame): the centre and the wrapped yaw are the
    bits numpy's scalars gave, over the rule's 36 steps and random poses, a turn past +-pi included."""
    from bpy_pipeline.geometry.placement import turn_about

    rng = np.random.default_rng(21)
    for _ in range(3000):
        pivot = rng.uniform(-40, 40, 2)
        position = pivot + rng.uniform(-30, 30, 2)
        yaw = float(rng.uniform(-np.pi, np.pi))
        for angle_deg in (0, 10.0, 170.0, 180.0, 350.0, float(rng.integers(36)) * 10.0, float(rng.uniform(0, 360))):
            got, expected = turn_about(pivot, position, yaw, angle_deg), _turn_about_numpy(pivot, position, yaw, angle_deg)
            assert got[0].tobytes() == expected[0].tobytes() and got[1] == expected[1]


def _overlap_by_corners(centre1, half1, yaw1, centre2, half2, yaw2, clearance=0.0):
    """The separating-axis test on the four corners' projections (the reference: what rectangles_overlap did)."""
    from bpy_pipeline.geometry.collision import rectangle_corners

    grow = clearance / 2.0
    c1 = rectangle_corners(centre1, np.asarray(half1, float) + grow, yaw1)
    c2 = rectangle_corners(centre2, np.asarray(half2, float) + grow, yaw2)
    for yaw in (yaw1, yaw2):
        for axis in (np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])):
            p1, p2 = c1 @ axis, c2 @ axis
            if p1.max() <= p2.min() or p2.max() <= p1.min():
                return False
    return True


def test_rectangles_overlap_in_floats_answers_as_the_corners_projections():
    """Random pairs near each other (about half overlap), with and without clearance; touching edges count as apart,
    as before (axis-aligned and turned by 90 degrees, where the sums are exact)."""
    rng = np.random.default_rng(22)
    answers = []
    for _ in range(20000):
        c1, c2 = rng.uniform(-5, 5, 2), rng.uniform(-5, 5, 2)
        h1, h2 = rng.uniform(0.2, 3.0, 2), rng.uniform(0.2, 3.0, 2)
        y1, y2 = rng.uniform(-np.pi, np.pi, 2)
        clearance = float(rng.choice([0.0, 0.3]))
        got = rectangles_overlap(c1, h1, y1, c2, h2, y2, clearance)
        assert got == _overlap_by_corners(c1, h1, y1, c2, h2, y2, clearance)
        answers.append(got)
    assert 0.2 < np.mean(answers) < 0.8
    assert not rectangles_overlap((0.0, 0.0), (1.0, 0.5), 0.0, (3.0, 0.0), (2.0, 0.5), 0.0)  # touching at x = 1
    assert rectangles_overlap((0.0, 0.0), (1.0, 0.5), 0.0, (2.75, 0.0), (2.0, 0.5), 0.0)
    assert not rectangles_overlap((0.0, 0.0), (1.0, 0.5), 0.0, (0.0, 1.5), (1.0, 0.5), 0.0, clearance=0.5)  # grown to touch
    assert not _overlap_by_corners((0.0, 0.0), (1.0, 0.5), 0.0, (3.0, 0.0), (2.0, 0.5), 0.0)


def test_the_placers_region_and_keep_out_tests_answer_as_numpy():
    """FloorBoxPlacer's region test (centre, circle, then corners) and keep-out circle, in Python floats, against the
    numpy forms they replace, on random boxes around the region's edges and the sensor."""
    from bpy_pipeline.geometry.collision import rectangle_inside
    from bpy_pipeline.geometry.placement import FloorBoxPlacer

    rng = np.random.default_rng(23)
    low, high = np.array([-20.0, -8.0]), np.array([20.0, 8.0])
    placer = FloorBoxPlacer(np.array([1.0, 0.5, 0.8]), (low, high), keep_out=1.0)
    seen = {"inside": set(), "near": set()}
    for _ in range(20000):
        centre = rng.uniform(low - 3, high + 3) if rng.random() < 0.7 else placer.sensor[:2] + rng.uniform(-4, 4, 2)
        half, yaw = rng.uniform(0.5, 2.5, 3), float(rng.uniform(-np.pi, np.pi))
        inside = placer._inside(centre, half[:2], yaw)
        assert inside == rectangle_inside(centre, half[:2], yaw, low, high)
        nearest = np.abs((placer.sensor[:2] - centre) @ box_axes(yaw)[:2, :2])
        near = placer._near_sensor(centre, half, yaw)
        assert near == bool(np.linalg.norm(np.maximum(nearest - half[:2], 0.0)) < placer.keep_out)
        seen["inside"].add(inside)
        seen["near"].add(near)
    assert seen == {"inside": {True, False}, "near": {True, False}}


def test_row_norms_are_numpys_norms_bit_for_bit():
    rng = np.random.default_rng(8)
    rows = rng.normal(size=(50000, 3)) * 10.0 ** rng.uniform(-8, 8, (50000, 1))
    rows[:6] = [[0, 0, 0], [-0.0, 3, 4], [np.inf, 1, 0], [np.nan, 0, 1], [1e200, 1e200, 0], [1e-200, 0, 0]]
    with np.errstate(over="ignore", invalid="ignore"):  # 1e200 squared is inf, as numpy's own norm has it
        expected = np.linalg.norm(rows, axis=1)
        assert np.array_equal(row_norms(rows), expected, equal_nan=True)
        assert (row_norms(rows) != np.sqrt(rows[:, 0] ** 2 + (rows[:, 1] ** 2 + rows[:, 2] ** 2))).any()  # the order matters: a test that can fail
    assert row_norms(np.zeros((0, 3))).shape == (0,)


def test_suspect_rays_moved_four_ways_in_one_query_are_one_query_a_way():
    """:meth:`RayCaster.retrace` asks Embree once for the four moved copies of every suspect ray; the answer
    is what four queries, one a way in order, keep (a later way wins only when strictly nearer)."""
    vertices, triangles = primitives.uv_sphere(1.0, 24)
    buffers = SceneBuffers.from_meshes({"ball": (vertices, triangles),
                                        "wall": (np.array([[3.0, -5, -5], [3, 5, -5], [3, 5, 5], [3, -5, 5]]), np.array([[0, 2, 1], [0, 3, 2]]))})
    caster = RayCaster(buffers, frame=np.eye(4), threads=1)
    rng = np.random.default_rng(3)
    n = 400
    origins = np.column_stack([np.full(n, -4.0), rng.uniform(-1.2, 1.2, n), rng.uniform(-1.2, 1.2, n)])
    origins[: n // 4] = vertices[rng.integers(0, len(vertices), n // 4)] * 0.5  # inside the ball: back faces
    directions = _unit(np.column_stack([np.ones(n), rng.normal(0, 0.05, (n, 2))]))
    far = np.full(n, 30.0, np.float32)
    tfar, prim = caster._embree(np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32), far)
    rays = np.arange(n)
    new_t, new_p, moved = caster.retrace(rays, origins, directions, far, tfar, prim)
    # one query a way, as before
    d, o = directions, origins
    axis = np.zeros_like(d)
    axis[np.arange(n), np.argmin(np.abs(d), axis=1)] = 1.0
    u = _unit(np.cross(d, axis))
    shift = JITTER * (1.0 + np.abs(o).max(axis=1))
    best_t, best_p, expected = tfar.copy(), prim.copy(), np.zeros(n, bool)
    for across in (u, -u, np.cross(d, u), -np.cross(d, u)):
        turned = _unit(d + JITTER * across)
        t2, p2 = caster._embree(np.ascontiguousarray(o + shift[:, None] * across, np.float32), np.ascontiguousarray(turned, np.float32), far)
        better = (p2 >= 0) & ((best_p < 0) | (t2 < best_t))
        best_t[better], best_p[better] = t2[better], p2[better]
        expected |= better
    assert expected.any() and not expected.all()
    assert np.array_equal(moved, expected)
    assert np.array_equal(new_p, best_p) and np.array_equal(new_t, best_t)


def test_objects_wholly_covered_get_the_truncation_their_samples_give(monkeypatch):
    """Truncation without the samples of objects whose every direction and distance is surely covered (:func:`wholly_covered`)
    is the sampled truncation, bit for bit: cars around a VLP-16 cut by its lowest and highest beams, across the azimuth
    seam behind it, at its minimum and maximum ranges, above it and around its vertical axis, level (high and low) and tilted,
    and cut at the sides of a narrower field of view."""
    from bpy_pipeline.geometry.boxes import fit_boxes
    from bpy_pipeline.geometry.transforms import pose_matrix
    from bpy_pipeline.lidar.cast import visibility as vis
    from bpy_pipeline.lidar.sensor.sensors import iter_pattern, resolve_sensor
    from bpy_pipeline.buffers import ObjectTable

    sensor = resolve_sensor({"preset": "vlp16", "rotation_hz": 10.0}, "sensor")
    rng = np.random.default_rng(3)
    placed = [(8.0, 0.0, 0.0), (-9.0, 0.0, 0.0), (-9.0, 0.4, 1.2), (4.0, 3.0, 0.7), (2.5, -1.0, 0.3), (98.0, 5.0, 0.1), (0.0, 0.0, 2.5), (1.2, 0.2, 0.0),
              (0.6, 0.0, 0.0), (150.0, 0.0, 0.0)]
    placed += [(*rng.uniform(-40, 40, 2), rng.uniform(-np.pi, np.pi)) for _ in range(25)]
    near = rng.uniform(2.5, 9.0, 40), rng.uniform(-np.pi, np.pi, 40)  # where the lowest and highest beams cut cars
    placed += [(r * np.cos(a), r * np.sin(a), yaw) for r, a, yaw in zip(*near, rng.uniform(-np.pi, np.pi, 40))]
    sides = rng.uniform(12.0, 30.0, 16), np.radians(np.concatenate([rng.uniform(66.0, 84.0, 8), rng.uniform(-69.0, -51.0, 8)]))  # the narrow sensor's sides
    placed += [(r * np.cos(a), r * np.sin(a), yaw) for r, a, yaw in zip(*sides, rng.uniform(-np.pi, np.pi, 16))]
    vertices, triangles, owner = [], [], []
    for row, (x, y, yaw) in enumerate(placed):
        v, t = primitives.box(4.5, 1.8, 1.5)
        c, s = np.cos(yaw), np.sin(yaw)
        vertices.append(v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [x, y, 0.75 + (2.0 if row == 6 else 0.0)])
        triangles.append(t + 8 * row)
        owner.append(np.full(len(t), row, np.int32))
    k = len(placed)
    objects = ObjectTable([f"car{i}" for i in range(k)], [""] * k, ["car"] * k, np.zeros(k, np.uint16), np.arange(1, k + 1, dtype=np.uint32),
                          np.zeros(k, np.uint8), np.full(k, 0.5, np.float32))
    buffers = SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)
    shortcut = []
    found = vis.wholly_covered
    narrow = resolve_sensor({"preset": "vlp16", "rotation_hz": 10.0, "horizontal_fov_deg": [-60.0, 75.0]}, "sensor")  # cars cut at its sides too
    level, low, tilted = (pose_matrix([0.0, 0.0, 1.6], [0.0, 0.0, 0.0]), pose_matrix([0.0, 0.0, 0.3], [0.0, 0.0, 0.0]),
                          pose_matrix([0.3, -0.2, 1.6], [4.0, -3.0, 30.0]))
    for sensor, pose in ((sensor, level), (sensor, low), (sensor, tilted), (narrow, level)):
        ours, reference = fit_boxes(buffers, ["car"]), fit_boxes(buffers, ["car"])
        monkeypatch.setattr(vis, "wholly_covered", lambda *a: shortcut.append(found(*a)) or shortcut[-1])
        vis.visibility(buffers, ours, iter_pattern(sensor, 1 << 16), pose, sensor.min_range, sensor.max_range, cell_deg=2.0)
        monkeypatch.setattr(vis, "wholly_covered", lambda boxes, *a: np.zeros(len(boxes), bool))
        vis.visibility(buffers, reference, iter_pattern(sensor, 1 << 16), pose, sensor.min_range, sensor.max_range, cell_deg=2.0)
        np.testing.assert_array_equal(ours["truncation"], reference["truncation"])
        truncation = reference["truncation"]
        assert ((truncation > 0) & (truncation < 1)).sum() >= 3 and (truncation == 1).any()
        assert 5 <= shortcut[-1].sum() < (truncation == 0).sum() + 1 and (truncation[shortcut[-1]] == 0).all()


def test_a_box_has_area_when_the_sum_of_its_triangles_areas_is_positive():
    """have_area against every triangle's area summed: boxes in runs of triangles (an object's), some first triangles
    slivers or points (then the sum decides), boxes with no area at all and boxes with no triangle."""
    rng = np.random.default_rng(14)
    vertices = rng.normal(size=(3000, 3))
    vertices[:40] = vertices[0]  # triangles of these corners have no area
    count = 60
    runs = rng.integers(0, count - 5, 90)  # runs of one box's triangles, a box in several; the last five boxes have none
    runs[0] = 7
    owner = np.repeat(runs, rng.integers(1, 12, len(runs)))
    triangles = rng.integers(40, len(vertices), (len(owner), 3)).astype(np.int32)
    flat = rng.random(len(owner)) < 0.3
    flat |= owner == 7  # box 7 has no area at all
    triangles[flat] = rng.integers(0, 40, (int(flat.sum()), 3))
    objects = ObjectTable(["o"], [""], ["car"], np.zeros(1, np.uint16), np.ones(1, np.uint32), np.zeros(1, np.uint8), np.ones(1, np.float32))
    buffers = SceneBuffers(vertices, triangles, np.zeros(len(triangles), np.int32), objects)
    triangle = np.arange(len(triangles))
    total = np.bincount(owner, triangle_areas(vertices[triangles]), minlength=count)
    wanted = np.concatenate([[7], rng.permutation(np.delete(np.arange(count), 7))[:45]])
    expected = total[wanted] > 0
    assert np.array_equal(have_area(buffers, triangle, owner, wanted), expected)
    flat_first = np.array([(owner == k).any() and flat[np.flatnonzero(owner == k)[0]] for k in wanted])
    assert (flat_first & expected).any() and (flat_first & ~expected).any()  # a flat first, with area after it or not
    assert (wanted >= count - 5).any()  # a box without triangles
