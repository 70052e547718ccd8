"""The compiled passes of the boxes' visibility cast (bpy_pipeline/lidar/cast/visibility_kernels.py) give the bits of
their numpy paths: the pairs' sphere test (rays from the sensor's centre and from origins of their own), the boxes' slab
test (rays along a box's faces and axes, where the numpy path divides 0 by 0), the wholly covered windows, and the
whole visibility of a street of boxes with and without them (the samples' windows: tests/test_box_speed_paths.py)."""

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.boxes import fit_boxes
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.cast import visibility as vis
from bpy_pipeline.lidar.cast.raycast import RayCaster, choose_kernels
from bpy_pipeline.lidar.sensor.sensors import iter_pattern, resolve_sensor, sensor_pattern

passes = vis.compiled_passes(choose_kernels("auto"))
pytestmark = pytest.mark.skipif(passes is None, reason="numba is not installed: only the numpy paths exist")


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _same(a, b):
    return all(x.dtype == y.dtype and x.tobytes() == y.tobytes() for x, y in zip(a, b))


def _street(count: int, rng) -> SceneBuffers:
    """``count`` car-sized boxes around the origin, turned at random (the first and some others along the axes): most
    8 to 45 m away, a sixth close (cut by the lowest beams), a sixth 85 to 250 m away (at or beyond a sensor's range)."""
    vertices, triangles, owner = [], [], []
    reach = np.concatenate([rng.uniform(8.0, 45.0, count - count // 3), rng.uniform(2.5, 6.0, count // 6), rng.uniform(85.0, 250.0, count // 3 - count // 6)])
    bearing = rng.uniform(-np.pi, np.pi, count)
    for row in range(count):
        x, y = reach[row] * np.cos(bearing[row]), reach[row] * np.sin(bearing[row])
        yaw = 0.0 if row == 0 else rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)])
        v, t = primitives.box(4.5, 1.8, 1.5)
        c, s = np.cos(yaw), np.sin(yaw)
        vertices.append(v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [x, y, 0.75])
        triangles.append(t + 8 * row)
        owner.append(np.full(len(t), row, np.int32))
    objects = ObjectTable([f"car{i}" for i in range(count)], [""] * count, ["car"] * count, np.zeros(count, np.uint16),
                          np.arange(1, count + 1, dtype=np.uint32), np.zeros(count, np.uint8), np.full(count, 0.5, np.float32))
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)


def test_the_compiled_sphere_test_keeps_numpys_pairs_and_distances():
    directions = np.ascontiguousarray(sensor_pattern(resolve_sensor({"preset": "hdl64e"})).directions, np.float64)
    rng = np.random.default_rng(5)
    centres = rng.normal(size=(40, 3)) * [20.0, 20.0, 1.0]
    centres[-1] = [0.2, -0.1, 0.0]  # the sensor within this sphere
    radii = rng.uniform(0.5, 4.0, len(centres))
    distance = np.linalg.norm(centres, axis=1)
    reach = radii + 0.3  # the cone widened as for origins off the centre: some pairs it keeps miss the sphere
    cos_limit = np.where(distance > reach, np.sqrt(np.clip(1 - (reach / distance) ** 2, 0, 1)), -2.0)
    ray, box = vis.cone_pairs(directions, centres / distance[:, None], cos_limit)
    for origins in (None, rng.normal(size=directions.shape) * 0.05):
        for max_range in (120.0, 15.0):
            numpy_pairs = vis.sphere_pairs(directions, origins, ray, box, centres, radii, max_range)
            compiled_pairs = vis.sphere_pairs(directions, origins, ray, box, centres, radii, max_range, passes)
            assert _same(compiled_pairs, numpy_pairs)
            assert 1000 < len(numpy_pairs[0]) < len(ray)


def test_the_compiled_slab_test_meets_numpys_boxes_rays_along_faces_included():
    """Rays at random near the boxes, along the axes, and from the plane of a face of box 0 along that plane (the sensor
    at its centre, the box level: the numpy path's 0 / 0 there)."""
    rng = np.random.default_rng(8)
    boxes = fit_boxes(_street(30, rng), ["car"], {1: 0.0})  # box 0 level and along the axes: its frame's zeros are zeros
    pose = np.eye(4)
    pose[:3, 3] = boxes["centre"][0]
    box = rng.integers(0, len(boxes), 20000)
    centres = boxes["centre"] - pose[:3, 3]
    directions = _unit(centres[box] + rng.normal(size=(len(box), 3)) * 1.5)
    directions[:3000] = np.eye(3)[rng.integers(0, 3, 3000)] * rng.choice([-1.0, 1.0], (3000, 1))
    origins = np.zeros((len(box), 3))
    face = np.arange(3000, 6000)  # on a face's plane of box 0, along it
    box[face] = 0
    axis = rng.integers(0, 3, len(face))
    half = boxes["size"][0] / 2 + vis.BOX_MARGIN * (1.0 + np.abs(boxes["centre"][0]).max() / 1e4)
    origins[face] = rng.uniform(-4.0, 4.0, (len(face), 3)) * half
    origins[face, axis] = rng.choice([-1.0, 1.0], len(face)) * half[axis]
    directions[face, axis] = 0.0
    directions[face] = _unit(directions[face])
    # box 0's frame is the sensor's, so a face ray's coordinate across its face is the half size and its direction's a
    # zero, both exactly: one of the slab's quotients is 0 / 0
    assert (np.abs(origins[face, axis]) == half[axis]).all() and (directions[face, axis] == 0).all()
    numpy_meets = vis.meets_boxes(boxes, pose, origins, directions, box)
    compiled_meets = vis.meets_boxes(boxes, pose, origins, directions, box, passes)
    assert np.array_equal(compiled_meets, numpy_meets)
    assert 0.1 < numpy_meets.mean() < 0.9 and numpy_meets[face].all()  # a line along a face's plane counts as meeting it


@pytest.mark.parametrize("preset, pose, cell", [("vlp16", pose_matrix([0.0, 0.0, 1.6], [0.0, 0.0, 0.0]), 2.0),
                                                ("hdl64e", pose_matrix([0.3, -0.2, 1.7], [0.0, 0.0, 40.0]), 0.5)])
def test_visibility_with_its_compiled_passes_is_the_numpy_visibility(preset, pose, cell, monkeypatch):
    """Every field of every box, through the whole cast: with the scene traced (no scan answers) and the compiled
    passes or not; some boxes wholly covered, some cut, some beyond the range or the field of view."""
    rng = np.random.default_rng(21)
    buffers = _street(40, rng)
    sensor = resolve_sensor({"preset": preset, "rotation_hz": 10.0}, "sensor")
    found, covered = [], vis.wholly_covered
    monkeypatch.setattr(vis, "wholly_covered", lambda *args: found.append(covered(*args)) or found[-1])
    results = []
    for kernel in ("numpy", "numba"):
        boxes = fit_boxes(buffers, ["car"])
        caster = RayCaster(buffers, frame=pose, kernel=kernel)
        vis.visibility(buffers, boxes, iter_pattern(sensor, 1 << 16), pose, sensor.min_range, sensor.max_range, cell_deg=cell, caster=caster)
        results.append(boxes)
    assert results[0].tobytes() == results[1].tobytes()
    assert np.array_equal(found[0], found[1]) and 0 < found[0].sum() < len(found[0])
    truncation = results[0]["truncation"]
    assert (truncation == 1).any() and ((truncation > 0) & (truncation < 1)).any() and results[0]["unoccluded"].sum() > 1000


def test_the_compiled_windows_are_numpys_sparse_marks_and_the_seam_included():
    """wholly_covered's windows with marks a cell or two apart (some covered, some with a gap), across the azimuth
    seam (columns wrap), points outside their window and boxes not asked."""
    rng = np.random.default_rng(9)
    columns, count = 720, 300
    row0, col0 = rng.integers(1, 300, count), rng.integers(0, columns, count)
    col0[:40] = columns - rng.integers(1, 4, 40)  # windows across the seam
    height, width = rng.integers(3, 9, count), rng.integers(3, 9, count)
    candidate = rng.random(count) < 0.9
    owner = np.repeat(np.arange(count), (height * width * rng.uniform(0.3, 1.2, count)).astype(np.int64))
    row = row0[owner] - 1 + rng.integers(0, height[owner] + 1, len(owner))
    col = (col0[owner] - 1 + rng.integers(0, width[owner] + 1, len(owner))) % columns
    step = rng.integers(2, 4, count)  # every second or third cell only for these boxes: a gap or not
    sparse = rng.random(count) < 0.5
    keep = ~sparse[owner] | ((row % step[owner] == 0) & (col % step[owner] == 0))
    owner, row, col = owner[keep], row[keep], col[keep]
    numpy_covered = vis.windows_covered(owner, row, col, candidate, row0, col0, height, width, columns)
    compiled_covered = passes.windows_covered(owner, row, col, candidate, row0, col0, height, width, columns)
    assert np.array_equal(compiled_covered, numpy_covered)
    assert 0.1 < numpy_covered[candidate].mean() < 0.9 and not numpy_covered[~candidate].any() and numpy_covered[:40].any()
