"""Fog (``effects.weather.fog``), after Hahner et al., "Fog Simulation on Real LiDAR Point Clouds for 3D Object
Detection in Adverse Weather" (ICCV 2021): the formulas are in :mod:`bpy_pipeline.lidar.effects.weather`'s notes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ....errors import InputError
from ....schema import meta
from .kind import Returns, WeatherKind, register_weather_kind
from .particles import overlap

C = 299_792_458.0  # m/s
MAX_VISIBILITY = 100_000.0  # m: beyond this fog is clear air


@dataclass(frozen=True)
class FogConfig:
    """``effects.weather.fog``: Hahner et al.'s fog (ICCV 2021)."""

    visibility: float = field(default=0.0, metadata=meta("m", soft=(0, MAX_VISIBILITY), help="meteorological optical range: 0 (no fog) or 1..100000"))
    backscatter: float = field(default=0.046, metadata=meta("", 0, 1, low_open=True, help="beta x MOR (1/sr); their 0.046 (0.023..0.092)"))
    gamma: float = field(default=1e-6, metadata=meta("", 0, 1, low_open=True, help="hard-target reflectivity calibration Gamma (beta0 = Gamma / pi)"))
    pulse_ns: float = field(default=20.0, metadata=meta("ns", 0, 1000, low_open=True, help="tau_H, half-power pulse width (their lookup tables: 20 ns)"))
    noise: float = field(default=10.0, metadata=meta("m", 0, 100, help="a fog return lies noise x Beta(2, 20) behind the soft peak (their variant v4)"))


def fog_alpha(visibility: float) -> float:
    """Extinction coefficient (1/m) of fog of meteorological optical range ``visibility`` (m): ``ln(20) / MOR``."""
    return math.log(20.0) / visibility


FOG_TABLE_STEP = 0.1  # m between tabulated hard-target ranges (their lookup tables: 0.1 m)


@lru_cache(maxsize=16)
def fog_soft_table(alpha: float, pulse_ns: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fog paper's soft-target integral against the hard target's range.

    Returns ``(r0, integral, distance)``: (m,) float64 hard-target ranges from 0 in steps of
    :data:`FOG_TABLE_STEP` (m), ``I(R0)`` (s/m^2, the integral's peak over R) and the range of that
    peak (m, shifted by ``c tau_H / 2`` as their tables are). Beyond the last tabulated range the
    target no longer cuts the integral, so the last row holds for every farther one.
    """
    tau = pulse_ns * 1e-9
    width = C * tau  # m: the pulse's length in range (2 tau_H in time is c tau_H in range)
    t = np.linspace(0.0, 2.0 * tau, 201)
    pulse = np.sin(np.pi * t / (2.0 * tau)) ** 2
    r_grid = np.arange(0.0, 2.0 * width + 10.0, 0.02)  # R: where the receiver samples (the soft peak lies within metres of the sensor)
    u = r_grid[:, None] - C * t[None, :] / 2.0  # (R, t): the range that scatters
    with np.errstate(divide="ignore", invalid="ignore"):
        medium = np.where(u > 0.9, np.exp(-2.0 * alpha * u) * overlap(u) / np.maximum(u, 1e-9) ** 2, 0.0)
    # the fog between the sensor and a target at R0 counts (H(R0 - u)); u falls with t, so that is a tail of the
    # integral over t: from the first sample with u <= R0 (tail sums per R, one gather per R0)
    dt = t[1] - t[0]
    weights = np.full(len(t), dt)
    weights[0] = weights[-1] = dt / 2  # trapezoid rule
    terms = medium * pulse * weights
    tail = np.concatenate([np.cumsum(terms[:, ::-1], axis=1)[:, ::-1], np.zeros((len(r_grid), 1))], axis=1)
    r0 = np.arange(0.0, r_grid[-1] - width, FOG_TABLE_STEP)
    first = np.ceil((r_grid[None, :] - r0[:, None]) * 2.0 / C / dt - 1e-9).astype(np.intp)  # (R0, R) first t index with u <= R0
    values = np.take_along_axis(np.broadcast_to(tail, (len(r0),) + tail.shape), np.clip(first, 0, len(t))[:, :, None], axis=2)[:, :, 0]
    peak = np.argmax(values, axis=1)
    integral = values[np.arange(len(r0)), peak]
    distance = r_grid[peak] - width / 2.0
    return r0, integral, distance


def fog_soft(r0: np.ndarray, alpha: float, pulse_ns: float) -> tuple[np.ndarray, np.ndarray]:
    """``(I(R0), peak range)`` at each hard-target range ``r0`` (m), (p,) float64 each, from :func:`fog_soft_table`."""
    grid, integral, distance = fog_soft_table(alpha, pulse_ns)
    k = np.clip(np.rint(np.asarray(r0, np.float64) / FOG_TABLE_STEP).astype(np.intp), 0, len(grid) - 1)
    return integral[k], distance[k]


class Fog(WeatherKind):
    """Attenuation ``exp(-2 alpha R)``; the fog's soft return offered where it beats the attenuated hard target."""

    name, config, label = "fog", FogConfig, "fog"

    def check(self, fog: FogConfig, where: str) -> None:
        if not (fog.visibility == 0 or 1.0 <= fog.visibility <= MAX_VISIBILITY):
            raise InputError(f"{where}.visibility: must be 0 (no fog) or 1..{MAX_VISIBILITY:g} m (meteorological optical range), got {fog.visibility}")

    def active(self, fog: FogConfig) -> bool:
        return fog.visibility > 0

    def prepare(self, fog: FogConfig) -> None:
        fog_soft_table(fog_alpha(fog.visibility), fog.pulse_ns)  # the soft-target table, once, before the threads share it

    def attenuate(self, fog: FogConfig, returns: Returns) -> None:
        returns.medium.transmit *= np.exp(-2.0 * fog_alpha(fog.visibility) * returns.r)

    def scatter(self, fog: FogConfig, returns: Returns, rng: np.random.Generator) -> None:
        r, medium = returns.r, returns.medium
        integral, distance = fog_soft(r, fog_alpha(fog.visibility), fog.pulse_ns)
        factor = r * r * (fog.backscatter / fog.visibility) / (fog.gamma / math.pi) * integral  # i_soft / i_clear
        rows = np.flatnonzero(factor > medium.transmit)  # elsewhere the hard target's return is the stronger
        at = np.clip(distance[rows] + fog.noise * rng.beta(2.0, 20.0, len(rows)), 0.0, r[rows])
        # the soft return's power is factor x the clear return's (a / r^2); at its range that is apparent reflectance x at^2 / r^2
        returns.offer(self.name, rows, at, (returns.a * factor)[rows] * at * at / (r[rows] * r[rows]), factor[rows])


register_weather_kind(Fog())
