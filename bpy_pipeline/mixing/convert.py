"""A dense real scan resampled into a sparser sensor's pattern and mounting height (the parking paper, section 4.2).

Two methods, both from the dense scan's returns (``(n, 3)`` points in its sensor frame) to the
target sensor's firings (a :class:`~bpy_pipeline.lidar.sensor.sensors.SensorSpec`, mounted ``height``
metres above or below the source: ``target_offset`` is the target's optical centre in the
source frame):

- :func:`project_to_cones`, the paper's: every point goes to the target ring whose cone is
  nearest in elevation (seen from the target's centre), onto that cone at its range; each cone
  is then scanned in the target's azimuth steps and the nearest point of each cell kept
  ("removing all points located behind it"). Its points lie on the target's cones but keep the
  source's azimuths and ranges: off the target's firing directions by up to half a step.
- :func:`raycast_convert`, the alternative: the dense scan meshed as a range image
  (:func:`mesh_range_image`: neighbouring firings joined where their ranges agree) and the
  target's firings cast at the mesh from the target's centre. Points lie on the target's
  firing directions; their ranges interpolate the dense surface.
- ``hybrid`` (ours, :func:`convert_firings`): the meshed cast where the mesh is joined, and the
  cone projection's point of a cell, moved onto the cell's firing direction at its range, where
  the cast found nothing (grazing ground and thin objects the mesh leaves unjoined).

Labels are carried over by source: every converted point names the dense scan's firing it came
from (the cone projection's point itself; the meshed cast's nearest corner of the triangle it
hit), so its class, instance and intensity are that firing's (:func:`convert_firings`).
"""

from __future__ import annotations

import numpy as np

from ..buffers import SceneBuffers
from ..lidar.cast.raycast import RayCaster
from ..lidar.sensor.sensors import azimuths, elevations, spherical_directions


def mesh_range_image(points: np.ndarray, valid: np.ndarray, max_jump: float = 0.1, min_jump: float = 0.3, wrap: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Triangles between neighbouring firings of an organised scan.

    points : (rings, columns, 3) float64 returns; valid : (rings, columns) bool
    Two triangles per cell of 2 x 2 firings, each where its three corners returned and their
    ranges differ by at most ``max_jump`` times the nearest plus ``min_jump`` metres (so a
    silhouette is not joined to the background), wound to face the sensor. ``wrap``: the last column meets the first.
    Returns ``(vertices (rings * columns, 3), triangles (m, 3) int32)`` (vertex ``r * columns + c``).
    """
    rings, columns = valid.shape
    rng_ = np.linalg.norm(points, axis=2)
    idx = np.arange(rings * columns).reshape(rings, columns)
    c1 = np.arange(columns if wrap else columns - 1)
    c2 = (c1 + 1) % columns
    a, b = idx[:-1][:, c1], idx[:-1][:, c2]  # ring r
    c, d = idx[1:][:, c1], idx[1:][:, c2]  # ring r + 1
    flat_v, flat_r = valid.reshape(-1), rng_.reshape(-1)

    def ok(i, j, k):
        r = np.stack([flat_r[i], flat_r[j], flat_r[k]])
        return flat_v[i] & flat_v[j] & flat_v[k] & (r.max(axis=0) - r.min(axis=0) <= max_jump * r.min(axis=0) + min_jump)

    tris = []
    for i, j, k in ((a, c, b), (b, c, d)):
        keep = ok(i, j, k)
        tris.append(np.stack([i[keep], j[keep], k[keep]], 1))
    vertices, triangles = points.reshape(-1, 3), np.concatenate(tris).astype(np.int32)
    # wound to face the sensor, so rays from it meet front faces (back faces would be re-traced as slipped rays)
    v0, v1, v2 = (vertices[triangles[:, m]] for m in range(3))
    away = np.einsum("ij,ij->i", np.cross(v1 - v0, v2 - v0), v0 + v1 + v2) > 0
    triangles[away] = triangles[away][:, ::-1]
    return vertices, triangles


def target_rays(spec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(directions (rings * columns, 3), ring (.,), column (.,))`` of a spinning target, ring-major."""
    el, az = np.asarray(elevations(spec), float), np.asarray(azimuths(spec), float)
    ring = np.repeat(np.arange(len(el)), len(az))
    column = np.tile(np.arange(len(az)), len(el))
    return spherical_directions(az[column], el[ring]), ring, column


def project_to_cones(points: np.ndarray, spec, target_offset=(0.0, 0.0, 0.0), max_range: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parking paper's conversion: ``(points (k, 3) in the target frame, ring (k,), column (k,))``, one per occupied cell
    (:func:`cones_with_source` without the source rows)."""
    return cones_with_source(points, spec, target_offset, max_range)[:3]


def raycast_convert(grid_points: np.ndarray, valid: np.ndarray, spec, target_offset=(0.0, 0.0, 0.0), threads: int | None = None,
                    max_jump: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The meshed alternative: ``(points (k, 3) in the target frame, ring (k,), column (k,))`` of the target's firings that hit the mesh.

    grid_points : (rings, columns, 3) the dense scan organised (source frame); valid : (rings, columns) bool
    """
    vertices, triangles = mesh_range_image(grid_points, valid, max_jump)
    directions, ring, column = target_rays(spec)
    if not len(triangles):
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    buffers = SceneBuffers.from_meshes({"dense scan": (vertices, triangles)})
    frame = np.eye(4)
    frame[:3, 3] = target_offset
    caster = RayCaster(buffers, frame=frame, threads=threads)
    hits = caster.intersect(np.zeros(3), directions, spec.max_range)
    keep = hits.distance >= spec.min_range
    ray, distance = hits.ray[keep], hits.distance[keep]
    return directions[ray] * distance[:, None], ring[ray], column[ray]


def firing_grid(firings) -> tuple[np.ndarray, np.ndarray]:
    """A real scan's returns as a ``(rings, columns, 3)`` grid and its ``valid`` mask (the nearest return of a cell shared by several)."""
    rings, columns = firings.shape
    grid, valid = np.zeros((rings, columns, 3)), np.zeros((rings, columns), bool)
    rows = np.flatnonzero(firings.valid)
    order = rows[np.argsort(-firings.range[rows], kind="stable")]  # farthest first: the nearest writes last
    grid[firings.ring[order], firings.column[order]] = firings.returns[order]
    valid[firings.ring[order], firings.column[order]] = True
    return grid, valid


def convert_scan(firings, spec, target_offset=(0.0, 0.0, 0.0), method: str = "raycast", threads: int | None = None) -> np.ndarray:
    """A real scan's firings (:class:`~.firings.Firings`) resampled into ``spec``'s pattern, mounted at
    ``target_offset`` (m, the scan's frame): ``(k,)`` POINT_DTYPE records in the target's frame
    (``ring``, ``range``, ``time`` and the source firing's ``intensity`` filled). Labels live in the scan, not
    its firings: :func:`convert_firings` names each point's source firing, whose labels ``bpy-pipeline convert`` carries.

    method : ``cones`` (the parking paper's), ``mesh`` (also spelled ``raycast``) or ``hybrid`` (:func:`convert_firings`)
    """
    from ..lidar.points import POINT_DTYPE

    points, ring, _, source = convert_firings(firings, spec, target_offset, {"raycast": "mesh"}.get(method, method), threads)
    out = np.zeros(len(points), POINT_DTYPE)
    out["x"], out["y"], out["z"] = points.T
    out["ring"] = ring
    out["range"] = np.linalg.norm(points, axis=1)
    out["intensity"] = firings.intensity[source]
    out["time"] = firings.time[source]
    return out


METHODS = ("cones", "mesh", "hybrid")  # the parking paper's, the meshed ray cast, ours (module notes)


def cones_with_source(points: np.ndarray, spec, target_offset=(0.0, 0.0, 0.0),
                      max_range: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`project_to_cones` with where each point came from: ``(points (k, 3), ring (k,), column (k,), source (k,))``,
    ``source`` the row of ``points`` (n, 3) that the cell kept (its nearest)."""
    p = np.asarray(points, float) - np.asarray(target_offset, float)
    r = np.linalg.norm(p, axis=1)
    rows = np.flatnonzero((r > 1e-6) & (r <= (max_range or spec.max_range)) & (r >= spec.min_range))
    p, r = p[rows], r[rows]
    el = np.degrees(np.arcsin(np.clip(p[:, 2] / r, -1, 1)))
    az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    table = np.asarray(elevations(spec), float)
    ring = np.abs(el[:, None] - table[None]).argmin(axis=1)
    spacing = np.median(np.diff(table)) if len(table) > 1 else 1.0
    inside = np.abs(el - table[ring]) <= spacing / 2  # beyond the outermost cones: not seen by the target
    rows, r, az, ring = rows[inside], r[inside], az[inside], ring[inside]
    columns = np.asarray(azimuths(spec), float)
    step = columns[1] - columns[0] if len(columns) > 1 else 1.0
    column = np.round((az - columns[0]) / step).astype(np.int64) % len(columns)
    cell = ring * len(columns) + column
    order = np.lexsort((r, cell))
    first = np.ones(len(order), bool)
    first[1:] = cell[order][1:] != cell[order][:-1]
    pick = order[first]
    projected = spherical_directions(az[pick], table[ring[pick]]) * r[pick, None]
    return projected, ring[pick], column[pick], rows[pick]


def raycast_with_source(grid_points: np.ndarray, valid: np.ndarray, spec, target_offset=(0.0, 0.0, 0.0), threads: int | None = None,
                        max_jump: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`raycast_convert` with where each point came from: ``(points (k, 3), ring (k,), column (k,), cell (k,))``,
    ``cell`` the flat index ``r * columns + c`` into ``grid_points`` (rings, columns, 3) of the hit triangle's corner
    nearest the hit."""
    vertices, triangles = mesh_range_image(grid_points, valid, max_jump)
    directions, ring, column = target_rays(spec)
    if not len(triangles):
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    buffers = SceneBuffers.from_meshes({"dense scan": (vertices, triangles)})
    frame = np.eye(4)
    frame[:3, 3] = target_offset
    hits = RayCaster(buffers, frame=frame, threads=threads).intersect(np.zeros(3), directions, spec.max_range)
    keep = hits.distance >= spec.min_range
    ray, distance, tri = hits.ray[keep], hits.distance[keep], hits.triangle[keep]
    points = directions[ray] * distance[:, None]
    corners = triangles[tri]  # (k, 3) vertex ids, vertices in the source frame
    world = points + np.asarray(target_offset, float)
    gap = np.linalg.norm(vertices[corners] - world[:, None, :], axis=2)
    cell = corners[np.arange(len(corners)), gap.argmin(axis=1)].astype(np.int64)
    return points, ring[ray], column[ray], cell


def organised(firings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`firing_grid` and, per cell, the firing row it holds: ``(grid (rings, columns, 3), valid, row (rings, columns) int64, -1 for none)``."""
    rings, columns = firings.shape
    grid, valid = np.zeros((rings, columns, 3)), np.zeros((rings, columns), bool)
    row = np.full((rings, columns), -1, np.int64)
    rows = np.flatnonzero(firings.valid)
    order = rows[np.argsort(-firings.range[rows], kind="stable")]  # farthest first: the nearest writes last
    grid[firings.ring[order], firings.column[order]] = firings.returns[order]
    valid[firings.ring[order], firings.column[order]] = True
    row[firings.ring[order], firings.column[order]] = order
    return grid, valid, row


def convert_firings(firings, spec, target_offset=(0.0, 0.0, 0.0), method: str = "hybrid", threads: int | None = None,
                    max_jump: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A real scan's firings (:class:`~.firings.Firings`) resampled into ``spec``'s pattern mounted at ``target_offset``
    (m, the scan's frame), each converted point naming the firing it came from.

    method : ``cones`` (the parking paper's), ``mesh`` (the meshed ray cast) or ``hybrid`` (ours: the cast, and the
        cones' point moved onto the cell's firing direction where the cast found nothing)
    Returns ``(points (k, 3) target frame, ring (k,), column (k,), source (k,) firing row)``, cells in ring-major order.
    """
    from ..errors import InputError

    if method not in METHODS:
        raise InputError(f"method: {method!r} is not one of {', '.join(METHODS)}")
    rows = np.flatnonzero(firings.valid)
    if method == "cones":
        points, ring, column, pick = cones_with_source(firings.returns[rows], spec, target_offset)
        source = rows[pick]
    else:
        grid, valid, cell_row = organised(firings)
        points, ring, column, cell = raycast_with_source(grid, valid, spec, target_offset, threads, max_jump)
        source = cell_row.reshape(-1)[cell]
        if method == "hybrid":
            c_points, c_ring, c_column, c_pick = cones_with_source(firings.returns[rows], spec, target_offset)
            columns = len(azimuths(spec))
            missing = ~np.isin(c_ring * columns + c_column, ring * columns + column)
            directions = spherical_directions(np.asarray(azimuths(spec), float)[c_column[missing]], np.asarray(elevations(spec), float)[c_ring[missing]])
            moved = directions * np.linalg.norm(c_points[missing], axis=1, keepdims=True)
            points = np.concatenate([points, moved])
            ring, column = np.concatenate([ring, c_ring[missing]]), np.concatenate([column, c_column[missing]])
            source = np.concatenate([source, rows[c_pick[missing]]])
    order = np.lexsort((column, ring))
    return points[order], ring[order].astype(np.int64), column[order].astype(np.int64), source[order].astype(np.int64)
