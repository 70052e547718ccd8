"""Level of detail that follows the sensor: model no finer than the beams can tell apart. Pure numpy.

A :class:`SensorView` holds where a scene will be scanned from (one or more optical centres)
and how far apart neighbouring beams are (radians). At distance d two beams are d * step
apart; a modelled shape whose error stays under half that spacing cannot be told from the
true one by the scan, and a feature narrower than two beam spacings cannot be resolved
(sampled at least twice across). Builders use it to pick curve sampling, mesh resolution,
which small features to model at all, and what lies beyond the sensor's range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FINEST_STEP_DEG = 0.01  # for patterns without a regular step (rays from a file): assume a fine scanner


@dataclass(frozen=True)
class SensorView:
    """Where a scene is seen from and how finely.

    positions : (k, 3) float64 optical centres in the world, metres (k >= 1)
    step : float, radians between neighbouring beams (the coarser of the azimuth and elevation steps)
    max_range : float, metres
    """

    positions: np.ndarray
    step: float
    max_range: float

    def spacing(self, distance) -> np.ndarray:
        """Beam spacing (m) at ``distance`` (m, scalar or array)."""
        return np.asarray(distance, float) * self.step

    def tolerance(self, distance) -> np.ndarray:
        """Largest shape error (m) the scan cannot see at ``distance``: half the beam spacing."""
        return 0.5 * self.spacing(distance)

    def resolve_radius(self, feature: float) -> float:
        """Distance (m) within which a feature of size ``feature`` (m) spans two beam spacings."""
        return feature / (2.0 * self.step)

    def distance(self, points) -> np.ndarray:
        """``(n,)`` distance (m) from each of ``points`` (n, 3) to the nearest optical centre."""
        points = np.asarray(points, float).reshape(-1, 3)
        return np.sqrt(((points[:, None, :] - self.positions[None]) ** 2).sum(-1)).min(axis=1)

    def segment_distance(self, a, b) -> np.ndarray:
        """``(n,)`` distance (m) from the nearest optical centre to each segment ``a[i]``-``b[i]`` ((n, 3) each)."""
        a = np.asarray(a, float).reshape(-1, 3)
        b = np.asarray(b, float).reshape(-1, 3)
        ab = b - a
        length2 = np.maximum((ab**2).sum(-1), 1e-300)
        rel = self.positions[None] - a[:, None]  # (n, k, 3)
        t = np.clip((rel * ab[:, None]).sum(-1) / length2[:, None], 0.0, 1.0)
        nearest = a[:, None] + t[..., None] * ab[:, None]
        return np.sqrt(((nearest - self.positions[None]) ** 2).sum(-1)).min(axis=1)


def view_of(spec, positions) -> SensorView:
    """The :class:`SensorView` of a :class:`~bpy_pipeline.lidar.sensors.SensorSpec` at ``positions`` ((k, 3), m)."""
    from ..lidar.sensors import angular_resolution, elevations

    azimuth, elevation = angular_resolution(spec)
    if elevation is None:  # an uneven elevation table: its coarsest gap
        table = np.sort(elevations(spec))
        elevation = float(np.diff(table).max()) if len(table) > 1 else azimuth
    steps = [s for s in (azimuth, elevation) if s is not None and math.isfinite(s) and s > 0]
    step = math.radians(max(steps) if steps else FINEST_STEP_DEG)
    positions = np.asarray(positions, float).reshape(-1, 3)
    return SensorView(positions, step, float(spec.max_range))


def polygon_sides(radius: float, tolerance: float, minimum: int = 4) -> int:
    """Fewest sides (>= ``minimum``, even) of a polygon within ``tolerance`` (m) of a circle of ``radius`` (m).

    A regular n-gon inscribed in the circle misses it by r (1 - cos(pi / n)) at its edges' middles.
    """
    if tolerance >= radius:
        return minimum
    sides = math.ceil(math.pi / math.acos(1.0 - tolerance / radius))
    return max(minimum, sides + sides % 2)


def equal_perimeter_radius(radius: float, sides: int) -> float:
    """Circumradius (m) of the regular ``sides``-gon with the perimeter of a circle of ``radius`` (m).

    A convex section's width averaged over all directions is its perimeter / pi, so this polygon
    shows the beams the circle's mean width (its diameter): a thin wire keeps its hit rate
    (an inscribed square would lose 10 % of its returns, a hexagon 4.5 %).
    """
    return radius * math.pi / (sides * math.sin(math.pi / sides))


def section_error(radius: float, sides: int) -> float:
    """Largest distance (m) between a circle of ``radius`` and the equal-perimeter ``sides``-gon
    (:func:`equal_perimeter_radius`): at its corners (outside) or its edges' middles (inside)."""
    r = equal_perimeter_radius(radius, sides)
    return max(r - radius, radius - r * math.cos(math.pi / sides))
