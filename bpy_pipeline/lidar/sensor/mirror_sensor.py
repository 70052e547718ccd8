"""The super-resolution mirror LiDAR: a spinning sensor that sees the world through its own ring of mirrors.

The sensor of *Raphael: Realistic 3D Data Generation and Unsupervised Learning for Enhanced Human-Robot Detection in the Real World* is an Ouster
OS1-128 (128 channels
over 45 deg, 2048 columns, 10 Hz) mounted overhead inside ``segments`` planar mirrors arranged
around it. Every ray reflects once on the sensor's own mirrors before it enters the scene, so
the whole 360 x 45 deg sweep is folded down onto the floor below: each segment maps its own
45 deg wedge of columns onto a trapezoid of floor centred on its own direction, and the eight
overlapping trapezoids form the real sensor's star pattern.

Geometry, in the sensor frame (z the spin axis, up; the optical centre at the origin). Segment
``k`` is centred at azimuth ``phi_k = azimuth_deg + k * 360 / segments`` (u_k the horizontal
unit vector there). Its plane passes through ``distance * u_k`` (where the horizontal beam of
that azimuth meets it) and makes ``inclination_deg`` (i) with the spin axis; its unit normal
``n_k = -cos(i) u_k - sin(i) z`` faces the sensor and the floor. A horizontal beam therefore
leaves the mirror 2 i below the horizon, heading back under the sensor: at the paper's 34 deg
the 45 deg fan of the OS1-128 (+-22.5 deg) covers 45.5 to 90.5 deg below the horizon at a
segment's centre, a cone of 44.5 deg around the nadir (40.4 deg below the horizon at the
segments' edges: the points of the star). (34 deg measured from the horizontal instead is
``inclination_deg: 56``: the same cone with the fan sent outward, not under the sensor; its
mirrors must reach about three times as far down the slope.) Together the planes form
a pyramid frustum narrowing upward; segment ``k`` is its facet, cut to ``bottom`` and ``top``
metres along the slope below and above the centre point and, when ``width`` > 0, to that width.

A ray from the optical centre stays in its vertical half-plane, so the facet of its azimuth is
the only one it can meet. It is reflected there (r = d - 2 (d.n) n); rays that miss their
facet, meet it from behind, or would meet a second facet after reflecting are lost. Points are
placed at their true positions: the real sensor is calibrated for its mirrors, and the scanner
starts each reflected ray at its mirror point (``Pattern.origins``). The scanner's ``range`` of
such a point is therefore the path from the mirror point; the leg from the optical centre to
the mirror (:attr:`MirrorRays.leg`, 0.08 to 0.17 m in the default geometry) is not in it.

Mirror-edge drop: where a beam's footprint straddles a segment edge the beam splits and its
return is lost. :func:`edge_drop_mask` gives the per-pixel drop probability over the frame's
rows x columns image (:mod:`.grid`), from the segment edges and the beam's diameter at the
mirror; :func:`load_edge_mask` reads a measured one instead; :func:`drop_at_edges` applies
either with the frame's generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ...errors import InputError
from . import grid
from .sensors import SensorSpec, sensor_pattern
from .rays import Pattern, load_numeric_npy

# A ``reflector`` below is any object with the attributes of ``config.ReflectorConfig``: segments (int),
# inclination_deg, azimuth_deg (degrees), distance, bottom, top, width (metres).


@dataclass(frozen=True)
class Facets:
    """The mirror segments (``s`` of them), sensor frame.

    centre : (s, 3) float64 where each segment's central horizontal beam meets it, metres
    normal : (s, 3) float64 unit normals facing the sensor
    across : (s, 3) float64 unit horizontal in-plane axes (``a`` coordinate, towards growing azimuth)
    up : (s, 3) float64 unit in-plane axes up the slope (``b`` coordinate)
    edges : (e, 3) float64 the segment outline as half-planes ``A a + B b <= C`` with unit (A, B),
        the same for every segment
    """

    centre: np.ndarray
    normal: np.ndarray
    across: np.ndarray
    up: np.ndarray
    edges: np.ndarray


@dataclass(frozen=True)
class MirrorRays:
    """Where each of ``n`` rays from the optical centre meets the sensor's mirrors.

    segment : (n,) int64 the segment met, -1 where the ray is lost
    origin : (n, 3) float64 the point on the mirror, sensor frame, metres (NaN where lost)
    direction : (n, 3) float64 the reflected unit direction (NaN where lost)
    leg : (n,) float64 metres from the optical centre to the mirror point (NaN where lost)
    clearance : (n,) float64 the widest beam radius, metres (across the beam), whose footprint
        on the mirror stays inside the segment (NaN where lost)
    """

    segment: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    leg: np.ndarray
    clearance: np.ndarray

    @property
    def kept(self) -> np.ndarray:
        """(n,) bool: rays that leave the sensor."""
        return self.segment >= 0


def check_reflector(reflector, where: str = "sensor.reflector") -> None:
    """``InputError`` naming the key when the mirror geometry cannot be built (beyond its fields' ranges, the schema's)."""
    n, incl = reflector.segments, reflector.inclination_deg
    if n < 3 and reflector.width <= 0:
        raise InputError(f"{where}.width: {n} segment(s) do not close around the sensor; give each a width > 0 m (or use >= 3 segments)")
    if reflector.bottom + reflector.top <= 0:
        raise InputError(f"{where}.top: top and bottom must have a sum > 0 m, got top {reflector.top}, bottom {reflector.bottom}")
    apex = reflector.distance / math.sin(math.radians(incl))
    if n >= 3 and reflector.top >= apex:
        raise InputError(f"{where}.top: the segments meet {apex:.4g} m up the slope; top must be below that, got {reflector.top}")


def facets(reflector) -> Facets:
    """The segment planes and outline of ``reflector`` (see the module docstring)."""
    n = reflector.segments
    incl = math.radians(reflector.inclination_deg)
    phi = np.radians(reflector.azimuth_deg + np.arange(n) * 360.0 / n)
    u = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])
    across = np.column_stack([-np.sin(phi), np.cos(phi), np.zeros(n)])
    z = np.array([0.0, 0.0, 1.0])
    normal = -math.cos(incl) * u - math.sin(incl) * z
    up = -math.sin(incl) * u + math.cos(incl) * z
    edges = [(0.0, 1.0, reflector.top), (0.0, -1.0, reflector.bottom)]
    if n >= 3:  # the hips where neighbouring facets meet: |a| <= (distance - b sin i) tan(pi / n)
        t = math.tan(math.pi / n)
        norm = math.hypot(1.0, t * math.sin(incl))
        edges += [(1.0 / norm, t * math.sin(incl) / norm, reflector.distance * t / norm),
                  (-1.0 / norm, t * math.sin(incl) / norm, reflector.distance * t / norm)]
    if reflector.width > 0:
        edges += [(1.0, 0.0, reflector.width / 2), (-1.0, 0.0, reflector.width / 2)]
    return Facets(reflector.distance * u, normal, across, up, np.array(edges))


def _segment_of_azimuth(reflector, directions: np.ndarray) -> np.ndarray:
    """``(n,)`` int64 segment whose azimuth wedge holds each direction (a ray on a hip: the upper wedge)."""
    wedge = 2.0 * math.pi / reflector.segments
    azimuth = np.arctan2(directions[:, 1], directions[:, 0]) - math.radians(reflector.azimuth_deg)
    return np.floor((azimuth + wedge / 2) / wedge + 1e-9).astype(np.int64) % reflector.segments  # a ray on a hip goes to the upper wedge


EDGE_TOLERANCE = 1e-12  # metres: a ray this close outside an edge still counts as on its segment


def _edge_margins(f: Facets, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(m, e)`` in-plane distances of points ``(a, b)`` (m,) to each edge line, > 0 inside."""
    return f.edges[:, 2] - a[:, None] * f.edges[:, 0] - b[:, None] * f.edges[:, 1]


def trace_mirrors(reflector, directions: np.ndarray) -> MirrorRays:
    """Reflect rays leaving the optical centre along ``directions`` (n, 3) unit vectors on the sensor's mirrors."""
    d = np.asarray(directions, np.float64)
    f = facets(reflector)
    incl = math.radians(reflector.inclination_deg)
    plane = -reflector.distance * math.cos(incl)  # n_k . centre_k, the same for every segment
    k = _segment_of_azimuth(reflector, d)
    normal = f.normal[k]
    d_dot_n = np.einsum("ij,ij->i", d, normal)
    d_across, d_up = np.einsum("ij,ij->i", d, f.across[k]), np.einsum("ij,ij->i", d, f.up[k])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = plane / d_dot_n
        front = (d_dot_n < 0) & (t > 0)
        t = np.where(front, t, 0.0)
        a, b = t * d_across, t * d_up + reflector.distance * math.sin(incl)  # in-plane, from the centre point
        margins = _edge_margins(f, a, b)
        kept = front & (margins >= -EDGE_TOLERANCE).all(axis=1)
        point = d * t[:, None]
        reflected = d - 2.0 * d_dot_n[:, None] * normal
        kept &= ~_meets_another_facet(reflector, f, point, reflected, kept)
        # A beam of radius rho covers, across edge line j (in-plane unit normal m_j), rho * sqrt(1 + ((d.m_j) / (d.n))^2)
        # of the plane; the clearance is the rho whose footprint just touches the nearest edge.
        d_dot_m = d_across[:, None] * f.edges[:, 0] + d_up[:, None] * f.edges[:, 1]
        clearance = (np.maximum(margins, 0.0) / np.sqrt(1.0 + (d_dot_m / d_dot_n[:, None]) ** 2)).min(axis=1)
    lost = ~kept
    point[lost] = np.nan
    reflected[lost] = np.nan
    return MirrorRays(np.where(kept, k, -1), point, reflected, np.where(kept, t, np.nan), np.where(kept, clearance, np.nan))


def _meets_another_facet(reflector, f: Facets, point: np.ndarray, reflected: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: kept rays whose reflection meets another segment (they are lost).

    The facet planes bound a convex frustum between the segments' bottom and top heights, and a
    reflected ray starts on its boundary heading in. It leaves through the first facet plane it
    crosses or through the bottom or top height; it meets a mirror only in the first case, and
    only there (outside a convex body it never comes back).
    """
    blocked = np.zeros(len(point), bool)
    rows = np.flatnonzero(kept)
    if len(f.centre) < 2 or not len(rows):
        return blocked
    p, r = point[rows], reflected[rows]
    incl = math.radians(reflector.inclination_deg)
    plane = -reflector.distance * math.cos(incl)
    r_dot_n = r @ f.normal.T  # (m, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (plane - p @ f.normal.T) / r_dot_n
        t = np.where((r_dot_n < 0) & (t > 1e-12), t, np.inf)  # crossings from inside to outside
        z_low, z_high = -reflector.bottom * math.cos(incl), reflector.top * math.cos(incl)
        t_slab = np.where(r[:, 2] < 0, (z_low - p[:, 2]) / r[:, 2], np.where(r[:, 2] > 0, (z_high - p[:, 2]) / r[:, 2], np.inf))
    first = np.argmin(t, axis=1)
    t_first = t[np.arange(len(rows)), first]
    candidate = t_first < t_slab
    if candidate.any():
        c = np.flatnonzero(candidate)
        other = first[c]
        q = p[c] + t_first[c, None] * r[c]
        rel = q - f.centre[other]
        a, b = np.einsum("ij,ij->i", rel, f.across[other]), np.einsum("ij,ij->i", rel, f.up[other])
        blocked[rows[c[(_edge_margins(f, a, b) >= -EDGE_TOLERANCE).all(axis=1)]]] = True
    return blocked


def reflect_pattern(pattern: Pattern, reflector, rays: MirrorRays | None = None) -> Pattern:
    """The rays of ``pattern`` as they leave the mirrors: per-ray origins on the mirrors, reflected directions.

    Lost rays are left out; the others keep their ring and firing time (so their pixel in the
    frame's image is still known, :func:`.grid.pixels`). Origins and directions are in the
    sensor frame. ``rays``: :func:`trace_mirrors` of ``pattern``, when already traced. A pattern
    that already has per-ray origins is refused: the mirrors are traced from the optical centre.
    """
    if pattern.origins is not None:
        raise ValueError("reflect_pattern: the sensor's mirrors are traced from its optical centre; this pattern already has per-ray origins")
    rays = trace_mirrors(reflector, pattern.directions) if rays is None else rays
    kept = rays.kept
    return Pattern(rays.direction[kept], pattern.ring[kept], pattern.time[kept], rays.origin[kept])


def reflect_patterns(patterns: Iterable[Pattern], reflector) -> Iterator[Pattern]:
    """:func:`reflect_pattern` of each chunk of a pattern stream (``sensors.iter_pattern``)."""
    for pattern in patterns:
        yield reflect_pattern(pattern, reflector)


@dataclass(frozen=True)
class MirrorFrame:
    """Every ray of one frame of a sensor and where its own mirrors send it (traced once, used twice).

    pattern : :class:`Pattern` the sensor's rays as fired (sensor frame), all of a frame
    rays : :class:`MirrorRays` of them
    """

    pattern: Pattern
    rays: MirrorRays

    @classmethod
    def of(cls, reflector, spec: SensorSpec, frame: int = 0) -> "MirrorFrame":
        pattern = sensor_pattern(spec, frame)
        return cls(pattern, trace_mirrors(reflector, pattern.directions))

    def reflected(self, reflector) -> Pattern:
        """The rays that leave the sensor (:func:`reflect_pattern`)."""
        return reflect_pattern(self.pattern, reflector, self.rays)

    def edge_drop_mask(self, spec: SensorSpec, probability: float, beam_diameter: float) -> np.ndarray:
        """``(rows, columns)`` float32 drop probabilities (:func:`edge_drop_mask`); ``spec`` must be the frame's."""
        grid.check_grid(spec, "sensor.reflector.edge_drop")
        rays = self.rays
        p = np.where(rays.kept, np.where(rays.clearance < beam_diameter / 2.0, probability, 0.0), 1.0)
        mask = np.ones(grid.image_shape(spec), np.float32)
        row, column = grid.pixels(spec, self.pattern.ring, self.pattern.time)
        mask[row, column] = p
        return mask


# ----------------------------------------------------------------------------- mirror-edge drop
def edge_drop_mask(reflector, spec: SensorSpec, probability: float, beam_diameter: float) -> np.ndarray:
    """``(rows, columns)`` float32 drop probability of every pixel of the frame's image (:mod:`.grid` layout).

    ``probability`` where the beam's footprint on the mirror (``beam_diameter`` metres across
    the beam, stretched by the incidence) straddles an edge of its segment, 0 elsewhere, and 1
    where the ray misses the mirrors altogether. With ``segments`` evenly spaced and a column
    count that is a multiple of ``segments``, the mask repeats every ``columns / segments``
    columns: once per mirror.
    """
    grid.check_grid(spec, "sensor.reflector.edge_drop")
    return MirrorFrame.of(reflector, spec).edge_drop_mask(spec, probability, beam_diameter)


def load_edge_mask(path: str | Path, shape: tuple[int, int], where: str = "sensor.reflector.edge_drop.mask") -> np.ndarray:
    """A measured ``(rows, columns)`` drop-probability mask from an ``.npy`` file, as float32 in 0..1.

    The file holds probabilities (float, 0..1) or a dropped-or-not mask (bool, or integers 0/1),
    in the :mod:`.grid` layout (row 0 the highest beam, column 0 the first fired).
    """
    mask = load_numeric_npy(path, where, "biuf", "drop probabilities")
    if mask.shape != tuple(shape):
        raise InputError(f"{where}: {path} has shape {mask.shape}, expected {tuple(shape)} (rows x columns of the sensor's image)")
    mask = mask.astype(np.float32)
    if not (np.isfinite(mask).all() and (mask >= 0).all() and (mask <= 1).all()):
        raise InputError(f"{where}: {path} must hold probabilities in 0..1")
    return mask


def drop_at_edges(points: np.ndarray, mask: np.ndarray, spec: SensorSpec, rng: np.random.Generator) -> np.ndarray:
    """``(p,)`` bool: which of ``points`` (POINT_DTYPE) survive the per-pixel drop ``mask`` (rows, columns).

    One uniform draw per point from ``rng``, in point order; a point is dropped when its draw
    falls below its pixel's probability.
    """
    row, column = grid.pixels(spec, points["ring"], points["time"])
    return rng.random(len(points)) >= mask[row, column]
