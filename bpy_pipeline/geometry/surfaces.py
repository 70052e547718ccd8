"""Where placed objects may stand: horizontal surfaces of a static scene found in its triangles. Pure numpy.

The human-robot paper (seed 002) finds the floor and the desk tops of its reconstructed hall by
fitting planes (RANSAC) and clustering them (DBSCAN). A synthetic scene's triangles are exact, so
the same step is done directly: triangles facing up (normal within ``max_tilt_deg`` of +z) are
grouped by height, a new group starting wherever sorted heights jump by more than ``gap`` (a
one-dimensional DBSCAN with ``eps = gap``, ``min_samples = 1``), and a group is kept when its area
reaches ``min_area``. Each group is sampled on a regular grid of ``cell`` metres: a grid node is a
standing spot when it lies inside one of the group's triangles and nothing solid is above it
(the first triangle straight above faces down, i.e. the spot is outside every closed solid, and
lies at least ``headroom`` higher).

Coordinates: metres, world frame, z up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Surface:
    """One horizontal surface group and its standing spots.

    z : height of the group (area-weighted mean of its triangles' centroid heights), m
    area : total area of its triangles, m^2
    triangles : (k,) int indices of its triangles in the scene's triangle array
    spots : (n, 3) float64 free grid nodes on it (z on the triangle's plane), m
    edges : (e, 3) float64 spots at the group's boundary, moved half a cell outwards onto the edge
    outward : (e, 2) float64 unit vectors pointing off the surface at each edge spot
    """

    z: float
    area: float
    triangles: np.ndarray
    spots: np.ndarray
    edges: np.ndarray
    outward: np.ndarray


def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(unit normals (m, 3), areas (m,))`` of ``triangles (m, 3) int`` over ``vertices (n, 3)``; a degenerate
    triangle gets normal (0, 0, 0) and area 0."""
    tri = np.asarray(vertices, float)[np.asarray(triangles)]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    double = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, double[:, None], out=np.zeros_like(cross), where=double[:, None] > 0)
    return normals, double / 2


def height_groups(z: np.ndarray, gap: float) -> np.ndarray:
    """``(k,)`` int group label of each height ``z (k,)``: sorted heights split where they jump by more than ``gap`` m."""
    order = np.argsort(z, kind="stable")
    labels = np.empty(len(z), int)
    labels[order] = np.concatenate([[0], np.cumsum(np.diff(z[order]) > gap)]) if len(z) else []
    return labels


def grid_pairs(origin, step: float, shape, vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (grid node, triangle) pair where the node lies inside the triangle seen from above.

    origin : (2,) xy of node (0, 0); step : m; shape : (nx, ny) nodes
    Returns ``(node (p,) int flat index i * ny + j, triangle (p,) int, z (p,) float64)`` with ``z`` the
    height of the triangle's plane above the node. Vertical triangles cover no node.
    """
    tri = np.asarray(vertices, float)[np.asarray(triangles)]
    nx, ny = shape
    low = np.ceil((tri[:, :, :2].min(axis=1) - origin) / step - 1e-9).astype(int)
    high = np.floor((tri[:, :, :2].max(axis=1) - origin) / step + 1e-9).astype(int)
    low = np.maximum(low, 0)
    high = np.minimum(high, [nx - 1, ny - 1])
    counts_x, counts_y = np.maximum(high[:, 0] - low[:, 0] + 1, 0), np.maximum(high[:, 1] - low[:, 1] + 1, 0)
    counts = counts_x * counts_y
    if counts.sum() == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    t = np.repeat(np.arange(len(tri)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    i = low[t, 0] + local // counts_y[t]
    j = low[t, 1] + local % counts_y[t]
    p = np.asarray(origin, float) + np.stack([i, j], 1) * step
    a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
    d1, d2, dp = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2], p - a[:, :2]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)
    u = (dp[:, 0] * d2[:, 1] - dp[:, 1] * d2[:, 0]) / det
    v = (d1[:, 0] * dp[:, 1] - d1[:, 1] * dp[:, 0]) / det
    inside = ok & (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
    z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2])
    return (i * ny + j)[inside], t[inside], z[inside]


def find_surfaces(
    vertices: np.ndarray,
    triangles: np.ndarray,
    candidates: np.ndarray | None = None,
    cell: float = 0.1,
    gap: float = 0.05,
    min_area: float = 0.25,
    headroom: float = 0.5,
    max_tilt_deg: float = 10.0,
) -> list[Surface]:
    """The horizontal surfaces of a scene, lowest first.

    vertices : (n, 3) float, m; triangles : (m, 3) int, the whole static scene (what may stand above a spot)
    candidates : (m,) bool, the triangles that may carry objects (``None``: all); the others only block
    cell : grid step of the spots, m; gap : height jump that starts a new group, m
    min_area : smallest group kept, m^2; headroom : free height needed above a spot, m
    """
    vertices = np.asarray(vertices, float)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    if not len(triangles):
        return []
    normals, areas = triangle_normals(vertices, triangles)
    up = normals[:, 2] >= np.cos(np.radians(max_tilt_deg))
    if candidates is not None:
        up &= np.asarray(candidates, bool)
    rows = np.flatnonzero(up & (areas > 0))
    if not len(rows):
        return []
    centroid_z = vertices[triangles[rows]].mean(axis=1)[:, 2]
    labels = height_groups(centroid_z, gap)
    not_flat = np.abs(normals[:, 2]) > 1e-6
    blockers = np.flatnonzero(not_flat)
    out = []
    for g in range(labels.max() + 1):
        members = rows[labels == g]
        area = float(areas[members].sum())
        if area < min_area:
            continue
        z = float(np.average(centroid_z[labels == g], weights=areas[members]))
        tri_xy = vertices[triangles[members]][:, :, :2]
        low, high = tri_xy.min(axis=(0, 1)), tri_xy.max(axis=(0, 1))
        origin = np.floor(low / cell) * cell + cell / 2
        shape = (max(int(np.floor((high[0] - origin[0]) / cell)) + 1, 1), max(int(np.floor((high[1] - origin[1]) / cell)) + 1, 1))
        node, _, node_z = grid_pairs(origin, cell, shape, vertices, triangles[members])
        on = np.full(shape[0] * shape[1], np.nan)
        np.fmax.at(on, node, node_z)  # the group's highest plane over each node
        occupied = ~np.isnan(on)
        # the first triangle straight above each occupied node (blockers: every non-vertical triangle of the scene)
        b_node, b_tri, b_z = grid_pairs(origin, cell, shape, vertices, triangles[blockers])
        above = occupied[b_node] & (b_z > on[b_node] + 1e-3)
        b_node, b_tri, b_z = b_node[above], blockers[b_tri[above]], b_z[above]
        first = np.full(len(on), np.inf)
        np.minimum.at(first, b_node, b_z)
        is_first = b_z == first[b_node]
        facing_up = np.zeros(len(on), bool)
        facing_up[b_node[is_first]] |= normals[b_tri[is_first], 2] > 0
        free = occupied & ~facing_up & (first - np.nan_to_num(on) >= headroom)
        grid = free.reshape(shape)
        i, j = np.nonzero(grid)
        xy = origin + np.stack([i, j], 1) * cell
        spots = np.column_stack([xy, on.reshape(shape)[i, j]]) if len(i) else np.zeros((0, 3))
        # boundary spots: a free node whose neighbour in a direction is not on the surface at all
        surface = occupied.reshape(shape)
        padded = np.pad(surface, 1)
        edges, outward = [], []
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            missing = ~padded[1 + i + di, 1 + j + dj]
            if missing.any():
                direction = np.array([di, dj], float)
                edges.append(spots[missing] + np.append(direction * cell / 2, 0.0))
                outward.append(np.repeat(direction[None], missing.sum(), axis=0))
        out.append(Surface(z, area, members, spots, np.concatenate(edges) if edges else np.zeros((0, 3)),
                           np.concatenate(outward) if outward else np.zeros((0, 2))))
    return sorted(out, key=lambda s: s.z)


def floor_and_seats(surfaces: list[Surface], seat_height: tuple[float, float] = (0.35, 0.8), floor_band: float = 0.3) -> tuple[list[Surface], list[Surface]]:
    """Split detected surfaces into floors and seats.

    Floors: the groups within ``floor_band`` m of the lowest group that has the largest area there
    (a hall's floor, a sunken pit beside it). Seats: groups ``seat_height`` (min, max) m above the floor.
    """
    if not surfaces:
        return [], []
    lowest = surfaces[0].z
    floors = [s for s in surfaces if s.z <= lowest + floor_band]
    floor_z = max(floors, key=lambda s: s.area).z
    seats = [s for s in surfaces if seat_height[0] <= s.z - floor_z <= seat_height[1]]
    return floors, seats


def on_surface(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, tolerance: float = 0.03) -> np.ndarray:
    """``(k,)`` bool: each point ``(k, 3)`` lies over one of ``triangles`` (seen from above) within ``tolerance`` m above its plane."""
    points = np.asarray(points, float)
    tri = np.asarray(vertices, float)[np.asarray(triangles)]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    p = points[:, None]
    d1, d2, dp = b[..., :2] - a[..., :2], c[..., :2] - a[..., :2], p[..., :2] - a[..., :2]
    det = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)
    u = (dp[..., 0] * d2[..., 1] - dp[..., 1] * d2[..., 0]) / det
    v = (d1[..., 0] * dp[..., 1] - d1[..., 1] * dp[..., 0]) / det
    z = a[..., 2] + u * (b[..., 2] - a[..., 2]) + v * (c[..., 2] - a[..., 2])
    inside = ok & (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (p[..., 2] >= z - 1e-6) & (p[..., 2] <= z + tolerance)
    return inside.any(axis=1)
