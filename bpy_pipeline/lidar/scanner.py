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
from typing import Iterable, Iterator

import numpy as np

from ..buffers import MATERIAL_ID, SceneBuffers
from .points import BEAM_DTYPE, POINT_DTYPE, empty_points
from .raycast import RayCaster
from .sensors import Pattern

MIRROR = MATERIAL_ID["mirror"]
OFFSET_ULPS = 64.0 * np.finfo(np.float32).eps  # mirror re-launch offset per metre of local coordinate


@dataclass
class Beams:
    """The beams that returned (k of n), in firing order.

    ray : (k,) int64 index of the beam among the n traced
    path : (k,) float64 total path length, metres
    point : (k, 3) float64 world position of the final hit
    triangle : (k,) int64 final triangle
    bounces : (k,) uint8 mirror reflections before the final hit
    mirror_object : (k,) int32 object row of the first mirror met, -1 for none
    gain : (k,) float64 product of the reflectivities of the mirrors met
    cos_incidence : (k,) float64 |cos| of the angle between the last ray and the final surface normal
    """

    ray: np.ndarray
    path: np.ndarray
    point: np.ndarray
    triangle: np.ndarray
    bounces: np.ndarray
    mirror_object: np.ndarray
    gain: np.ndarray
    cos_incidence: np.ndarray


def trace_beams(caster: RayCaster, buffers: SceneBuffers, origin, directions, min_range: float, max_range: float, max_bounces: int = 3, directions32=None) -> Beams:
    """Trace beams through mirrors, in the caster's local frame.

    origin : (3,) or (n, 3) float64 local coordinates, metres
    directions : (n, 3) float64 unit vectors, local frame (``directions32``: the same as float32, optional)
    Returns :class:`Beams` whose ``point`` is in the local frame.
    """
    n = len(directions)
    objects = buffers.objects
    rows = None  # beam of each active ray; None while it is the identity (first segment)
    o, d = np.asarray(origin, np.float64), np.asarray(directions, np.float64)
    travelled, bounces, gain, mirror = 0.0, np.zeros(n, np.uint8), np.ones(n), np.full(n, -1, np.int32)
    done = []
    while True:
        hits = caster.intersect(o, d, max_range - travelled, directions32)
        directions32 = None
        i = hits.ray
        seg_d = d[i]
        point = (o if o.ndim == 1 else o[i]) + hits.distance[:, None] * seg_d
        path = hits.distance + (travelled[i] if rows is not None else 0.0)
        obj = buffers.triangle_object[hits.triangle]
        facing = -np.einsum("ij,ij->i", seg_d, hits.normal)  # > 0 on the front face
        reflects = (objects.material[obj] == MIRROR) & (facing > 0)
        beam = i if rows is None else rows[i]
        if not reflects.any():
            if rows is None:  # one segment, no mirror met: the defaults need no gathering
                done.append((beam, path, point, hits.triangle, np.zeros(len(i), np.uint8), np.full(len(i), -1, np.int32), np.ones(len(i)), np.abs(facing)))
            else:
                done.append((beam, path, point, hits.triangle, bounces[i], mirror[i], gain[i], np.abs(facing)))
            break
        final = ~reflects
        done.append((beam[final], path[final], point[final], hits.triangle[final], bounces[i][final], mirror[i][final], gain[i][final], np.abs(facing[final])))
        bounce = reflects & (bounces[i] < max_bounces) & (objects.reflectivity[obj] > 0)
        if not bounce.any():
            break
        j, obj, normal = i[bounce], obj[bounce], hits.normal[bounce]
        rows, travelled, bounces = beam[bounce], path[bounce], bounces[j] + 1
        gain = gain[j] * objects.reflectivity[obj]
        mirror = np.where(mirror[j] < 0, obj, mirror[j])
        d = seg_d[bounce]
        d = d - 2.0 * np.einsum("ij,ij->i", d, normal)[:, None] * normal
        point = point[bounce]
        offset = OFFSET_ULPS * (1.0 + np.abs(point).max(axis=1))
        o = point + offset[:, None] * normal
    if len(done) == 1:
        beams = Beams(*done[0])
    else:
        fields = [np.concatenate(column) for column in zip(*done)]
        order = np.argsort(fields[0], kind="stable")
        beams = Beams(*(f[order] for f in fields))
    near = beams.path >= min_range
    if not near.all():
        beams = Beams(*(getattr(beams, f)[near] for f in Beams.__dataclass_fields__))
    return beams


def scan_chunk(caster, buffers, pattern: Pattern, sensor_to_local: np.ndarray, min_range: float, max_range: float, max_bounces: int = 3, ghost_semantic=None, ideal: bool = False):
    """Point records of one chunk of rays, in the caster's local frame.

    pattern : the chunk's rays (sensor frame)
    sensor_to_local : (4, 4) sensor pose in the caster's frame, or (n, 4, 4) one per ray (a moving sensor)
    Returns ``(points, beam, ray)``: :data:`POINT_DTYPE` records, :data:`BEAM_DTYPE` facts for the
    effects, and for each point the index of its ray in the chunk.
    """
    directions = pattern.directions
    if sensor_to_local.ndim == 2 and pattern.origins is None and np.allclose(sensor_to_local, np.eye(4), rtol=0, atol=1e-12):
        origin, world_d = np.zeros(3), directions  # the caster works in this sensor's frame: rays go in as they are
        beams = trace_beams(caster, buffers, origin, directions, min_range, max_range, max_bounces, directions.astype(np.float32))
    else:
        rotation, translation = sensor_to_local[..., :3, :3], sensor_to_local[..., :3, 3]
        rotate = (lambda v: v @ rotation.T) if rotation.ndim == 2 else (lambda v: np.einsum("nij,nj->ni", rotation, v))
        world_d = rotate(directions)
        origin = translation if pattern.origins is None else translation + rotate(pattern.origins)
        beams = trace_beams(caster, buffers, origin, world_d, min_range, max_range, max_bounces)
    objects = buffers.objects
    obj = buffers.triangle_object[beams.triangle]
    ghost = beams.bounces > 0
    points = empty_points(len(beams.ray))
    if ideal:
        xyz = beams.point
    else:  # where the sensor believes the return is: along the emitted ray at the total path length
        start = origin if origin.ndim == 1 else origin[beams.ray]
        xyz = start + world_d[beams.ray] * beams.path[:, None]
    points["x"], points["y"], points["z"] = xyz.T
    points["range"] = beams.path
    reflectivity = objects.reflectivity[obj]
    points["intensity"] = np.clip(reflectivity * beams.cos_incidence * beams.gain, 0.0, 1.0)
    points["semantic"] = objects.semantic[obj]
    points["instance"] = objects.instance[obj]
    if ghost.any():
        points["instance"][ghost] = objects.instance[beams.mirror_object[ghost]]
        if ghost_semantic is not None:
            points["semantic"][ghost] = ghost_semantic
    points["bounces"] = beams.bounces
    points["ring"] = pattern.ring[beams.ray]
    points["time"] = pattern.time[beams.ray]
    beam = np.empty(len(beams.ray), BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"] = beams.cos_incidence, reflectivity, beams.gain
    return points, beam, beams.ray


def scan_chunks(
    caster: RayCaster,
    buffers: SceneBuffers,
    patterns: Pattern | Iterable[Pattern],
    pose,
    min_range: float,
    max_range: float,
    max_bounces: int = 3,
    ghost_semantic: int | None = None,
    ideal: bool = False,
    chunk_rays: int = 1 << 18,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(points, beam)`` of a scan, chunk by chunk in firing order; points in the caster's frame.

    patterns : the sensor's rays (sensor frame): one :class:`Pattern`, or consecutive chunks of
        one (``sensors.iter_pattern``), so a 23-million-ray scan never holds all its rays at once
    pose : (4, 4) float64 sensor-to-world transform of a static sensor, or a callable mapping
        firing times (n,) to (n, 4, 4) poses for a moving one
    ghost_semantic : class id given to points seen through mirrors; ``None`` keeps the final object's class
    ideal : report mirrored points at their true position instead of along the original beam
    Points come out in the caster's local frame: give the caster the sensor's pose (at frame
    start, for a moving sensor) and they are in the sensor frame, motion-compensated to that pose.
    Rays go through in chunks of at most ``chunk_rays``, so memory does not grow with the ray
    count; each chunk's Embree queries use every core (:meth:`RayCaster.intersect`).
    """
    world_to_local = np.linalg.inv(caster.frame)
    for pattern in [patterns] if isinstance(patterns, Pattern) else patterns:
        for start in range(0, len(pattern), chunk_rays):
            s = slice(start, start + chunk_rays)
            chunk = Pattern(pattern.directions[s], pattern.ring[s], pattern.time[s], None if pattern.origins is None else pattern.origins[s])
            poses = pose(chunk.time) if callable(pose) else pose
            points, beam, _ = scan_chunk(caster, buffers, chunk, world_to_local @ poses, min_range, max_range, max_bounces, ghost_semantic, ideal)
            yield points, beam


def scan(*args, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """All ``(points, beam)`` of :func:`scan_chunks`, each in one array."""
    chunks = list(scan_chunks(*args, **kwargs))
    if not chunks:
        return np.zeros(0, POINT_DTYPE), np.zeros(0, BEAM_DTYPE)
    return np.concatenate([c[0] for c in chunks]), np.concatenate([c[1] for c in chunks])
