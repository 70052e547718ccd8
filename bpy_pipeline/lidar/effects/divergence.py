"""Beam divergence: each beam's footprint as sub-rays over its divergence cone, reduced to one return.

A real beam is a cone, not a line: its footprint is ``aperture + mrad * 1e-3 * range`` metres
wide, so a 12 mm catenary wire that slips between two zero-width rays still returns light
from a beam whose footprint touches it. :func:`expand` replaces every beam of a
:class:`~bpy_pipeline.lidar.sensor.rays.Pattern` by ``rays`` sub-rays (sharing its ring and firing time) spread
over the cone; the scanner traces them like any rays, and :func:`reduce_returns` turns the
sub-ray hits of each beam back into one point:

1. the hits of a beam are grouped into *returns*: sorted by range, a gap larger than
   ``separation`` metres (about the pulse length, c * tau / 2) starts a new return;
2. a return's *energy* is the sum of its sub-rays' intensities (the scanner's reflectivity x
   |cos incidence| x mirror gain) over ``rays``: the share of the footprint it sends back;
   its range is the energy-weighted mean of its sub-rays' ranges (the waveform's centroid);
3. ``first``, ``last`` or ``strongest`` (most energy; ties go to the nearer) return per beam
   is kept; ``dual`` keeps two, as Velodyne's dual return mode reports them: the strongest and the
   last, or, when the last is the strongest, the strongest and the second strongest (one point
   when the beam has one return). Its point lies along the beam's *central* direction at the return's range (where
   the sensor believes it is, so thin objects look as wide as the footprint, as in real
   scans), its intensity is the return's energy, and its labels, bounces and beam facts are
   those of the return's strongest sub-ray, except that the facts' ``gain`` is scaled by the
   return's share of that sub-ray's intensity (energy / its intensity, at most 1), so that
   ``reflectivity x cos_incidence x gain`` is the return's energy and the effects (intensity
   models, detection thresholds) see the power the return really carries. With
   ``mirrors.ideal`` the point is that sub-ray's true hit instead. ``separation: 0`` makes
   every distinct sub-ray range its own return.

Dual returns in the point record: the record (:mod:`bpy_pipeline.lidar.points`) has no return-index field and writers keep
every field their format holds, so the second return is an extra point: a beam's points are
consecutive, its strongest first, and the second carries the same ``ring`` and ``time``. A reader
tells them apart by that (:func:`return_index`); effects such as drop act on each return alone.

The sub-ray pattern is deterministic (no seed): a central ray, then ``rays - 1`` rays in
opposite pairs on a golden-angle (Vogel-like) spiral (:func:`footprint_offsets`), so each stands
for an equal share of the footprint's area (a top-hat beam) and their centroid is the beam's
axis. Each sub-ray leaves
its point of the exit ``aperture`` (metres across) and diverges by the same fraction of the
half-angle ``mrad / 2``, so the footprint grows linearly from ``aperture`` at the sensor.

Memory: :func:`scan_footprint_chunks` expands one chunk of beams at a time (``chunk_rays``
sub-rays), never a whole 23-million-ray scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Iterator, Literal

import numpy as np

from ...schema import meta
from ...errors import InputError
from ...geometry.transforms import rotate
from ..cast.scanner import collect, scan_chunk
from ..sensor.rays import Pattern, pattern_chunks

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))  # radians
MAX_SUB_RAYS = 1024
MAX_MRAD = 100.0  # full-angle divergence: a beam wider than 0.1 rad (5.7 degrees) is no lidar's (effects.weather.divergence_mrad's bound too)


@dataclass(frozen=True)
class Divergence:
    """``sensor.divergence``: the beam footprint model; off (one zero-width ray a beam) by default.

    mrad : full-angle beam divergence, milliradians (footprint diameter grows by mrad mm per metre)
    rays : sub-rays per beam over the footprint (1: the central ray only, i.e. off)
    pick : which return of a beam is kept (``return`` in YAML): first, strongest or last; ``dual``:
        the strongest and the last (the sensor's dual return mode; presets list it in ``return_modes``)
    separation : metres between sub-ray ranges that split a beam's hits into separate returns
    aperture : beam diameter at the sensor's exit window, metres
    """

    mrad: float = field(default=0.0, metadata=meta("", 0, MAX_MRAD, help="full divergence angle, mrad (lidars have 0.1..10)"))
    rays: int = field(default=1, metadata=meta("", 1, MAX_SUB_RAYS, help="sub-rays per beam (1: off)"))
    pick: Literal["first", "strongest", "last", "dual"] = field(default="first", metadata={"key": "return"})
    separation: float = field(default=0.5, metadata=meta("m", low=0))
    aperture: float = field(default=0.0, metadata=meta("m", low=0))

    @property
    def active(self) -> bool:
        """True when beams are traced as several sub-rays."""
        return self.rays > 1


def check_divergence(divergence: Divergence, where: str = "sensor.divergence") -> None:
    """``InputError`` naming the key when the footprint model cannot describe a beam (beyond its fields' ranges, the schema's)."""
    if divergence.rays > 1 and divergence.mrad == 0 and divergence.aperture == 0:
        raise InputError(f"{where}.rays: {divergence.rays} sub-rays of a zero-width beam all coincide; set mrad (or aperture) > 0, or rays: 1")


def check_return_mode(divergence: Divergence, spec, where: str = "sensor.divergence") -> None:
    """``InputError`` when ``return: dual`` is asked of a preset whose ``return_modes`` (sensors.yaml) lack it,
    or of a flash camera (its pixels share ring and time, so a second return could not be told apart)."""
    if divergence.pick != "dual":
        return
    from ..sensor.sensors import FLASH_PATTERNS

    modes = preset_return_modes(spec.name)
    if spec.pattern in FLASH_PATTERNS or (spec.name != "custom" and "dual" not in modes):
        raise InputError(f"{where}.return: the {spec.name} sensor has no dual return mode; allowed: first, strongest, last")


def preset_return_modes(name: str) -> tuple[str, ...]:
    """The return modes preset ``name``'s sensor offers (its ``return_modes`` in sensors.yaml; ``()`` when it lists none)."""
    from ..sensor.sensors import _presets_file

    return tuple(_presets_file().get(name, {}).get("return_modes") or ())


def return_index(points: np.ndarray) -> np.ndarray:
    """(p,) uint8: 0 for a beam's first point, 1 for the second of a dual-return beam (same ``ring`` and
    ``time`` as the point before it, as :func:`scan_footprint_chunks` writes them)."""
    same = np.zeros(len(points), np.uint8)
    if len(points) > 1:
        same[1:] = (points["ring"][1:] == points["ring"][:-1]) & (points["time"][1:] == points["time"][:-1])
    return same


def footprint_offsets(rays: int) -> np.ndarray:
    """``(rays, 2)`` float64 sub-ray positions in the unit disk (1 = the cone's edge), centroid exactly 0.

    Equal-area cells, as a Vogel spiral makes them: the disk splits into ``rays`` rings of equal
    area, the centre ray stands for the innermost, and the others come in opposite pairs at
    golden-angle turns from the diagonal, each pair at the root-mean-square radius of its two cells; when the
    count left is odd, the outermost three cells form a triangle (120 degrees apart). Opposite
    pairs keep the footprint's centroid on the beam's axis, so a tilted surface's return is not
    biased to one side. Two rays: one opposite pair, no centre.
    """
    if rays == 2:
        return np.array([[math.sqrt(0.5), 0.0], [-math.sqrt(0.5), 0.0]])
    outer = rays - 1
    triangle = outer % 2  # 1 when the outermost three cells make a triangle
    pairs = (outer - 3 * triangle) // 2
    p = np.arange(pairs, dtype=np.float64)
    radius = np.sqrt((2 * p + 2) / rays)  # pair p: cells 2p + 1 and 2p + 2 (area fractions (k + 0.5) / rays)
    angle = math.pi / 4 + p * GOLDEN_ANGLE  # the first pair diagonal: small counts favour neither axis
    half = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    parts = [np.zeros((1, 2)), np.stack([half, -half], axis=1).reshape(-1, 2)]
    if triangle:
        turn = math.pi / 4 + pairs * GOLDEN_ANGLE + np.array([0.0, 2.0, 4.0]) * math.pi / 3
        parts.append(math.sqrt((outer - 0.5) / rays) * np.column_stack([np.cos(turn), np.sin(turn)]))
    return np.concatenate(parts)


def beam_axes(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(n, 3)`` float64 across each of the ``(n, 3)`` unit directions, right-handed with it.

    ``u`` is horizontal (z x d, normalised) unless the beam is within 26 degrees of vertical
    (then x x d); ``v = d x u``.
    """
    helper = np.zeros_like(directions)
    steep = np.abs(directions[:, 2]) > 0.9
    helper[~steep, 2] = 1.0
    helper[steep, 0] = 1.0
    u = np.cross(helper, directions)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(directions, u)


def expand(pattern: Pattern, divergence: Divergence) -> tuple[Pattern, np.ndarray]:
    """Every beam of ``pattern`` as ``divergence.rays`` sub-rays over its cone.

    Returns ``(sub_rays, beam)``: a :class:`Pattern` of ``n * rays`` rays, beam-major (the sub-rays
    of beam i are rows ``i * rays ... i * rays + rays - 1``, sub-ray 0 its central ray), sharing
    their beam's ring and time, with per-ray origins when ``aperture > 0``; and ``beam`` (n * rays,)
    int64, the beam of each sub-ray.
    """
    n, k = len(pattern), divergence.rays
    offsets = footprint_offsets(k)  # (k, 2)
    radius = np.hypot(offsets[:, 0], offsets[:, 1])
    alpha = radius * (divergence.mrad * 1e-3 / 2.0)  # (k,) radians off the beam's axis
    around = np.arctan2(offsets[:, 1], offsets[:, 0])
    along, across_u, across_v = np.cos(alpha), np.sin(alpha) * np.cos(around), np.sin(alpha) * np.sin(around)
    d = pattern.directions
    u, v = beam_axes(d)
    directions = d[:, None, :] * along[None, :, None] + u[:, None, :] * across_u[None, :, None] + v[:, None, :] * across_v[None, :, None]
    origins = pattern.origins
    if divergence.aperture > 0:
        half = divergence.aperture / 2.0
        shift = u[:, None, :] * (half * offsets[None, :, 0, None]) + v[:, None, :] * (half * offsets[None, :, 1, None])
        origins = shift if origins is None else origins[:, None, :] + shift
        origins = origins.reshape(n * k, 3)
    elif origins is not None:
        origins = np.repeat(origins, k, axis=0)
    sub = Pattern(directions.reshape(n * k, 3), np.repeat(pattern.ring, k), np.repeat(pattern.time, k), origins)
    return sub, np.repeat(np.arange(n, dtype=np.int64), k)


def reduce_returns(beam: np.ndarray, distance: np.ndarray, intensity: np.ndarray, rays: int, pick: str, separation: float):
    """One return per beam from its sub-ray hits.

    beam : (h,) int64 beam of each sub-ray hit
    distance : (h,) float64 range of each hit, metres
    intensity : (h,) float64 scanner intensity of each hit, 0..1
    rays : sub-rays per beam; pick : ``first`` | ``strongest`` | ``last`` | ``dual``; separation : metres
    Returns ``(row, distance, energy)``, one entry per beam that returned (``dual``: two where the
    beam has two returns or more, its strongest first), in beam order:
    ``row`` (k,) int64 the hit standing for the return (its strongest sub-ray, the nearer on a
    tie), ``distance`` (k,) float64 the return's energy-weighted mean range, and ``energy`` (k,)
    float64 the return's summed intensity over ``rays``.
    """
    if len(beam) == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    # by beam, then range: one float64 key (beam + range scaled into [0, 1)) sorts ten times faster than lexsort
    order = np.argsort(beam + distance / (distance.max() + 1.0), kind="stable")
    b, r, w = beam[order], distance[order], intensity[order]
    new_beam = np.r_[True, b[1:] != b[:-1]]
    starts = np.flatnonzero(new_beam | np.r_[True, np.diff(r) > separation])  # first hit of each return
    opens_return = np.zeros(len(b), bool)
    opens_return[starts] = True
    group = np.cumsum(opens_return) - 1  # (h,) return of each sorted hit
    weight = np.add.reduceat(w, starts)
    count = np.diff(np.r_[starts, len(b)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(weight > 0, np.add.reduceat(w * r, starts) / weight, np.add.reduceat(r, starts) / count)
    energy = weight / rays
    strongest_hit = w == np.maximum.reduceat(w, starts)[group]
    first_strongest = np.flatnonzero(strongest_hit)  # in sorted order, so each return's nearest strongest hit opens its run
    candidate = group[first_strongest]
    representative = order[first_strongest[np.r_[True, candidate[1:] != candidate[:-1]]]]  # (returns,) rows into the hits
    return_beam = b[starts]
    opens = np.r_[True, return_beam[1:] != return_beam[:-1]]
    if pick == "first":
        chosen = np.flatnonzero(opens)
    elif pick == "last":
        chosen = np.flatnonzero(np.r_[opens[1:], True])
    else:
        ranked = np.lexsort((np.arange(len(energy)), -energy, return_beam))  # beam, then energy down, then nearer
        heads = np.r_[True, return_beam[ranked][1:] != return_beam[ranked][:-1]]
        chosen = ranked[heads]
        if pick == "dual":
            chosen = _dual(chosen, ranked, heads, opens)
    return representative[chosen], mean[chosen], energy[chosen]


def _dual(strongest: np.ndarray, ranked: np.ndarray, heads: np.ndarray, opens: np.ndarray) -> np.ndarray:
    """Returns kept by the dual mode, in beam order, the strongest of a beam first.

    strongest : (b,) the strongest return of each beam; ranked : (q,) returns by beam, then energy
    down; heads : (q,) True where ``ranked`` starts a beam; opens : (q,) True where a return (in
    range order) starts a beam. The second is the beam's last return, or its second strongest
    when the last is the strongest (Velodyne's rule); beams of one return keep one.
    """
    last = np.flatnonzero(np.r_[opens[1:], True])  # (b,) in beam order, as strongest
    second_strongest = np.full(len(strongest), -1, np.int64)
    head = np.flatnonzero(heads & np.r_[~heads[1:], False])  # ranked positions of beams with two returns or more
    second_strongest[(np.cumsum(heads) - 1)[head]] = ranked[head + 1]
    second = np.where(last != strongest, last, second_strongest)
    pairs = np.column_stack([strongest, second]).ravel()
    return pairs[pairs >= 0]


def scan_footprint_chunks(
    caster,
    buffers,
    patterns: Pattern | Iterable[Pattern],
    pose,
    divergence: Divergence,
    min_range: float,
    max_range: float,
    max_bounces: int = 3,
    ghost_semantic: int | None = None,
    ideal: bool = False,
    chunk_rays: int = 1 << 18,
    **trace,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(points, beam)`` chunk by chunk, one point per returning beam, in the caster's frame.

    The arguments are those of :func:`bpy_pipeline.lidar.cast.scanner.scan_chunks`, plus ``divergence``; keyword
    arguments in ``trace`` go to :func:`bpy_pipeline.lidar.cast.scanner.scan_chunk` as they are. Each chunk of
    ``chunk_rays // divergence.rays`` beams is expanded, traced with the pose of each beam's
    firing time (its sub-rays share it), and reduced by :func:`reduce_returns`.
    """
    world_to_local = np.linalg.inv(caster.frame)
    k = divergence.rays
    beams_per_chunk = max(1, chunk_rays // k)
    for beams in pattern_chunks(patterns, beams_per_chunk):
        to_local = world_to_local @ (pose(beams.time) if callable(pose) else pose)  # (4, 4) or (b, 4, 4)
        sub, _ = expand(beams, divergence)
        sub_to_local = to_local if to_local.ndim == 2 else np.repeat(to_local, k, axis=0)
        points, facts, ray = scan_chunk(caster, buffers, sub, sub_to_local, min_range, max_range, max_bounces, ghost_semantic, ideal, **trace)
        beam = ray // k
        row, distance, energy = reduce_returns(beam, points["range"].astype(np.float64), points["intensity"].astype(np.float64), k, divergence.pick,
                                               divergence.separation)
        out, out_facts, beam = points[row], facts[row], beam[row]
        strongest = out["intensity"].astype(np.float64)
        share = np.divide(energy, strongest, out=np.zeros_like(energy), where=strongest > 0)  # <= 1
        out_facts["gain"] = out_facts["gain"] * share  # so reflectivity x cos x gain is the return's energy
        out["range"], out["intensity"] = distance, energy
        if not ideal:  # along the beam's central direction at the return's range
            rotation = to_local[:3, :3] if to_local.ndim == 2 else to_local[beam, :3, :3]
            translation = to_local[:3, 3] if to_local.ndim == 2 else to_local[beam, :3, 3]
            origin = translation if beams.origins is None else translation + rotate(beams.origins[beam], rotation)
            central = rotate(beams.directions[beam], rotation)
            xyz = origin + central * distance[:, None]
            out["x"], out["y"], out["z"] = xyz.T
            out_facts["direction"] = central
        yield out, out_facts


def scan_footprint(*args, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """All ``(points, beam)`` of :func:`scan_footprint_chunks`, each in one array."""
    return collect(scan_footprint_chunks(*args, **kwargs))
