"""Particles along beams, and what the weather does to each return (:class:`_Medium`), shared by every weather kind.

A medium of particles (:class:`_Particles`: rain drops, snow flakes) is sampled in each beam's cone; only the
particles that can clear the sensor's noise floor are drawn, in passes of at most :data:`PARTICLES_PER_PASS`,
and the strongest of each beam is offered as its scatterer (:func:`_offer_particles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..intensity import MIN_RANGE

DEFAULT_DIVERGENCE_MRAD = 3.0  # the snowfall paper's HDL-64 beam
PARTICLES_PER_PASS = 4e6  # visible particles drawn at once (a pass peaks at 421 MB: benchmarks/results/weather_particles.json); more are drawn in passes


def overlap(r: np.ndarray, r1: float = 0.9, r2: float = 1.0) -> np.ndarray:
    """The fog paper's transmitter/receiver overlap ``xi(R)``: 0 up to ``r1``, 1 from ``r2``, linear between; (n,) float64."""
    return np.clip((np.asarray(r, np.float64) - r1) / (r2 - r1), 0.0, 1.0)


@dataclass(frozen=True)
class _Particles:
    """A medium of particles: ``per_m3`` of them per cubic metre, diameters ``d0 + Exp(mean)`` truncated at ``cap`` (m),
    returning like a diffuse target of ``reflectivity`` over their share ``(D / (phi x))^2`` of the footprint."""

    per_m3: float
    d0: float
    mean: float
    cap: float
    reflectivity: float

    def tail(self, d: np.ndarray) -> np.ndarray:
        """P(D >= d), (k,) float64."""
        d = np.maximum(np.asarray(d, np.float64), self.d0)
        full = 1.0 - math.exp(-(self.cap - self.d0) / self.mean)
        return np.clip((np.exp(-(d - self.d0) / self.mean) - math.exp(-(self.cap - self.d0) / self.mean)) / full, 0.0, 1.0)

    def draw_above(self, d: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A diameter in [``d``, cap] (each) from the truncated exponential, by its inverse distribution (memoryless)."""
        low = np.minimum(np.maximum(np.asarray(d, np.float64), self.d0), self.cap)
        span = 1.0 - np.exp(-(self.cap - low) / self.mean)
        return np.minimum(low - self.mean * np.log1p(-rng.random(len(low)) * span), self.cap)


def _visible_mass(limit: float, medium: _Particles, divergence: float, detect, extinction: float):
    """``(grid (k,) m, cumulative (k,), d_min (k,) m)``: the mean count of visible particles in a beam's cone up to
    each grid range, and the smallest visible diameter there (inf: none) (:func:`_visible_particles`)."""
    grid = np.concatenate([np.linspace(0.0, 2.0, 201)[:-1], np.geomspace(2.0, max(limit, 2.0) + 1e-9, 400)])
    # the smallest apparent reflectance the floor sees at each grid range (bisection on the detection probability)
    lo, hi = np.full(len(grid), 1e-12), np.full(len(grid), 10.0)
    at = np.maximum(grid, MIN_RANGE).astype(np.float32)
    for _ in range(50):
        mid = np.sqrt(lo * hi)
        ok = detect(mid.astype(np.float32), at) > 0.02
        lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
    full = medium.reflectivity * overlap(grid) * np.exp(-extinction * grid)  # a particle covering the whole footprint
    with np.errstate(divide="ignore", invalid="ignore"):
        d_min = np.where(full >= hi, divergence * grid * np.sqrt(hi / np.maximum(full, 1e-300)), np.inf)
    density = medium.per_m3 * np.pi * (divergence / 2.0) ** 2 * grid**2 * np.where(np.isfinite(d_min), medium.tail(np.where(np.isfinite(d_min), d_min, 0.0)),
                                                                                   0.0)
    cumulative = np.concatenate([[0.0], np.cumsum((density[1:] + density[:-1]) / 2 * np.diff(grid))])
    return grid, cumulative, d_min


def _visible_particles(limit: np.ndarray, medium: _Particles, grid: np.ndarray, cumulative: np.ndarray, d_min: np.ndarray, rng: np.random.Generator):
    """The particles of each beam's cone up to ``limit`` (p,) metres that can clear the noise floor:
    ``(beam row, range m, diameter m)``, by beam, nearest first; ``grid, cumulative, d_min``: :func:`_visible_mass`.

    A particle at ``x`` of diameter ``D`` reads the apparent reflectance ``rho min(1, (D / (phi x))^2) xi(x) exp(-k x)``
    (``k``: the medium's own ``extinction`` in front of it); below the smallest diameter ``D_min(x)`` that the floor
    sees with probability 2 % it cannot be a return, so only the rest are drawn: a Poisson count per beam of mean
    ``int_0^limit per_m3 pi (phi / 2)^2 x^2 P(D >= D_min(x)) dx``, ranges by that intensity's inverse (the uniforms
    of a beam drawn in order: normalised sums of exponential spacings, no sort), then each diameter above ``D_min(x)``.
    """
    mass = np.interp(limit, grid, cumulative)
    count = rng.poisson(mass)
    rows = np.repeat(np.arange(len(limit)), count)
    sizes = count + 1  # k spacings of k ordered uniforms and the last one
    ends = np.cumsum(sizes)
    sums = np.cumsum(rng.exponential(1.0, int(ends[-1]) if len(ends) else 0))
    before = np.concatenate([[0.0], sums])[ends - sizes]
    total = sums[ends - 1] - before if len(ends) else before
    last = np.zeros(len(sums), bool)
    last[ends - 1] = True
    u = (sums[~last] - before[rows]) / total[rows]
    rising = np.concatenate([[True], np.diff(cumulative) > 0])  # a strictly increasing inverse
    x = np.interp(u * mass[rows], cumulative[rising], grid[rising])
    d = medium.draw_above(np.interp(x, grid, np.where(np.isfinite(d_min), d_min, medium.cap)), rng)
    return rows, x, d


@dataclass
class _Medium:
    """What the weather does to each of p returns: the hard target's power factor and the strongest scatterer."""

    transmit: np.ndarray  # (p,) float64 factor on the hard target's power
    range: np.ndarray  # (p,) float64 scatterer's range, m
    apparent: np.ndarray  # (p,) float64 scatterer's apparent reflectance at that range (power x range^2)
    kind: np.ndarray  # (p,) int8 index into WEATHER_CLASSES, -1 for none
    intensity: np.ndarray  # (p,) float64 scatterer's reported intensity over the clear return's (fog) or NaN (apparent reflectance)

    def offer(self, rows, range_m, apparent, kind, intensity=None) -> None:
        """A scatterer per row; it replaces the row's current one where its received power is stronger."""
        power = apparent / np.maximum(range_m, MIN_RANGE) ** 2
        old = self.apparent[rows] / np.maximum(self.range[rows], MIN_RANGE) ** 2
        better = power > old
        rows = rows[better]
        self.range[rows], self.apparent[rows], self.kind[rows] = range_m[better], apparent[better], kind
        self.intensity[rows] = np.nan if intensity is None else intensity[better]


def _starts(rows: np.ndarray) -> np.ndarray:
    """Where each run of equal ``rows`` (sorted) begins."""
    start = np.ones(len(rows), bool)
    start[1:] = rows[1:] != rows[:-1]
    return np.flatnonzero(start)


def _strongest(rows: np.ndarray, power: np.ndarray) -> np.ndarray:
    """Indices of the strongest particle of each beam (the nearest of equals); ``rows`` sorted."""
    starts = _starts(rows)
    best = np.maximum.reduceat(power, starts)
    hit = np.flatnonzero(power == np.repeat(best, np.diff(np.append(starts, len(rows)))))
    return hit[_starts(rows[hit])]


def _offer_particles(medium: _Medium, r: np.ndarray, particles: _Particles, divergence: float, detect, extinction: float, kind: int, rng) -> None:
    """The strongest visible particle of each beam, offered as its scatterer. Beams are drawn in passes of at most
    about :data:`PARTICLES_PER_PASS` particles, so that the memory stays bounded whatever the rate and divergence."""
    grid, cumulative, d_min = _visible_mass(float(r.max(initial=2.0)), particles, divergence, detect, extinction)
    passes = (np.cumsum(np.interp(r, grid, cumulative)) // PARTICLES_PER_PASS).astype(np.int64)
    bounds = np.flatnonzero(np.diff(passes)) + 1
    for start, stop in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [len(r)]])):
        rows, x, d = _visible_particles(r[start:stop], particles, grid, cumulative, d_min, rng)
        if len(rows):
            apparent = particles.reflectivity * np.minimum(1.0, (d / (divergence * x)) ** 2) * overlap(x) * np.exp(-extinction * x)
            best = _strongest(rows, apparent / (x * x))
            medium.offer(rows[best] + start, x[best], apparent[best], kind)
