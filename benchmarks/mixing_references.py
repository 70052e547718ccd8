"""The two papers' insertion methods, the references :func:`bpy_pipeline.mixing.frame.mix_frame` is measured against (bench_mixing.py).

- :func:`parking_paper_insert` (the parking paper, sections 3.1-3.2): each object is scanned
  alone by a simulated sensor (a preset's nominal pattern from the scan's origin), its points
  are copied into the scan, and the background points it occludes are removed by the cone test
  of section 3.2.2 (points within the cone from the sensor over the object's bounding box whose
  ray from the sensor enters the box before reaching them).
- :func:`kitti_paper_insert` (the KITTI paper, sections 3.2.1-3.2.2): the object is a dense point
  model (its mesh sampled); the real returns and a "point wall" (the sensor's resolution over the
  object's angular extent, jittered by up to 30 % of a step, at W_r = 100 m, where no real return
  is) are traced spherically: each takes the object's range where the object's nearest sample in
  angle (a spherical z-buffer) is nearer than it.

Both return ``(points (p, 3) float64, inserted (p,) bool)`` in the scan's sensor frame.
:func:`angular_error` measures how far points lie from the real firings' rays.
"""

from __future__ import annotations

import math

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.lidar.cast.visibility import subset_buffers, surface_samples
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.sensors import azimuth_step, resolve_sensor, sensor_pattern
from bpy_pipeline.mixing.firings import Firings, angle_between, angles_deg
from bpy_pipeline.mixing.placement import Placement, ray_box_entry


def _returns(firings: Firings, valid: np.ndarray) -> np.ndarray:
    return firings.origin[valid] + firings.range[valid, None] * firings.direction[valid]


def parking_paper_insert(firings: Firings, valid: np.ndarray, buffers: SceneBuffers, placements: list[Placement], preset: str = "hdl32e",
                         threads: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The parking paper's method (module notes); ``valid`` (f,) the real firings that returned."""
    spec = resolve_sensor({"preset": preset}, "preset")
    pattern = sensor_pattern(spec)
    background = _returns(firings, valid)
    keep = np.ones(len(background), bool)
    inserted = []
    for k, p in enumerate(placements):
        alone = _object_alone(buffers, k)
        caster = RayCaster(alone, frame=np.eye(4), threads=threads)
        hits = caster.intersect(np.zeros(3), pattern.directions, spec.max_range)
        inserted.append(pattern.directions[hits.ray] * hits.distance[:, None])
        # cone test: background points whose direction falls in the box's angular cone, then the ray-box test
        d = background / np.maximum(np.linalg.norm(background, axis=1, keepdims=True), 1e-12)
        corners = _box_corners(p)
        axis = p.centre / np.linalg.norm(p.centre)
        cos_cone = min(float((corners / np.linalg.norm(corners, axis=1, keepdims=True) @ axis).min()), 1.0)
        cone = np.flatnonzero(keep & (d @ axis >= cos_cone))
        entry = ray_box_entry(np.zeros((len(cone), 3)), d[cone], p.centre, p.size, p.yaw)
        behind = np.isfinite(entry) & (entry < np.linalg.norm(background[cone], axis=1))
        keep[cone[behind]] = False
    new = np.concatenate(inserted) if inserted else np.zeros((0, 3))
    return np.concatenate([background[keep], new]), np.concatenate([np.zeros(keep.sum(), bool), np.ones(len(new), bool)])


def _object_alone(buffers: SceneBuffers, k: int) -> SceneBuffers:
    """The parts of the k-th placement (instances are consecutive, one per placement)."""
    instances = np.unique(buffers.objects.instance)
    rows = np.flatnonzero(buffers.objects.instance == instances[k])
    return subset_buffers(buffers, list(int(r) for r in rows))


def _box_corners(p: Placement) -> np.ndarray:
    c, s = math.cos(p.yaw), math.sin(p.yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    return p.centre + (signs * p.size / 2) @ rotation.T


def spherical_zbuffer(points: np.ndarray, cell_deg: float) -> tuple[dict, float]:
    """The nearest range per angular cell of ``(n, 3)`` points: ``({(i, j): range}, cell)`` as sorted key arrays."""
    r = np.linalg.norm(points, axis=1)
    az, el = angles_deg(points / r[:, None])
    key = np.floor(az / cell_deg).astype(np.int64) * 1_000_003 + np.floor(el / cell_deg).astype(np.int64)
    order = np.lexsort((r, key))
    first = np.ones(len(order), bool)
    first[1:] = key[order][1:] != key[order][:-1]
    return {"key": key[order][first], "range": r[order][first]}, cell_deg


def _lookup(zbuffer: dict, cell: float, directions: np.ndarray) -> np.ndarray:
    az, el = angles_deg(directions)
    key = np.floor(az / cell).astype(np.int64) * 1_000_003 + np.floor(el / cell).astype(np.int64)
    at = np.clip(np.searchsorted(zbuffer["key"], key), 0, max(len(zbuffer["key"]) - 1, 0))
    found = (zbuffer["key"][at] == key) if len(zbuffer["key"]) else np.zeros(len(key), bool)
    return np.where(found, zbuffer["range"][at] if len(zbuffer["key"]) else np.inf, np.inf)


def kitti_paper_insert(firings: Firings, valid: np.ndarray, buffers: SceneBuffers, preset: str = "hdl32e", spacing: float = 0.02, cell_deg: float = 0.1,
                       rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The KITTI paper's method (module notes), the sensor's nominal resolution (``preset``) for the wall."""
    rng = rng or np.random.default_rng(0)
    spec = resolve_sensor({"preset": preset}, "preset")
    res_h = azimuth_step(spec)
    table = np.asarray(spec.elevations_deg, float)
    res_v = float(np.median(np.diff(table))) if len(table) > 1 else 1.0
    background = _returns(firings, valid)
    out_points, out_inserted = background.copy(), np.zeros(len(background), bool)
    instances = np.unique(buffers.objects.instance)
    extra = []
    for k in range(len(instances)):
        alone = _object_alone(buffers, k)
        samples, _ = surface_samples(alone.vertices[alone.triangles], spacing)
        zbuffer, cell = spherical_zbuffer(samples, cell_deg)
        az, el = angles_deg(samples / np.linalg.norm(samples, axis=1, keepdims=True))
        # real points: the object's range along their own direction where it is nearer
        d = out_points / np.maximum(np.linalg.norm(out_points, axis=1, keepdims=True), 1e-12)
        r_obj = _lookup(zbuffer, cell, d)
        nearer = r_obj < np.linalg.norm(out_points, axis=1)
        out_points[nearer] = d[nearer] * r_obj[nearer, None]
        out_inserted[nearer] = True
        # the point wall over the object's angular extent (equations 2 and 3), jittered by up to 30 % of a step
        i = np.arange(int((az.max() - az.min()) / res_h) + 1)
        j = np.arange(int((el.max() - el.min()) / res_v) + 1)
        wi, wj = np.meshgrid(i, j, indexing="ij")
        w_az = az.min() + res_h * wi.reshape(-1) + rng.uniform(-0.3, 0.3, wi.size) * res_h
        w_el = el.min() + res_v * wj.reshape(-1) + rng.uniform(-0.3, 0.3, wi.size) * res_v
        wall = np.column_stack([np.cos(np.radians(w_el)) * np.cos(np.radians(w_az)), np.cos(np.radians(w_el)) * np.sin(np.radians(w_az)),
                                np.sin(np.radians(w_el))])
        # where a real return already is (within half a step), the wall adds nothing: it fills losses only
        occupied, _ = spherical_zbuffer(out_points, res_h / 2)
        free = ~np.isfinite(_lookup(occupied, res_h / 2, wall))
        r_wall = _lookup(zbuffer, cell, wall[free])
        hit = np.isfinite(r_wall) & (r_wall < 100.0)
        extra.append(wall[free][hit] * r_wall[hit, None])
    new = np.concatenate(extra) if extra else np.zeros((0, 3))
    return np.concatenate([out_points, new]), np.concatenate([out_inserted, np.ones(len(new), bool)])


def angular_error(firings: Firings, points: np.ndarray, window: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``(angle (p,) radians, firing (p,) int64)``: each point's nearest real firing's ray (seen from that firing's origin).

    Candidates: every ring of the ``window`` columns each side of the point's column on the azimuth line.
    """
    if not len(points):
        return np.zeros(0), np.zeros(0, np.int64)
    rings, columns = firings.shape
    line = np.unwrap(np.radians(firings.azimuth_deg))
    step = (line[-1] - line[0]) / max(columns - 1, 1)
    grid = np.full((columns, rings), -1, np.int64)
    grid[firings.column, firings.ring] = np.arange(len(firings))
    origin = np.zeros((columns, 3))
    origin[firings.column] = firings.origin
    col = np.zeros(len(points), np.int64)
    for _ in range(3):  # the column's azimuth seen from that column's origin (a moving sensor's firings leave from a line)
        az, _ = angles_deg(points - origin[col])
        col = np.mod(np.round((np.radians(az) - line[0]) / step).astype(np.int64), columns)
    best, which = np.full(len(points), np.inf), np.full(len(points), -1, np.int64)
    for dc in range(-window, window + 1):
        cand = grid[np.mod(col + dc, columns)]  # (p, rings)
        ok = cand >= 0
        c = np.where(ok, cand, 0)
        rel = points[:, None, :] - firings.origin[c]
        rel /= np.maximum(np.linalg.norm(rel, axis=2, keepdims=True), 1e-12)
        a = angle_between(rel, firings.direction[c])
        a = np.where(ok, a, np.inf)
        pick = a.argmin(axis=1)
        better = a[np.arange(len(a)), pick] < best
        best[better] = a[np.arange(len(a)), pick][better]
        which[better] = c[np.arange(len(a)), pick][better]
    return best, which
