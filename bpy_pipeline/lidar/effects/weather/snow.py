"""Snowfall (``effects.weather.snow``), after Hahner et al., "LiDAR Snowfall Simulation for Robust 3D Object
Detection" (CVPR 2022), and a wet ground after Lekner and Dorf, "Why some things are darker when wet": the
formulas are in :mod:`bpy_pipeline.lidar.effects.weather`'s notes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ....schema import meta
from .kind import Returns, WeatherKind, register_weather_kind
from .particles import _Particles

WATER_INDEX = 1.33  # refractive index of water in the near infrared
MAX_SNOW = 20  # mm/h water equivalent: far above the heaviest snowfall (their heavy snow: > 2.5)
WET_CLASSES = ("road", "ground", "terrain", "sidewalk", "kerb", "ballast", "platform", "floor", "ramp")


@dataclass(frozen=True)
class SnowConfig:
    """``effects.weather.snow``: Hahner et al.'s snowfall (CVPR 2022)."""

    rate: float = field(default=0.0, metadata=meta("mm/h", 0, MAX_SNOW, help="water equivalent (0: no snow); their light < 1, moderate 1..2.5, heavy above"))
    terminal_velocity: float = field(default=1.0, metadata=meta("m/s", 0.05, 10, help="the flakes' fall speed (their 0.2..2)"))
    density: float = field(default=0.1, metadata=meta("", 0.005, 0.9, help="g/cm^3 of the flakes (their 0.01..0.2)"))
    flake_reflectivity: float = field(default=0.9, metadata=meta("", 0, 1, help="a flake returns like this diffuse target (their 90 % target)"))
    wet_ground: bool = field(default=False, metadata=meta(help="the ground's returns through a water film"))
    wet_classes: list[str] = field(default_factory=lambda: list(WET_CLASSES), metadata=meta(help="the classes the wet ground applies to"))


def snow_occupancy(rate: float, terminal_velocity: float = 1.0, density: float = 0.1) -> float:
    """Share of the air's volume the flakes fill at snowfall ``rate`` (mm/h water): ``rate / (3.6e6 rho_s v_s)``."""
    return rate / (3.6e6 * density * terminal_velocity)


def snow_equivalent_rain(rate: float, terminal_velocity: float = 1.0, density: float = 0.1, diameter: float = 0.003) -> float:
    """The snowfall paper's equivalent rain rate (mm/h) of a snowfall ``rate``: ``(rate / (487 rho_s D v_s))^1.5``."""
    return (rate / (487.0 * density * diameter * terminal_velocity)) ** 1.5


def snow_mean_diameter(rate: float, terminal_velocity: float = 1.0, density: float = 0.1) -> float:
    """Mean flake diameter (m) at snowfall ``rate``: 1 / the Sekhon-Srivastava rate ``22.9 R^-0.45`` (1/cm) of the equivalent rain rate."""
    return 0.01 / (22.9 * snow_equivalent_rain(rate, terminal_velocity, density) ** -0.45)


SNOW_MAX_DIAMETER = 0.02  # m: their cap on a flake's diameter


def _exponential_moments(mean: float, cap: float) -> tuple[float, float]:
    """``(E[D^2], E[D^3])`` (m^2, m^3) of an exponential of ``mean`` truncated at ``cap`` (numerically)."""
    d = np.linspace(0.0, cap, 4001)
    step = np.full(len(d), d[1] - d[0])
    step[0] = step[-1] = (d[1] - d[0]) / 2  # trapezoid rule
    w = np.exp(-d / mean) * step
    w /= w.sum()
    return float(w @ (d * d)), float(w @ d**3)


def snow_density(snow: SnowConfig) -> tuple[float, float]:
    """``(flakes per m^3, mean diameter m)`` of a snowfall: the volume share over the mean flake volume."""
    mean = snow_mean_diameter(snow.rate, snow.terminal_velocity, snow.density)
    _, m3 = _exponential_moments(mean, SNOW_MAX_DIAMETER)
    return snow_occupancy(snow.rate, snow.terminal_velocity, snow.density) / (math.pi / 6.0 * m3), mean


def snow_extinction(snow: SnowConfig) -> float:
    """Share of a beam's power the flakes occlude per metre (1/m): flakes per m^3 times their mean cross-section."""
    n, mean = snow_density(snow)
    m2, _ = _exponential_moments(mean, SNOW_MAX_DIAMETER)
    return n * math.pi / 4.0 * m2


def wet_ground_factor(albedo: np.ndarray, cos_incidence: np.ndarray) -> np.ndarray:
    """Reflectance of a wet diffuse surface over its dry one, (p,) float64 (Lekner and Dorf's water film):
    ``(1 - r(theta)) (1 - r_i) / (1 - r_i A)`` with ``r`` water's Fresnel reflectance at the incidence."""
    cos_i = np.clip(np.asarray(cos_incidence, np.float64), 1e-6, 1.0)
    sin_t = np.sqrt(1.0 - cos_i**2) / WATER_INDEX
    cos_t = np.sqrt(1.0 - sin_t**2)
    rs = ((cos_i - WATER_INDEX * cos_t) / (cos_i + WATER_INDEX * cos_t)) ** 2
    rp = ((cos_t - WATER_INDEX * cos_i) / (cos_t + WATER_INDEX * cos_i)) ** 2
    fresnel = 0.5 * (rs + rp)
    internal = 1.0 - (1.0 - 0.066) / WATER_INDEX**2
    return (1.0 - fresnel) * (1.0 - internal) / (1.0 - internal * np.clip(np.asarray(albedo, np.float64), 0.0, 1.0))


class Snow(WeatherKind):
    """A wet ground's darker returns; the flakes' occlusion ``exp(-k R)`` and their returns."""

    name, config, label = "snow", SnowConfig, "snow"

    def check_labels(self, snow: SnowConfig, where: str, table) -> None:
        for name in snow.wet_classes:
            table.id_of(name, f"{where}.wet_classes")

    def active(self, snow: SnowConfig) -> bool:
        return snow.rate > 0 or snow.wet_ground

    def particles(self, snow: SnowConfig):
        if snow.rate <= 0:
            return None
        per_m3, mean = snow_density(snow)
        return _Particles(per_m3, 0.0, mean, SNOW_MAX_DIAMETER, snow.flake_reflectivity), snow_extinction(snow)

    def surface(self, snow: SnowConfig, returns: Returns) -> None:
        if snow.wet_ground:
            ids = np.array([returns.table.id_of(name) for name in snow.wet_classes], np.int64)
            wet = np.isin(returns.points["semantic"], ids)
            returns.medium.transmit[wet] *= wet_ground_factor(returns.beam["reflectivity"][wet], returns.beam["cos_incidence"][wet])

    def attenuate(self, snow: SnowConfig, returns: Returns) -> None:
        if snow.rate > 0:  # the flakes' mean occlusion of the footprint (the snowfall paper's, one way)
            returns.medium.transmit *= np.exp(-snow_extinction(snow) * returns.r)

    def scatter(self, snow: SnowConfig, returns: Returns, rng: np.random.Generator) -> None:
        if snow.rate > 0:
            returns.offer_particles(self.name, *self.particles(snow), rng)


register_weather_kind(Snow())
