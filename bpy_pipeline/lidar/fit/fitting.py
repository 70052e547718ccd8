"""Ray drop and range noise fitted to real organised scans, for ``effects.drop.model_file`` and
``effects.noise.model_file``.

An *organised* scan is a range image: ``rings x columns`` firings of a spinning sensor, each
either a return or empty. Two ways to learn from it:

* **one scan**: an empty firing whose ring neighbours (left and right, at most ``max_gap``
  columns away) both returned had a target there: its range is interpolated between them
  (linearly when they agree within ``agree`` of their range, else the nearer one, the
  foreground of an edge), its direction too. Empty firings with no such neighbours (sky,
  the sensor's own vehicle, long gaps) say nothing about a drop model and are left out.
  Range noise comes from the second difference along the ring, ``r_c - (r_{c-1} + r_{c+1}) / 2``,
  of three returns on one surface (variance ``1.5 sigma^2`` for independent noise; surface
  roughness at the column spacing counts as noise, so far bins are upper bounds);
* **repeated scans of a static scene**: the per-pixel median range of the returns is the
  geometry and the drop ratio is counted per pixel (the human-robot paper's method); noise is
  the spread about the per-pixel mean.

Incidence comes from local normals of the range image (the cross product of the ring-wise and
column-wise neighbour differences, each taken on the side with the smaller range jump, so a
silhouette's edge keeps its surface's normal). Samples then feed the models of
:mod:`bpy_pipeline.lidar.effects.apply`: ``uniform`` (the drop fraction), ``threshold`` (a logistic regression of
detection on ``ln a - n ln R``, ``a`` the apparent reflectance from the intensity, the exponent
``n`` searched), ``table`` (drop fraction per (range, incidence) bin, bins with fewer than
``min_samples`` discarded) and the noise ``table`` and ``range`` models. Fit error is judged
on held-out column blocks (:func:`cross_validate`).

Ego-motion: nuScenes sweeps are motion compensated, so a return was moved to the sensor pose at
the sweep's end, and an empty firing (zero range) lands on the sensor's position at firing
time. :func:`read_scan` finds that straight line through the empty returns and measures every
range from it, which undoes the compensation to within the sweep's rotation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..effects.drop.mlp import MLP, fit_mlp
from ..effects.drop.threshold import ThresholdModel
from ..effects.apply import BinnedTable, FittedModels, apply_effects
from ..points import BEAM_DTYPE, empty_points


# ----------------------------------------------------------------------------- reading scans
@dataclass(frozen=True)
class OrganisedScan:
    """``s`` sweeps of one sensor as range images.

    xyz : (s, rings, columns, 3) float64 returns relative to the sensor position at firing time, m
    valid : (s, rings, columns) bool, False for an empty firing
    intensity : (s, rings, columns) float64, the file's units
    source : file names, for the model file
    """

    xyz: np.ndarray
    valid: np.ndarray
    intensity: np.ndarray
    source: tuple[str, ...] = ()

    @property
    def shape(self) -> tuple[int, int]:
        return self.valid.shape[1:]


def sensor_track(xyz: np.ndarray, candidates: np.ndarray, tolerance: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """The sensor position at each column from the empty returns of a motion-compensated sweep.

    xyz : (rings, columns, 3) float64; candidates : (rings, columns) bool, returns near the origin
    Returns ``(position (columns, 3) float64, empty (rings, columns) bool)``: a straight line in
    the column index fitted to the candidates (trimmed: the candidates farther than
    ``tolerance`` m from it, real returns from the vehicle itself, are refitted away) and the
    candidates on it. Without candidates the sensor sits at the origin and nothing is empty.
    """
    rings, columns = candidates.shape
    if not candidates.any():
        return np.zeros((columns, 3)), np.zeros_like(candidates)
    column = np.broadcast_to(np.arange(columns), (rings, columns))
    design = np.column_stack([np.ones(columns), np.arange(columns)])
    inliers = candidates.copy()
    for _ in range(10):
        coef, *_ = np.linalg.lstsq(design[column[inliers]], xyz[inliers], rcond=None)
        distance = np.linalg.norm(xyz - (design @ coef)[None], axis=2)
        new = candidates & (distance < max(3.0 * float(np.median(distance[inliers])), 0.5 * tolerance))
        if (new == inliers).all() or new.sum() < 2:
            break
        inliers = new
    return design @ coef, candidates & (distance < tolerance)


def organise(data: np.ndarray, rings: int, where: str, intensity_field: int = 3, ring_field: int | None = 4, empty_radius: float = 0.5) -> OrganisedScan:
    """One sweep from firing-ordered records ``(n, f)`` (x y z intensity [ring], column after column)."""
    n = len(data)
    if rings < 1 or n == 0 or n % rings:
        raise InputError(f"{where}: {n} returns do not fill {rings} rings (--rings); an organised scan lists every firing, empty ones included")
    columns = n // rings
    if ring_field is not None:
        if data.shape[1] <= ring_field:
            raise InputError(f"{where}: no ring field {ring_field} in {data.shape[1]} fields (--ring-field)")
        if not (data[:, ring_field].astype(np.int64) == np.tile(np.arange(rings), columns)).all():
            raise InputError(f"{where}: not organised: the ring field must run 0..{rings - 1} in every column of {rings} firings")
    grid = data[:, :3].astype(np.float64).reshape(columns, rings, 3).transpose(1, 0, 2)
    intensity = data[:, intensity_field].astype(np.float64).reshape(columns, rings).T
    near = np.linalg.norm(grid, axis=2) < empty_radius
    position, empty = sensor_track(grid, near)
    return OrganisedScan((grid - position[None])[None], ~empty[None], intensity[None], (where,))


def read_scan(path: str | Path, rings: int, fields: int = 5, intensity_field: int = 3, ring_field: int | None = 4, empty_radius: float = 0.5) -> OrganisedScan:
    """Read one organised sweep: a float32 ``.bin`` of ``fields`` per firing (nuScenes: x y z
    intensity ring, turned from LIDAR_TOP's x right, y forward to the sensor frame's x forward,
    y left) or an ``.npy`` of ``(rings, columns, >= 4)`` (x y z intensity, the sensor frame)."""
    path = Path(path)
    try:
        if path.suffix == ".npy":
            grid = np.load(path)
            if grid.ndim != 3 or grid.shape[0] != rings or grid.shape[2] < 4:
                raise InputError(f"{path}: expected an array of ({rings}, columns, >= 4) x y z intensity, got {grid.shape}")
            data = grid.transpose(1, 0, 2).reshape(-1, grid.shape[2])
            ring_field = None
        else:
            raw = np.fromfile(path, np.float32)
            if raw.size % fields:
                raise InputError(f"{path}: {raw.size} floats are not records of {fields} fields (--fields)")
            data = raw.reshape(-1, fields)
            if fields == 5 and ring_field == 4:  # nuScenes LIDAR_TOP is x right, y forward: to x forward, y left (io/real_scans.py)
                data = np.column_stack([data[:, 1], -data[:, 0], data[:, 2:]])
    except OSError as err:
        raise InputError(f"{path}: cannot read the scan ({err.strerror or err})") from None
    except ValueError as err:
        raise InputError(f"{path}: not a numpy array file ({err})") from None
    return organise(data, rings, str(path), intensity_field, ring_field, empty_radius)


def stack_scans(scans: list[OrganisedScan]) -> OrganisedScan:
    """Repeated sweeps of a static scene as one :class:`OrganisedScan` (same rings and columns)."""
    shapes = {s.shape for s in scans}
    if len(shapes) != 1:
        raise InputError(f"fit: repeated scans must have the same rings x columns, got {sorted(shapes)}")
    return OrganisedScan(
        np.concatenate([s.xyz for s in scans]), np.concatenate([s.valid for s in scans]),
        np.concatenate([s.intensity for s in scans]), tuple(x for s in scans for x in s.source),
    )


# ----------------------------------------------------------------------------- geometry of a range image
@dataclass(frozen=True)
class Geometry:
    """Where each firing's target is, from the returns.

    range : (rings, columns) float64 m, NaN where unknown
    direction : (rings, columns, 3) float64 unit vectors
    cos_incidence : (rings, columns) float64, NaN where no normal could be formed
    reflectance : (rings, columns) float64 apparent reflectance (intensity / scale)
    filled : (rings, columns) bool, the range was interpolated from ring neighbours (no return in any scan)
    """

    range: np.ndarray
    direction: np.ndarray
    cos_incidence: np.ndarray
    reflectance: np.ndarray
    filled: np.ndarray


def fill_from_ring_neighbours(values: np.ndarray, have: np.ndarray, max_gap: int, agree: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolation positions for the missing cells of each ring.

    values : (rings, columns) ranges (m) where ``have``; have : (rings, columns) bool
    Returns ``(cells, left, right, t, t_range)`` as index arrays into the flattened image: each
    missing cell with returns on both sides within ``max_gap`` columns, its neighbours, the
    weight of the right one by column position (for directions) and for the range (the same
    when their ranges agree within ``agree``, else 0 or 1: the nearer one).
    """
    rings, columns = have.shape
    cells, lefts, rights, weights, range_weights = [], [], [], [], []
    for ring in range(rings):
        ok = np.flatnonzero(have[ring])
        missing = np.flatnonzero(~have[ring])
        if len(ok) < 2 or not len(missing):
            continue
        k = np.searchsorted(ok, missing)
        inside = (k > 0) & (k < len(ok))
        missing, k = missing[inside], k[inside]
        left, right = ok[k - 1], ok[k]
        close = right - left - 1 <= max_gap
        missing, left, right = missing[close], left[close], right[close]
        r_left, r_right = values[ring, left], values[ring, right]
        t = (missing - left) / (right - left)
        same = np.abs(r_left - r_right) <= agree * np.minimum(r_left, r_right)
        base = ring * columns
        cells.append(base + missing), lefts.append(base + left), rights.append(base + right), weights.append(t)
        range_weights.append(np.where(same, t, (r_right < r_left).astype(float)))
    if not cells:
        empty = np.zeros(0, np.intp)
        return empty, empty, empty, np.zeros(0), np.zeros(0)
    return tuple(np.concatenate(a) for a in (cells, lefts, rights, weights, range_weights))


def _one_sided(points: np.ndarray, ranges: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour difference along ``axis`` on the side with the smaller range jump; (jump, vector)."""
    n = ranges.shape[axis]
    forward = np.full(points.shape, np.nan)
    backward = np.full(points.shape, np.nan)
    lo = [slice(None)] * 2
    hi = [slice(None)] * 2
    lo[axis], hi[axis] = slice(0, n - 1), slice(1, n)
    lo, hi = tuple(lo), tuple(hi)
    forward[lo] = points[hi] - points[lo]
    backward[hi] = points[hi] - points[lo]
    jump_f = np.full(ranges.shape, np.inf)
    jump_b = np.full(ranges.shape, np.inf)
    jump_f[lo] = np.abs(ranges[hi] - ranges[lo])
    jump_b[hi] = np.abs(ranges[hi] - ranges[lo])
    jump_f[np.isnan(jump_f)] = np.inf
    jump_b[np.isnan(jump_b)] = np.inf
    use_forward = jump_f <= jump_b
    return np.minimum(jump_f, jump_b), np.where(use_forward[..., None], forward, backward)


def local_cos_incidence(ranges: np.ndarray, direction: np.ndarray, max_jump: float = 1.0) -> np.ndarray:
    """|cos| of the angle between each beam and the surface normal of the range image there.

    ranges : (rings, columns) m (NaN unknown); direction : (rings, columns, 3) unit vectors
    The normal is the cross product of the column-wise and ring-wise neighbour differences;
    NaN where a side has no neighbour within ``max_jump`` of the cell's range (relative).
    """
    points = ranges[..., None] * direction
    jump_c, along_ring = _one_sided(points, ranges, 1)
    jump_r, across = _one_sided(points, ranges, 0)
    normal = np.cross(along_ring, across)
    length = np.linalg.norm(normal, axis=2)
    ok = (jump_c <= max_jump * ranges) & (jump_r <= max_jump * ranges) & (length > 0)
    cos = np.abs(np.einsum("ijk,ijk->ij", normal, direction)) / np.where(length > 0, length, 1.0)
    return np.where(ok, np.clip(cos, 0.0, 1.0), np.nan)


def _median_where(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Per-pixel median over the sweeps (axis 0) of the valid values; NaN where none is."""
    if len(values) == 1:
        return np.where(valid[0], values[0], np.nan)
    masked = np.sort(np.where(valid, values, np.inf), axis=0)  # invalid ones sort last
    count = valid.sum(axis=0)
    lo = np.take_along_axis(masked, np.maximum((count - 1) // 2, 0)[None], 0)[0]
    hi = np.take_along_axis(masked, np.maximum(count // 2, 0)[None], 0)[0]
    return np.where(count > 0, 0.5 * (lo + hi), np.nan)


def scan_geometry(scan: OrganisedScan, max_gap: int = 4, agree: float = 0.1, intensity_scale: float = 100.0) -> Geometry:
    """The targets of every firing: per-pixel medians over the sweeps, gaps filled along rings.

    intensity_scale : intensity that means an apparent reflectance of 1 (Velodyne's calibrated
        reflectivity: 100 for a white Lambertian target; 101-255 are retro-reflectors)
    """
    ranges = np.linalg.norm(scan.xyz, axis=3)
    valid = scan.valid
    have = valid.any(axis=0)
    median, reflectance = _median_where(ranges, valid), _median_where(scan.intensity, valid) / intensity_scale
    direction = np.where(valid[..., None], scan.xyz / np.where(ranges > 0, ranges, 1.0)[..., None], 0.0).sum(axis=0)
    length = np.linalg.norm(direction, axis=2, keepdims=True)
    direction = direction / np.where(length > 0, length, 1.0)
    cells, left, right, t, t_range = fill_from_ring_neighbours(median, have, max_gap, agree)
    flat_r, flat_a, flat_d = median.flatten(), reflectance.flatten(), direction.reshape(-1, 3).copy()
    flat_r[cells] = flat_r[left] * (1 - t_range) + flat_r[right] * t_range
    flat_a[cells] = flat_a[left] * (1 - t_range) + flat_a[right] * t_range
    d = flat_d[left] * (1 - t)[:, None] + flat_d[right] * t[:, None]
    flat_d[cells] = d / np.linalg.norm(d, axis=1, keepdims=True)
    filled = np.zeros(have.size, bool)
    filled[cells] = True
    median, reflectance, direction = flat_r.reshape(have.shape), flat_a.reshape(have.shape), flat_d.reshape(*have.shape, 3)
    return Geometry(median, direction, local_cos_incidence(median, direction), reflectance, filled.reshape(have.shape))


# ----------------------------------------------------------------------------- samples
@dataclass(frozen=True)
class Samples:
    """One row per firing with a known target: what a drop model sees, and whether it returned.

    range : (k,) float64 m; cos_incidence : (k,) float64; reflectance : (k,) float64 apparent
    ring, column : (k,) int64 position in the range image; dropped : (k,) bool
    """

    range: np.ndarray
    cos_incidence: np.ndarray
    reflectance: np.ndarray
    ring: np.ndarray
    column: np.ndarray
    dropped: np.ndarray

    def __len__(self) -> int:
        return len(self.range)

    def subset(self, mask: np.ndarray) -> "Samples":
        return Samples(*(getattr(self, f)[mask] for f in Samples.__dataclass_fields__))


@dataclass(frozen=True)
class NoiseSamples:
    """Range deviations with where they were seen: range, cos_incidence (k,) float64;
    residual (k,) float64 m, each an estimate of one draw of the noise (already scaled)."""

    range: np.ndarray
    cos_incidence: np.ndarray
    residual: np.ndarray
    column: np.ndarray


def drop_samples(scan: OrganisedScan, geometry: Geometry, min_range: float = 2.0, max_range: float = 100.0) -> Samples:
    """Every (sweep, firing) whose target is known and within ``min_range..max_range`` m."""
    g = geometry
    known = np.isfinite(g.range) & np.isfinite(g.cos_incidence) & (g.range >= min_range) & (g.range <= max_range)
    rings, columns = known.shape
    ring, column = np.nonzero(known)
    s = len(scan.valid)
    reflectance = np.where(np.isfinite(g.reflectance), g.reflectance, np.nanmedian(g.reflectance))
    return Samples(
        np.tile(g.range[known], s), np.tile(g.cos_incidence[known], s), np.tile(np.maximum(reflectance[known], 0.0), s),
        np.tile(ring, s), np.tile(column, s), ~scan.valid[:, known].reshape(-1),
    )


def noise_samples(scan: OrganisedScan, geometry: Geometry, min_range: float = 2.0, max_range: float = 100.0, agree: float = 0.01) -> NoiseSamples:
    """Range deviations: about the per-pixel mean (repeated scans, pixels with >= 3 returns,
    scaled by ``sqrt(m / (m - 1))`` for m returns; deviations from a median would hold exact
    zeros and bias the robust sigma) or, from one sweep, the second difference
    along the ring over ``sqrt(1.5)`` where three neighbouring returns agree within ``agree``."""
    g = geometry
    ranges = np.linalg.norm(scan.xyz, axis=3)
    cos = g.cos_incidence
    if len(scan.valid) >= 2:
        m = scan.valid.sum(axis=0)
        use = scan.valid & (m >= 3)[None] & np.isfinite(cos)[None] & (g.range >= min_range)[None] & (g.range <= max_range)[None]
        mean = np.where(scan.valid, ranges, 0.0).sum(axis=0) / np.maximum(m, 1)
        residual = (ranges - mean[None]) * np.sqrt(m / np.maximum(m - 1, 1))[None]
        _, _, column = np.nonzero(use)
        return NoiseSamples(np.broadcast_to(g.range, use.shape)[use], np.broadcast_to(cos, use.shape)[use], residual[use], column)
    r = np.where(scan.valid[0], ranges[0], np.nan)
    mid, left, right = r[:, 1:-1], r[:, :-2], r[:, 2:]
    with np.errstate(invalid="ignore"):
        use = (np.abs(left - mid) <= agree * mid) & (np.abs(right - mid) <= agree * mid) & (mid >= min_range) & (mid <= max_range)
        use &= np.isfinite(cos[:, 1:-1])
    residual = (mid - 0.5 * (left + right)) / math.sqrt(1.5)
    _, column = np.nonzero(use)
    return NoiseSamples(mid[use], cos[:, 1:-1][use], residual[use], column + 1)


# ----------------------------------------------------------------------------- fits
def range_edges(samples: Samples, bins: int, low: float | None = None, high: float | None = None) -> np.ndarray:
    """``bins + 1`` log-spaced range edges (m) over ``low..high`` (default: the samples' span)."""
    low = float(samples.range.min()) if low is None else low
    high = float(samples.range.max()) * (1 + 1e-9) if high is None else high
    return np.geomspace(low, high, bins + 1)


def incidence_edges(bins: int) -> np.ndarray:
    """``bins + 1`` incidence edges over 0..90 degrees."""
    return np.linspace(0.0, 90.0, bins + 1)


def binned(range_m, cos_incidence, r_edges, i_edges) -> tuple[np.ndarray, np.ndarray]:
    """Bin index of each sample (flattened ``nr * ni``) and whether it lies within the edges."""
    angle = np.degrees(np.arccos(np.clip(cos_incidence, 0.0, 1.0)))
    ri = np.searchsorted(r_edges, range_m, side="right") - 1
    ii = np.minimum(np.searchsorted(i_edges, angle, side="right") - 1, len(i_edges) - 2)
    inside = (ri >= 0) & (ri < len(r_edges) - 1) & (ii >= 0)
    return ri * (len(i_edges) - 1) + ii, inside


def fit_uniform(samples: Samples) -> float:
    """The drop fraction."""
    return float(samples.dropped.mean())


def fit_drop_table(samples: Samples, r_edges: np.ndarray, i_edges: np.ndarray, min_samples: int = 100) -> BinnedTable:
    """Drop fraction per (range, incidence) bin; bins with fewer than ``min_samples`` discarded (NaN)."""
    index, inside = binned(samples.range, samples.cos_incidence, r_edges, i_edges)
    size = (len(r_edges) - 1) * (len(i_edges) - 1)
    n = np.bincount(index[inside], minlength=size)
    k = np.bincount(index[inside], weights=samples.dropped[inside].astype(float), minlength=size)
    p = np.where(n >= min_samples, k / np.maximum(n, 1), np.nan)
    shape = (len(r_edges) - 1, len(i_edges) - 1)
    if np.isnan(p).all():
        raise InputError(f"fit: no (range, incidence) bin holds {min_samples} samples (--min-samples); use fewer bins")
    return BinnedTable(r_edges, i_edges, p.reshape(shape), n.reshape(shape))


def bin_means(range_m, cos_incidence, value, r_edges, i_edges, min_samples: int = 100, statistic=None) -> dict:
    """Per (range, incidence) bin: mean range (m), mean incidence (deg), the bin's statistic of
    ``value`` and its sample count, for the bins with at least ``min_samples`` samples (the
    Raphael paper's ``(d_mean, phi_mean, P)`` rows; thinner bins are discarded).

    statistic : ``None`` for the mean of ``value``, else ``f(values) -> float`` (the robust sigma)
    Returns ``{"range", "incidence_deg", "value", "samples"}``, each (b,) over the kept bins.
    """
    index, inside = binned(range_m, cos_incidence, r_edges, i_edges)
    size = (len(r_edges) - 1) * (len(i_edges) - 1)
    index = index[inside]
    angle = np.degrees(np.arccos(np.clip(np.asarray(cos_incidence)[inside], 0.0, 1.0)))
    n = np.bincount(index, minlength=size)
    keep = n >= min_samples
    mean_r = np.bincount(index, weights=np.asarray(range_m)[inside], minlength=size) / np.maximum(n, 1)
    mean_a = np.bincount(index, weights=angle, minlength=size) / np.maximum(n, 1)
    values = np.asarray(value, np.float64)[inside]
    if statistic is None:
        stat = np.bincount(index, weights=values, minlength=size) / np.maximum(n, 1)
    else:
        order = np.argsort(index, kind="stable")
        groups = np.split(values[order], np.cumsum(n)[:-1])
        stat = np.array([statistic(g) if len(g) >= min_samples else np.nan for g in groups])
    return {"range": mean_r[keep], "incidence_deg": mean_a[keep], "value": stat[keep], "samples": n[keep]}


@dataclass(frozen=True)
class MLPOptions:
    """How the ``mlp`` models are fitted: the bins they learn from and the network."""

    range_bins: int = 8  # log-spaced over the fit's range
    incidence_bins: int = 4  # over 0..90 deg
    hidden: tuple[int, ...] = (8,)  # tanh units per hidden layer (one layer of 8: the held-out choice, benchmarks/bench_fitting.py)
    steps: int = 3000  # full-batch Adam steps
    learning_rate: float = 0.01
    decay: float = 1e-4  # L2 on the weights
    seed: int = 0  # the weights' start; the same seed gives the same bytes


def fit_drop_mlp(samples: Samples, r_edges: np.ndarray, options: MLPOptions = MLPOptions(), min_samples: int = 100) -> MLP:
    """The Raphael paper's drop MLP: bins over (range, incidence) with ``min_samples`` or more
    firings, each bin's ``(mean range, mean incidence, drop ratio)``, and a perceptron from the
    first two to the third, the bins weighted by their firings (cross-entropy: the likelihood of
    the binned data). ``r_edges``: the range bins' edges (m); incidence bins from ``options``."""
    rows = bin_means(samples.range, samples.cos_incidence, samples.dropped.astype(float), r_edges, incidence_edges(options.incidence_bins), min_samples)
    if len(rows["value"]) == 0:
        raise InputError(f"fit: no (range, incidence) bin holds {min_samples} samples (--min-samples); use fewer --mlp-range-bins / --mlp-incidence-bins")
    return fit_mlp(rows["range"], rows["incidence_deg"], rows["value"], rows["samples"], (float(r_edges[0]), float(r_edges[-1])), "probability",
                   tuple(options.hidden), options.steps, options.learning_rate, options.decay, options.seed)


def fit_noise_mlp(noise: "NoiseSamples", r_edges: np.ndarray, options: MLPOptions = MLPOptions(), min_samples: int = 100) -> MLP:
    """The Raphael paper's noise MLP: each kept bin's robust range-noise sigma (m), learnt in ``ln sigma``
    over (mean range, mean incidence), the bins weighted by their samples."""
    rows = bin_means(noise.range, noise.cos_incidence, noise.residual, r_edges, incidence_edges(options.incidence_bins), min_samples, robust_sigma)
    ok = rows["value"] > 0
    if not ok.any():
        raise InputError(f"fit: no (range, incidence) bin holds {min_samples} noise samples (--min-samples); use fewer --mlp-range-bins / --mlp-incidence-bins")
    return fit_mlp(rows["range"][ok], rows["incidence_deg"][ok], rows["value"][ok], rows["samples"][ok], (float(r_edges[0]), float(r_edges[-1])), "positive",
                   tuple(options.hidden), options.steps, options.learning_rate, options.decay, options.seed)


def robust_sigma(residual: np.ndarray) -> float:
    """1.4826 x the median absolute deviation: the sigma of the Gaussian core."""
    return float(1.4826 * np.median(np.abs(residual - np.median(residual)))) if len(residual) else float("nan")


def fit_noise_table(noise: NoiseSamples, r_edges: np.ndarray, i_edges: np.ndarray, min_samples: int = 100) -> BinnedTable:
    """Robust range-noise sigma (m) per (range, incidence) bin; thin bins discarded (NaN)."""
    index, inside = binned(noise.range, noise.cos_incidence, r_edges, i_edges)
    shape = (len(r_edges) - 1, len(i_edges) - 1)
    size = shape[0] * shape[1]
    n = np.bincount(index[inside], minlength=size)
    sigma = np.full(size, np.nan)
    order = np.argsort(index[inside], kind="stable")
    groups = np.split(noise.residual[inside][order], np.cumsum(n)[:-1])
    for b, group in enumerate(groups):
        if len(group) >= min_samples:
            sigma[b] = robust_sigma(group)
    if np.isnan(sigma).all():
        raise InputError(f"fit: no (range, incidence) bin holds {min_samples} noise samples (--min-samples); use fewer bins")
    return BinnedTable(r_edges, i_edges, sigma.reshape(shape), n.reshape(shape))


def fit_noise_range(noise: NoiseSamples, r_edges: np.ndarray, min_samples: int = 100) -> tuple[float, float]:
    """``(sigma, sigma_per_metre)``: a line through the robust sigma of each range bin, weighted
    by its samples, with both coefficients kept >= 0."""
    table = fit_noise_table(noise, r_edges, incidence_edges(1), min_samples)
    ok = ~np.isnan(table.values[:, 0])
    centre = 0.5 * (r_edges[:-1] + r_edges[1:])[ok]
    sigma, w = table.values[ok, 0], np.sqrt(table.samples[ok, 0].astype(float))
    if ok.sum() < 2:
        return float(sigma.mean()), 0.0
    slope, intercept = np.polyfit(centre, sigma, 1, w=w)
    if intercept < 0:
        slope, intercept = float(np.sum(w * w * centre * sigma) / np.sum(w * w * centre * centre)), 0.0
    if slope < 0:
        slope, intercept = 0.0, float(np.average(sigma, weights=w * w))
    return float(intercept), float(slope)


def _logistic(x: np.ndarray, y: np.ndarray, weights: np.ndarray | None = None, ridge: float = 1e-8) -> tuple[np.ndarray, float]:
    """Maximum-likelihood logistic regression by Newton steps: (coefficients, log-likelihood)."""
    w = np.ones(len(y)) if weights is None else weights
    beta = np.zeros(x.shape[1])
    beta[0] = math.log((np.sum(w * y) + 0.5) / (np.sum(w * (1 - y)) + 0.5))
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-np.clip(x @ beta, -60, 60)))
        hessian = x.T @ (x * (w * p * (1 - p))[:, None]) + ridge * np.eye(x.shape[1])
        step = np.linalg.solve(hessian, x.T @ (w * (y - p)) - ridge * beta)
        beta += step
        if np.abs(step).max() < 1e-10:
            break
    z = np.clip(x @ beta, -60, 60)
    return beta, float(np.sum(w * (y * z - np.logaddexp(0.0, z))))


def fit_threshold(samples: Samples, exponent: float | None = None, exponents=np.arange(0.0, 8.01, 0.125)) -> ThresholdModel:
    """The detection threshold that best explains which firings returned.

    Detection is logistic in ``ln a - n ln R`` (``a`` apparent reflectance): the slope gives the
    softness, the intercept the sensitivity; the range exponent ``n`` is searched over
    ``exponents`` (or fixed with ``exponent``: 2 is the lidar equation). Firings are grouped by
    (range, reflectance) on a fine grid first, so the fit costs little on large scans.
    """
    detected = (~samples.dropped).astype(float)
    log_a = np.log(np.maximum(samples.reflectance, 1e-3))
    log_r = np.log(samples.range)
    # group identical features (to 1/200 of their spans) to keep the regressions small
    key_a = np.round((log_a - log_a.min()) / max(np.ptp(log_a), 1e-9) * 200).astype(np.int64)
    key_r = np.round((log_r - log_r.min()) / max(np.ptp(log_r), 1e-9) * 200).astype(np.int64)
    key = (key_a * 201 + key_r) * 2 + detected.astype(np.int64)
    unique, first, counts = np.unique(key, return_index=True, return_counts=True)
    ga, gr, gy = log_a[first], log_r[first], detected[first]
    best = None
    for n in [exponent] if exponent is not None else exponents:
        x = np.column_stack([np.ones(len(ga)), ga - n * gr])
        beta, ll = _logistic(x, gy, counts.astype(float))
        if beta[1] > 0 and (best is None or ll > best[0]):
            best = (ll, n, beta)
    if best is None:
        raise InputError("fit: detection does not rise with received power in these scans; the threshold model does not apply")
    _, n, beta = best
    return ThresholdModel(sensitivity=math.exp(-beta[0] / beta[1]), exponent=float(n), softness=float(1.0 / beta[1]), alpha=0.0)


# ----------------------------------------------------------------------------- held-out error
def column_folds(samples: Samples, folds: int, columns: int) -> np.ndarray:
    """Fold of each sample: ``folds`` blocks of neighbouring columns (whole azimuth sectors, so a
    held-out block shares no surface patch with the training data but its edges)."""
    return (samples.column * folds) // columns


def log_loss(p_drop: np.ndarray, dropped: np.ndarray) -> np.ndarray:
    """Per-sample negative log-likelihood (nats) of the outcomes under drop probabilities ``p_drop``."""
    p = np.clip(np.asarray(p_drop, np.float64), 1e-6, 1 - 1e-6)
    return -np.where(dropped, np.log(p), np.log1p(-p))


def predictor(name: str, train: Samples, options: dict):
    """Fit model ``name`` on ``train`` and return ``(p_drop(samples) -> (k,), parameter count)``.

    Names: ``uniform``, ``threshold`` (``threshold_n2``: exponent fixed at 2), ``table RxI``
    (R log-spaced range bins over ``options['range']``, I incidence bins), ``mlp RxI`` (the
    perceptron over such bins; ``options['mlp']``: an :class:`MLPOptions`), ``carla`` (CARLA's
    defaults, nothing fitted).
    """
    if name == "uniform":
        p = fit_uniform(train)
        return (lambda s: np.full(len(s), p)), 1
    if name.startswith("threshold"):
        model = fit_threshold(train, 2.0 if name == "threshold_n2" else None)
        return (lambda s: 1.0 - model.detection_probability(s.reflectance, s.range)), 2 if name == "threshold_n2" else 3
    if name.startswith("table"):
        nr, ni = (int(v) for v in name.split()[1].split("x"))
        low, high = options["range"]
        table = fit_drop_table(train, np.geomspace(low, high, nr + 1), incidence_edges(ni), options.get("min_samples", 100))
        return (lambda s: table.lookup(s.range, s.cos_incidence)), int((~np.isnan(table.values)).sum())
    if name.startswith("mlp"):
        nr, ni = (int(v) for v in name.split()[1].split("x"))
        low, high = options["range"]
        mlp_options = replace(options.get("mlp", MLPOptions()), range_bins=nr, incidence_bins=ni)
        model = fit_drop_mlp(train, np.geomspace(low, high, nr + 1), mlp_options, options.get("min_samples", 100))
        return (lambda s: model.lookup(s.range, s.cos_incidence).astype(np.float64)), model.parameters
    if name == "carla":
        from ..effects.drop.carla import carla_keep_probability
        from ..effects.intensity import carla_intensity

        return (lambda s: 1.0 - 0.55 * carla_keep_probability(carla_intensity(s.range, 0.004), 0.8, 0.4)), 0
    raise ValueError(f"unknown model {name!r}")


def cross_validate(samples: Samples, names: list[str], folds: int, columns: int, options: dict) -> dict:
    """Held-out log-loss of each model over column-block folds.

    Returns ``{name: {"loss": (folds,) mean nats per firing, "parameters": int (mean over folds),
    "p_drop": (k,) held-out predictions}}``.
    """
    fold = column_folds(samples, folds, columns)
    out = {}
    for name in names:
        losses, params, p_all = np.zeros(folds), [], np.zeros(len(samples))
        for k in range(folds):
            test = fold == k
            predict, count = predictor(name, samples.subset(~test), options)
            p = predict(samples.subset(test))
            p_all[test] = p
            losses[k] = log_loss(p, samples.dropped[test]).mean()
            params.append(count)
        out[name] = {"loss": losses, "parameters": int(round(np.mean(params))), "p_drop": p_all}
    return out


def simplest_within_noise(scores: dict, order: list[str]) -> tuple[str, str]:
    """``(best, pick)``: the model of least mean held-out loss, and the first of ``order``
    (simplest first) whose paired fold-by-fold loss difference to it is within one standard error."""
    best = min(scores, key=lambda k: scores[k]["loss"].mean())
    for name in order:
        diff = scores[name]["loss"] - scores[best]["loss"]
        se = diff.std(ddof=1) / math.sqrt(len(diff)) if len(diff) > 1 else 0.0
        if diff.mean() <= se:
            return best, name
    return best, best


# ----------------------------------------------------------------------------- simulated scans
def samples_as_points(samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """Point records and beam facts with each sample's geometry, for :func:`bpy_pipeline.lidar.effects.apply.apply_effects`.

    The sample index rides in ``instance`` so survivors can be traced back; the apparent
    reflectance goes in as ``reflectivity / cos`` so their product is unchanged.
    """
    points = empty_points(len(samples))
    points["range"] = samples.range
    points["x"] = samples.range  # along +x: direction does not matter to drop models
    points["ring"] = samples.ring
    points["instance"] = np.arange(len(samples))
    beam = np.zeros(len(samples), BEAM_DTYPE)
    beam["cos_incidence"] = samples.cos_incidence
    beam["reflectivity"] = samples.reflectance / np.maximum(samples.cos_incidence, 1e-6)
    beam["gain"] = 1.0
    beam["direction"] = (1.0, 0.0, 0.0)
    return points, beam


def simulate_drops(samples: Samples, effects, rng: np.random.Generator) -> np.ndarray:
    """(k,) bool: which samples a scan with ``effects`` (``config.EffectsConfig``) drops."""
    points, beam = samples_as_points(samples)
    quiet = replace(effects.noise, model="constant", sigma=0.0, ring_bias=[], angular_jitter_deg=0.0)
    kept = apply_effects(points, beam, replace(effects, noise=quiet), rng)
    dropped = np.ones(len(samples), bool)
    dropped[kept["instance"]] = False
    return dropped


# ----------------------------------------------------------------------------- everything at once
MAX_FOLDS = 64  # held-out column blocks (each refits every model; the default 8)
MAX_MLP_STEPS = 100_000  # Adam steps of one mlp fit (33 x the default; each fold refits it)
MAX_GAP = 1024  # columns of empty firings filled from ring neighbours


@dataclass(frozen=True)
class FitOptions:
    """What ``python -m bpy_pipeline fit`` asks of the fits (defaults: the choice the held-out
    comparison on the nuScenes HDL-32E sweep recommends; see benchmarks/bench_fitting.py)."""

    max_gap: int = 4  # columns: longest run of empty firings filled from its ring neighbours
    agree: float = 0.1  # relative range difference under which two neighbours are one surface
    intensity_scale: float = 100.0  # intensity of an apparent reflectance of 1
    min_range: float = 2.0  # m: nearer targets (the sensor's own vehicle) are left out
    max_range: float = 100.0  # m
    range_bins: int = 4  # log-spaced over min_range..max_range
    incidence_bins: int = 2  # over 0..90 deg
    noise_range_bins: int = 8
    noise_incidence_bins: int = 2
    min_samples: int = 100  # bins with fewer samples are discarded (the human-robot paper's rule)
    folds: int = 8  # column blocks for the held-out comparison (0: none)
    mlp_range_bins: int = 8  # the mlp models' bins (log-spaced over min_range..max_range)
    mlp_incidence_bins: int = 4
    mlp_steps: int = 3000  # Adam steps of each mlp fit
    seed: int = 0  # the mlp weights' start (same seed, same bytes)

    @property
    def mlp(self) -> MLPOptions:
        return MLPOptions(range_bins=self.mlp_range_bins, incidence_bins=self.mlp_incidence_bins, steps=self.mlp_steps, seed=self.seed)


def fit_models(scan: OrganisedScan, options: FitOptions = FitOptions()) -> tuple[FittedModels, dict]:
    """Fit the uniform, threshold, table and mlp drop models and the range, table and mlp noise models.

    Returns the models (with a ``source`` record of the data and options) and a report: sample
    counts, and with ``folds`` > 1 the held-out log-loss of each drop model per fold.
    """
    geometry = scan_geometry(scan, options.max_gap, options.agree, options.intensity_scale)
    samples = drop_samples(scan, geometry, options.min_range, options.max_range)
    if len(samples) < options.min_samples or not samples.dropped.any() or samples.dropped.all():
        raise InputError(
            f"fit: {len(samples)} firings with a known target, {int(samples.dropped.sum())} of them empty: too few to fit (need both returns and drops)"
        )
    noise = noise_samples(scan, geometry, options.min_range, options.max_range)
    r_edges = np.geomspace(options.min_range, options.max_range, options.range_bins + 1)
    n_edges = np.geomspace(options.min_range, options.max_range, options.noise_range_bins + 1)
    models = FittedModels(
        uniform=fit_uniform(samples),
        threshold=fit_threshold(samples),
        drop_table=fit_drop_table(samples, r_edges, incidence_edges(options.incidence_bins), options.min_samples),
        noise_range=fit_noise_range(noise, n_edges, options.min_samples),
        noise_table=fit_noise_table(noise, n_edges, incidence_edges(options.noise_incidence_bins), options.min_samples),
        drop_mlp=fit_drop_mlp(samples, np.geomspace(options.min_range, options.max_range, options.mlp_range_bins + 1), options.mlp, options.min_samples),
        noise_mlp=fit_noise_mlp(noise, np.geomspace(options.min_range, options.max_range, options.mlp_range_bins + 1), options.mlp, options.min_samples),
        source={
            "scans": list(scan.source),
            "rings": int(scan.shape[0]), "columns": int(scan.shape[1]), "sweeps": int(len(scan.valid)),
            "firings": int(scan.valid.size), "empty": int((~scan.valid).sum()),
            "samples": int(len(samples)), "dropped": int(samples.dropped.sum()), "filled_from_neighbours": int(geometry.filled.sum()),
            "noise_samples": int(len(noise.residual)),
            "options": {k: getattr(options, k) for k in FitOptions.__dataclass_fields__},
        },
    )
    report = {"samples": samples, "noise": noise, "geometry": geometry}
    if options.folds > 1:
        names = ["uniform", "threshold", f"table {options.range_bins}x{options.incidence_bins}", f"mlp {options.mlp_range_bins}x{options.mlp_incidence_bins}"]
        report["cross_validation"] = cross_validate(samples, names, options.folds, scan.shape[1],
                                                    {"range": (options.min_range, options.max_range), "min_samples": options.min_samples, "mlp": options.mlp})
    return models, report
