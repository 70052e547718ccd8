"""Weather that affects the LiDAR: fog, rain and snowfall (``effects.weather``), one kind a module. Pure numpy.

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

Scatterer returns get the class their kind names (``fog``, ``rain``, ``snow`` of assets_manifest/labels.yaml),
instance 0; beams that hit nothing in the clear scan stay empty (the papers augment real scans,
which hold no empty beams' geometry).

Each kind is one module (:mod:`.fog`, :mod:`.rain`, :mod:`.snow`): its config section, its check and its part of
each phase (:class:`.kind.WeatherKind`), registered in :data:`.kind.WEATHER_KINDS` by the import line below;
``effects.weather`` (:data:`WeatherConfig`) has one section per registered kind. docs/layout.md shows a new kind.
"""

from __future__ import annotations

import dataclasses
from dataclasses import field

import numpy as np

from ....schema import meta
from ..base import Chunk, Effect, register_effect
from ..drop.threshold import threshold_model
from ..intensity import MIN_RANGE, reflectance, sensor_units
from .kind import Returns, WeatherKind, WEATHER_KINDS, register_weather_kind
from .particles import DEFAULT_DIVERGENCE_MRAD, PARTICLES_PER_PASS, _Medium, _offer_particles, overlap, _visible_mass
from . import fog, rain, snow  # noqa: F401  (registration: the weather kinds, applied in this order)
from .fog import FogConfig, fog_alpha, fog_soft, fog_soft_table
from .rain import RainConfig, _rain_particles, marshall_palmer_lambda, rain_alpha, rain_max_range, rain_range_sigma
from .snow import SnowConfig, snow_density, snow_extinction, snow_occupancy, wet_ground_factor

__all__ = [
    "WEATHER_KINDS", "WeatherKind", "register_weather_kind", "WeatherConfig", "check_weather", "apply_weather", "expected_particles",
    "weather_active", "FogConfig", "RainConfig", "SnowConfig", "fog_alpha", "fog_soft", "fog_soft_table", "rain_alpha", "rain_max_range",
    "rain_range_sigma", "marshall_palmer_lambda", "snow_density", "snow_extinction", "snow_occupancy", "wet_ground_factor", "overlap",
    "DEFAULT_DIVERGENCE_MRAD", "PARTICLES_PER_PASS", "_Medium", "_offer_particles", "_rain_particles",
]


def _weather_config() -> type:
    """``effects.weather``: one section per registered kind (each off unless given), and the particles' beam divergence."""
    fields = [(name, kind.config, field(default_factory=kind.config)) for name, kind in WEATHER_KINDS.items()]
    fields.append(("divergence_mrad", float,
                   field(default=0.0,
                         metadata=meta("", 0, 100, help="full-angle beam divergence in mrad for the particles (0: sensor.divergence.mrad, else 3 mrad)"))))
    names = ", ".join(WEATHER_KINDS.names())
    cls = dataclasses.make_dataclass("WeatherConfig", fields, frozen=True, namespace={
        "__doc__": f"``effects.weather``: {names}, each off unless given; ``effects.ideal: true`` turns them off.",
        "active": property(lambda self: any(kind.active(getattr(self, name)) for name, kind in WEATHER_KINDS.items())),
    })
    cls.__module__ = __name__
    return cls


WeatherConfig = _weather_config()


def check_weather(weather, where: str = "effects.weather") -> None:
    """``InputError`` naming the key of the first value the kinds refuse beyond their fields' ranges (the schema's), or an unknown class."""
    for name, kind in WEATHER_KINDS.items():
        kind.check(getattr(weather, name), f"{where}.{name}")
    from ....labels import load_class_table

    table = load_class_table()
    for name, kind in WEATHER_KINDS.items():
        kind.check_labels(getattr(weather, name), f"{where}.{name}", table)


def weather_active(effects) -> bool:
    """True when ``effects.weather`` asks for any weather and ``effects.ideal`` does not turn it off."""
    weather = getattr(effects, "weather", None)
    return weather is not None and not effects.ideal and weather.active


def _active_kinds(weather) -> list[tuple[WeatherKind, object]]:
    """``[(kind, its section)]`` of the kinds the config asks for, in the registry's order."""
    return [(kind, getattr(weather, name)) for name, kind in WEATHER_KINDS.items() if kind.active(getattr(weather, name))]


def expected_particles(effects, max_range: float, detect) -> float:
    """The most visible particles (rain drops, snow flakes) one beam can meet (its cone up to ``max_range`` m): the
    Poisson mean :func:`.particles._visible_particles` draws, for the estimate of a run's work (:mod:`~bpy_pipeline.estimate`)."""
    if effects.ideal:
        return 0.0
    weather = effects.weather
    media = [medium for kind, section in _active_kinds(weather) if (medium := kind.particles(section)) is not None]
    divergence = (weather.divergence_mrad or DEFAULT_DIVERGENCE_MRAD) * 1e-3
    return float(sum(_visible_mass(max_range, medium, divergence, detect, extinction)[1][-1] for medium, extinction in media))


def apply_weather(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, detect) -> tuple[np.ndarray, np.ndarray | None]:
    """The configured weather on the returns of a clear scan: ``(records, keep)``, the records moved and relabelled
    where a scatterer took the return, and ``keep`` (p,) bool the returns still seen (``None``: all, weather off).

    points : (p,) POINT_DTYPE records, sensor frame, their intensity already computed; beam : (p,) BEAM_DTYPE
    effects : the config's ``effects`` (``weather``, and ``intensity`` for the apparent reflectance and units)
    detect : ``detect(apparent_reflectance, range_m) -> (p,) float32`` the noise floor's detection probability
        (the ``threshold`` drop model)
    The kinds' phases run in the order of :mod:`.kind`, each kind in the registry's order within a phase.
    """
    weather = effects.weather
    n = len(points)
    if n == 0 or effects.ideal or not weather.active:
        return points, None
    from ....labels import load_class_table

    r = np.maximum(points["range"].astype(np.float64), MIN_RANGE)
    a = reflectance(beam, effects.intensity.incidence_exponent).astype(np.float64)
    medium = _Medium(np.ones(n), r.copy(), np.zeros(n), np.full(n, -1, np.int8), np.full(n, np.nan))
    divergence = (weather.divergence_mrad or DEFAULT_DIVERGENCE_MRAD) * 1e-3
    returns = Returns(points, beam, effects, r, a, medium, divergence, detect, load_class_table())
    kinds = _active_kinds(weather)
    for kind, section in kinds:
        kind.surface(section, returns)
    for kind, section in kinds:  # the media's attenuation of the hard target first (a scatterer competes with what is left of it)
        kind.attenuate(section, returns)
    for kind, section in kinds:
        kind.scatter(section, returns, rng)
    return _resolve(returns, kinds, rng)


def _resolve(returns: Returns, kinds, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Each return: the scatterer where its power beats the attenuated hard target's, then the noise floor and the kinds' range noise."""
    points, beam, effects, detect, medium, r, a = returns.points, returns.beam, returns.effects, returns.detect, returns.medium, returns.r, returns.a
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
    for kind, section in kinds:
        range_w = kind.range_noise(section, range_w, ~scattered, rng)
    step = (range_w - points["range"].astype(np.float64)).astype(np.float32)
    for axis, k in enumerate("xyz"):
        out[k] += step * beam["direction"][:, axis]
    out["range"] = range_w.astype(np.float32)
    ids = np.array([returns.table.id_of(kind.label) if kind.label else 0 for _, kind in WEATHER_KINDS.items()], out["semantic"].dtype)
    out["semantic"][scattered] = ids[medium.kind[scattered]]
    out["instance"][scattered] = 0
    out["bounces"][scattered] = 0
    return out, keep


class Weather(Effect):
    """The configured weather on the returns the drop kept (:func:`apply_weather`); the noise floor is the ``threshold`` drop model's."""

    name, section, config, order = "weather", "weather", WeatherConfig, 40

    def check(self, effects, spec=None) -> None:
        check_weather(effects.weather)

    def prepare(self, effects, models: dict) -> None:
        if weather_active(effects):
            for kind, section in _active_kinds(effects.weather):
                kind.prepare(section)

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        if not weather_active(chunk.effects):
            return
        detect = threshold_model(chunk.effects, chunk.models["drop"]).detection_probability
        chunk.points, keep = apply_weather(chunk.records, chunk.beam, chunk.effects, rng, detect)
        chunk.keep(keep)


register_effect(Weather())
