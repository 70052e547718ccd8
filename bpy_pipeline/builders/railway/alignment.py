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

from ...errors import InputError

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

    def curvature(self, s) -> np.ndarray:
        """``(n,)`` curvature (1/m) at chainages ``s``: 1 / radius on an arc, 0 on a straight line."""
        s = np.asarray(s, float).reshape(-1)
        return np.full(len(s), 0.0 if self.straight else 1.0 / self.radius)

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


# ----------------------------------------------------------------------------- transition curves
TABLE_STEP = 0.05  # m between the tabulated points of a transition alignment


def _transition_headings(s: np.ndarray, length: float, transition: float, kappa: float) -> np.ndarray:
    """Heading change (radians) at chainages ``s`` of clothoid - arc - clothoid: curvature rising linearly from 0
    to ``kappa`` (1/m) over ``transition`` m, constant, then falling to 0 over the last ``transition`` m."""
    s = np.asarray(s, float)
    L, S = transition, length
    entry = kappa * s**2 / (2 * L)
    body = kappa * (L / 2 + (s - L))
    rest = S - s
    exit_ = kappa * (S - L) - kappa * rest**2 / (2 * L)
    return np.where(s < L, entry, np.where(s <= S - L, body, exit_))


def _transition_table(length: float, transition: float, kappa: float, step: float = TABLE_STEP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s (k,), xy (k, 2), heading (k,))`` in the curve's own frame (start at the origin heading +x, turning left)."""
    count = max(2, int(np.ceil(length / step)) + 1)
    s = np.linspace(0.0, length, count)
    mid = (s[:-1] + s[1:]) / 2
    theta_mid = _transition_headings(mid, length, transition, kappa)
    h = np.diff(s)
    xy = np.zeros((count, 2))
    xy[1:, 0] = np.cumsum(h * np.cos(theta_mid))
    xy[1:, 1] = np.cumsum(h * np.sin(theta_mid))
    return s, xy, _transition_headings(s, length, transition, kappa)


@dataclass(frozen=True)
class TransitionAlignment(Alignment):
    """A level curve of clothoid transitions and a circular arc between them, from the same start and end
    points and tangents as the arc it replaces (:func:`with_transitions`). ``radius`` and ``centre`` are
    the central arc's (smaller than the plain arc's); positions come from a table every 5 cm.

    transition : m of each clothoid; table_s (k,), table_xy (k, 2) world plan positions, table_heading (k,) radians
    """

    transition: float = 0.0
    table_s: np.ndarray = None
    table_xy: np.ndarray = None
    table_heading: np.ndarray = None

    def curvature(self, s) -> np.ndarray:
        """``(n,)`` plan curvature (1/m, >= 0) at chainages ``s``."""
        s = np.clip(np.asarray(s, float).reshape(-1), 0.0, self.length)
        k, L, S = 1.0 / self.radius, self.transition, self.length
        return np.where(s < L, k * s / L, np.where(s <= S - L, k, k * (S - s) / L))

    def point(self, s) -> np.ndarray:
        s = np.clip(np.asarray(s, float).reshape(-1), 0.0, self.length)
        x = np.interp(s, self.table_s, self.table_xy[:, 0])
        y = np.interp(s, self.table_s, self.table_xy[:, 1])
        return np.column_stack([x, y, np.full(len(s), self.start[2])])

    def tangent(self, s) -> np.ndarray:
        s = np.clip(np.asarray(s, float).reshape(-1), 0.0, self.length)
        theta = np.interp(s, self.table_s, self.table_heading)
        return np.column_stack([np.cos(theta), np.sin(theta), np.zeros(len(s))])

    def chainage_samples(self, tolerance: float, s0: float = 0.0, s1: float | None = None) -> np.ndarray:
        """Chainages whose chords stay within ``tolerance`` of the curve (the central arc's spacing everywhere)."""
        s1 = self.length if s1 is None else s1
        if s1 <= s0:
            return np.array([s0, s0])
        ratio = min(max(tolerance, 1e-12) / self.radius, 1.0)
        step = max(2.0 * self.radius * np.arccos(1.0 - ratio), TABLE_STEP)
        return np.linspace(s0, s1, max(1, int(np.ceil((s1 - s0) / step))) + 1)

    def nearest_chainage(self, points) -> np.ndarray:
        """Nearest chainage to each of ``points`` (n, 3): the nearest tabulated point within 1 m steps, then refined."""
        points = np.asarray(points, float).reshape(-1, 3)[:, :2]
        coarse = np.arange(0, len(self.table_s), max(1, int(round(1.0 / TABLE_STEP))))
        out = np.empty(len(points))
        for start in range(0, len(points), 2048):
            p = points[start:start + 2048]
            d = ((p[:, None] - self.table_xy[coarse][None]) ** 2).sum(-1)
            best = coarse[np.argmin(d, axis=1)]
            window = best[:, None] + np.arange(-40, 41)[None]
            window = np.clip(window, 0, len(self.table_s) - 1)
            fine = ((p[:, None] - self.table_xy[window]) ** 2).sum(-1)
            i = window[np.arange(len(p)), np.argmin(fine, axis=1)]
            along = np.column_stack([np.cos(self.table_heading[i]), np.sin(self.table_heading[i])])
            out[start:start + 2048] = self.table_s[i] + ((p - self.table_xy[i]) * along).sum(1)  # onto the tangent there
        return np.clip(out, 0.0, self.length)


def with_transitions(arc: Alignment, transition: float, where: str = "alignment") -> Alignment:
    """``arc`` with clothoid transitions of ``transition`` m at both ends: the same start and end points and
    tangents and the same total turn, the central arc tighter. ``transition`` 0 (or a straight line) gives ``arc``.

    ``InputError`` naming ``where`` when the arc is not level or too short for two transitions.
    """
    if transition <= 0 or arc.straight:
        return arc
    if abs(arc.normal[2]) < 0.999 or abs(arc.end[2] - arc.start[2]) > 1e-9:
        raise InputError(f"{where}.transition_length: transition curves need a level curve (start, mid and end at one height)")
    turn = arc.sweep
    chord = float(np.linalg.norm((arc.end - arc.start)[:2]))

    def chord_of(length):
        kappa = turn / (length - transition)
        _, xy, _ = _transition_table(length, transition, kappa, max(TABLE_STEP, length / 4000))
        return float(np.linalg.norm(xy[-1]))

    lo, hi = max(arc.length, 2 * transition * 1.0001), 2 * arc.length + 4 * transition
    if chord_of(lo) > chord:
        raise InputError(
            f"{where}.transition_length: two transitions of {transition:g} m do not fit a {turn * 180 / np.pi:.3g} deg curve between the points; shorten them"
        )
    for _ in range(80):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if chord_of(mid) < chord else (lo, mid)
    length = (lo + hi) / 2
    kappa = turn / (length - transition)
    s, xy, heading = _transition_table(length, transition, kappa)
    left = 1.0 if arc.normal[2] > 0 else -1.0  # anticlockwise seen from above: turning left
    t0 = arc.tangent(np.zeros(1))[0]
    theta0 = float(np.arctan2(t0[1], t0[0]))
    c, sn = np.cos(theta0), np.sin(theta0)
    local = np.column_stack([xy[:, 0], left * xy[:, 1]])
    world = arc.start[:2] + local @ np.array([[c, sn], [-sn, c]])
    headings = theta0 + left * heading
    middle = np.interp(length / 2, s, np.arange(len(s)))
    i = int(round(middle))
    normal_left = np.array([-np.sin(headings[i]), np.cos(headings[i])])
    centre2 = world[i] + left * normal_left / kappa
    centre = np.array([centre2[0], centre2[1], arc.start[2]])
    end = np.array([world[-1, 0], world[-1, 1], arc.start[2]])
    return TransitionAlignment(arc.start, end, centre, 1.0 / kappa, arc.normal, turn, length, transition, s, world, headings)
