"""``profile``: a 2D profile scanner (railway and road mobile mapping): one mirror turning in a plane.

The scanner sweeps its ``y``-``z`` plane (x is forward, along the track when mounted on a trolley or a
train roof with heading on: every profile cuts across the track), ``rotation_hz`` profiles per second.
A profile's angle runs from +y (0 deg) through +z (90 deg), -y (180 deg) and -z (270 deg) over
``horizontal_fov_deg`` (default the full circle) in steps of ``horizontal_resolution_deg /
sampling_factor``; each frame holds ``columns`` profiles (``1 / rotation_hz`` s each), so a frame lasts
``columns / rotation_hz`` s and the platform's motion spreads its profiles along the path. Rays come
profile by profile; ``ring`` is the profile's index in its frame; each ray fires at its own time.
Mounting the scanner turned (``sensor.rotation_deg``, e.g. a yaw of 30 deg) tilts the profiles against
the track, so faces square to the track (masts, droppers, registration arms) are cut obliquely.
"""

from __future__ import annotations

import math

import numpy as np

from ....errors import InputError
from .base import MAX_RINGS, RayPattern, register_pattern
from ..rays import Pattern


def angle_step(spec) -> float:
    """Degrees between neighbouring rays of a profile."""
    return spec.horizontal_resolution_deg / spec.sampling_factor


def _full_circle(spec) -> bool:
    lo, hi = spec.horizontal_fov_deg
    return math.isclose(hi - lo, 360.0)


def angles(spec) -> np.ndarray:
    """``(k,)`` profile angles (degrees) of one profile, in firing order."""
    lo, hi = spec.horizontal_fov_deg
    step = angle_step(spec)
    count = max(1, math.ceil(360.0 / step - 1e-6)) if _full_circle(spec) else math.floor((hi - lo) / step + 1e-6) + 1
    return lo + np.arange(count) * step


def profiles(spec) -> int:
    return max(spec.columns, 1)


def count(spec) -> int:
    if spec.horizontal_resolution_deg <= 0 or spec.sampling_factor <= 0:
        return 0
    return len(angles(spec)) * profiles(spec)


def check(spec, where: str) -> None:
    lo, hi = spec.horizontal_fov_deg
    if not lo < hi <= lo + 360:
        raise InputError(f"{where}.horizontal_fov_deg: the profile's angular window, expected [min, max] with min < max <= min + 360, got {[lo, hi]}")
    if not 0 < spec.horizontal_resolution_deg <= hi - lo:
        raise InputError(
            f"{where}.horizontal_resolution_deg: the angle between a profile's rays must lie in (0, {hi - lo}], got {spec.horizontal_resolution_deg}"
        )
    if spec.columns < 1:
        raise InputError(f"{where}.columns: profiles per frame, must be >= 1, got {spec.columns}")
    if spec.columns > MAX_RINGS:
        raise InputError(f"{where}.columns: {spec.columns} profiles per frame exceed the {MAX_RINGS} ring ids of uint16")


def frame_time(spec) -> float:
    """Seconds a frame lasts: its ``columns`` profiles."""
    return profiles(spec) / spec.rotation_hz


def rays(spec):
    """Profile-major rays: ray j of profile p fires at ``(p + j / k) / rotation_hz`` (k rays a profile)."""
    theta = np.radians(angles(spec))
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    k = len(theta)
    period = 1.0 / spec.rotation_hz

    def chunk(start: int, stop: int, frame: int):
        i = np.arange(start, stop)
        profile, j = np.divmod(i, k)
        directions = np.zeros((len(i), 3))
        directions[:, 1] = cos_t[j]
        directions[:, 2] = sin_t[j]
        return Pattern(directions, profile.astype(np.uint16), (profile + j / k) * period)

    return chunk


def resolution(spec) -> tuple[float, float | None]:
    """The in-profile step; no second axis (profiles are as far apart as the platform moves)."""
    return angle_step(spec), None


def density_key(spec) -> str:
    return "sampling_factor" if spec.sampling_factor != 1 else "horizontal_resolution_deg"


def extent(spec) -> tuple[np.ndarray, np.ndarray]:
    theta = np.radians(angles(spec))
    return np.degrees(np.arcsin(np.clip(np.sin(theta), -1, 1))), np.degrees(np.arctan2(np.cos(theta), 0.0))


PROFILE = RayPattern(rays, count, resolution, check, density_key, angle_step, lambda spec: None, frame_time=frame_time, rings=profiles, extent=extent)
register_pattern("profile", PROFILE)
