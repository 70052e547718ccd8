"""What a sensor sees, for placement: its field of view and range, and the share of a box's sample points inside it. Pure numpy.

Shared by the street builder's field-of-view aware placement (:mod:`bpy_pipeline.builders.street.layout`)
and the sensor rig (:mod:`bpy_pipeline.rig`, a field of view per member).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class FieldOfView:
    """What one sensor sees: its pose (4, 4) sensor-to-world, azimuth and elevation limits (deg, sensor frame), range (m)."""

    pose: np.ndarray
    azimuth: tuple[float, float]
    elevation: tuple[float, float]
    min_range: float
    max_range: float

    def contains(self, points) -> np.ndarray:
        """``(n,)`` bool: which world ``points`` (n, 3) lie inside the field of view and range.

        The numbers of ``np.linalg.norm(local, axis=1)`` and ``np.clip(..., -1, 1)``, without their dispatch (a street
        frame asks this of every road user placed)."""
        local = (np.asarray(points, float) - self.pose[:3, 3]) @ self.pose[:3, :3]
        r = np.sqrt(np.add.reduce(local * local, axis=1))
        sine = np.minimum(np.maximum(local[:, 2] / np.maximum(r, 1e-12), -1.0), 1.0)
        el = np.degrees(np.arcsin(sine))
        inside = (el >= self.elevation[0]) & (el <= self.elevation[1]) & (r >= self.min_range) & (r <= self.max_range)
        if self.azimuth[1] - self.azimuth[0] >= 360.0:  # all round: every azimuth
            return inside
        az = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
        return inside & (az >= self.azimuth[0]) & (az <= self.azimuth[1])


@lru_cache(maxsize=8)
def _grid(per_axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sample grid's steps ``u`` (per_axis,) from -0.9 to 0.9 and, per grid point in ``meshgrid(..., indexing="ij")``'s
    raveled order, the index of its x, y and z step (``(per_axis^3,)`` each); read only."""
    u = np.linspace(-0.9, 0.9, per_axis)
    ix, iy, iz = (g.ravel() for g in np.meshgrid(*(np.arange(per_axis),) * 3, indexing="ij"))
    for a in (u, ix, iy, iz):
        a.flags.writeable = False
    return u, ix, iy, iz


def box_samples(centre_xy, half, yaw: float, height: float, z: float = 0.0, per_axis: int = 3) -> np.ndarray:
    """``(per_axis^3, 3)`` points on a grid through an upright box (the sample a field-of-view test counts)."""
    u, ix, iy, iz = _grid(per_axis)
    x, y = (u * half[0])[ix], (u * half[1])[iy]
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty((len(ix), 3))
    out[:, 0] = centre_xy[0] + c * x - s * y
    out[:, 1] = centre_xy[1] + s * x + c * y
    out[:, 2] = ((u + 1) / 2 * height + z)[iz]
    return out


def in_view_fraction(views, centre_xy, half, yaw, height, z=0.0) -> float:
    """The largest share of a box's sample points that one of ``views`` sees (1 when ``views`` is empty)."""
    if not views:
        return 1.0
    samples = box_samples(centre_xy, half, yaw, height, z)
    return max(float(v.contains(samples).mean()) for v in views)
