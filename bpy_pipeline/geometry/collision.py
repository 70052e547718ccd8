"""Collision primitives for placing things that must not intersect: capsules, boxes, rectangles. Pure numpy, and one
loop compiled with numba where it is (:func:`smallest_gap`, the same numbers).

People and robot links are unions of **capsules** (a segment swept by a sphere); their meshes are
inscribed in those capsules (:func:`capsule_mesh`), so a capsule test that says "apart" is a
guarantee for the meshes too. Furniture, pillars and car bodies are **oriented boxes**; on the
floor plan they are **rectangles**.

Shapes are plain arrays:

- capsules: ``a (n, 3)``, ``b (n, 3)`` segment end points and ``radius (n,)``, metres
- an oriented box: ``centre (3,)``, ``axes (3, 3)`` (columns: the box's x, y, z axes, unit) and
  ``half (3,)`` half extents, metres
- a rectangle: ``centre (2,)``, ``half (2,)``, ``yaw`` radians (its x axis at ``yaw`` from world x)
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Closest distance between segments ``p1 q1`` and ``p2 q2``; ``(..., 3)`` in, ``(...)`` out.

    Ericson, *Real-Time Collision Detection* (2005), 5.1.9, vectorised; zero-length segments
    (points) are handled, parallel segments too.
    """
    p1, q1, p2, q2 = (np.asarray(v, np.float64) for v in (p1, q1, p2, q2))
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    tiny = 1e-18
    denom = a * e - b * b
    safe_a = np.where(a > tiny, a, 1.0)
    safe_e = np.where(e > tiny, e, 1.0)
    s = np.where(denom > tiny * np.maximum(a * e, 1.0), np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / safe_e
    # t outside [0, 1]: clamp it and recompute s for the clamped t
    s = np.where(t < 0.0, np.clip(-c / safe_a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / safe_a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments
    point1, point2 = a <= tiny, e <= tiny
    s = np.where(point1, 0.0, s)
    t = np.where(point1 & ~point2, np.clip(f / safe_e, 0.0, 1.0), t)
    s = np.where(point2 & ~point1, np.clip(-c / safe_a, 0.0, 1.0), s)
    t = np.where(point2, 0.0, t)
    closest1 = p1 + d1 * s[..., None]
    closest2 = p2 + d2 * t[..., None]
    return np.linalg.norm(closest1 - closest2, axis=-1)


def smallest_gap(a: np.ndarray, b: np.ndarray, radius: np.ndarray, pairs: np.ndarray) -> float:
    """The smallest surface gap (metres, negative where they overlap) of the capsule pairs ``pairs`` ((p, 2) int rows
    into capsules ``a (c, 3)``, ``b (c, 3)``, ``radius (c,)``): ``(segment_distance - r_i - r_j).min()``, the same
    numbers. One compiled loop over the pairs where numba is (:func:`_gap_kernel`), else :func:`segment_distance`."""
    i, j = pairs[:, 0], pairs[:, 1]
    kernel = _gap_kernel()
    if kernel is None:
        return float((segment_distance(a[i], b[i], a[j], b[j]) - radius[i] - radius[j]).min())
    return float(kernel(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64), np.asarray(radius, np.float64),
                        np.ascontiguousarray(i, np.int64), np.ascontiguousarray(j, np.int64)))


@lru_cache(maxsize=1)
def _gap_kernel():
    """The compiled loop of :func:`smallest_gap` (numba, cached on disk), or ``None`` without numba or when the numpy
    paths are asked for (:func:`~bpy_pipeline.compiled.compiled_wanted`). Per pair, :func:`segment_distance`'s
    operations in its order (its einsum dot products as ``(x0 y0 + x2 y2) + x1 y1``, its norm as
    ``sqrt((x0^2 + x1^2) + x2^2)``), each choice of its ``np.where`` taken as a branch: the same bits (tested)."""
    from ..compiled import compiled_wanted

    if not compiled_wanted():
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def smallest(a, b, radius, first, second):  # pragma: no cover (compiled)
        tiny = 1e-18
        best = np.inf
        for k in range(len(first)):
            i, j = first[k], second[k]
            d1 = (b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2])
            d2 = (b[j, 0] - a[j, 0], b[j, 1] - a[j, 1], b[j, 2] - a[j, 2])
            r = (a[i, 0] - a[j, 0], a[i, 1] - a[j, 1], a[i, 2] - a[j, 2])
            aa = (d1[0] * d1[0] + d1[2] * d1[2]) + d1[1] * d1[1]
            e = (d2[0] * d2[0] + d2[2] * d2[2]) + d2[1] * d2[1]
            f = (d2[0] * r[0] + d2[2] * r[2]) + d2[1] * r[1]
            c = (d1[0] * r[0] + d1[2] * r[2]) + d1[1] * r[1]
            bb = (d1[0] * d2[0] + d1[2] * d2[2]) + d1[1] * d2[1]
            denom = aa * e - bb * bb
            safe_a = aa if aa > tiny else 1.0
            safe_e = e if e > tiny else 1.0
            s = 0.0
            if denom > tiny * max(aa * e, 1.0):
                s = min(max((bb * f - c * e) / (denom if denom > 0 else 1.0), 0.0), 1.0)
            t = (bb * s + f) / safe_e
            if t < 0.0:
                s = min(max(-c / safe_a, 0.0), 1.0)
            elif t > 1.0:
                s = min(max((bb - c) / safe_a, 0.0), 1.0)
            t = min(max(t, 0.0), 1.0)
            point1, point2 = aa <= tiny, e <= tiny
            if point1:
                s = 0.0
                if not point2:
                    t = min(max(f / safe_e, 0.0), 1.0)
            if point2:
                if not point1:
                    s = min(max(-c / safe_a, 0.0), 1.0)
                t = 0.0
            x = (a[i, 0] + d1[0] * s) - (a[j, 0] + d2[0] * t)
            y = (a[i, 1] + d1[1] * s) - (a[j, 1] + d2[1] * t)
            z = (a[i, 2] + d1[2] * s) - (a[j, 2] + d2[2] * t)
            gap = np.sqrt((x * x + y * y) + z * z) - radius[i] - radius[j]
            if gap < best:
                best = gap
        return best

    return smallest


def capsule_gaps(a1, b1, r1, a2, b2, r2) -> np.ndarray:
    """``(n, m)`` surface gaps (metres, negative where they overlap) between two capsule sets."""
    a1, b1, a2, b2 = (np.asarray(v, np.float64) for v in (a1, b1, a2, b2))
    distance = segment_distance(a1[:, None], b1[:, None], a2[None], b2[None])
    return distance - np.asarray(r1, float)[:, None] - np.asarray(r2, float)[None]


def point_box_distance(points: np.ndarray, centre, axes, half) -> np.ndarray:
    """``(n,)`` distance from ``(n, 3)`` points to an oriented box (0 inside)."""
    local = (np.asarray(points, np.float64) - np.asarray(centre, float)) @ np.asarray(axes, float)
    outside = np.maximum(np.abs(local) - np.asarray(half, float), 0.0)
    return np.linalg.norm(outside, axis=-1)


def capsule_box_gaps(a, b, radius, centre, axes, half, iterations: int = 40) -> np.ndarray:
    """``(n,)`` gaps (metres, negative where they overlap) between capsules and an oriented box.

    The distance from a point moving along a segment to a convex box is a convex function of
    its position, so a golden-section search finds the segment's closest point; 40 steps
    narrow it to 5e-9 of the segment's length.
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = b - a
    ratio = (np.sqrt(5.0) - 1.0) / 2.0

    def f(t, rows=slice(None)):
        return point_box_distance(a[rows] + t[:, None] * d[rows], centre, axes, half)

    lo, hi = np.zeros(len(a)), np.ones(len(a))
    x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(iterations):
        left = f1 <= f2  # the minimum lies in [lo, x2]: x1 becomes the new x2
        right = ~left  # the minimum lies in [x1, hi]: x2 becomes the new x1
        hi = np.where(left, x2, hi)
        lo = np.where(right, x1, lo)
        new_x1 = np.where(left, hi - ratio * (hi - lo), x2)
        new_x2 = np.where(left, x1, lo + ratio * (hi - lo))
        new_f1 = np.where(left, 0.0, f2)
        new_f2 = np.where(left, f1, 0.0)
        if left.any():
            new_f1[left] = f(new_x1[left], left)
        if right.any():
            new_f2[right] = f(new_x2[right], right)
        x1, x2, f1, f2 = new_x1, new_x2, new_f1, new_f2
    ends = np.minimum(f(np.zeros(len(a))), f(np.ones(len(a))))
    return np.minimum(np.minimum(f1, f2), ends) - np.asarray(radius, float)


def box_axes(yaw: float) -> np.ndarray:
    """``(3, 3)`` axes (columns) of an upright box turned by ``yaw`` radians about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rectangle_corners(centre, half, yaw: float) -> np.ndarray:
    """``(4, 2)`` corners of a rectangle, counter-clockwise."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * np.asarray(half, float)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(centre, float)


def rectangles_overlap(centre1, half1, yaw1, centre2, half2, yaw2, clearance: float = 0.0) -> bool:
    """Separating-axis test of two rectangles, each grown by ``clearance / 2``: they overlap unless their
    projections on one of the four edge directions are apart or touch.

    Rectangles whose circumscribed circles are apart (by more than a micrometre, far beyond
    rounding) cannot overlap: answered before the test, the same answer about 20x sooner. The test
    itself is in Python floats: a rectangle's projection on a unit axis is its centre's, give or take
    ``hx |cos| + hy |sin|`` of the angle between them (the extremes of projecting its four corners).
    """
    grow = clearance / 2.0
    hx1, hy1, hx2, hy2 = half1[0] + grow, half1[1] + grow, half2[0] + grow, half2[1] + grow
    dx, dy = centre2[0] - centre1[0], centre2[1] - centre1[1]
    if math.hypot(dx, dy) > math.hypot(hx1, hy1) + math.hypot(hx2, hy2) + 1e-6:
        return False
    c1, s1, c2, s2 = math.cos(yaw1), math.sin(yaw1), math.cos(yaw2), math.sin(yaw2)
    cos12, sin12 = abs(c1 * c2 + s1 * s2), abs(s2 * c1 - c2 * s1)  # |cos|, |sin| of the angle between the two
    for ax, ay, reach in (
        (c1, s1, hx1 + hx2 * cos12 + hy2 * sin12),
        (-s1, c1, hy1 + hx2 * sin12 + hy2 * cos12),
        (c2, s2, hx2 + hx1 * cos12 + hy1 * sin12),
        (-s2, c2, hy2 + hx1 * sin12 + hy1 * cos12),
    ):
        if abs(dx * ax + dy * ay) >= reach:
            return False
    return True


def rectangles_near(centre, half, clearance: float, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The rows of ``centres`` ((o, 2) rectangles' centres, ``radii`` (o,) their circumscribed radii grown by
    ``clearance / 2``) that :func:`rectangles_overlap` of the rectangle ``centre``, ``half`` needs to test, in order.

    The others' circles lie apart from the candidate's by more than 2 micrometres, where
    :func:`rectangles_overlap`'s own circle test (a micrometre) answers no: one array test instead of a
    call per rectangle.
    """
    if len(centres) == 0:
        return np.zeros(0, np.int64)
    grow = clearance / 2.0
    reach = radii + np.hypot(half[0] + grow, half[1] + grow) + 2e-6
    return np.flatnonzero(np.hypot(centres[:, 0] - centre[0], centres[:, 1] - centre[1]) <= reach)


def rectangle_inside(centre, half, yaw, low, high, margin: float = 0.0) -> bool:
    """True when the rectangle lies within the axis-aligned region ``low (2,) .. high (2,)`` shrunk by ``margin``."""
    corners = rectangle_corners(centre, half, yaw)
    return bool((corners >= np.asarray(low) + margin).all() and (corners <= np.asarray(high) - margin).all())


def ray_box_distance(origin, directions, centre, axes, half, max_distance=np.inf) -> np.ndarray:
    """``(n,)`` distance along unit ``directions`` from ``origin`` (3,) to an oriented box; inf on a miss.

    Slab test; a ray starting inside the box reports 0.
    """
    local_o = (np.asarray(origin, np.float64) - np.asarray(centre, float)) @ np.asarray(axes, float)
    local_d = np.asarray(directions, np.float64) @ np.asarray(axes, float)
    half = np.asarray(half, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / local_d
        t1 = (-half - local_o) * inv
        t2 = (half - local_o) * inv
    near = np.nanmax(np.minimum(t1, t2), axis=-1)
    far = np.nanmin(np.maximum(t1, t2), axis=-1)
    # rays parallel to a slab they start outside of never enter it
    parallel_out = ((local_d == 0) & (np.abs(local_o) > half)).any(axis=-1)
    hit = (far >= np.maximum(near, 0.0)) & ~parallel_out & (np.maximum(near, 0.0) <= max_distance)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def _cross3(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.cross`` of (..., 3) float64 vectors, component for component the same products and differences
    (the same bits) without its general-shape set-up (capsules are made per body, per frame)."""
    p0, p1, p2 = p[..., 0], p[..., 1], p[..., 2]
    q0, q1, q2 = q[..., 0], q[..., 1], q[..., 2]
    return np.stack([p1 * q2 - p2 * q1, p2 * q0 - p0 * q2, p0 * q1 - p1 * q0], -1)


def _norms(p: np.ndarray) -> np.ndarray:
    """``(n,)`` lengths of ``(n, 3)`` float64 vectors, each ``np.linalg.norm`` of its row, bit for bit: the row's dot
    product with itself is the same BLAS dot (a stacked row-by-column ``matmul`` is one dot per row), then its root."""
    return np.sqrt(np.matmul(p[:, None, :], p[:, :, None]).reshape(-1))


@lru_cache(maxsize=32)
def capsule_topology(segments: int, rings: int, flat_start: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What every capsule mesh of these counts shares: ``(cos (s,), sin (s,) around the axis, triangles (m, 3) int32)``.

    Read only (cached per process: the same counts give the same arrays).
    """
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    rows = (1 if flat_start else rings + 1) + 1 + rings
    s = segments
    j = np.arange(s)
    k = (j + 1) % s
    lo = 1 + np.arange(rows - 1)[:, None] * s  # (rows - 1, 1): each band between two rings
    hi = lo + s
    bands = np.stack([np.stack([lo + j, lo + k, hi + k], -1), np.stack([lo + j, hi + k, hi + j], -1)], 1)  # (rows - 1, 2, s, 3)
    last = 1 + (rows - 1) * s
    pole = 2 + rows * s - 1
    tris = [np.stack([np.zeros(s, int), 1 + k, 1 + j], 1),  # start fan: normals point away from b
            bands.reshape(-1, 3), np.stack([np.full(s, pole), last + j, last + k], 1)]
    out = (np.cos(phi), np.sin(phi), np.concatenate(tris).astype(np.int32))
    for array in out:
        array.flags.writeable = False
    return out


def capsule_meshes(a, b, radius, segments: int = 10, rings: int = 3, flat_start: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle meshes inscribed in the capsules ``a[i]``-``b[i]`` of ``radius[i]``, all at once.

    a, b : (c, 3) axis ends, metres; radius : (c,)
    Returns ``(vertices (c, n, 3) float64, triangles (m, 3) int32)``: every capsule's mesh has the same
    triangles (indices into its own ``n`` vertices). Each is :func:`capsule_mesh` of that capsule, bit for bit.
    """
    a, b = np.asarray(a, float).reshape(-1, 3), np.asarray(b, float).reshape(-1, 3)
    radius = np.asarray(radius, float).reshape(-1)
    axis = b - a
    length = _norms(axis)
    w = np.where((length > 1e-12)[:, None], axis / np.where(length > 1e-12, length, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    helper = np.where((np.abs(w[:, 0]) < 0.9)[:, None], np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    u = _cross3(w, helper)
    u /= _norms(u)[:, None]
    v = _cross3(w, u)
    cos_phi, sin_phi, triangles = capsule_topology(segments, rings, flat_start)
    circle = cos_phi[None, :, None] * u[:, None, :] + sin_phi[None, :, None] * v[:, None, :]  # (c, s, 3)
    # rings from the start pole to the end pole: (polar angle measured from -w at a, +w at b)
    theta = [np.pi / 2 * k / (rings + 1) for k in range(1, rings + 1)]
    r = radius[:, None]  # (c, 1); each row below is (c, 1): its axial offset or its ring's radius
    zero = np.zeros_like(r)
    if flat_start:
        start_offsets, start_radii = [zero], [r]
    else:
        start_offsets = [-r * np.cos(t) for t in theta] + [zero]
        start_radii = [r * np.sin(t) for t in theta] + [r]
    end_offsets = [zero] + [r * np.cos(t) for t in theta[::-1]]
    end_radii = [r] + [r * np.sin(t) for t in theta[::-1]]
    n_start = len(start_offsets)
    offsets = np.concatenate(start_offsets + end_offsets, axis=1)  # (c, rows)
    radii = np.concatenate(start_radii + end_radii, axis=1)
    centres = np.concatenate([np.repeat(a[:, None], n_start, 1), np.repeat(b[:, None], len(end_offsets), 1)], axis=1)  # (c, rows, 3)
    # (c, rows, s, 3)
    ring_vertices = (centres[:, :, None, :] + (offsets[:, :, None] * w[:, None, :])[:, :, None, :]) + radii[:, :, None, None] * circle[:, None]
    start_pole = a if flat_start else a - radius[:, None] * w
    end_pole = b + radius[:, None] * w
    vertices = np.concatenate([start_pole[:, None], ring_vertices.reshape(len(a), -1, 3), end_pole[:, None]], axis=1)
    return vertices, triangles


def capsule_mesh(a, b, radius: float, segments: int = 10, rings: int = 3, flat_start: bool = False):
    """A closed triangle mesh inscribed in the capsule ``a``-``b`` of ``radius``: ``(vertices (n, 3), triangles (m, 3))``.

    Every vertex lies on the capsule's surface, so the mesh lies inside the capsule (the capsule
    is convex) and collision tests on capsules hold for the mesh. ``segments`` around the axis,
    ``rings`` per hemispherical cap. ``flat_start`` replaces the cap at ``a`` by a flat disc
    through ``a`` (a robot base standing on the floor). A zero-length axis gives a sphere.
    """
    vertices, triangles = capsule_meshes(a, b, [radius], segments, rings, flat_start)
    return vertices[0], triangles.copy()
