"""Level of detail that follows the sensor: model no finer than the beams can tell apart. Pure numpy.

A :class:`SensorView` holds where a scene will be scanned from (one or more optical centres)
and how far apart neighbouring beams are (radians). At distance d two beams are d * step
apart; a modelled shape whose error stays under half that spacing cannot be told from the
true one by the scan, and a feature narrower than two beam spacings cannot be resolved
(sampled at least twice across). Builders use it to pick curve sampling, mesh resolution,
which small features to model at all, and what lies beyond the sensor's range.

A moving sensor's scene serves every frame of its run, so its :class:`PathView` holds the optical
centre's whole path (a polyline) and grades by the distance to its nearest point; a
:class:`PlannedPath` stands for it until the builder knows the curve the path follows.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

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

    def distinct(self) -> "SensorView":
        """This view with each optical centre once, in first-seen order (frames that revisit a station share it)."""
        _, first = np.unique(np.round(np.asarray(self.positions, float), 6), axis=0, return_index=True)
        if len(first) == len(self.positions):
            return self
        return dataclasses.replace(self, positions=np.asarray(self.positions)[np.sort(first)])

    def following(self, curves: dict) -> "SensorView":
        """The view once the scene's curves ({name: (k, 3) polyline}) are known: a static view needs none."""
        return self


def view_from_steps(azimuth_deg: float | None, elevation_deg: float | None, max_range: float, positions) -> SensorView:
    """The :class:`SensorView` of a sensor whose neighbouring beams are ``azimuth_deg`` and ``elevation_deg``
    apart (degrees; ``None`` or not finite: no such spacing) reaching ``max_range`` (m), at ``positions`` ((k, 3), m).
    The coarser of the two steps counts; a sensor with neither is assumed fine (:data:`FINEST_STEP_DEG`).
    :func:`bpy_pipeline.lidar.sensor.view.view_of` gives it for a sensor spec."""
    steps = [s for s in (azimuth_deg, elevation_deg) if s is not None and math.isfinite(s) and s > 0]
    step = math.radians(max(steps) if steps else FINEST_STEP_DEG)
    positions = np.asarray(positions, float).reshape(-1, 3)
    return SensorView(positions, step, float(max_range))


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


def _segment_pair_distance(a, b, p, q) -> np.ndarray:
    """``(n, m)`` distance (m) between segments ``a[i]``-``b[i]`` ((n, 3) each) and ``p[j]``-``q[j]`` ((m, 3) each).

    The closest points of two segments (Ericson, *Real-Time Collision Detection* 5.1.9): the
    unclamped closest pair, clamped to the first segment, the second's parameter recomputed and
    clamped, the first's recomputed against it; point-like segments fall out of the same formulas.
    """
    d1, d2 = (b - a)[:, None, :], (q - p)[None]  # (n, 1, 3), (1, m, 3)
    r = a[:, None, :] - p[None]  # (n, m, 3)
    a2, e2 = (d1**2).sum(-1), (d2**2).sum(-1)  # (n, 1), (1, m)
    f, c, cross = (d2 * r).sum(-1), (d1 * r).sum(-1), (d1 * d2).sum(-1)  # (n, m) each
    tiny = 1e-18
    denom = a2 * e2 - cross**2
    s = np.where(denom > tiny * np.maximum(a2 * e2, tiny), np.clip((cross * f - c * e2) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    s = np.where(a2 > tiny, s, 0.0)
    t = np.where(e2 > tiny, (cross * s + f) / np.where(e2 > tiny, e2, 1.0), 0.0)
    safe_a2 = np.where(a2 > tiny, a2, 1.0)
    s = np.where(t < 0.0, np.where(a2 > tiny, np.clip(-c / safe_a2, 0.0, 1.0), 0.0),
                 np.where(t > 1.0, np.where(a2 > tiny, np.clip((cross - c) / safe_a2, 0.0, 1.0), 0.0), s))
    t = np.clip(t, 0.0, 1.0)
    point_like = (e2 <= tiny) & (a2 > tiny)  # the second segment is a point: the first's nearest point to it
    s = np.where(point_like, np.clip(-c / safe_a2, 0.0, 1.0), s)
    t = np.where(point_like, 0.0, t)
    gap = r + s[..., None] * d1 - t[..., None] * d2
    return np.sqrt((gap**2).sum(-1))


@dataclass(frozen=True)
class PathView(SensorView):
    """The view of a moving sensor: ``positions`` (k, 3) is the optical centre's path over every frame
    the scene serves, a polyline in the world (m); distances are to its nearest point, not to its vertices.

    motion_spacing : m the platform moves between two passes of one beam direction (its fastest speed
        / the sensor's rotation rate): along the path no two beams fall closer than this, whatever the
        distance, so a feature shorter than two of them is not resolved anywhere
    """

    motion_spacing: float = 0.0

    def _segments(self) -> tuple[np.ndarray, np.ndarray]:
        path = np.asarray(self.positions, float).reshape(-1, 3)
        if len(path) == 1:
            return path, path
        return path[:-1], path[1:]

    def distance(self, points) -> np.ndarray:
        """``(n,)`` distance (m) from each of ``points`` (n, 3) to the nearest point of the path."""
        points = np.asarray(points, float).reshape(-1, 3)
        return self.segment_distance(points, points)

    def segment_distance(self, a, b) -> np.ndarray:
        """``(n,)`` distance (m) between each segment ``a[i]``-``b[i]`` ((n, 3) each) and the path."""
        a = np.asarray(a, float).reshape(-1, 3)
        b = np.asarray(b, float).reshape(-1, 3)
        p, q = self._segments()
        out = np.empty(len(a))
        rows = max(1, 2_000_000 // max(1, len(p)))  # bound the (n, m, 3) temporaries
        for start in range(0, len(a), rows):
            out[start:start + rows] = _segment_pair_distance(a[start:start + rows], b[start:start + rows], p, q).min(axis=1)
        return out

    def resolve_radius(self, feature: float) -> float:
        """Distance (m) from the path within which a feature of size ``feature`` (m) spans two beam spacings
        across the path and two passes along it (0 when the platform moves too fast for that anywhere)."""
        if feature < 2.0 * self.motion_spacing:
            return 0.0
        return feature / (2.0 * self.step)

    def samples(self, spacing: float) -> np.ndarray:
        """``(s, 3)`` points along the path at most ``spacing`` m apart, its vertices included, in path order."""
        path = np.asarray(self.positions, float).reshape(-1, 3)
        out = [path[:1]]
        for a, b in zip(path[:-1], path[1:]):
            pieces = max(1, int(math.ceil(np.linalg.norm(b - a) / spacing)))
            out.append(a + (b - a) * (np.arange(1, pieces + 1) / pieces)[:, None])
        return np.concatenate(out)

    def distinct(self) -> "PathView":
        """The path as it is: a polyline keeps its order and any point it passes twice."""
        return self

    def following(self, curves: dict) -> "PathView":
        return self


def path_positions(trajectory, duration: float) -> np.ndarray:
    """``(k, 3)`` polyline of the optical centre of ``trajectory`` (a :class:`~bpy_pipeline.lidar.sensor.platform.Trajectory`)
    over frame-clock seconds 0 .. ``duration``: its position at both ends and every vertex between (exact: the
    platform moves straight between vertices and its offset is fixed in the world)."""
    s0, s1 = trajectory.distance([0.0, duration])
    inside = trajectory.arc[(trajectory.arc > s0) & (trajectory.arc < s1)]
    return trajectory.positions(np.concatenate([[s0], inside, [s1]])) + trajectory.offset


def fastest_speed(trajectory) -> float:
    """m/s: the platform's constant speed, or the fastest leg of a timed path."""
    if trajectory.speed is not None:
        return float(trajectory.speed)
    return float((np.diff(trajectory.clock_arc) / np.diff(trajectory.clock_times)).max())


@dataclass(frozen=True)
class PlannedPath:
    """A moving sensor's view before its scene is built: the path may follow a curve of the scene
    (``sensor.trajectory.curve``) that only the builder knows until it is built.

    sensor : the config's ``sensor`` section (:class:`~bpy_pipeline.config.SensorConfig`, with a trajectory)
    frames : frames of the whole run (the scene serves them all: any frame range gets the same view)
    follow : ``follow(path (k, 3) world polyline or None) -> PathView``: the view along the path once the
        curve is known (``None``: the trajectory's own waypoints); made by the layer that knows the
        config (:func:`bpy_pipeline.stages.view.planned_path`), so this module needs none of it
    """

    sensor: object
    frames: int
    follow: Callable[[np.ndarray | None], PathView] | None = dataclasses.field(default=None, compare=False, repr=False)

    @property
    def curve(self) -> str:
        """The name of the curve the path follows, ``""`` for waypoints."""
        return self.sensor.trajectory.curve or ""

    def following(self, curves: dict) -> PathView | None:
        """The :class:`PathView` once ``curves`` ({name: (k, 3) world polyline}) of the scene are known;
        ``None`` (fixed detail) when the path follows a curve not among them."""
        if self.curve and self.curve not in curves:
            return None
        return self.follow(curves[self.curve] if self.curve else None)


def path_view(trajectory, frames: int, frame_time: float, step: float, max_range: float, rotation_hz: float) -> PathView:
    """The :class:`PathView` of ``trajectory`` (a :class:`~bpy_pipeline.lidar.sensor.platform.Trajectory`) over ``frames``
    frames of ``frame_time`` s, beams ``step`` rad apart, reaching ``max_range`` m, turning at ``rotation_hz``."""
    path = path_positions(trajectory, frames * frame_time)
    return PathView(np.asarray(path, float).reshape(-1, 3), step, float(max_range), fastest_speed(trajectory) / float(rotation_hz))
