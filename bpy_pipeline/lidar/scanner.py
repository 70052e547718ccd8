"""The scan: a sensor pattern at a pose traced through the scene, with mirror bounces, into point records.

Rays leave the sensor, hit the nearest triangle (:class:`~.raycast.RayCaster`), and either
end there or, on a ``mirror`` object's front face, reflect (r = d - 2 (d.n) n) and go on from
the hit point, offset along the normal by an epsilon that follows float32's resolution at that
point, up to ``max_bounces`` reflections. A beam that meets a mirror with no bounces left, or
a mirror of zero reflectivity, is lost. The reported point lies where the sensor believes it
is: along the original beam at the total path length (a "ghost" behind the mirror), or at the
true hit with ``ideal=True``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..buffers import MATERIAL_ID, SceneBuffers
from .points import POINT_DTYPE, empty_points
from .raycast import RayCaster
from .sensors import Pattern

MIRROR = MATERIAL_ID["mirror"]
OFFSET_ULPS = 64.0 * np.finfo(np.float32).eps  # mirror re-launch offset per metre of local coordinate


@dataclass
class Beams:
    """Where n beams ended.

    path : (n,) float64 total path length, metres (inf where lost)
    point : (n, 3) float64 world position of the final hit
    triangle : (n,) int64 final triangle, -1 where lost
    bounces : (n,) uint8 mirror reflections before the final hit
    mirror_object : (n,) int32 object row of the first mirror met, -1 for none
    gain : (n,) float64 product of the reflectivities of the mirrors met
    cos_incidence : (n,) float64 |cos| of the angle between the last ray and the final surface normal
    """

    path: np.ndarray
    point: np.ndarray
    triangle: np.ndarray
    bounces: np.ndarray
    mirror_object: np.ndarray
    gain: np.ndarray
    cos_incidence: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.triangle >= 0


def trace_beams(caster: RayCaster, buffers: SceneBuffers, origins, directions, min_range: float, max_range: float, max_bounces: int = 3) -> Beams:
    """Trace ``(n, 3)`` world origins and unit directions through mirrors to their final hits."""
    n = len(origins)
    beams = Beams(np.zeros(n), np.zeros((n, 3)), np.full(n, -1, np.int64), np.zeros(n, np.uint8), np.full(n, -1, np.int32), np.ones(n), np.zeros(n))
    objects = buffers.objects
    active = np.arange(n)
    o, d = np.asarray(origins, np.float64), np.asarray(directions, np.float64)
    while len(active):
        hits = caster.intersect(o, d, max_range - beams.path[active])
        keep = hits.hit
        rows, o, d = active[keep], o[keep], d[keep]
        t, tri, normal = hits.distance[keep], hits.triangle[keep], hits.normal[keep]
        beams.path[rows] += t
        point = o + t[:, None] * d
        obj = buffers.triangle_object[tri]
        facing = -np.einsum("ij,ij->i", d, normal)  # > 0 on the front face
        reflects = (objects.material[obj] == MIRROR) & (facing > 0)
        final = ~reflects
        beams.triangle[rows[final]] = tri[final]
        beams.point[rows[final]] = point[final]
        beams.cos_incidence[rows[final]] = np.abs(facing[final])
        bounce = reflects & (beams.bounces[rows] < max_bounces) & (objects.reflectivity[obj] > 0)
        rows, obj = rows[bounce], obj[bounce]
        first = beams.mirror_object[rows] < 0
        beams.mirror_object[rows[first]] = obj[first]
        beams.gain[rows] *= objects.reflectivity[obj]
        beams.bounces[rows] += 1
        normal, d, point = normal[bounce], d[bounce], point[bounce]
        d = d - 2.0 * np.einsum("ij,ij->i", d, normal)[:, None] * normal
        offset = OFFSET_ULPS * (1.0 + np.abs(point - caster.origin).max(axis=1))
        o = point + offset[:, None] * normal
        active = rows
    lost = (beams.triangle < 0) | (beams.path < min_range)
    beams.triangle[lost] = -1
    beams.path[lost] = np.inf
    return beams


def scan_chunks(
    caster: RayCaster,
    buffers: SceneBuffers,
    pattern: Pattern,
    pose: np.ndarray,
    min_range: float,
    max_range: float,
    max_bounces: int = 3,
    ghost_semantic: int | None = None,
    ideal: bool = False,
    chunk_rays: int = 1 << 18,
) -> Iterator[np.ndarray]:
    """Point records (sensor frame) of a static scan, ``chunk_rays`` rays at a time.

    pattern : the sensor's rays (sensor frame)
    pose : (4, 4) float64 sensor-to-world transform
    ghost_semantic : class id given to points seen through mirrors; ``None`` keeps the final object's class
    ideal : report mirrored points at their true position instead of along the original beam
    Yields :data:`~.points.POINT_DTYPE` arrays holding the hits of consecutive ray chunks.
    """
    rotation, position = pose[:3, :3], pose[:3, 3]
    objects = buffers.objects
    for start in range(0, len(pattern), chunk_rays):
        s = slice(start, start + chunk_rays)
        local_dirs = pattern.directions[s]
        beams = trace_beams(caster, buffers, np.broadcast_to(position, local_dirs.shape), local_dirs @ rotation.T, min_range, max_range, max_bounces)
        hit = beams.hit
        obj = buffers.triangle_object[beams.triangle[hit]]
        ghost = beams.bounces[hit] > 0
        points = empty_points(int(hit.sum()))
        if ideal:
            xyz = (beams.point[hit] - position) @ rotation
        else:
            xyz = local_dirs[hit] * beams.path[hit, None]
        points["x"], points["y"], points["z"] = xyz.T
        points["range"] = beams.path[hit]
        points["intensity"] = np.clip(objects.reflectivity[obj] * beams.cos_incidence[hit] * beams.gain[hit], 0.0, 1.0)
        points["semantic"] = objects.semantic[obj]
        points["instance"] = np.where(ghost, objects.instance[beams.mirror_object[hit]], objects.instance[obj])
        if ghost_semantic is not None:
            points["semantic"][ghost] = ghost_semantic
        points["ring"] = pattern.ring[s][hit]
        points["time"] = pattern.time[s][hit]
        points["bounces"] = beams.bounces[hit]
        yield points


def scan(*args, **kwargs) -> np.ndarray:
    """All point records of :func:`scan_chunks` in one ``(p,)`` array."""
    chunks = list(scan_chunks(*args, **kwargs))
    return np.concatenate(chunks) if chunks else np.zeros(0, POINT_DTYPE)
