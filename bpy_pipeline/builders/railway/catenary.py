"""Overhead-line wires between two attachment points: sag law, sampling, droppers, exact catenary. Pure numpy.

The catenary manager of the railway thesis (section 4.1.2, table 4.2), in metres:

- sag law: f(L) = f_ref (L / L_ref)^alpha, or f_ref when L_ref is (numerically) zero;
- the wire: z(t) = z_line(t) - 4 s x (L - x) / L^2 along the chord from A to B, x = L t;
- sampling: n = max(3, floor(max(2, L / 10 m) * points_per_10m)) samples at t = i / (n - 1);
- droppers: n = max(1, floor(L / spacing)), jittered along the span, staggered between the two
  contact wires of a doubled contact wire.

Beside the thesis's parabola, the exact catenary z = a cosh((x - x0) / a) + c is available
(:func:`catenary_points`) with the parabola's error against it (:func:`parabola_error`):
for level supports and the same mid-span sag s that error is s^3 / (3 L^2) to leading order,
so a railway wire (s / L about 1 %) is a parabola to a micrometre.
A span whose two ends share x and y (zero length, or vertical) raises ``InputError``.
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError

EPS = 1e-6  # m: the thesis's numerical guard


def sag_for_span(span: float, reference_sag: float, reference_length: float, exponent: float) -> float:
    """Mid-span sag (m) of a wire over ``span`` (m): f_ref (L / L_ref)^alpha; f_ref when L_ref <= EPS."""
    if reference_length <= EPS:
        return float(reference_sag)
    return float(reference_sag) * (float(span) / float(reference_length)) ** float(exponent)


def _span(start: np.ndarray, end: np.ndarray, where: str) -> float:
    span = float(np.linalg.norm((end - start)[:2]))
    if span <= EPS:
        raise InputError(f"{where}: zero-length span: the attachment points {start.tolist()} and {end.tolist()} share x and y")
    return span


def parabolic_sag(start, end, sag: float, samples: int, where: str = "span") -> np.ndarray:
    """``(samples, 3)`` float64 points of a wire hanging between ``start`` and ``end`` ((3,), m).

    z(t) = z_line(t) - 4 s x (L - x) / L^2 with x = L t the distance along the span, L the span
    and s the sag at mid-span (the railway thesis, section 4.1.2); samples at t = i / (samples - 1).
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    if samples < 3:
        raise InputError(f"{where}: a sagging wire needs at least three samples, got {samples}")
    _span(start, end, where)
    u = np.linspace(0.0, 1.0, samples)
    points = start + u[:, None] * (end - start)
    points[:, 2] -= 4.0 * sag * u * (1.0 - u)
    return points


def thesis_sample_count(span: float, points_per_10m: int) -> int:
    """The thesis's sample count: max(3, floor(max(2, L / 10 m) * points_per_10m))."""
    return max(3, int(math.floor(max(2.0, span / 10.0) * points_per_10m)))


def chord_error(span: float, sag: float, samples: int) -> float:
    """Largest distance (m) between the parabola and its chords when sampled at ``samples`` even steps.

    A parabola of mid-span sag s has the constant second derivative 8 s / L^2, so a chord over
    a step h misses it by s h^2 / L^2 at the chord's middle.
    """
    steps = max(samples - 1, 1)
    return abs(sag) / steps**2


def samples_for_tolerance(sag: float, tolerance: float, minimum: int = 3) -> int:
    """Fewest even samples (>= ``minimum``) whose chords stay within ``tolerance`` (m) of a wire of sag ``sag`` (m)."""
    if tolerance <= 0:
        raise InputError(f"wire sampling: the tolerance must be > 0 m, got {tolerance}")
    steps = math.ceil(math.sqrt(abs(sag) / tolerance)) if sag else 1
    return max(minimum, steps + 1)


def dropper_count(span: float, spacing: float) -> int:
    """The thesis's dropper count n = max(1, floor(L / s)), with s = max(spacing, EPS)."""
    return max(1, int(math.floor(span / max(spacing, EPS))))


def dropper_positions(span: float, spacing: float, jitter: float, rng: np.random.Generator, shift: float = 0.0) -> np.ndarray:
    """``(n,)`` float64 dropper parameters t in (0, 1) along a span of ``span`` metres, in order.

    n = :func:`dropper_count`; the droppers sit at t_k = (k + shift) / (n + 1), k = 1..n (evenly
    between the supports; the thesis snaps them to its curve samples, which ties them to the
    sampling density), each moved along the span by a uniform jitter of +-``jitter`` metres and
    kept a quarter step clear of the supports. A doubled contact wire takes shift -1/4 for one
    wire and +1/4 for the other: their droppers alternate half a step apart ("en quinconce").
    """
    n = dropper_count(span, spacing)
    step = 1.0 / (n + 1)
    t = (np.arange(1, n + 1) + shift) * step
    if jitter > 0:
        t = t + rng.uniform(-jitter, jitter, n) / span
    return np.clip(t, 0.25 * step, 1.0 - 0.25 * step)


# ----------------------------------------------------------------------------- the exact catenary
def catenary_parameter(span: float, sag: float) -> float:
    """The parameter a = H / w (m) of the catenary with level supports ``span`` apart and mid-span ``sag``.

    Solves a (cosh(L / (2 a)) - 1) = s by Newton's method from the parabola's a = L^2 / (8 s).
    """
    if span <= 0 or sag <= 0:
        raise InputError(f"catenary: span and sag must be > 0 m, got span {span}, sag {sag}")
    half = span / 2.0
    # in u = L / (2 a): cosh(u) - 1 = (2 s / L) u, a smooth root; start from the parabola's u = 4 s / L
    k = 2.0 * sag / span
    u = 2.0 * k
    for _ in range(100):
        f = math.cosh(u) - 1.0 - k * u
        step = f / (math.sinh(u) - k)
        u -= step
        if abs(step) < 1e-15 * max(u, 1e-300):
            break
    return half / u


def catenary_points(start, end, parameter: float, samples: int, where: str = "span") -> np.ndarray:
    """``(samples, 3)`` float64 points of the exact catenary of parameter a (m) through ``start`` and ``end``.

    z(x) = z0 + a (cosh((x - x0) / a) - cosh((0 - x0) / a)) along the horizontal chord, x0 placing
    the lowest point so the curve meets both ends (x0 = L/2 - a asinh(dz / (2 a sinh(L / (2 a))))).
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    span = _span(start, end, where)
    a = float(parameter)
    dz = end[2] - start[2]
    x0 = span / 2.0 - a * math.asinh(dz / (2.0 * a * math.sinh(span / (2.0 * a))))
    u = np.linspace(0.0, 1.0, samples)
    x = u * span
    points = start + u[:, None] * (end - start)
    points[:, 2] = start[2] + a * (np.cosh((x - x0) / a) - math.cosh(x0 / a))
    return points


def catenary_with_sag(start, end, sag: float, samples: int, where: str = "span") -> np.ndarray:
    """The exact catenary through ``start`` and ``end`` that hangs ``sag`` (m) below the chord at mid-span."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    span = _span(start, end, where)
    if sag <= 0:
        return parabolic_sag(start, end, 0.0, max(samples, 3), where)
    # the chord's mid-span depth grows monotonically with 1 / a: bisect on log a
    dz = end[2] - start[2]

    def depth(a: float) -> float:
        x0 = span / 2.0 - a * math.asinh(dz / (2.0 * a * math.sinh(span / (2.0 * a))))
        mid = a * (math.cosh((span / 2.0 - x0) / a) - math.cosh(x0 / a))
        return dz / 2.0 - mid

    a = catenary_parameter(span, sag)
    lo, hi = a / 10.0, a * 10.0
    while depth(lo) <= sag:
        lo /= 2.0
    while depth(hi) > sag:
        hi *= 2.0
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if depth(mid) > sag:
            lo = mid
        else:
            hi = mid
        if hi / lo - 1.0 < 1e-14:
            break
    return catenary_points(start, end, math.sqrt(lo * hi), samples, where)


def parabola_error(span: float, sag: float, samples: int = 2001) -> float:
    """Largest vertical distance (m) between the parabola and the exact catenary of the same mid-span sag.

    Level supports ``span`` (m) apart; to leading order s^3 / (3 L^2), at x = L / 2 +- L / (2 sqrt 2).
    """
    if sag <= 0:
        return 0.0
    start, end = np.zeros(3), np.array([span, 0.0, 0.0])
    exact = catenary_with_sag(start, end, sag, samples)
    return float(np.abs(parabolic_sag(start, end, sag, samples)[:, 2] - exact[:, 2]).max())


def resample(points: np.ndarray, t) -> np.ndarray:
    """``(k, 3)`` points at parameters ``t`` (k,) in [0, 1] of a polyline ``points`` (n, 3) sampled at even t."""
    grid = np.linspace(0.0, 1.0, len(points))
    t = np.asarray(t, float)
    return np.column_stack([np.interp(t, grid, points[:, k]) for k in range(3)])
