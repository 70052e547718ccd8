"""The caster's record pool: memory is used again only once nothing made from it is alive."""

import numpy as np
import pytest

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.compiled import numba_available
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.cast.raycast import RayCaster, RecordPool
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern


def test_busy_while_a_view_lives():
    pool = RecordPool(limit=2)
    a = pool.take(100_000, np.float64)
    b = pool.take(100_000, np.float64)
    assert a.base is not b.base  # a is alive: b gets other memory
    view = a[10:].view(np.int64)
    del a
    c = pool.take(50_000, np.float64)
    assert c.base is not view.base  # a view of a view keeps it busy
    d = pool.take(100_000, np.float64)  # two kept, both busy: fresh memory, not kept
    assert d.base is None and len(pool.buffers) == 2
    del view
    e = pool.take(80_000, np.float64)
    assert e.base is pool.buffers[0]  # free again: reused
    small = pool.take(10, np.float64)
    assert small.base is None  # small arrays are not pooled


@pytest.mark.skipif(not numba_available(), reason="the pool serves the compiled path (numba not installed)")
def test_a_held_scan_keeps_its_bytes_through_later_scans():
    buffers = SceneBuffers.from_meshes({"box": primitives.box(40.0, 40.0, 10.0)})
    spec = resolve_sensor({"preset": "os1_128"})
    pattern = sensor_pattern(spec)
    caster = RayCaster(buffers, frame=np.eye(4), kernel="numba")
    first, first_beam = scan(caster, buffers, pattern, pose_matrix([0.2, -0.3, 0.1], [0, 0, 0]) @ np.eye(4), spec.min_range, spec.max_range)
    kept, kept_beam = first.copy(), first_beam.copy()
    for k in range(3):  # other poses, other records, the same caster and pool
        other, _ = scan(caster, buffers, pattern, pose_matrix([1.0 + k, 2.0, 0.5], [0, 0, 10.0 * k]), spec.min_range, spec.max_range)
        assert other.tobytes() != kept.tobytes()
        del other
    assert first.tobytes() == kept.tobytes() and first_beam.tobytes() == kept_beam.tobytes()
    fresh, _ = scan(RayCaster(buffers, frame=np.eye(4), kernel="numba"), buffers, pattern, pose_matrix([0.2, -0.3, 0.1], [0, 0, 0]), spec.min_range,
                    spec.max_range)
    assert fresh.tobytes() == kept.tobytes()
