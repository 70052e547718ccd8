"""The compiled passes of the boxes' visibility cast (numba; imported only by :func:`.visibility.compiled_passes`).

Each kernel computes exactly what its numpy path in :mod:`.visibility` computes, operation for operation in the
same order (no fused multiply-add, no reassociation; a row's dot product summed as :func:`.raycast.dot3` sums it,
``(a0 b0 + a2 b2) + a1 b1``, numpy 1.26's ``einsum`` order), so both give the same bytes
(``tests/test_visibility_kernels.py`` runs both): one loop over the (ray, box) pairs instead of some twenty passes
of numpy temporaries over them.
"""

from __future__ import annotations

import numba
import numpy as np

jit = numba.njit(nogil=True, cache=True, error_model="numpy", fastmath=False)


@jit
def sphere_pairs(directions, origins, ray, box, centres, radii, max_range):
    """``(ray, box, along)`` of the ``(p,)`` pairs ``ray``, ``box`` (int64) whose ray passes the box's bounding sphere.

    directions : (n, 3) the chunk's unit rays; origins : (n, 3) their origins, or (0, 3) for the sensor's centre
    centres, radii : (k, 3) sensor-frame sphere centres and (k,) radii (m); max_range : m
    A pair passes when its ray's line comes within the radius of the centre (``miss2 <= r^2``), the centre is not
    more than a radius behind the origin and the sphere begins within ``max_range``; ``along`` (m) is the distance
    along the ray to its point nearest the centre. The kept pairs stay in their order."""
    n = ray.shape[0]
    keep_ray, keep_box, keep_along = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n)
    shifted = origins.shape[0] > 0
    at = 0
    for p in range(n):
        r, k = ray[p], box[p]
        o0, o1, o2 = centres[k, 0], centres[k, 1], centres[k, 2]
        if shifted:
            o0, o1, o2 = o0 - origins[r, 0], o1 - origins[r, 1], o2 - origins[r, 2]
        d0, d1, d2 = directions[r, 0], directions[r, 1], directions[r, 2]
        along = (o0 * d0 + o2 * d2) + o1 * d1
        miss2 = ((o0 * o0 + o2 * o2) + o1 * o1) - along * along
        radius = radii[k]
        if miss2 <= radius * radius and along >= -radius and along - radius <= max_range:
            keep_ray[at], keep_box[at], keep_along[at] = r, k, along
            at += 1
    return keep_ray[:at], keep_box[:at], keep_along[:at]


@jit
def _min(a, b):
    """``np.minimum`` of two floats as far as later comparisons see it: a NaN wins."""
    if a != a or b != b:
        return np.nan
    return a if a < b else b


@jit
def _max(a, b):
    """``np.maximum`` of two floats as far as later comparisons see it: a NaN wins."""
    if a != a or b != b:
        return np.nan
    return a if a > b else b


@jit
def meets_boxes(world_o, world_d, shift, cos, sin, half, box):
    """``(p,)`` bool: does each pair's line meet its box? (:func:`.visibility.meets_boxes`' slab test).

    world_o, world_d : (3, p) the rays' origins and directions turned into the world's axes (not yet moved)
    shift : (3, k) from each box's centre to the sensor; cos, sin : (k,) of the boxes' headings
    half : (3, k) the boxes' grown half sizes; box : (p,) int64 each pair's box"""
    p = box.shape[0]
    out = np.empty(p, np.bool_)
    for i in range(p):
        k = box[i]
        o0, o1, o2 = world_o[0, i] + shift[0, k], world_o[1, i] + shift[1, k], world_o[2, i] + shift[2, k]
        d0, d1, d2 = world_d[0, i], world_d[1, i], world_d[2, i]
        c, s = cos[k], sin[k]
        near, far = -np.inf, np.inf
        for axis in range(3):
            if axis == 0:
                o, d = c * o0 + s * o1, c * d0 + s * d1
            elif axis == 1:
                o, d = c * o1 - s * o0, c * d1 - s * d0
            else:
                o, d = o2, d2
            h = half[axis, k]
            low, high = (-h - o) / d, (h - o) / d
            near = _max(near, _min(low, high))
            far = _min(far, _max(low, high))
        out[i] = not (near > far)
    return out


@jit
def windows_covered(owner, row, col, candidate, row0, col0, height, width, columns):
    """``(k,)`` bool: is every cell of each candidate box's window within one cell of a point's? (:func:`.visibility.wholly_covered`)

    owner, row, col : (p,) int64 each point's box and cell; candidate : (k,) bool the boxes to answer (others False)
    row0, col0 : (k,) the first row and column of each box's directions; height, width : (k,) its window with one
        more cell on every side; columns : the cells in a turn (a window's columns wrap)"""
    k = candidate.shape[0]
    offset = np.zeros(k + 1, np.int64)
    for j in range(k):
        offset[j + 1] = offset[j] + (height[j] * width[j] if candidate[j] else 0)
    mask = np.zeros(offset[k], np.bool_)
    for i in range(owner.shape[0]):
        j = owner[i]
        if candidate[j]:
            r, q = row[i] - (row0[j] - 1), (col[i] - (col0[j] - 1)) % columns
            if r >= 0 and r < height[j] and q < width[j]:
                mask[offset[j] + r * width[j] + q] = True
    out = np.zeros(k, np.bool_)
    for j in range(k):
        if not candidate[j]:
            continue
        w, covered = width[j], True
        for r in range(height[j] - 2):
            for q in range(w - 2):
                seen = False
                for dr in range(3):
                    for dq in range(3):
                        seen = seen or mask[offset[j] + (r + dr) * w + q + dq]
                if not seen:
                    covered = False
                    break
            if not covered:
                break
        out[j] = covered
    return out


@jit
def owner_covered(point_owner, point_row, point_col, sample_owner, row, col, count, rows, columns):
    """``(s,)`` bool: is each sample's cell within one cell of a point of its own box? (:func:`.visibility.covered_by_owner`)

    point_owner, point_row, point_col : (p,) int64 each point's box (0..count-1) and cell; sample_owner, row, col : (s,)
    the samples'; rows, columns : the grid's. Each box's window: the rows and columns its points and samples fall in
    and one more on every side (every column, wrapping, when that would wrap)."""
    low_row, high_row = np.full(count, rows, np.int64), np.zeros(count, np.int64)
    low_col, high_col = np.full(count, columns, np.int64), np.zeros(count, np.int64)
    for owner, r, c in ((point_owner, point_row, point_col), (sample_owner, row, col)):
        for i in range(owner.shape[0]):
            k = owner[i]
            low_row[k], high_row[k] = min(low_row[k], r[i]), max(high_row[k], r[i])
            low_col[k], high_col[k] = min(low_col[k], c[i]), max(high_col[k], c[i])
    whole, width, offset = np.empty(count, np.bool_), np.empty(count, np.int64), np.empty(count, np.int64)
    at = 0
    for k in range(count):
        low_row[k], low_col[k] = min(low_row[k], high_row[k]), min(low_col[k], high_col[k])  # no cell: a window of one
        whole[k] = high_col[k] - low_col[k] + 3 > columns
        width[k] = columns if whole[k] else high_col[k] - low_col[k] + 3
        offset[k] = at - (low_row[k] - 1) * width[k] - (0 if whole[k] else low_col[k] - 1)  # cell (k, r, c): offset[k] + r width[k] + c
        at += (high_row[k] - low_row[k] + 3) * width[k]
    mask = np.zeros(at, np.bool_)
    for i in range(point_owner.shape[0]):
        k = point_owner[i]
        step = width[k]
        base = offset[k] + point_row[i] * step
        for dc in range(-1, 2):
            c = point_col[i] + dc
            if whole[k]:
                c = c % columns
            mask[base + c - step] = True
            mask[base + c] = True
            mask[base + c + step] = True
    found = np.empty(sample_owner.shape[0], np.bool_)
    for j in range(sample_owner.shape[0]):
        k = sample_owner[j]
        found[j] = mask[offset[k] + row[j] * width[k] + col[j]]
    return found
