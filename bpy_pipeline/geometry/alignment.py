"""Track alignment: the circular arc through a start, a mid and an end point. Pure numpy.

The construction of the railway thesis (section 4.1.1, eqs. 4.1-4.11): the plane normal
n = AB x AC, the circle centre where the perpendicular bisectors of AB and AC meet, the
tangent t = n x r / |n x r| at a point with radius vector r, and the horizontal lateral
perpendicular p = (-t_y, t_x, 0) / |(-t_y, t_x)| (to the left of the direction of travel).

Where the thesis raises an exception, this module falls back:

- collinear points (|AB x AC| numerically zero) give the straight line from start to end;
- a near-vertical tangent (|t_xy| numerically zero) takes the horizontal part of the arc's
  plane normal as its lateral axis (the continuous choice for an arc in a vertical plane),
  or +y when that is vertical too (a straight vertical line).

Start and end at the same place is a zero-length track and raises ``InputError``.
Chainage ``s`` is the arc length in metres from the start point, ``0 <= s <= length``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

COLLINEAR = 1e-9  # B closer than this fraction of |AC| to the line AC: straight
VERTICAL = 1e-9  # |t_xy| below this: the tangent is vertical, use the fallback lateral axis
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Alignment:
    """A straight line or a circular arc, parameterised by chainage (m from the start).

    start, end : (3,) float64 world points, metres
    centre : (3,) float64 circle centre, ``None`` for a straight line
    radius : float, metres (``inf`` for a straight line)
    normal : (3,) float64 unit normal of the arc's plane, the arc turns anticlockwise about it
        (a straight line: the zero vector)
    sweep : float, radians turned from start to end (0 for a straight line)
    length : float, metres along the alignment
    """

    start: np.ndarray
    end: np.ndarray
    centre: np.ndarray | None
    radius: float
    normal: np.ndarray
    sweep: float
    length: float

    @property
    def straight(self) -> bool:
        return self.centre is None

    # ------------------------------------------------------------------ evaluation at chainages
    def _angles(self, s) -> np.ndarray:
        return np.asarray(s, float).reshape(-1) / self.radius

    def _basis(self) -> tuple[np.ndarray, np.ndarray]:
        u = (self.start - self.centre) / self.radius
        return u, np.cross(self.normal, u)

    def point(self, s) -> np.ndarray:
        """``(n, 3)`` float64 points at chainages ``s`` (scalar or (n,)), metres."""
        s = np.asarray(s, float).reshape(-1)
        if self.straight:
            return self.start + s[:, None] * ((self.end - self.start) / self.length)
        phi = self._angles(s)
        u, v = self._basis()
        # relative to the start point: keeps precision on huge radii (nearly collinear points)
        return self.start + self.radius * (-2.0 * np.sin(phi / 2)[:, None] ** 2 * u + np.sin(phi)[:, None] * v)

    def tangent(self, s) -> np.ndarray:
        """``(n, 3)`` float64 unit tangents (direction of travel) at chainages ``s`` (eq. 4.9)."""
        s = np.asarray(s, float).reshape(-1)
        if self.straight:
            return np.tile((self.end - self.start) / self.length, (len(s), 1))
        phi = self._angles(s)
        u, v = self._basis()
        return -np.sin(phi)[:, None] * u + np.cos(phi)[:, None] * v

    def lateral(self, s) -> np.ndarray:
        """``(n, 3)`` float64 horizontal unit vectors to the left of travel at chainages ``s`` (eqs. 4.10-4.11)."""
        t = self.tangent(s)
        out = np.column_stack([-t[:, 1], t[:, 0], np.zeros(len(t))])
        norm = np.linalg.norm(out, axis=1)
        vertical = norm < VERTICAL
        out[~vertical] /= norm[~vertical, None]
        if vertical.any():
            out[vertical] = self.fallback_lateral()
        return out

    def fallback_lateral(self) -> np.ndarray:
        """``(3,)`` the lateral axis where the tangent is vertical: the plane normal's horizontal part, else +y."""
        horizontal = np.array([self.normal[0], self.normal[1], 0.0])
        norm = np.linalg.norm(horizontal)
        return horizontal / norm if norm >= VERTICAL else np.array([0.0, 1.0, 0.0])

    def heading(self, s) -> np.ndarray:
        """``(n,)`` float64 yaw in radians of the direction of travel (0 along +x, anticlockwise)."""
        lateral = self.lateral(s)
        return np.arctan2(-lateral[:, 0], lateral[:, 1])

    def frames(self, s, lateral_offset=0.0, height=0.0) -> np.ndarray:
        """``(n, 4, 4)`` float64 level frames at chainages ``s``: x ahead (horizontal), y left, z up.

        The origin sits ``lateral_offset`` metres along the lateral axis and ``height`` above the
        alignment point; a sensor or a support placed with this frame faces along the track.
        """
        lateral = self.lateral(s)
        out = np.zeros((len(lateral), 4, 4))
        out[:, :3, 0] = np.cross(lateral, UP)
        out[:, :3, 1] = lateral
        out[:, :3, 2] = UP
        out[:, :3, 3] = self.offset(s, lateral_offset, height)
        out[:, 3, 3] = 1.0
        return out

    def offset(self, s, lateral_offset=0.0, height=0.0) -> np.ndarray:
        """``(n, 3)`` points ``lateral_offset`` (m, + left) beside and ``height`` (m) above the alignment."""
        s = np.asarray(s, float).reshape(-1)
        lateral = np.broadcast_to(np.asarray(lateral_offset, float), s.shape)
        up = np.broadcast_to(np.asarray(height, float), s.shape)
        return self.point(s) + lateral[:, None] * self.lateral(s) + up[:, None] * UP

    def chainage_samples(self, tolerance: float, s0: float = 0.0, s1: float | None = None) -> np.ndarray:
        """``(k,)`` chainages from ``s0`` to ``s1`` whose chords stay within ``tolerance`` (m) of the arc.

        A chord over angle a deviates R (1 - cos(a / 2)) from its arc; a straight line needs its ends only.
        """
        s1 = self.length if s1 is None else s1
        if s1 <= s0:
            return np.array([s0, s0])
        if self.straight:
            return np.array([s0, s1])
        ratio = min(max(tolerance, 1e-12) / self.radius, 1.0)
        step = 2.0 * self.radius * np.arccos(1.0 - ratio)
        count = max(1, int(np.ceil((s1 - s0) / step)))
        return np.linspace(s0, s1, count + 1)

    def nearest_chainage(self, points) -> np.ndarray:
        """``(n,)`` chainage of the alignment point nearest each of ``points`` (n, 3) (ends included)."""
        points = np.asarray(points, float).reshape(-1, 3)
        if self.straight:
            direction = (self.end - self.start) / self.length
            return np.clip((points - self.start) @ direction, 0.0, self.length)
        u, v = self._basis()
        r = points - self.centre
        phi = np.mod(np.arctan2(r @ v, r @ u), 2 * np.pi)
        beyond = phi > self.sweep
        # past the end: the nearer of the two ends, measured around the circle
        to_end = phi - self.sweep
        to_start = 2 * np.pi - phi
        phi = np.where(beyond, np.where(to_end < to_start, self.sweep, 0.0), phi)
        return phi * self.radius


def arc_through(start, mid, end, where: str = "alignment") -> Alignment:
    """The :class:`Alignment` through ``start``, ``mid`` and ``end`` (each (3,), metres, world).

    Collinear points, or a mid point on an end point, give the straight line from start to end.
    ``InputError`` naming ``where`` when start and end coincide or a point is not finite.
    """
    a, b, c = (np.asarray(p, float).reshape(3) for p in (start, mid, end))
    if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(c).all()):
        raise InputError(f"{where}: start, mid and end must be finite points, got {a.tolist()}, {b.tolist()}, {c.tolist()}")
    ab, ac = b - a, c - a
    chord = float(np.linalg.norm(ac))
    if chord == 0.0 or chord < 1e-9 * max(1.0, float(np.abs(a).max())):
        raise InputError(f"{where}: start and end coincide ({a.tolist()}); a track needs a length")
    n = np.cross(ab, ac)
    n_norm = float(np.linalg.norm(n))
    if n_norm <= COLLINEAR * chord * chord:  # distance of B from line AC <= COLLINEAR * |AC|
        return Alignment(a, c, None, float("inf"), np.zeros(3), 0.0, chord)
    normal = n / n_norm
    # circumcentre: where the perpendicular bisectors of AB and AC meet (eqs. 4.3-4.5)
    centre = a + np.cross(np.dot(ab, ab) * ac - np.dot(ac, ac) * ab, n) / (2.0 * n_norm**2)
    radius = float(np.linalg.norm(a - centre))
    u = (a - centre) / radius
    v = np.cross(normal, u)
    rc = c - centre
    sweep = float(np.mod(np.arctan2(rc @ v, rc @ u), 2 * np.pi))
    return Alignment(a, c, centre, radius, normal, sweep, radius * sweep)
