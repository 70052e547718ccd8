"""Weather that affects the LiDAR: fog, rain and snowfall (``effects.weather``). Pure numpy.

Each model follows a published one, with that paper's parameters, and works on the returns of the
clear scan (as the papers work on real clear-weather scans): it attenuates every return, lets a
scatterer of the medium take a beam's return where the scatterer's received power wins, and lets the
sensor's noise floor decide which returns are lost.

Fog, after Hahner et al., "Fog Simulation on Real LiDAR Point Clouds for 3D Object Detection in
Adverse Weather" (ICCV 2021):
    extinction ``alpha = ln(20) / MOR`` (about 3 / MOR, the meteorological optical range
    ``visibility``), so a hard target's power falls by ``exp(-2 alpha R)``; back-scatter
    ``beta = 0.046 / MOR`` (their value) from the fog between the sensor and the target, through
    their pulse ``P0 sin^2(pi t / (2 tau_H))`` (``tau_H`` 20 ns) and the transmitter/receiver overlap
    ``xi(R)`` (0 below 0.9 m, 1 from 1.0 m, linear between). The soft return's peak is
    ``i_soft = i R0^2 (beta / beta0) I(R0)`` with ``I(R0) = max_R int_0^{2 tau_H} sin^2(pi t / (2 tau_H))
    exp(-2 alpha (R - ct/2)) xi(R - ct/2) / (R - ct/2)^2 H(R0 - R + ct/2) dt`` and their
    ``beta0 = Gamma / pi``, ``Gamma = 1e-6``; it replaces the point where it exceeds the attenuated
    ``i_hard = i exp(-2 alpha R0)``, at the range of the peak (shifted by ``c tau_H / 2``) plus
    ``10 m x Beta(2, 20)`` (their code's noise variant v4).
Rain, after Goodin et al., "Predicting the Influence of Rain on LIDAR in ADAS" (Electronics 2019):
    extinction ``alpha = 0.01 rate^0.6`` (1/m, rate in mm/h), so the maximum range ``z`` of a target
    solves ``rho exp(-2 alpha z) / z^2 = P_min`` (clear: ``z_max``; so ``z = z_max exp(-alpha z)``
    with the lidar equation's exponent 2); range noise ``sigma = 0.02 R (1 - exp(-rate))^2`` (m).
    Droplet returns along the beam, as in later work (Kilic et al., "Lidar Light Scattering
    Augmentation (LISA)"): drops of the Marshall-Palmer distribution ``N(D) = 8000 exp(-4.1
    rate^-0.21 D)`` (m^-3 mm^-1) sampled in each beam's cone; a drop covering the share
    ``(D / (phi x))^2`` of the footprint returns like a target of ``droplet_reflectivity`` (assumed
    0.02, water's Fresnel reflectance at normal incidence) over that share.
Snowfall, after Hahner et al., "LiDAR Snowfall Simulation for Robust 3D Object Detection" (CVPR 2022):
    the snowfall rate ``r_s`` (mm/h of water) fills the air with the volume share
    ``r_s / (3.6e6 rho_s v_s)`` of flakes (snow density ``rho_s`` 0.1 g/cm^3, terminal velocity
    ``v_s``); diameters are exponential with the Sekhon-Srivastava rate ``22.9 R^-0.45`` 1/cm of the
    equivalent rain rate ``R = (r_s / (487 rho_s D v_s))^1.5`` (capped at 2 cm): the occupied share
    grows with the rate, the flakes grow faster than they multiply (their number per m^3 falls).
    Flakes are sampled per beam in its cone (divergence ``phi``); one covering the share
    ``(D / (phi x))^2`` of the footprint returns like a 90 % target over that share (their value),
    and the flakes occlude the footprint by their mean cross-section per metre (one way, as the
    paper's unoccluded ratio); the return is the component with the strongest peak power (pulses
    are compared by peak, not summed). Only the particles that can clear the noise floor are drawn
    (a diameter above ``D_min(x)``, from the truncated exponential's tail), the same in
    distribution as drawing all and discarding the rest. A wet ground (``wet_ground``) returns less: a water film over a diffuse
    surface of albedo ``A`` reflects ``(1 - r) (1 - r_i) A / (1 - r_i A)`` (Lekner and Dorf, "Why
    some things are darker when wet"; ``r`` water's Fresnel reflectance at the incidence,
    ``r_i = 1 - (1 - 0.066) / n^2`` the film's internal reflectance, ``n = 1.33``).

Detection: a return is seen when its received power ``a / R^n`` (apparent reflectance ``a = rho
cos^k g``) clears the sensor's noise floor, the ``threshold`` drop model of ``effects.drop``
(a preset's datasheet ranges for 10 % and 80 % targets, or a fitted one). The clear scan has already
drawn its own drop, so a weather return is kept with probability ``min(1, p(weather) / p(clear))``
of that model's detection probabilities: weather only removes what it weakens below the floor,
and nothing when it is off.

Scatterer returns get the classes ``fog``, ``rain`` and ``snow`` of assets_manifest/labels.yaml,
instance 0; beams that hit nothing in the clear scan stay empty (the papers augment real scans,
which hold no empty beams' geometry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ...errors import InputError
from .intensity import MIN_RANGE, reflectance, sensor_units

C = 299_792_458.0  # m/s
WATER_INDEX = 1.33  # refractive index of water in the near infrared
MAX_VISIBILITY = 100_000.0  # m: beyond this fog is clear air
MAX_RAIN = 300.0  # mm/h: above the heaviest measured hourly rain rates
MAX_SNOW = 20.0  # mm/h water equivalent: far above the heaviest snowfall (their heavy snow: > 2.5)
WEATHER_CLASSES = ("fog", "rain", "snow")
WET_CLASSES = ("road", "ground", "terrain", "sidewalk", "kerb", "ballast", "platform", "floor", "ramp")


# ----------------------------------------------------------------------------- config sections
@dataclass(frozen=True)
class FogConfig:
    """``effects.weather.fog``: Hahner et al.'s fog (ICCV 2021)."""

    visibility: float = 0.0  # m, meteorological optical range (0: no fog)
    backscatter: float = 0.046  # beta x MOR (1/sr); their 0.046 (0.023..0.092)
    gamma: float = 1e-6  # their hard-target reflectivity calibration Gamma (beta0 = Gamma / pi)
    pulse_ns: float = 20.0  # tau_H, half-power pulse width (their lookup tables: 20 ns)
    noise: float = 10.0  # m: a fog return lies noise x Beta(2, 20) behind the soft peak (their variant v4)


@dataclass(frozen=True)
class RainConfig:
    """``effects.weather.rain``: Goodin et al.'s rain (Electronics 2019) with droplet returns."""

    rate: float = 0.0  # mm/h (0: no rain)
    droplet_reflectivity: float = 0.02  # a drop returns like this diffuse target over its share of the footprint (assumed)
    min_diameter_mm: float = 0.5  # smaller drops are left to the extinction alone


@dataclass(frozen=True)
class SnowConfig:
    """``effects.weather.snow``: Hahner et al.'s snowfall (CVPR 2022)."""

    rate: float = 0.0  # mm/h of water equivalent (0: no snow); their light < 1, moderate 1..2.5, heavy above
    terminal_velocity: float = 1.0  # m/s (their 0.2..2)
    density: float = 0.1  # g/cm^3 of the flakes (their 0.01..0.2)
    flake_reflectivity: float = 0.9  # their 90 % target
    wet_ground: bool = False  # the ground's returns through a water film
    wet_classes: list[str] = field(default_factory=lambda: list(WET_CLASSES))


@dataclass(frozen=True)
class WeatherConfig:
    """``effects.weather``: fog, rain and snow, each off unless given; ``effects.ideal: true`` turns them off."""

    fog: FogConfig = field(default_factory=FogConfig)
    rain: RainConfig = field(default_factory=RainConfig)
    snow: SnowConfig = field(default_factory=SnowConfig)
    divergence_mrad: float = 0.0  # full-angle beam divergence for the particles (0: sensor.divergence.mrad, else 3 mrad)

    @property
    def active(self) -> bool:
        return self.fog.visibility > 0 or self.rain.rate > 0 or self.snow.rate > 0 or self.snow.wet_ground


DEFAULT_DIVERGENCE_MRAD = 3.0  # the snowfall paper's HDL-64 beam
PARTICLES_PER_PASS = 4e6  # visible particles drawn at once (a pass peaks at 421 MB: benchmarks/results/weather_particles.json); more are drawn in passes


def check_weather(weather: WeatherConfig, where: str = "effects.weather") -> None:
    """``InputError`` naming the key of the first value outside what the models allow."""
    fog, rain, snow = weather.fog, weather.rain, weather.snow
    if not (fog.visibility == 0 or 1.0 <= fog.visibility <= MAX_VISIBILITY):
        raise InputError(f"{where}.fog.visibility: must be 0 (no fog) or 1..{MAX_VISIBILITY:g} m (meteorological optical range), got {fog.visibility}")
    for key, value, hi in (("fog.backscatter", fog.backscatter, 1.0), ("fog.gamma", fog.gamma, 1.0), ("fog.pulse_ns", fog.pulse_ns, 1000.0)):
        if not 0 < value <= hi:
            raise InputError(f"{where}.{key}: must lie in (0, {hi:g}], got {value}")
    if not 0 <= fog.noise <= 100:
        raise InputError(f"{where}.fog.noise: must lie in 0..100 m, got {fog.noise}")
    if not 0 <= rain.rate <= MAX_RAIN:
        raise InputError(f"{where}.rain.rate: must lie in 0..{MAX_RAIN:g} mm/h, got {rain.rate}")
    if not 0 <= rain.droplet_reflectivity <= 1:
        raise InputError(f"{where}.rain.droplet_reflectivity: must lie in 0..1, got {rain.droplet_reflectivity}")
    if not 0 < rain.min_diameter_mm <= 6:
        raise InputError(f"{where}.rain.min_diameter_mm: must lie in (0, 6] mm, got {rain.min_diameter_mm}")
    if not 0 <= snow.rate <= MAX_SNOW:
        raise InputError(f"{where}.snow.rate: must lie in 0..{MAX_SNOW:g} mm/h (water equivalent), got {snow.rate}")
    if not 0.05 <= snow.terminal_velocity <= 10:
        raise InputError(f"{where}.snow.terminal_velocity: must lie in 0.05..10 m/s, got {snow.terminal_velocity}")
    if not 0.005 <= snow.density <= 0.9:
        raise InputError(f"{where}.snow.density: must lie in 0.005..0.9 g/cm^3, got {snow.density}")
    if not 0 <= snow.flake_reflectivity <= 1:
        raise InputError(f"{where}.snow.flake_reflectivity: must lie in 0..1, got {snow.flake_reflectivity}")
    if not 0 <= weather.divergence_mrad <= 100:
        raise InputError(f"{where}.divergence_mrad: must lie in 0..100 mrad (0: the sensor's), got {weather.divergence_mrad}")
    from ...labels import load_class_table

    table = load_class_table()
    for name in snow.wet_classes:
        table.id_of(name, f"{where}.snow.wet_classes")


# ----------------------------------------------------------------------------- fog (Hahner et al., ICCV 2021)
def fog_alpha(visibility: float) -> float:
    """Extinction coefficient (1/m) of fog of meteorological optical range ``visibility`` (m): ``ln(20) / MOR``."""
    return math.log(20.0) / visibility


def overlap(r: np.ndarray, r1: float = 0.9, r2: float = 1.0) -> np.ndarray:
    """The fog paper's transmitter/receiver overlap ``xi(R)``: 0 up to ``r1``, 1 from ``r2``, linear between; (n,) float64."""
    return np.clip((np.asarray(r, np.float64) - r1) / (r2 - r1), 0.0, 1.0)


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


# ----------------------------------------------------------------------------- rain (Goodin et al., 2019)
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


# ----------------------------------------------------------------------------- snow (Hahner et al., CVPR 2022)
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


# ----------------------------------------------------------------------------- particles along beams
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


def _rain_particles(rain: RainConfig) -> _Particles:
    """Marshall-Palmer drops above ``rain.min_diameter_mm``."""
    lam = marshall_palmer_lambda(rain.rate)
    return _Particles(8000.0 * math.exp(-lam * rain.min_diameter_mm) / lam, rain.min_diameter_mm * 1e-3, 1e-3 / lam, 6e-3, rain.droplet_reflectivity)


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
    density = medium.per_m3 * np.pi * (divergence / 2.0) ** 2 * grid**2 * np.where(np.isfinite(d_min), medium.tail(np.where(np.isfinite(d_min), d_min, 0.0)), 0.0)
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


def expected_particles(effects, max_range: float, detect) -> float:
    """The most visible rain drops and snow flakes one beam can meet (its cone up to ``max_range`` m): the
    Poisson mean :func:`_visible_particles` draws, for the estimate of a run's work (:mod:`~bpy_pipeline.estimate`)."""
    weather = effects.weather
    if effects.ideal or not (weather.rain.rate > 0 or weather.snow.rate > 0):
        return 0.0
    divergence = (weather.divergence_mrad or DEFAULT_DIVERGENCE_MRAD) * 1e-3
    media = []
    if weather.rain.rate > 0:
        media.append((_rain_particles(weather.rain), 0.0))
    if weather.snow.rate > 0:
        per_m3, mean = snow_density(weather.snow)
        media.append((_Particles(per_m3, 0.0, mean, SNOW_MAX_DIAMETER, weather.snow.flake_reflectivity), snow_extinction(weather.snow)))
    return float(sum(_visible_mass(max_range, medium, divergence, detect, extinction)[1][-1] for medium, extinction in media))


# ----------------------------------------------------------------------------- applying it
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


def apply_weather(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, detect) -> tuple[np.ndarray, np.ndarray | None]:
    """The configured weather on the returns of a clear scan: ``(records, keep)``, the records moved and relabelled
    where a scatterer took the return, and ``keep`` (p,) bool the returns still seen (``None``: all, weather off).

    points : (p,) POINT_DTYPE records, sensor frame, their intensity already computed; beam : (p,) BEAM_DTYPE
    effects : the config's ``effects`` (``weather``, and ``intensity`` for the apparent reflectance and units)
    detect : ``detect(apparent_reflectance, range_m) -> (p,) float32`` the noise floor's detection probability
        (the ``threshold`` drop model)
    """
    weather: WeatherConfig = effects.weather
    n = len(points)
    if n == 0 or effects.ideal or not weather.active:
        return points, None
    from ...labels import load_class_table

    table = load_class_table()
    r = np.maximum(points["range"].astype(np.float64), MIN_RANGE)
    a = reflectance(beam, effects.intensity.incidence_exponent).astype(np.float64)
    medium = _Medium(np.ones(n), r.copy(), np.zeros(n), np.full(n, -1, np.int8), np.full(n, np.nan))
    divergence = (weather.divergence_mrad or DEFAULT_DIVERGENCE_MRAD) * 1e-3

    snow = weather.snow
    if snow.wet_ground:
        ids = np.array([table.id_of(name) for name in snow.wet_classes], np.int64)
        wet = np.isin(points["semantic"], ids)
        medium.transmit[wet] *= wet_ground_factor(beam["reflectivity"][wet], beam["cos_incidence"][wet])
    fog, rain = weather.fog, weather.rain
    # the media's attenuation of the hard target first (a scatterer competes with what is left of it)
    if fog.visibility > 0:
        alpha = fog_alpha(fog.visibility)
        medium.transmit *= np.exp(-2.0 * alpha * r)
    if rain.rate > 0:
        medium.transmit *= np.exp(-2.0 * rain_alpha(rain.rate) * r)
    if snow.rate > 0:
        per_m3, mean = snow_density(snow)
        extinction = snow_extinction(snow)  # the flakes' mean occlusion of the footprint (the snowfall paper's, one way)
        medium.transmit *= np.exp(-extinction * r)
    if fog.visibility > 0:
        integral, distance = fog_soft(r, alpha, fog.pulse_ns)
        factor = r * r * (fog.backscatter / fog.visibility) / (fog.gamma / math.pi) * integral  # i_soft / i_clear
        rows = np.flatnonzero(factor > medium.transmit)  # elsewhere the hard target's return is the stronger
        at = np.clip(distance[rows] + fog.noise * rng.beta(2.0, 20.0, len(rows)), 0.0, r[rows])
        # the soft return's power is factor x the clear return's (a / r^2); at its range that is apparent reflectance x at^2 / r^2
        medium.offer(rows, at, (a * factor)[rows] * at * at / (r[rows] * r[rows]), 0, factor[rows])
    if rain.rate > 0:
        _offer_particles(medium, r, _rain_particles(rain), divergence, detect, 0.0, 1, rng)
    if snow.rate > 0:
        flakes = _Particles(per_m3, 0.0, mean, SNOW_MAX_DIAMETER, snow.flake_reflectivity)
        _offer_particles(medium, r, flakes, divergence, detect, extinction, 2, rng)
    return _resolve(points, beam, effects, rng, detect, medium, r, a, table)


def _resolve(points, beam, effects, rng, detect, medium: _Medium, r, a, table) -> np.ndarray:
    """Each return: the scatterer where its power beats the attenuated hard target's, then the noise floor and rain's range noise."""
    hard_power = a * medium.transmit / (r * r)
    scatter_power = medium.apparent / (medium.range * medium.range)
    scattered = (medium.kind >= 0) & (scatter_power > hard_power)
    range_w = np.where(scattered, medium.range, r)
    apparent_w = np.where(scattered, medium.apparent, a * medium.transmit)
    clear = detect(a.astype(np.float32), r.astype(np.float32)).astype(np.float64)
    now = detect(apparent_w.astype(np.float32), range_w.astype(np.float32)).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        keep_p = np.where(now >= clear, 1.0, now / np.where(clear > 0, clear, 1.0))
    keep = rng.random(len(points)) < keep_p
    # intensity: the clear reading times the change of apparent reflectance (fog: the paper's i_soft / i_clear)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(scattered, np.where(np.isnan(medium.intensity), medium.apparent / np.maximum(a, 1e-6), medium.intensity), medium.transmit)
    out = points.copy()
    intensity_cfg = effects.intensity
    value = out["intensity"].astype(np.float64) * ratio
    fresh = scattered & (a <= 1e-6)  # a scatterer in front of a black target reads its own reflectance
    value[fresh] = medium.apparent[fresh] * intensity_cfg.scale
    value = np.minimum(value, 1.0).astype(np.float32)
    out["intensity"] = sensor_units(value, 1.0, intensity_cfg.steps)
    rain = effects.weather.rain
    if rain.rate > 0:  # Goodin et al.'s range noise on the returns of hard targets
        hard = ~scattered
        range_w = range_w + np.where(hard, rng.standard_normal(len(points)) * rain_range_sigma(range_w, rain.rate), 0.0)
        range_w = np.maximum(range_w, 0.0)
    step = (range_w - points["range"].astype(np.float64)).astype(np.float32)
    for axis, k in enumerate("xyz"):
        out[k] += step * beam["direction"][:, axis]
    out["range"] = range_w.astype(np.float32)
    ids = np.array([table.id_of(name) for name in WEATHER_CLASSES], out["semantic"].dtype)
    out["semantic"][scattered] = ids[medium.kind[scattered]]
    out["instance"][scattered] = 0
    out["bounces"][scattered] = 0
    return out, keep
