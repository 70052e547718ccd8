"""Rain (``effects.weather.rain``), after Goodin et al., "Predicting the Influence of Rain on LIDAR in ADAS"
(Electronics 2019), with droplet returns along the beam as in Kilic et al.'s LISA: the formulas are in
:mod:`bpy_pipeline.lidar.effects.weather`'s notes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ....schema import meta
from .kind import Returns, WeatherKind, register_weather_kind
from .particles import _Particles

MAX_RAIN = 300  # mm/h: above the heaviest measured hourly rain rates


@dataclass(frozen=True)
class RainConfig:
    """``effects.weather.rain``: Goodin et al.'s rain (Electronics 2019) with droplet returns."""

    rate: float = field(default=0.0, metadata=meta("mm/h", 0, MAX_RAIN, help="rain rate (0: no rain)"))
    droplet_reflectivity: float = field(default=0.02,
                                        metadata=meta("", 0, 1, help="a drop returns like this diffuse target over its share of the footprint (assumed)"))
    min_diameter_mm: float = field(default=0.5,
                                   metadata=meta("", 0, 6, low_open=True, help="drop diameter in mm; smaller drops are left to the extinction alone"))


def rain_alpha(rate: float) -> float:
    """Goodin et al.'s extinction coefficient (1/m) of rain of ``rate`` mm/h: ``0.01 rate^0.6``."""
    return 0.01 * rate**0.6


def rain_range_sigma(range_m: np.ndarray, rate: float) -> np.ndarray:
    """Goodin et al.'s range noise (m, one sigma) of returns at ``range_m`` in rain of ``rate`` mm/h: ``0.02 R (1 - exp(-rate))^2``."""
    return 0.02 * np.asarray(range_m, np.float64) * (1.0 - math.exp(-rate)) ** 2


def rain_max_range(clear_max_range: float, rate: float, exponent: float = 2.0) -> float:
    """The range (m) at which a target seen to ``clear_max_range`` in clear air is lost in rain: ``z^n exp(2 alpha z) = z_max^n``
    (``n = 2``: Goodin et al.'s lidar equation, ``z = z_max exp(-alpha z)``)."""
    alpha = rain_alpha(rate)
    lo, hi = 0.0, clear_max_range
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if exponent * math.log(max(mid, 1e-12)) + 2 * alpha * mid < exponent * math.log(clear_max_range) else (lo, mid)
    return 0.5 * (lo + hi)


def marshall_palmer_lambda(rate: float) -> float:
    """Slope (1/mm) of the Marshall-Palmer drop-size distribution ``8000 exp(-Lambda D)`` m^-3 mm^-1: ``4.1 rate^-0.21``."""
    return 4.1 * rate**-0.21


def _rain_particles(rain: RainConfig) -> _Particles:
    """Marshall-Palmer drops above ``rain.min_diameter_mm``."""
    lam = marshall_palmer_lambda(rain.rate)
    return _Particles(8000.0 * math.exp(-lam * rain.min_diameter_mm) / lam, rain.min_diameter_mm * 1e-3, 1e-3 / lam, 6e-3, rain.droplet_reflectivity)


class Rain(WeatherKind):
    """Attenuation ``exp(-2 alpha R)``, droplet returns, and range noise on the returns of hard targets."""

    name, config, label = "rain", RainConfig, "rain"

    def active(self, rain: RainConfig) -> bool:
        return rain.rate > 0

    def particles(self, rain: RainConfig):
        return _rain_particles(rain), 0.0

    def attenuate(self, rain: RainConfig, returns: Returns) -> None:
        returns.medium.transmit *= np.exp(-2.0 * rain_alpha(rain.rate) * returns.r)

    def scatter(self, rain: RainConfig, returns: Returns, rng: np.random.Generator) -> None:
        returns.offer_particles(self.name, *self.particles(rain), rng)

    def range_noise(self, rain: RainConfig, range_m: np.ndarray, hard: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Goodin et al.'s range noise on the returns of hard targets."""
        range_m = range_m + np.where(hard, rng.standard_normal(len(range_m)) * rain_range_sigma(range_m, rain.rate), 0.0)
        return np.maximum(range_m, 0.0)


register_weather_kind(Rain())
