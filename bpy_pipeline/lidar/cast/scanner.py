"""The scan: a sensor pattern at a pose traced through the scene, with mirrors and glass, into point records.

Rays leave the sensor and hit the nearest triangle (:class:`~.raycast.RayCaster`). What
happens there depends on the object's ``lidar_material`` (:func:`trace_beams` has the rules):
``diffuse`` surfaces return the beam; ``absorber`` swallows it (no return); a ``mirror``'s
front face reflects it (r = d - 2 (d.n) n) and its back face is a diffuse surface; ``glass``
lets it through unchanged, returns it from its own surface near normal incidence, or reflects
a configured fraction of beams like a mirror. A reflected or transmitted beam goes on from
the hit point, offset off the surface by an epsilon that follows float32's resolution there,
until ``max_bounces`` reflections (or :attr:`MirrorGlassRules.glass_passes` passes through glass);
one more loses the beam. Path length accumulates and counts against the maximum range.

The reported point of a reflected beam lies where the sensor believes it is: along the
original beam at the total path length (a "ghost" behind the mirror), or at the true hit with
``ideal=True``. A beam that only passed through glass is reported where it truly hit: its
direction never changed.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ...buffers import MATERIAL_ID, SceneBuffers
from ...geometry.transforms import rotate
from ..points import BEAM_DTYPE, POINT_DTYPE
from .kernels import back_face_rays, fill_diffuse, trace_fill
from .raycast import Hits, RayCaster, dot3
from ..sensor.rays import Pattern, pattern_chunks

DIFFUSE, MIRROR, GLASS, ABSORBER = (MATERIAL_ID[name] for name in ("diffuse", "mirror", "glass", "absorber"))
# Re-launch offset off a mirror or glass surface, per metre of the largest local coordinate of
# the hit point and of the hit triangle's corners (float32 rounds both Embree's hit and its copy
# of the triangle at that scale): 64 float32 ulps, 7.6 um at 1 m, 0.76 mm at 100 m.
OFFSET_ULPS = 64.0 * np.finfo(np.float32).eps


@dataclass(frozen=True)
class MirrorGlassRules:
    """How the trace treats mirrors and glass (the config's ``effects.mirrors``). Angles in degrees.

    mirror_return_deg : a mirror's front face met within this angle of normal incidence sends
        the beam straight back into the receiver: the point lies on the mirror itself
        (0: never; a beam at exactly normal incidence then bounces back past the sensor)
    glass_return_deg : the same for glass (either face): the glass itself returns the beam
    glass_reflect : fraction, 0..1, of the other beams meeting glass that reflect like a mirror
        instead of passing through; drawn from the scan's ``rng`` when strictly between 0 and 1
    glass_passes : the most glass surfaces a beam passes through; meeting one more loses it
    glass_transmission : None (every beam not returned or reflected passes, gain x (1 - reflectivity)), or
        ``(cos (k,), object rows (k,)) -> (k,)`` the share of a pane's power that crosses it and back
        (lidar/effects/materials.py :func:`~bpy_pipeline.lidar.effects.materials.glass_transmission`; NaN for a row it does not model, which keeps
        the rule before): such a beam passes with that probability, drawn from ``rng``, gain unchanged, else is lost
    """

    mirror_return_deg: float = 0.0
    glass_return_deg: float = 0.0
    glass_reflect: float = 0.0
    glass_passes: int = 8
    glass_transmission: object = None


@dataclass
class Beams:
    """The beams that returned (k of n), in firing order.

    ray : (k,) int64 index of the beam among the n traced
    path : (k,) float64 total path length, metres
    point : (k, 3) float64 local position of the final hit
    triangle : (k,) int64 final triangle
    bounces : (k,) uint8 specular reflections (mirror or glass) before the final hit
    mirror_object : (k,) int32 object row of the first surface that reflected the beam, -1 for none
    gain : (k,) float64 product of the one-way factors met: a reflecting surface's
        reflectivity, a traversed glass surface's 1 - reflectivity (1 for direct returns)
    cos_incidence : (k,) float64 |cos| of the angle between the last ray and the final surface normal
    direction : (k, 3) float64 unit direction of the last segment, local frame
    """

    ray: np.ndarray
    path: np.ndarray
    point: np.ndarray
    triangle: np.ndarray
    bounces: np.ndarray
    mirror_object: np.ndarray
    gain: np.ndarray
    cos_incidence: np.ndarray
    direction: np.ndarray
    single: bool = False  # every beam returned from its first segment: point and direction are those of the emitted ray

    def select(self, keep: np.ndarray) -> "Beams":
        """The beams ``keep`` (a boolean mask or indices) selects."""
        return Beams(*(getattr(self, f)[keep] for f in ARRAY_FIELDS), single=self.single)


ARRAY_FIELDS = tuple(f for f in Beams.__dataclass_fields__ if f != "single")

def _relaunch_offset(caster: RayCaster, buffers: SceneBuffers, point: np.ndarray, triangle: np.ndarray) -> np.ndarray:
    """``(k,)`` metres to move re-launched rays off their surface (see :data:`OFFSET_ULPS`)."""
    scale = np.maximum(np.abs(point).max(axis=1), caster.corner_scales(triangle))
    return OFFSET_ULPS * (1.0 + scale)


def _from_launch(caster: RayCaster, launch: np.ndarray, d: np.ndarray, hits, shift: np.ndarray) -> np.ndarray:
    """``(h,)`` distances of ``hits`` solved again in float64 from the un-offset ``launch`` points (h, 3).

    The relaunched ray started ``shift`` (h,) metres off its surface; solving the hit triangle's
    plane from the true launch point removes that bias from the path. Where the solve disagrees
    with the caster's distance by more than the offset could explain (grazing rays), the
    caster's distance is kept.
    """
    normal = hits.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = (caster.plane_offset[hits.triangle] - dot3(launch, normal)) / dot3(d, normal)
    trust = np.abs(exact - hits.distance) <= 4.0 * shift
    return np.where(trust, exact, hits.distance)


def trace_beams(
    caster: RayCaster,
    buffers: SceneBuffers,
    origin,
    directions,
    min_range: float,
    max_range: float,
    max_bounces: int = 3,
    directions32=None,
    surfaces: MirrorGlassRules | None = None,
    rng: np.random.Generator | None = None,
    first: Hits | None = None,
) -> Beams:
    """Trace beams through mirrors and glass, in the caster's local frame.

    origin : (3,) or (n, 3) float64 local coordinates, metres
    directions : (n, 3) float64 unit vectors, local frame (``directions32``: the same as float32, optional)
    surfaces : the rules for mirrors and glass (default :class:`MirrorGlassRules`: no normal-incidence
        returns, glass always transmits)
    rng : needed only when ``surfaces.glass_reflect`` lies strictly between 0 and 1
    first : the first segment's hits when the caller has them (the compiled path hands over the
        rays that met glass or a mirror; rays not in it are not traced)
    Returns :class:`Beams` whose ``point`` is in the local frame.

    At each hit, by the hit object's material (``n`` the triangle's normal, ``d`` the ray):

    - ``diffuse``, and a mirror's back face (d.n > 0): the beam returns from there;
    - ``absorber``: the beam is lost;
    - ``mirror`` front face: within ``mirror_return_deg`` of normal incidence the beam returns
      from the mirror itself; otherwise it reflects, gain x reflectivity. It is lost instead
      when the mirror's reflectivity is 0 or ``max_bounces`` reflections are used up;
    - ``glass``, either face: within ``glass_return_deg`` of normal incidence it returns from the
      glass (if reflectivity > 0); otherwise a ``glass_reflect`` share of beams reflects like a
      mirror (gain x reflectivity) and the rest passes straight through (gain x (1 - reflectivity));
      lost when that factor is 0 or the reflection or pass budget is used up.

    Every segment is bounded by what is left of ``max_range``, so no trace outlives its range
    and the loop ends after at most ``max_bounces + glass_passes + 1`` Embree queries.
    """
    surfaces = surfaces or MirrorGlassRules()
    n = len(directions)
    objects = buffers.objects
    cos_mirror_return = math.cos(math.radians(surfaces.mirror_return_deg)) if surfaces.mirror_return_deg > 0 else math.inf
    cos_glass_return = math.cos(math.radians(surfaces.glass_return_deg)) if surfaces.glass_return_deg > 0 else math.inf
    rows = None  # beam of each active ray; None while it is the identity (first segment)
    o, d = np.asarray(origin, np.float64), np.asarray(directions, np.float64)
    launch = shift = None  # after a bounce: the un-offset points the rays leave from, and their offsets
    travelled = 0.0
    bounces, passes = np.zeros(n, np.uint8), np.zeros(n, np.uint16)
    gain, mirror = np.ones(n), np.full(n, -1, np.int32)
    done = []
    while True:
        hits = first if first is not None else caster.intersect(o, d, max_range - travelled, directions32)
        directions32 = first = None
        i = hits.ray
        seg_d = hits.direction
        if launch is None:
            start, distance = (o if o.ndim == 1 else o[i]), hits.distance
        else:  # measure from where the beam really left the surface, not from the offset origin
            start = launch[i]
            distance = _from_launch(caster, start, seg_d, hits, shift[i])
        point = start + distance[:, None] * seg_d
        path = distance + (travelled[i] if rows is not None else 0.0)
        obj = buffers.triangle_object[hits.triangle]
        facing = -dot3(seg_d, hits.normal)  # cos of incidence, > 0 on the front face
        cos_incidence = np.abs(facing)
        material = objects.material[obj]
        beam = i if rows is None else rows[i]
        if rows is None and not (material != DIFFUSE).any():  # one segment, only diffuse hits: nothing to gather
            beams = Beams(beam, path, point, hits.triangle, np.zeros(len(i), np.uint8), np.full(len(i), -1, np.int32), np.ones(len(i)),
                          cos_incidence, seg_d, single=True)
            near = beams.path >= min_range
            return beams if near.all() else beams.select(near)
        reflectivity = objects.reflectivity[obj].astype(np.float64)
        is_mirror, is_glass = material == MIRROR, material == GLASS
        mirror_front = is_mirror & (facing > 0)
        specular_return = (reflectivity > 0) & np.where(is_mirror, cos_incidence >= cos_mirror_return, cos_incidence >= cos_glass_return)
        returns = (material == DIFFUSE) | (is_mirror & (facing <= 0)) | ((mirror_front | is_glass) & specular_return)
        reflect = mirror_front & ~returns
        through = is_glass & ~returns
        if surfaces.glass_reflect > 0 and through.any():
            if surfaces.glass_reflect >= 1:
                turn = through
            else:
                if rng is None:
                    raise ValueError("trace_beams: glass_reflect between 0 and 1 needs a numpy Generator (rng)")
                turn = np.zeros(len(i), bool)
                turn[through] = rng.random(int(through.sum())) < surfaces.glass_reflect
            reflect |= turn
            through &= ~turn
        reflect &= (reflectivity > 0) & (bounces[i] < max_bounces)
        through &= (reflectivity < 1) & (passes[i] < surfaces.glass_passes)
        modelled = np.zeros(len(i), bool)
        if surfaces.glass_transmission is not None and through.any():
            if rng is None:
                raise ValueError("trace_beams: glass_transmission needs a numpy Generator (rng)")
            pick = np.flatnonzero(through)
            share = surfaces.glass_transmission(cos_incidence[pick], obj[pick])
            modelled[pick] = np.isfinite(share)
            through[pick] &= ~np.isfinite(share) | (rng.random(len(pick)) < np.nan_to_num(share))
        if returns.any():
            done.append((beam[returns], path[returns], point[returns], hits.triangle[returns], bounces[i][returns], mirror[i][returns], gain[i][returns],
                         cos_incidence[returns], seg_d[returns]))
        go = reflect | through
        if not go.any():
            break
        j, turned = i[go], reflect[go]
        rows, travelled = beam[go], path[go]
        bounces, passes = bounces[j] + turned, passes[j] + ~turned
        gain = gain[j] * np.where(turned, reflectivity[go], np.where(modelled[go], 1.0, 1.0 - reflectivity[go]))
        mirror = np.where((mirror[j] < 0) & turned, obj[go], mirror[j])
        normal, d = hits.normal[go], seg_d[go]
        d_dot_n = dot3(d, normal)
        d = np.where(turned[:, None], d - 2.0 * d_dot_n[:, None] * normal, d)
        launch = point[go]
        shift = _relaunch_offset(caster, buffers, launch, hits.triangle[go])
        # Off the surface on the side the beam now travels to: back towards it after a reflection, beyond it after a pass.
        side = np.where(turned, -np.sign(d_dot_n), np.sign(d_dot_n))
        o = launch + (side * shift)[:, None] * normal
    if len(done) == 1:
        beams = Beams(*done[0])
    elif not done:
        beams = Beams(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.int32), np.zeros(0),
                      np.zeros(0), np.zeros((0, 3)))
    else:
        fields = [np.concatenate(column) for column in zip(*done)]
        slot = np.full(n, -1, np.int64)  # each beam returns at most once: firing order by scattering, not sorting
        slot[fields[0]] = np.arange(len(fields[0]))
        order = slot[slot >= 0]
        beams = Beams(*(f[order] for f in fields))
    near = beams.path >= min_range
    return beams if near.all() else beams.select(near)


def scan_chunk(
    caster,
    buffers,
    pattern: Pattern,
    sensor_to_local: np.ndarray,
    min_range: float,
    max_range: float,
    max_bounces: int = 3,
    ghost_semantic=None,
    ideal: bool = False,
    *,
    surfaces: MirrorGlassRules | None = None,
    rng: np.random.Generator | None = None,
):
    """Point records of one chunk of rays, in the caster's local frame.

    pattern : the chunk's rays (sensor frame)
    sensor_to_local : (4, 4) sensor pose in the caster's frame, or (n, 4, 4) one per ray (a moving sensor)
    surfaces, rng : the mirror and glass rules and the frame's generator (:func:`trace_beams`)
    Returns ``(points, beam, ray)``: :data:`POINT_DTYPE` records, :data:`BEAM_DTYPE` facts for the
    effects, and for each point the index of its ray in the chunk.
    """
    directions = pattern.directions
    if sensor_to_local.ndim == 2 and pattern.origins is None and np.abs(sensor_to_local - np.eye(4)).max() <= 1e-12:
        origin, world_d = np.zeros(3), directions  # the caster works in this sensor's frame: rays go in as they are
        as_given = True
    else:
        rotation, translation = sensor_to_local[..., :3, :3], sensor_to_local[..., :3, 3]
        world_d = rotate(directions, rotation)
        origin = translation if pattern.origins is None else translation + rotate(pattern.origins, rotation)
        as_given = False
    if getattr(caster, "kernels", None) is not None:  # the compiled path; glass and mirrors go on in trace_beams
        return _fused_chunk(caster, buffers, pattern, origin, world_d, min_range, max_range, max_bounces, ghost_semantic, ideal, surfaces, rng)
    beams = trace_beams(caster, buffers, origin, world_d, min_range, max_range, max_bounces, directions.astype(np.float32) if as_given else None, surfaces, rng)
    return _records(beams, buffers, pattern, origin, world_d, ghost_semantic, ideal)


def _records(beams: Beams, buffers: SceneBuffers, pattern: Pattern, origin: np.ndarray, world_d: np.ndarray, ghost_semantic, ideal: bool):
    """``(points, beam, ray)`` of :func:`scan_chunk` from traced ``beams`` (the numpy path)."""
    objects = buffers.objects
    obj = buffers.triangle_object[beams.triangle]
    ghost = beams.bounces > 0
    points = np.empty(len(beams.ray), POINT_DTYPE)
    emitted = beams.direction if ideal or beams.single else world_d[beams.ray]
    if ideal or beams.single:
        xyz = beams.point
    else:  # where the sensor believes the return is: along the emitted ray at the total path length
        start = origin if origin.ndim == 1 else origin[beams.ray]
        xyz = start + emitted * beams.path[:, None]
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
    beam["direction"] = beams.direction if ideal else emitted
    return points, beam, beams.ray


NO_RAYS = np.zeros(0, np.bool_)
IDENTITY = np.zeros(0, np.int64)


def _fused_chunk(caster: RayCaster, buffers: SceneBuffers, pattern: Pattern, origin: np.ndarray, world_d: np.ndarray, min_range: float, max_range: float,
                 max_bounces: int = 3, ghost_semantic=None, ideal: bool = False,
                 surfaces: MirrorGlassRules | None = None, rng: np.random.Generator | None = None):  # fmt: skip
    """:func:`scan_chunk` through the compiled kernel (:mod:`.kernels`).

    Each of the caster's threads takes a part of the rays and, block by block, calls Embree and fills
    each ray's record (solve, trust test, range limits, labels) in one compiled pass
    (:func:`.kernels.trace_fill`); the parts' records are then joined. Where Embree cannot be
    called from the pass, embreex traces first and the pass fills each part's records straight
    into the rows they end up in (:func:`.kernels.fill_diffuse`). Slipped rays are found from the objects the passes saw from both
    sides, traced again as the numpy path does (:meth:`RayCaster.retrace`) and the pass repeated
    over those whose hit moved (:func:`_refill`). Rays whose first hit is glass or a mirror's front face go on in
    :func:`trace_beams` from that hit. The records of both take their places among the others in firing order
    (:func:`spliced`): the same bytes as the numpy path.
    """
    world_d = np.ascontiguousarray(world_d, np.float64)
    n = len(world_d)
    local, origins32, directions32, far = caster.launch(origin, world_d, max_range, None, convert=False)  # float32 chunk by chunk, on the threads
    origins = np.ascontiguousarray(local.reshape(-1, 3), np.float64)
    shared = len(origins) == 1
    prim_triangle = IDENTITY if caster.embree_triangle is None else caster.embree_triangle
    objects = buffers.objects

    starts = list(range(0, n, caster.chunk)) or [0]

    def part(j):
        s, r = slice(starts[j], starts[j] + caster.chunk), slice(rows[j], rows[j + 1])
        return fill_diffuse(caster.kernels, tfar[s], prim[s], prim_triangle, NO_RAYS, origins if shared else origins[s], world_d[s],
                            caster, objects, pattern.ring[s], pattern.time[s], min_range, max_range, points[r], beam[r], ray[r], starts[j])

    if caster.kernels.traces and caster.embree_handles is not None:
        # Embree called inside the pass, each thread over its part of the rays: the records of part
        # j go into rows from starts[j] (room for all its rays), Embree's answer into tfar and prim.
        tfar, prim = caster.record_pool.take(n, np.float32), caster.record_pool.take(n, np.int32)
        rows = np.array(starts + [n], np.int64)
        points, beam, ray = caster.record_pool.take(n, POINT_DTYPE), caster.record_pool.take(n, BEAM_DTYPE), caster.record_pool.take(n, np.int64)

        joined = InOrder((points, beam, ray), starts)

        def traced(j):
            s, r = slice(starts[j], starts[j] + caster.chunk), slice(rows[j], rows[j + 1])
            out = trace_fill(caster.kernels, caster, far[s], origins if shared else origins[s], world_d[s], objects, pattern.ring[s], pattern.time[s],
                             min_range, max_range, points[r], beam[r], ray[r], tfar[s], prim[s], starts[j])  # fmt: skip
            joined.finished(j, out[0])
            return out

        parts = caster.map(traced, range(len(starts)))
        points, beam, ray = (a[: joined.ends[-1]] for a in (points, beam, ray))  # joined in order: one part after another
        rows = np.concatenate([[0], np.cumsum([p[0] for p in parts])]).astype(np.int64)  # the parts' rows now: nothing left to compact below
    else:  # Embree's answer first, then the compiled pass: each part of the rays fills its rows, placed by the hits before it
        tfar, prim = caster._embree(origins32, directions32, far)
        rows = hit_rows(prim, starts, caster.chunk)
        points, beam, ray = (caster.record_pool.take(rows[-1], POINT_DTYPE), caster.record_pool.take(rows[-1], BEAM_DTYPE),
                             caster.record_pool.take(rows[-1], np.int64))
        parts = caster.map(part, range(len(starts)))
    front = np.logical_or.reduce([p[1] for p in parts])
    back = np.logical_or.reduce([p[2] for p in parts])
    filled = np.array([p[0] for p in parts], np.int64)
    if not (filled == np.diff(rows)).all():  # rows left empty by misses (when traced in the pass), range limits, absorbers, glass and mirrors
        points, beam, ray = (compact(a, rows, filled, caster) for a in (points, beam, ray))
    specular = np.concatenate([p[3] for p in parts])
    suspect = caster.suspects(front, back, prim, lambda both: back_face_rays(caster.kernels, prim, prim_triangle, world_d, caster, both))
    moved, refilled = None, None
    if len(suspect):
        tfar, prim, moved = caster.retrace(suspect, local, world_d, far, tfar, prim)
        again = np.flatnonzero(moved)
        if len(again):  # only these rays' hits changed, and the pass fills each ray from its own hit alone: they are filled again
            refilled, glass = _refill(caster, objects, again, tfar, prim, prim_triangle, origins, world_d, pattern, min_range, max_range)
            specular = np.concatenate([specular[~moved[specular]], glass])
            specular.sort(kind="stable")
    if len(specular):
        first = _first_hits(caster, specular, tfar, prim, moved, local, world_d)
        beams = trace_beams(caster, buffers, origin, world_d, min_range, max_range, max_bounces, None, surfaces, rng, first=first)
        more = _records(beams, buffers, pattern, origin, world_d, ghost_semantic, ideal)
        refilled = more if refilled is None else in_firing_order(refilled, more)
    if refilled is None:
        return points, beam, ray
    return spliced((points, beam, ray), moved, refilled, caster.record_pool)


def _refill(caster: RayCaster, objects, again: np.ndarray, tfar, prim, prim_triangle, origins, world_d, pattern: Pattern, min_range: float,
            max_range: float):
    """The compiled pass over the re-traced rays ``again`` (a) alone: ``((points, beam, ray), specular)``, the records of
    those of them that return from a diffuse surface and the (s,) rays among them left to :func:`trace_beams`, both in
    firing order with indices among the chunk's rays. The pass reads nothing of a ray but its own hit, origin, direction,
    channel and firing time, and draws nothing: each ray's record is the one a pass over the whole chunk gives it."""
    k = len(again)
    points, beam, ray = np.empty(k, POINT_DTYPE), np.empty(k, BEAM_DTYPE), np.empty(k, np.int64)
    filled, _, _, specular = fill_diffuse(caster.kernels, tfar[again], prim[again], prim_triangle, np.ones(k, np.bool_),
                                          origins if len(origins) == 1 else origins[again], world_d[again], caster, objects,
                                          pattern.ring[again], pattern.time[again], min_range, max_range, points, beam, ray)
    return (points[:filled], beam[:filled], again[ray[:filled]]), again[specular]


def in_firing_order(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """Two sets of ``(points, beam, ray)`` records, each in firing order and no ray in both, joined in firing order."""
    order = np.argsort(np.concatenate([a[2], b[2]]), kind="stable")
    return tuple(take(join([x, y]), order) for x, y in zip(a, b))


def spliced(records: tuple[np.ndarray, ...], drop: np.ndarray | None, extra: tuple[np.ndarray, ...], pool) -> tuple[np.ndarray, ...]:
    """``records`` without the rows of the rays ``drop`` flags, with ``extra``'s rows among them: all in firing order.

    records, extra : ``(points, beam, ray)`` each, rows in firing order (``ray`` (r,) and (e,) int64 ascending; no ray of
    ``extra`` among the rows kept); drop : (n,) bool per ray of the chunk, or ``None`` to keep every row.
    Returns the same three arrays, (r - dropped + e,), in memory of ``pool`` (:class:`~.raycast.RecordPool`): each row
    put once, as raw bytes, at its place (no sort of all the rows, no copy of the kept rows first).
    """
    ray, more = records[-1], extra[-1]
    dropped = None if drop is None else drop[ray]
    kept = ray if dropped is None else ray[~dropped]
    at = np.searchsorted(kept, more) + np.arange(len(more))  # each extra row's place among all
    total = len(kept) + len(more)
    base = np.ones(total, np.bool_)
    base[at] = False
    if dropped is None:
        place = np.flatnonzero(base)
    else:  # a dropped row goes to the one spare row past the end
        place = np.full(len(ray), total, np.int64)
        place[~dropped] = np.flatnonzero(base)
    out = []
    for a, e in zip(records, extra):
        joined = pool.take(total + 1, a.dtype)
        raw = a.dtype if a.dtype.names is None else np.dtype((np.void, a.dtype.itemsize))  # records as raw bytes: whole, not field by field
        target, rows = joined.view(raw), np.ascontiguousarray(a).view(raw)
        if a.dtype.names is None:
            target[place] = rows
        else:  # np.put moves raw records faster than indexing does (a number: slower)
            np.put(target, place, rows)
        target[at] = np.ascontiguousarray(e).view(raw)
        out.append(joined[:total])
    return tuple(out)


class InOrder:
    """The records of a chunk's parts, each part filled on a thread at its own rows (room for all its rays),
    moved to follow the parts before it as soon as those are in place: the records end up joined in
    firing order, most parts moved by the thread that just filled them (still in its cache), and no
    copy of them all afterwards. No thread waits: a part finished before the one ahead of it is moved
    by whichever thread then finishes that one (one thread at a time moves, in order).

    arrays : the record arrays the parts fill (same rows in each); starts : (p,) each part's first row.
    ``ends[j]``: the row after part j's records once moved.
    """

    def __init__(self, arrays: tuple[np.ndarray, ...], starts: list[int]):
        self.arrays = [a.view(np.dtype((np.void, a.dtype.itemsize))) for a in arrays]  # moved as raw bytes
        self.starts = starts
        self.ends = [0] * len(starts)
        self.filled: list[int | None] = [None] * len(starts)
        self.next = 0  # the first part not yet moved
        self.lock = threading.Lock()

    def finished(self, j: int, filled: int) -> None:
        """Part j filled its first ``filled`` rows: move it, and any finished part after it, into place."""
        with self.lock:
            self.filled[j] = filled
            while self.next < len(self.starts) and self.filled[self.next] is not None:
                k, count = self.next, self.filled[self.next]
                at = self.ends[k - 1] if k else 0
                if count and at != self.starts[k]:
                    for a in self.arrays:  # leftwards within one array: numpy copies overlapping slices correctly
                        a[at : at + count] = a[self.starts[k] : self.starts[k] + count]
                self.ends[k] = at + count
                self.next += 1


def hit_rows(prim: np.ndarray, starts: list[int], chunk: int) -> np.ndarray:
    """``(len(starts) + 1,)`` int64 first record row of each part of ``chunk`` rays from ``starts``, and the total: one row per hit."""
    counts = [np.count_nonzero(prim[i : i + chunk] >= 0) for i in starts]
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def compact(records: np.ndarray, rows: np.ndarray, filled: np.ndarray, caster: RayCaster) -> np.ndarray:
    """The first ``filled[j]`` records from each ``rows[j]`` joined in order, into memory of the caster's pool.

    records : (r,) any dtype; rows : (p + 1,) int64 part starts; filled : (p,) int64. Each part is
    one contiguous copy, made on the caster's threads.
    """
    at = np.concatenate([[0], np.cumsum(filled)])
    out = caster.record_pool.take(int(at[-1]), records.dtype)
    raw = np.dtype((np.void, records.dtype.itemsize))
    source, target = records.view(raw), out.view(raw)

    def copy(j):
        target[at[j] : at[j + 1]] = source[rows[j] : rows[j] + filled[j]]

    caster.map(copy, range(len(filled)))
    return out


def _first_hits(caster: RayCaster, rays: np.ndarray, tfar: np.ndarray, prim: np.ndarray, moved, local: np.ndarray, world_d: np.ndarray) -> Hits:
    """The :class:`Hits` :meth:`RayCaster.intersect` gives for ``rays`` (sorted), from Embree's answer ``tfar``, ``prim``."""
    triangle = caster._triangles(prim[rays])
    normal = caster.plane_normal[triangle]
    d = world_d[rays]
    denom = dot3(d, normal)
    o_dot_n = dot3(local, normal) if local.ndim == 1 else dot3(local[rays], normal)
    coarse = tfar[rays].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = (caster.plane_offset[triangle] - o_dot_n) / denom
    trust = np.abs(exact - coarse) <= 1e-4 * (1.0 + coarse)
    if moved is not None:
        m = moved[rays]
        trust[m] = np.isfinite(exact[m]) & (np.abs(denom[m]) > 1e-6)
    return Hits(rays, np.maximum(np.where(trust, exact, coarse), 0.0), triangle, normal, d)


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
    *,
    surfaces: MirrorGlassRules | None = None,
    rng: np.random.Generator | None = None,
    with_rays: bool = False,
) -> Iterator[tuple[np.ndarray, ...]]:
    """``(points, beam)`` of a scan, chunk by chunk in firing order; points in the caster's frame.

    patterns : the sensor's rays (sensor frame): one :class:`Pattern`, or consecutive chunks of
        one (``sensors.iter_pattern``), so a 23-million-ray scan never holds all its rays at once
    pose : (4, 4) float64 sensor-to-world transform of a static sensor, or a callable mapping
        firing times (n,) to (n, 4, 4) poses for a moving one
    ghost_semantic : class id given to points seen through mirrors; ``None`` keeps the final object's class
    ideal : report mirrored points at their true position instead of along the original beam
    surfaces : the rules for mirrors and glass (:class:`MirrorGlassRules`); rng : the frame's generator,
        needed only when some glass reflects a fraction of beams (:func:`trace_beams`)
    Points come out in the caster's local frame: give the caster the sensor's pose (at frame
    start, for a moving sensor) and they are in the sensor frame, motion-compensated to that pose.
    Rays go through in chunks of at most ``chunk_rays``, so memory does not grow with the ray
    count; each chunk's Embree queries use every core (:meth:`RayCaster.intersect`).
    with_rays : yield ``(points, beam, ray)``, ``ray`` the ``(p,)`` int64 index of each point's ray among all the
        rays of ``patterns``, chunk after chunk (valid until the next chunk is pulled)
    """
    world_to_local = caster.world_to_local
    first = 0
    for chunk in pattern_chunks(patterns, chunk_rays):
        poses = pose(chunk.time) if callable(pose) else pose
        points, beam, ray = scan_chunk(
            caster, buffers, chunk, world_to_local @ poses, min_range, max_range, max_bounces, ghost_semantic, ideal, surfaces=surfaces, rng=rng
        )
        yield (points, beam, ray + first) if with_rays else (points, beam)
        first += len(chunk)


def collect(chunks: Iterable[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """``(points, beam)`` chunks of a scan joined into one array each."""
    chunks = list(chunks)
    if not chunks:
        return np.zeros(0, POINT_DTYPE), np.zeros(0, BEAM_DTYPE)
    if len(chunks) == 1:
        return chunks[0][0], chunks[0][1]
    return join([c[0] for c in chunks]), join([c[1] for c in chunks])


def take(records: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``records[index]`` for a structured array, copied as raw bytes (numpy copies fields one by one)."""
    raw = np.dtype((np.void, records.dtype.itemsize))
    return np.ascontiguousarray(records).view(raw)[index].view(records.dtype)


def join(parts: list[np.ndarray]) -> np.ndarray:
    """Structured arrays of one dtype joined as raw bytes (numpy's concatenate copies them field by field)."""
    raw = np.dtype((np.void, parts[0].dtype.itemsize))
    return np.concatenate([np.ascontiguousarray(p).view(raw) for p in parts]).view(parts[0].dtype)


WHOLE_PATTERN_RAYS = 1 << 21  # rays of one in-memory pattern :func:`scan` traces in one chunk


def scan(*args, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """All ``(points, beam)`` of :func:`scan_chunks`, each in one array.

    Without ``chunk_rays``, one :class:`Pattern` (its rays already in memory) goes through in chunks
    of :data:`WHOLE_PATTERN_RAYS`: a whole sensor frame at once, so its records need no join and
    the threads meet twice per frame, not twice per 262 k rays (``benchmarks/bench_scan.py``). The extra
    memory is about 12 bytes per ray (Embree's distances and triangles, the limits). Slipped rays are
    looked for per chunk, so a chunk size may decide, in rare cases, whether a ray is traced again (the
    pipeline keeps its own fixed chunks).
    """
    patterns = args[2] if len(args) > 2 else kwargs.get("patterns")
    if "chunk_rays" not in kwargs and len(args) < 10 and isinstance(patterns, Pattern):
        kwargs["chunk_rays"] = WHOLE_PATTERN_RAYS
    return collect(scan_chunks(*args, **kwargs))
