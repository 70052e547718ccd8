"""Tiles and point sampling for training on large static scans. Pure numpy.

A tile is a square window of ``size`` metres in plan (x, y). Tiles are laid on a grid of
``stride = size - overlap``: each point lies in exactly one tile's *core* (the grid cell of
stride metres at the window's centre), and the windows of neighbouring tiles overlap by
``overlap`` metres around the cores. So the cores partition the cloud (every point once),
while each window also carries the context around its core, as the railway thesis's
10 x 10 m training chunks do.

Sampling to a fixed count follows Pointcept and PointNet++: ``random`` (a uniform draw without
replacement) or ``fps`` (farthest-point sampling: the spatially most even subset). With
``class_aware`` the budget is shared between the classes in proportion to the square root of
their counts, so rare thin classes (droppers: 0.005 % of a railway scan) keep points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SAMPLING_METHODS = ("random", "fps")


@dataclass(frozen=True)
class Tile:
    """One tile: ``key`` (i, j) grid indices, ``window`` (n,) int64 indices of its points,
    ``core`` (n,) bool which of them lie in its core. ``bounds``: (xmin, ymin, xmax, ymax) of the window, m."""

    key: tuple[int, int]
    window: np.ndarray
    core: np.ndarray
    bounds: tuple[float, float, float, float]


def tiles(xy: np.ndarray, size: float, overlap: float = 0.0, origin: tuple[float, float] | None = None) -> list[Tile]:
    """The non-empty tiles of the points ``xy`` ((n, 2) float, m), in (i, j) order.

    size : window edge (m); overlap : m shared by neighbouring windows, 0 <= overlap < size
    origin : the grid's corner (m); default the points' minimum
    """
    if not size > 0 or not 0 <= overlap < size:
        raise ValueError(f"tiles: need size > 0 and 0 <= overlap < size, got size {size}, overlap {overlap}")
    xy = np.asarray(xy, float).reshape(-1, 2)
    if not len(xy):
        return []
    stride = size - overlap
    origin = xy.min(0) if origin is None else np.asarray(origin, float)
    cell = np.floor((xy - origin) / stride).astype(np.int64)
    order = np.lexsort((cell[:, 1], cell[:, 0]))
    keys, starts = np.unique(cell[order], axis=0, return_index=True)
    half = overlap / 2.0
    ends = np.append(starts[1:], len(order))
    ranges = {(int(k[0]), int(k[1])): (a, b) for k, a, b in zip(keys, starts, ends)}
    out = []
    for key, start, end in zip(keys, starts, ends):
        i, j = int(key[0]), int(key[1])
        core_idx = np.sort(order[start:end])
        lo = origin + key * stride - half
        hi = lo + stride + 2 * half
        if half > 0:  # the window reaches half the overlap (< one stride) into the 8 neighbouring cells
            near = [order[a:b] for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di or dj) and (a_b := ranges.get((i + di, j + dj))) for a, b in [a_b]]
            near = np.concatenate(near) if near else np.zeros(0, np.int64)
            near = near[((xy[near] >= lo) & (xy[near] < hi)).all(1)]
            window = np.sort(np.concatenate([core_idx, near]))
        else:
            window = core_idx
        core = np.isin(window, core_idx, assume_unique=True)
        out.append(Tile((i, j), window, core, (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))))
    return out


def farthest_point(xyz: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(min(n, len),)`` int64 indices of a farthest-point sample of ``xyz`` ((m, 3), m), starting at a random point."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    m = len(xyz)
    n = min(n, m)
    if n <= 0:
        return np.zeros(0, np.int64)
    chosen = np.empty(n, np.int64)
    chosen[0] = rng.integers(m)
    nearest = np.full(m, np.inf)
    for k in range(1, n):
        nearest = np.minimum(nearest, ((xyz - xyz[chosen[k - 1]]) ** 2).sum(1))
        chosen[k] = int(np.argmax(nearest))
    return chosen


def class_quotas(labels: np.ndarray, n: int) -> dict[int, int]:
    """Points per class for a class-aware sample of ``n`` from ``labels`` ((m,) int): shares in proportion to
    the square root of each class's count, never more than the class has, the rest handed on to the others."""
    classes, counts = np.unique(np.asarray(labels), return_counts=True)
    quota = np.zeros(len(classes), np.int64)
    left = min(n, int(counts.sum()))
    open_ = counts > 0
    while left > 0 and open_.any():
        weight = np.sqrt(counts) * open_
        share = np.floor(left * weight / weight.sum()).astype(np.int64)
        if share.sum() == 0:  # fewer points left than open classes: one each, largest first
            share[np.argsort(-weight)[:left]] = 1
        share = np.minimum(share, counts - quota)
        quota += share
        left -= int(share.sum())
        open_ = quota < counts
    return {int(c): int(q) for c, q in zip(classes, quota) if q > 0}


def sample(xyz: np.ndarray, n: int, method: str, rng: np.random.Generator, labels: np.ndarray | None = None) -> np.ndarray:
    """``(min(n, m),)`` sorted int64 indices of a sample of ``n`` of the points ``xyz`` ((m, 3)).

    method : ``random`` or ``fps``; labels : (m,) class ids for a class-aware sample (``None``: plain)
    """
    if method not in SAMPLING_METHODS:
        raise ValueError(f"sample: method must be one of {', '.join(SAMPLING_METHODS)}, got {method!r}")
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    if n >= len(xyz):
        return np.arange(len(xyz), dtype=np.int64)
    pick = (lambda idx, k: idx[farthest_point(xyz[idx], k, rng)]) if method == "fps" else (lambda idx, k: rng.choice(idx, k, replace=False))
    if labels is None:
        return np.sort(pick(np.arange(len(xyz)), n))
    labels = np.asarray(labels)
    parts = [pick(np.flatnonzero(labels == c), q) for c, q in class_quotas(labels, n).items()]
    return np.sort(np.concatenate(parts)).astype(np.int64)
