"""Where the sensors of a run will be, so that builders keep every solid clear of them. Pure numpy.

A :class:`SensorPoses` holds the optical centres of every sensor pose of a run (every frame's
station or position, every rig member, a moving sensor's path sampled at most ``step`` apart) and
the ``radius`` no placed solid may reach into. A solid is an upright box (a footprint rectangle and a
height range), a vertical cylinder (a circle and a height range) or capsules (a body's limbs);
:meth:`SensorPoses.clear_of_box`, :meth:`~SensorPoses.clear_of_circle` and :meth:`~SensorPoses.clear_of_capsules`
answer whether it keeps the radius from every pose. Between two path samples the sensor lies within
``step / 2`` of one of them, so the answers ask for ``radius + step / 2``: a solid they accept keeps
``radius`` from the whole path.

:func:`enclosing_instance` tells, after a scan, whether the sensor stood enclosed by one object anyway
(a pose or a shape the user placed): the scan stage warns about such a frame.

Coordinates: metres, world frame, z up; yaw in radians about +z.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

CLEARANCE = 0.5  # m: no placed solid comes closer to a sensor's optical centre
PATH_STEP = 0.1  # m: a moving sensor's path is sampled at most this far apart


@dataclass(frozen=True, eq=False)
class SensorPoses:
    """The optical centres every sensor of a run takes.

    points : (n, 3) float64 world m (n >= 0)
    radius : m kept free around each of them
    step : m, the largest gap between neighbouring samples of a path (0: only fixed poses)
    """

    points: np.ndarray
    radius: float = CLEARANCE
    step: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "points", np.asarray(self.points, float).reshape(-1, 3))

    def __eq__(self, other) -> bool:
        return isinstance(other, SensorPoses) and (self.radius, self.step) == (other.radius, other.step) and np.array_equal(self.points, other.points)

    __hash__ = None

    @property
    def reach(self) -> float:
        """m: the distance a solid must keep from every sample (``radius`` plus half the path's ``step``)."""
        return self.radius + self.step / 2.0

    def box_distance(self, centre, half, yaw: float = 0.0, z0: float = -math.inf, z1: float = math.inf) -> float:
        """m: the smallest distance from a pose to the upright box over the rectangle ``centre`` (2,), ``half`` (2,),
        turned by ``yaw``, from height ``z0`` to ``z1`` (0 when a pose lies inside; ``inf`` without poses)."""
        if not len(self.points):
            return math.inf
        c, s = math.cos(yaw), math.sin(yaw)
        d = self.points[:, :2] - np.asarray(centre, float)[:2]
        along = np.abs(d[:, 0] * c + d[:, 1] * s) - float(half[0])
        across = np.abs(d[:, 1] * c - d[:, 0] * s) - float(half[1])
        z = self.points[:, 2]
        up = np.maximum(np.maximum(z0 - z, z - z1), 0.0)
        return float(np.sqrt(np.maximum(along, 0.0) ** 2 + np.maximum(across, 0.0) ** 2 + up**2).min())

    def circle_distance(self, centre, radius: float, z0: float = -math.inf, z1: float = math.inf) -> float:
        """m: the smallest distance from a pose to the vertical cylinder of ``radius`` about ``centre`` (2,) from ``z0`` to ``z1``."""
        if not len(self.points):
            return math.inf
        flat = np.maximum(np.hypot(*(self.points[:, :2] - np.asarray(centre, float)[:2]).T) - radius, 0.0)
        z = self.points[:, 2]
        up = np.maximum(np.maximum(z0 - z, z - z1), 0.0)
        return float(np.hypot(flat, up).min())

    def capsule_distance(self, a, b, radius) -> float:
        """m: the smallest distance from a pose to the capsules from ``a`` to ``b`` ((k, 3) each) of ``radius`` (k,) (a body's limbs)."""
        a, b = np.asarray(a, float).reshape(-1, 3), np.asarray(b, float).reshape(-1, 3)
        if not len(self.points) or not len(a):
            return math.inf
        ab = b - a
        t = np.clip(((self.points[:, None] - a[None]) * ab[None]).sum(-1) / np.maximum((ab**2).sum(-1), 1e-300)[None], 0.0, 1.0)
        gap = np.linalg.norm(self.points[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1) - np.asarray(radius, float).reshape(-1)[None]
        return float(max(gap.min(), 0.0))

    def clear_of_capsules(self, a, b, radius) -> bool:
        """Whether the capsules of :meth:`capsule_distance` keep :attr:`reach` from every pose."""
        return self.capsule_distance(a, b, radius) >= self.reach

    def clear_of_box(self, centre, half, yaw: float = 0.0, z0: float = -math.inf, z1: float = math.inf) -> bool:
        """Whether the box of :meth:`box_distance` keeps :attr:`reach` from every pose."""
        return self.box_distance(centre, half, yaw, z0, z1) >= self.reach

    def clear_of_circle(self, centre, radius: float, z0: float = -math.inf, z1: float = math.inf) -> bool:
        """Whether the cylinder of :meth:`circle_distance` keeps :attr:`reach` from every pose."""
        return self.circle_distance(centre, radius, z0, z1) >= self.reach


NO_POSES = SensorPoses(np.zeros((0, 3)))  # a run whose sensor poses are not known before its scene is built


def sample_path(points, step: float = PATH_STEP) -> np.ndarray:
    """``(k, 3)``: the polyline ``points`` (n, 3) m with samples added so that neighbours lie at most ``step`` apart."""
    points = np.asarray(points, float).reshape(-1, 3)
    if len(points) < 2:
        return points
    out = [points[:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


# ----------------------------------------------------------------------------- a scan from inside a solid
ENCLOSED_SHARE = 0.8  # of the rays fired: returns from one object
ENCLOSED_RANGE = 3.0  # m: the median range of that object's returns


def enclosing_instance(ranges, instances, rays: int, share: float = ENCLOSED_SHARE, near: float = ENCLOSED_RANGE) -> tuple[int, float] | None:
    """``(instance, its share of the rays)`` when the sensor stands enclosed by one object, else ``None``.

    ranges : (p,) m of a frame's returns; instances : (p,) their instance ids (0: no object, as weather's returns);
    rays : how many rays the frame fired. Enclosed: one instance returns at least ``share`` of the rays and the median
    of its ranges is under ``near`` (a sensor inside a bus, a box or a wall; a garage or hall scanned from inside has its
    returns metres away).
    """
    ranges, instances = np.asarray(ranges).reshape(-1), np.asarray(instances).reshape(-1)
    if not (ranges.dtype == np.float32 and float(np.float32(near)) == near):  # float32 ranges (the records') compared as they are where that is exact
        ranges = ranges.astype(np.float64)
    if rays <= 0 or np.count_nonzero(ranges < near) < share * rays / 2 or np.count_nonzero(instances) < share * rays:
        return None  # cheap necessary conditions first: half of the object's returns lie nearer than ``near``
    ids, counts = np.unique(instances[instances != 0], return_counts=True)
    top = int(np.argmax(counts))
    if counts[top] < share * rays or float(np.median(ranges[instances == ids[top]].astype(np.float64))) >= near:
        return None
    return int(ids[top]), float(counts[top] / rays)
