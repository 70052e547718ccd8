"""Moving platforms: a sensor carried along a path, as sensor-to-world poses over time. Pure numpy.

A :class:`Trajectory` is a polyline of world points (waypoints from the config, or a curve of
the scene read by ``blender.curves``) and a clock: either a constant ``speed`` (m/s) or one
time per waypoint (s; the platform moves at constant speed between two waypoints and may
dwell at a repeated one). Positions interpolate linearly in arc length along the polyline.

The sensor's x axis follows the path's heading (yaw of the tangent, seen from above) when
``heading`` is on; the yaw is the direction of each segment at its midpoint, interpolated
linearly in arc length between midpoints, so a polyline sampled from a smooth curve turns
smoothly instead of in steps (for a uniformly sampled circle this is its exact tangent), and a
straight path keeps a constant heading. The configured ``rotation_deg`` (roll, pitch, yaw) turns
the sensor relative to that heading frame (relative to the world without heading), and
``offset`` (m, world) lifts the optical centre above the path (a height and a mount).

The clock: ``poses(t)`` takes seconds on the *frame clock*, 0 at the start of frame 0, which
lies ``start_time`` seconds after the path's start (and, with a constant speed, a further
``start_distance`` metres along it). Frame ``k`` of a sensor whose frames last ``T`` seconds
starts at ``t = k * T`` (:meth:`Trajectory.frame_poses`).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ...errors import InputError
from ...geometry.transforms import euler_xyz_matrix

PoseFunction = Callable[[np.ndarray], np.ndarray]  # (n,) s -> (n, 4, 4) sensor-to-world
TIME_SLACK = 1e-9  # s: times this far outside the path still count as on it (float rounding)


class Trajectory:
    """A sensor moving along a polyline.

    points : (k, 3) float64 world positions of the path, metres (k >= 2)
    speed : m/s along the path (> 0), or ``None`` when ``times`` is given
    times : (k,) float64 seconds at each point, strictly increasing, or ``None`` with ``speed``
    heading : the sensor's x axis follows the path's yaw (else the world's axes)
    rotation_deg : (3,) roll, pitch, yaw of the sensor relative to the heading frame, degrees
    offset : (3,) world offset of the optical centre from the path, metres
    start_distance : m along the path where the frame clock starts (``speed`` only)
    start_time : s after the path's start where the frame clock starts
    where : config key named in error messages
    """

    def __init__(
        self,
        points,
        speed: float | None = None,
        times=None,
        heading: bool = True,
        rotation_deg=(0.0, 0.0, 0.0),
        offset=(0.0, 0.0, 0.0),
        start_distance: float = 0.0,
        start_time: float = 0.0,
        where: str = "sensor.trajectory",
    ):
        self.where = where
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"{where}: expected a list of [x, y, z] points, got an array of shape {points.shape}")
        if len(points) < 2:
            raise InputError(f"{where}: a path needs at least 2 points, got {len(points)}")
        if not np.isfinite(points).all():
            raise InputError(f"{where}: point {int(np.argmin(np.isfinite(points).all(axis=1)))} is not finite")
        step = np.linalg.norm(np.diff(points, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(step)])  # (k,) arc length at each given point
        self.length = float(arc[-1])
        if not self.length > 0:
            raise InputError(f"{where}: the path has zero length (all its points coincide)")
        moves = np.concatenate([[True], step > 0])  # drop repeated points from the geometry
        self.vertices, self.arc = points[moves], arc[moves]  # (v, 3), (v,) strictly increasing arc
        if (speed is None) == (times is None):
            raise InputError(f"{where}: give either a speed (m/s) or one time per point (s)")
        if times is not None:
            times = np.asarray(times, np.float64)
            if times.shape != (len(points),):
                raise InputError(f"{where}.times: {times.size} times for {len(points)} points; give one per point")
            if not np.isfinite(times).all() or not (np.diff(times) > 0).all():
                raise InputError(f"{where}.times: must be finite and increase strictly, got {times.tolist()}")
            if start_distance:
                raise InputError(f"{where}.start_distance: only with a speed; with times, start later by start_time")
            self.clock_times, self.clock_arc = times - times[0], arc  # path seconds -> arc length
            self.speed = None
        else:
            if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
                raise InputError(f"{where}.speed: must be > 0 m/s, got {speed}")
            if not 0 <= start_distance < self.length:
                raise InputError(f"{where}.start_distance: must lie in [0, {self.length:.6g}) m (the path's length), got {start_distance}")
            self.speed = float(speed)
            self.clock_times = np.array([0.0, (self.length - start_distance) / self.speed])
            self.clock_arc = np.array([start_distance, self.length])
        if not 0 <= start_time < self.clock_times[-1]:
            raise InputError(f"{where}.start_time: must lie in [0, {self.clock_times[-1]:.6g}) s (the time the path lasts), got {start_time}")
        self.start_time = float(start_time)
        self.duration = float(self.clock_times[-1] - start_time)  # s of frame clock until the path ends
        self.heading = bool(heading)
        self.rotation = euler_xyz_matrix(rotation_deg)
        self.offset = np.asarray(offset, np.float64).reshape(3)
        direction = np.diff(self.vertices, axis=0)
        horizontal = np.hypot(direction[:, 0], direction[:, 1]) > 1e-12 * (1.0 + np.abs(self.vertices).max())
        yaw = np.arctan2(direction[:, 1], direction[:, 0])
        if horizontal.any():  # vertical segments keep the yaw of the nearest segment before them (or after)
            carry = np.maximum.accumulate(np.where(horizontal, np.arange(len(horizontal)), -1))
            carry = np.where(carry < 0, np.argmax(horizontal), carry)
            yaw = yaw[carry]
        else:
            yaw = np.zeros(len(direction))
        self.knot_arc = (self.arc[:-1] + self.arc[1:]) / 2  # (v - 1,) segment midpoints
        self.knot_yaw = np.unwrap(yaw)  # (v - 1,) radians

    # ------------------------------------------------------------------ clock and geometry
    def distance(self, t) -> np.ndarray:
        """``(n,)`` float64 arc length (m from the path's first point) at frame-clock times ``t`` (n,) s.

        ``InputError`` naming the trajectory when a time lies before its start or after its end.
        """
        clock = np.asarray(t, np.float64) + self.start_time
        low, high = self.clock_times[0], self.clock_times[-1]
        if clock.size and (clock.min() < low - TIME_SLACK or clock.max() > high + TIME_SLACK):
            bad = clock.max() if clock.max() > high + TIME_SLACK else clock.min()
            raise InputError(
                f"{self.where}: time {bad - self.start_time:.6g} s lies outside the path, which lasts "
                f"{self.duration:.6g} s ({self.length:.6g} m) from the start; use fewer frames, a lower speed or a longer path"
            )
        return np.interp(clock, self.clock_times, self.clock_arc)

    def positions(self, s) -> np.ndarray:
        """``(n, 3)`` float64 world points of the path (without ``offset``) at arc lengths ``s`` (n,) m."""
        s = np.asarray(s, np.float64)
        segment = np.clip(np.searchsorted(self.arc, s, side="right") - 1, 0, len(self.arc) - 2)
        start, end = self.arc[segment], self.arc[segment + 1]
        frac = ((s - start) / (end - start))[:, None]
        return self.vertices[segment] * (1.0 - frac) + self.vertices[segment + 1] * frac

    def yaw(self, s) -> np.ndarray:
        """``(n,)`` float64 heading in radians at arc lengths ``s`` (0 without ``heading``)."""
        if not self.heading:
            return np.zeros(np.shape(s))
        return np.interp(s, self.knot_arc, self.knot_yaw)

    def poses(self, t) -> np.ndarray:
        """``(n, 4, 4)`` float64 sensor-to-world transforms at frame-clock times ``t`` (n,) seconds."""
        s = self.distance(t)
        yaw = self.yaw(s)
        c, si = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        out = np.zeros((len(s), 4, 4))
        m = self.rotation
        out[:, 0, :3] = c * m[0] - si * m[1]  # Rz(yaw) @ rotation, row by row
        out[:, 1, :3] = si * m[0] + c * m[1]
        out[:, 2, :3] = m[2]
        out[:, :3, 3] = self.positions(s) + self.offset
        out[:, 3, 3] = 1.0
        return out

    def frame_poses(self, frame: int, frame_time: float) -> PoseFunction:
        """The pose function of frame ``frame`` (times from that frame's start), frames lasting ``frame_time`` s."""
        start = frame * frame_time
        return lambda t: self.poses(np.asarray(t, np.float64) + start)

    def check_frames(self, frames: int, frame_time: float, key: str = "frames") -> None:
        """``InputError`` naming ``key`` when ``frames`` frames of ``frame_time`` s run past the path's end."""
        need = frames * frame_time
        if need > self.duration + TIME_SLACK:
            raise InputError(
                f"{key}: {frames} frame(s) of {frame_time:.6g} s need {need:.6g} s of path, but {self.where} lasts "
                f"{self.duration:.6g} s ({self.length:.6g} m) from its start; use fewer frames, a lower speed or a longer path"
            )

    def frame_info(self, frame: int, frame_time: float) -> dict:
        """Where frame ``frame`` runs along the path, as plain JSON-ready data for the manifest."""
        t0, t1 = frame * frame_time, (frame + 1) * frame_time
        s0, s1 = self.distance([t0, min(t1, self.duration)])
        return {
            "start_time_s": t0,
            "end_time_s": t1,
            "distance_m": [float(s0), float(s1)],
            "speed_m_s": self.speed if self.speed is not None else float((s1 - s0) / frame_time),
            "end_pose": self.poses([min(t1, self.duration)])[0].tolist(),
        }

    def reach(self, frame: int, frame_time: float) -> float:
        """Metres the optical centre gets from its frame-start position during frame ``frame``."""
        t0, t1 = frame * frame_time, min((frame + 1) * frame_time, self.duration)
        s0, s1 = self.distance([t0, t1])
        inside = self.arc[(self.arc > s0) & (self.arc < s1)]
        path = self.positions(np.concatenate([[s0, s1], inside]))
        return float(np.linalg.norm(path - path[0], axis=1).max())
