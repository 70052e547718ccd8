"""Every firing of a real scan, hit or not: where it left from, where it pointed, what it returned.

A spinning sensor fires ``rings x columns`` beams a sweep. A scan that lists every firing
(nuScenes: column after column, rings 0..31, empty firings included) gives them directly: a
firing that returned points exactly at its return (from the sensor position at firing time);
an empty one gets a modelled direction, the ring's elevation (the median over the ring's
returns) and the column's azimuth (a straight line in the column index, plus the ring's
median offset from it), which reproduces the returned firings to about 0.03 deg.

nuScenes sweeps are motion compensated: a return was moved to the sensor pose at the sweep's
end, and an empty firing (zero range) lands on the sensor's position at firing time. Those
positions lie on a straight line in the column index (:func:`~bpy_pipeline.lidar.fit.fitting.sensor_track`),
the origin of every firing of that column; ranges and directions are measured from it.

A scan of returns only (KITTI) has no ring field: rings are rebuilt from the scan order (a new
ring starts where the azimuth wraps around), columns from the azimuth on a lattice of the
sensor's step. Where each ring's returns are listed in firing order (the scan order, or a ring
field read in file order), the empty firings are counted between consecutive returns of a ring
(a step of about k lattice steps hides k - 1 firings), where the gap stays inside the scan's
azimuth span. Otherwise (returns in no firing order) every lattice cell inside that span without
a return is an empty firing. All of that is approximate and :attr:`Firings.approximate` says so.
A sensor preset (``hdl64e``) fills what the file lacks: the azimuth step, the frame time and,
where the scan order gives no rings, the ring of each return by its nearest elevation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..io.real_scans import RealScan
from ..lidar.fit.fitting import sensor_track

EMPTY_RADIUS = 0.5  # m: returns of an organised file nearer than this are candidates for empty firings


@dataclass
class Firings:
    """The ``f`` firings of one real sweep, in firing order.

    origin : (f, 3) float64 sensor position at firing time (sensor frame of the scan), metres
    direction : (f, 3) float64 unit beam direction
    range : (f,) float64 metres from ``origin`` to the return; 0 for an empty firing
    valid : (f,) bool, True where the firing returned
    intensity : (f,) float64 0..1 (an empty nuScenes firing carries one too)
    ring, column : (f,) int64 position in the rings x columns grid
    time : (f,) float64 seconds from the sweep's start
    point : (f,) int64 index of the firing's record in the :class:`RealScan`, -1 for a firing made up from a gap
    shape : (rings, columns)
    elevation_deg : (rings,) the ring elevation table; azimuth_deg : (columns,) the column azimuth line
    residual_deg : median angle between the returned firings and their modelled direction
    approximate : what is approximate, for the manifest (empty for a file that lists every firing)
    """

    origin: np.ndarray
    direction: np.ndarray
    range: np.ndarray
    valid: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray
    column: np.ndarray
    time: np.ndarray
    point: np.ndarray
    shape: tuple[int, int]
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    residual_deg: float
    approximate: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.range)

    @property
    def returns(self) -> np.ndarray:
        """(f, 3) float64 the returns (``origin`` for an empty firing)."""
        return self.origin + self.range[:, None] * self.direction

    def info(self) -> dict:
        return {
            "firings": int(len(self)), "rings": int(self.shape[0]), "columns": int(self.shape[1]), "empty": int((~self.valid).sum()),
            "direction_residual_deg": round(float(self.residual_deg), 5), "approximate": list(self.approximate),
        }


def spherical(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """``(n, 3)`` unit vectors (azimuth from +x towards +y, elevation up from the xy plane)."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


def angles_deg(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(azimuth, elevation)`` degrees of ``(n, 3)`` directions."""
    d = np.asarray(direction, np.float64)
    return np.degrees(np.arctan2(d[..., 1], d[..., 0])), np.degrees(np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])))


def angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(n,)`` radians between unit vectors (stable near 0: atan2 of the cross and dot products)."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...i,...i", u, v))


def _wrap(deg: np.ndarray) -> np.ndarray:
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0


def _spec(preset: str | None):
    if not preset:
        return None
    from ..lidar.sensor.sensors import resolve_sensor

    return resolve_sensor({"preset": preset}, "scene.preset")


def preset_elevations(spec) -> np.ndarray:
    """``(rings,)`` float64 degrees of a preset's rings: its table, or its pattern's evenly spaced rows."""
    from ..lidar.sensor.sensors import elevations

    return np.asarray(spec.elevations_deg, float) if spec.elevations_deg else np.asarray(elevations(spec), float)


ELEVATION_SLACK_DEG = 1.0  # a scan's returns may reach this far past its preset's elevations (calibration, a tilted mount)
OUTSIDE_SHARE = 0.05  # returns past the slack: a preset that leaves more out of its span is another sensor
# rings taken from the nearest of a preset's elevations: each ring's interquartile elevation spread over the preset's
# ring spacing is 0.22-0.41 on the real scans of the preset that made them (nuScenes HDL-32E, KITTI HDL-64E), 0.49-0.51
# on those of a sensor with other rings (uniform within a ring: 0.5)
RING_SPREAD = 0.46


def check_preset_fits(scan: RealScan, spec, elevation_deg: np.ndarray, ring: np.ndarray, rings: int, nearest: bool = False) -> None:
    """``InputError`` when the scan's rings cannot be the preset's (an HDL-64E scan given as an HDL-32E): more rings than
    it has channels, more than :data:`OUTSIDE_SHARE` of the returns outside its elevations, or, where the rings are the
    nearest of its elevations (``nearest``), rings as wide as its spacing (:data:`RING_SPREAD`)."""
    table = preset_elevations(spec)
    if not len(table):
        return
    why = ""
    if rings > len(table):
        why = f"has {rings} rings; preset {spec.name} has {len(table)} channels"
    outside = float(np.mean((elevation_deg < table.min() - ELEVATION_SLACK_DEG) | (elevation_deg > table.max() + ELEVATION_SLACK_DEG)))
    if not why and outside > OUTSIDE_SHARE:
        why = f"has {outside:.0%} of its returns outside preset {spec.name}'s elevations {table.min():.2f}..{table.max():.2f} deg"
    if not why and nearest and len(table) > 1 and len(ring) >= 1000:  # a few returns do not show their rings
        count = np.bincount(ring, minlength=rings)
        spread = [np.subtract(*np.percentile(elevation_deg[ring == k], [75, 25])) for k in range(rings) if count[k] >= 20]
        ratio = float(np.median(spread)) / float(np.median(np.diff(np.sort(table)))) if spread else 0.0
        if ratio > RING_SPREAD:
            why = (f"has rings finer than preset {spec.name}'s (each of its rings spreads over {ratio:.2f} of the preset's ring spacing; "
                   f"the preset's own scans: under {RING_SPREAD})")
    if why:
        raise InputError(f"scene.preset: {scan.path} {why}: give the scan's own sensor")


def _azimuth_line(azimuth: np.ndarray, column: np.ndarray, ring: np.ndarray, rings: int, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """A straight line in the column index through the returns' azimuths (unwrapped, trimmed), plus each ring's median offset.

    azimuth : (k,) deg of the returned firings; column, ring : (k,) their grid cells
    Returns ``(line (columns,) deg, offset (rings,) deg)``.
    """
    # per-column circular mean, unwrapped along the columns, gives the line's first guess
    s = np.bincount(column, np.sin(np.radians(azimuth)), columns)
    c = np.bincount(column, np.cos(np.radians(azimuth)), columns)
    seen = np.flatnonzero((s != 0) | (c != 0))
    mean = np.degrees(np.unwrap(np.arctan2(s[seen], c[seen])))
    coef = np.polyfit(seen, mean, 1)[::-1] if len(seen) > 1 else np.array([mean[0] if len(seen) else 0.0, 0.0])
    keep = np.ones(len(azimuth), bool)
    for _ in range(4):
        unwrapped = coef[0] + coef[1] * column + _wrap(azimuth - (coef[0] + coef[1] * column))
        design = np.column_stack([np.ones(keep.sum()), column[keep]])
        coef, *_ = np.linalg.lstsq(design, unwrapped[keep], rcond=None)
        residual = unwrapped - (coef[0] + coef[1] * column)
        keep = np.abs(residual) < max(5.0 * np.median(np.abs(residual)), 1e-4)
    offset = np.zeros(rings)
    for r in range(rings):
        mine = keep & (ring == r)
        if mine.any():
            offset[r] = np.median(residual[mine])
    return coef[0] + coef[1] * np.arange(columns), offset


def _ring_elevations(elevation: np.ndarray, ring: np.ndarray, rings: int, fallback: np.ndarray | None) -> np.ndarray:
    table = np.full(rings, np.nan)
    for r in range(rings):
        mine = ring == r
        if mine.any():
            table[r] = np.median(elevation[mine])
    missing = np.isnan(table)
    if missing.any():
        if fallback is not None and len(fallback) == rings:
            table[missing] = fallback[missing]
        elif (~missing).sum() >= 2:
            table[missing] = np.interp(np.flatnonzero(missing), np.flatnonzero(~missing), table[~missing])
        else:
            table[missing] = 0.0
    return table


def organised_firings(scan: RealScan, preset: str | None = None) -> Firings:
    """The firings of a scan that lists every firing (column after column, rings 0..r-1)."""
    rings = scan.rings
    columns = len(scan) // rings
    spec = _spec(preset)
    grid = scan.points.reshape(columns, rings, 3).transpose(1, 0, 2)  # (rings, columns, 3)
    near = np.linalg.norm(grid, axis=2) < EMPTY_RADIUS
    position, empty = sensor_track(grid, near)
    rel = grid - position[None]
    rng_ = np.linalg.norm(rel, axis=2)
    valid = ~empty & (rng_ > 1e-6)
    ring = np.broadcast_to(np.arange(rings)[:, None], (rings, columns))
    column = np.broadcast_to(np.arange(columns)[None, :], (rings, columns))
    direction = np.zeros_like(rel)
    direction[valid] = rel[valid] / rng_[valid, None]
    az, el = angles_deg(direction[valid])
    if spec is not None:
        check_preset_fits(scan, spec, el, ring[valid], rings)
    fallback = None if spec is None or not spec.elevations_deg else np.asarray(spec.elevations_deg, float)
    elevation = _ring_elevations(el, ring[valid], rings, fallback)
    line, offset = _azimuth_line(az, column[valid], ring[valid], rings, columns)
    model = spherical(line[None, :] + offset[:, None], np.broadcast_to(elevation[:, None], (rings, columns)))
    residual = math.degrees(float(np.median(angle_between(model[valid], direction[valid])))) if valid.any() else 0.0
    direction[~valid] = model[~valid]
    period = (1.0 / spec.rotation_hz) if spec is not None else 0.05
    time = np.broadcast_to(np.arange(columns)[None, :] * (period / columns), (rings, columns))
    order = lambda a: np.ascontiguousarray(np.swapaxes(a, 0, 1).reshape((rings * columns,) + a.shape[2:]))  # noqa: E731 - firing order
    index = np.arange(rings * columns).reshape(columns, rings).T
    return Firings(
        order(np.broadcast_to(position[None], (rings, columns, 3))), order(direction), order(np.where(valid, rng_, 0.0)), order(valid),
        order(scan.intensity.reshape(columns, rings).T), order(ring).astype(np.int64), order(column).astype(np.int64), order(time),
        order(index).astype(np.int64), (rings, columns), elevation, _wrap(line), residual, [],
    )


SCAN_ORDER_MAX_STEP_DEG = 1.0  # a scan order steps this little in azimuth between most consecutive returns
SCAN_ORDER_MAX_RINGS = 256  # more "rings" than this (twice the densest spinning LiDARs' 128) is no scan order


def _scan_order_rings(azimuth: np.ndarray) -> np.ndarray | None:
    """Ring index of each return from the scan order: a new ring where the azimuth wraps around; ``None`` when the
    order shows no rings: no wrap, a median step between consecutive returns above :data:`SCAN_ORDER_MAX_STEP_DEG`,
    or more than :data:`SCAN_ORDER_MAX_RINGS` wraps (returns sorted or shuffled otherwise, as some published
    SemanticKITTI samples are: read in scan order they gave thousands of one-point "rings")."""
    if len(azimuth) < 3:
        return None
    d = _wrap(np.diff(azimuth))
    if np.median(np.abs(d)) > SCAN_ORDER_MAX_STEP_DEG:
        return None
    sense = 1.0 if np.median(d) >= 0 else -1.0
    turned = (sense * azimuth) % 360.0
    wraps = np.flatnonzero(np.diff(turned) < -180.0)
    if len(wraps) == 0 or len(wraps) >= SCAN_ORDER_MAX_RINGS:
        return None
    ring = np.zeros(len(azimuth), np.int64)
    ring[wraps + 1] = 1
    return np.cumsum(ring)


FIRING_ORDER_SHARE = 0.9  # a ring's returns are in firing order when this share of its steps goes forward, by under 10 lattice steps


def _lattice_column(azimuth: np.ndarray, phase: float, step: float, columns: int) -> np.ndarray:
    """``(n,)`` int64 column of the azimuth lattice (``phase + step k`` deg, ``columns`` a turn) nearest each azimuth (deg)."""
    return np.round((np.asarray(azimuth) - phase) / step).astype(np.int64) % columns


SPAN_HOLE_COLUMNS = 6  # lattice columns no ring returned in, between columns some ring did, that are still the scan's span


def _azimuth_span(column: np.ndarray, columns: int) -> np.ndarray:
    """(columns,) bool: the scan's azimuth span, the columns some return lies in (a front-camera crop keeps part of the
    circle) with holes of up to :data:`SPAN_HOLE_COLUMNS` closed (a lattice finer than the sensor's step leaves columns
    no ring's return falls in; a morphological closing on the circle)."""
    seen = np.zeros(columns, bool)
    seen[column] = True
    k = SPAN_HOLE_COLUMNS // 2
    grown = np.any([np.roll(seen, j) for j in range(-k, k + 1)], axis=0)
    return np.all([np.roll(grown, j) for j in range(-k, k + 1)], axis=0)


def _firing_order(azimuth: np.ndarray, ring: np.ndarray, step: float) -> float | None:
    """The sense (+1 or -1) in which each ring's returns advance in azimuth, when the scan lists them in firing order
    (:data:`FIRING_ORDER_SHARE` of the steps between a ring's consecutive returns go forward by less than 10 lattice
    steps); ``None`` when it does not (returns sorted or shuffled otherwise)."""
    same = np.diff(ring) == 0
    d = _wrap(np.diff(azimuth))[same]
    if len(d) < 2:
        return None
    sense = 1.0 if np.median(d) >= 0 else -1.0
    forward = (sense * d > -0.5 * step) & (sense * d < 10.0 * step)
    return sense if forward.mean() >= FIRING_ORDER_SHARE else None


def _gaps_in_firing_order(azimuth: np.ndarray, ring: np.ndarray, rings: int, step: float, sense: float, phase: float,
                          span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The empty firings of a scan whose rings list their returns in firing order: ``(ring (g,), azimuth (g,) deg)``.

    Between two consecutive returns of a ring that lie ``d`` apart (in the sense ``sense``; a step back counts as
    none; the last return is followed by the first) lie ``round(d / step) - 1`` empty firings, spaced evenly: the
    real firings' own spacing, which a fixed lattice does not follow (KITTI's HDL-64E steps about 0.18 deg six times,
    then 0.09, where the 0.17 deg lattice put two returns in one cell and made up an empty cell beside them every few
    firings). A gap that leaves the scan's azimuth span (``span``, (columns,) bool of the lattice of phase ``phase``
    and step ``step``: :func:`_azimuth_span`) is where a crop cut the ring (a front-camera crop keeps part of the
    circle, and its lower corners part of the lowest rings): no firings there.
    """
    columns = len(span)
    rings_out, azimuths = [], []
    for r in range(rings):
        a = sense * azimuth[ring == r]
        if len(a) < 2:
            continue
        d = np.diff(np.append(a, a[0])) % 360.0
        d[d > 360.0 - 10.0 * step] = 0.0  # a step back (the returns' jitter): no firing between
        missing = np.maximum(np.round(d / step) - 1, 0).astype(np.int64)
        after = np.repeat(np.arange(len(d)), missing)  # the return each empty firing follows
        k = np.arange(len(after)) - np.repeat(np.cumsum(missing) - missing, missing) + 1  # 1 .. its gap's count
        between = _wrap(sense * (a[after] + d[after] * k / (missing[after] + 1)))
        cut = np.zeros(len(d), bool)
        cut[after[~span[_lattice_column(between, phase, step, columns)]]] = True
        between = between[~cut[after]]
        rings_out.append(np.full(len(between), r))
        azimuths.append(between)
    if not rings_out:
        return np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(rings_out).astype(np.int64), np.concatenate(azimuths)


def unorganised_firings(scan: RealScan, preset: str | None = None, step_deg: float | None = None) -> Firings:
    """The firings of a scan of returns only: rings from the ring field, the scan order or the preset's elevations;
    columns on an azimuth lattice; empty firings counted between a ring's returns where they are in firing order
    (:func:`_gaps_in_firing_order`), else the lattice's gaps within the scan's azimuth span."""
    spec = _spec(preset)
    points = scan.points
    distance = np.linalg.norm(points, axis=1)
    keep = distance > 1e-6
    if not keep.all():
        raise InputError(f"{scan.path}: {int((~keep).sum())} points at the sensor's origin in a scan of returns only; give scene.format for an organised file")
    direction = points / distance[:, None]
    az, el = angles_deg(direction)
    approximate = []
    if scan.ring is not None:
        ring = scan.ring.astype(np.int64)
    else:
        ring = _scan_order_rings(az)
        if ring is not None:
            approximate.append("rings rebuilt from the scan order (a new ring where the azimuth wraps)")
        elif spec is not None and len(preset_elevations(spec)):
            table = preset_elevations(spec)
            ring = np.abs(el[:, None] - table[None]).argmin(axis=1)
            approximate.append(f"rings from the nearest elevation of preset {spec.name}")
        else:
            raise InputError(f"{scan.path}: no ring field and the scan order shows no rings; give scene.preset (a sensor preset such as hdl64e)")
    rings = int(ring.max()) + 1
    if spec is not None:
        check_preset_fits(scan, spec, el, ring, rings, nearest=scan.ring is None and any("nearest elevation" in note for note in approximate))
        from ..lidar.sensor.sensors import azimuth_step

        step = azimuth_step(spec)
        period = 1.0 / spec.rotation_hz
    else:
        same = np.diff(ring) == 0
        gaps = np.abs(_wrap(np.diff(az)))[same]
        step = float(np.median(gaps[gaps > 1e-4])) if (gaps > 1e-4).any() else 0.2
        period = 0.1
    step = step_deg or step
    approximate.append(f"columns on an azimuth lattice of {step:.4f} deg")
    columns = int(round(360.0 / step))
    phase = math.degrees(math.atan2(np.sin(np.radians(az / step * 360.0)).mean(), np.cos(np.radians(az / step * 360.0)).mean())) / 360.0 * step
    column = _lattice_column(az, phase, step, columns)
    elevation = _ring_elevations(el, ring, rings, None if spec is None or len(spec.elevations_deg) != rings else np.asarray(spec.elevations_deg, float))
    line = _wrap(phase + step * np.arange(columns))
    sense = _firing_order(az, ring, step)
    if sense is not None:
        gap_ring, gap_azimuth = _gaps_in_firing_order(az, ring, rings, step, sense, phase, _azimuth_span(column, columns))
        gap_column = _lattice_column(gap_azimuth, phase, step, columns)
        approximate.append("empty firings counted between each ring's consecutive returns (its firing order)")
    else:  # every cell of a ring's lattice in the scan's span (the columns some ring returned in) without a return
        seen, have = np.zeros(columns, bool), np.zeros((rings, columns), bool)
        seen[column], have[ring, column] = True, True
        gap_ring, gap_column = np.nonzero((np.bincount(ring, minlength=rings) > 0)[:, None] & seen[None, :] & ~have)
        gap_azimuth = line[gap_column]
        approximate.append("empty firings from the lattice's gaps")
    gap_direction = spherical(gap_azimuth, elevation[gap_ring])
    n, g = len(points), len(gap_ring)
    model = spherical(line[column], elevation[ring])
    residual = math.degrees(float(np.median(angle_between(model, direction))))
    spin = -1.0 if spec is None or spec.spin == "cw" else 1.0
    time_of = lambda c: ((spin * (np.asarray(c) - column.min())) % columns) * (period / columns)  # noqa: E731
    firing = Firings(
        np.zeros((n + g, 3)), np.concatenate([direction, gap_direction]), np.concatenate([distance, np.zeros(g)]),
        np.concatenate([np.ones(n, bool), np.zeros(g, bool)]), np.concatenate([scan.intensity, np.zeros(g)]),
        np.concatenate([ring, gap_ring]).astype(np.int64), np.concatenate([column, gap_column]).astype(np.int64),
        np.concatenate([time_of(column), time_of(gap_column)]), np.concatenate([np.arange(n), np.full(g, -1)]).astype(np.int64),
        (rings, columns), elevation, line, residual, approximate + ["empty firings carry no intensity; the sensor is taken as still (no ego-motion line)"],
    )
    return firing


def recover_firings(scan: RealScan, preset: str | None = None) -> Firings:
    """Every firing of ``scan`` (module notes); ``preset`` fills what the file lacks."""
    if scan.organised and scan.rings:
        return organised_firings(scan, preset)
    return unorganised_firings(scan, preset)
