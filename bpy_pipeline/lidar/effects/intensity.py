"""Intensity models: what a point's intensity (0..1) says (``effects.intensity.model``).

``reflectance``: ``rho cos(theta) g``, the object's ``lidar_reflectivity`` times the cosine of
incidence times the mirror gain ``g`` (product of the reflectivities of the mirrors met), which is
what range-compensated sensors report ("calibrated reflectivity"). ``lidar``: the lidar equation for
an extended Lambertian target, ``P ~ rho cos(theta) g exp(-2 alpha R) / R^2``, normalised so that a
target of ``reference_reflectivity`` at normal incidence at ``reference_range`` reads 1 (nearer or
brighter returns saturate at 1, as a receiver does). ``carla``: CARLA's ``exp(-a R)``. The models are a registry
(:data:`INTENSITY_MODELS`; a new one is a :func:`register_intensity_model` call).

The reading apart from detection (``effects.intensity.reading``, :class:`ReadingModel`, opt-in): the drop
models decide detection from the received power (the apparent reflectance ``a`` and the range, as
before); what a detected return *reads* is the receiver's calibrated value

    ``I = clip(g_k (a f(R))^gamma n - o_k, 0, 1)``,  ``f(R) = 1`` up to ``compensated_range`` ``R_c``, ``(R_c / R)^exponent`` beyond,

with ``gamma`` the receiver's ``response`` (1: linear; below 1 a compressing receiver, as the HDL-64E's: KITTI reads
asphalt 0.25 and foliage 0.36 where a calibrated reflectivity says 0.12 and 0.45),
``g_k = scale exp(gain_sd z_k)`` and ``o_k = max(offset + offset_sd w_k, 0)`` the gain and offset of
laser ``k`` (a multi-beam sensor calibrates each laser apart, as the HDL-64E's per-laser table does;
``z_k, w_k`` standard normals drawn once per sensor unit from ``unit_seed``, so every frame and chunk
of a run sees the same lasers), and ``n = exp(noise_sd e)`` a per-return factor (``e`` standard normal
from the frame's generator). A weak return is detected yet reads 0 where ``g_k (a f(R))^gamma < o_k``: a far
car, or a car's glass and cabin, as KITTI's reflectance shows. Defaults fitted on KITTI frame 000008
(docs/realism.md, "The reading apart from detection"); the ``hdl64e`` profile's values (its response included)
on SemanticKITTI and KITTI frames (docs/realism.md, "The HDL-64E's reading, fitted per class").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Literal

import numpy as np

from ...errors import InputError
from ...registry import Registry
from ...schema import meta
from .base import Chunk, Effect, register_effect

MIN_RANGE = 1e-3  # m: ranges are clamped here before dividing by them
MAX_RINGS = 1024  # lasers a unit's gains and offsets are drawn for (ring ids at or above wrap round); a power of two


@dataclass(frozen=True)
class ReadingModel:
    """``effects.intensity.reading``: the receiver's reading apart from its detection (module notes).

    The mean gain and offset are ``effects.intensity.scale`` and ``effects.intensity.offset``."""

    enabled: bool = field(default=False, metadata=meta(help="read the reflectance through the unit's lasers (reflectance model only)"))
    compensated_range: float = field(default=28.0,
                                     metadata=meta("m", 0, 10000, low_open=True, help="the reading is range-compensated up to here (KITTI 000008: 28)"))
    exponent: float = field(default=2.0, metadata=meta("", 0, 10, help="beyond it the reading falls as (R_c / R)^exponent (the lidar equation's 2; fitted: 2)"))
    gain_sd: float = field(default=0.16,
                           metadata=meta("", 0, 2, help="sd of ln(gain) across lasers (KITTI 000008's road: robust sd of its per-ring log medians)"))
    offset_sd: float = field(default=0.0, metadata=meta("", 0, 2, help="sd of the offset across lasers (not identifiable on one frame: 0)"))
    noise_sd: float = field(default=0.075,
                            metadata=meta("", 0, 2, help="sd of ln of a per-return factor (KITTI 000008's road: robust within-ring log spread, 8-20 m)"))
    unit_seed: int = field(default=0, metadata=meta("", low=0, help="the sensor unit: its lasers' gains and offsets are drawn from this seed"))
    response: float = field(default=1.0,
                            metadata=meta("", 0, 4, low_open=True,
                                          help="gamma: the reading grows as (a f(R))^gamma (1: linear; below 1: a compressing receiver)"))


def check_reading(reading: ReadingModel, model: str = "reflectance") -> None:
    """One-line :class:`InputError` when the reading model is on under an intensity model it cannot read (``model``:
    ``effects.intensity``'s); its fields' ranges are their metadata's (the schema checks them)."""
    if reading.enabled and INTENSITY_MODELS.get(model).apparent is None:
        raise InputError(f"effects.intensity.reading.enabled: the reading model reads the reflectance model's value; effects.intensity.model is {model!r}")


@lru_cache(maxsize=64)
def laser_calibration(unit_seed: int, scale: float, offset: float, gain_sd: float, offset_sd: float) -> tuple[np.ndarray, np.ndarray]:
    """The gains and offsets of one sensor unit's lasers: ``((MAX_RINGS,) float32 g_k, (MAX_RINGS,) float32 o_k)``,
    ``g_k = scale exp(gain_sd z_k)``, ``o_k = max(offset + offset_sd w_k, 0)``; ``z, w`` from ``default_rng(unit_seed)``."""
    draw = np.random.default_rng(unit_seed).standard_normal((2, MAX_RINGS))
    gain = (scale * np.exp(gain_sd * draw[0])).astype(np.float32)
    off = np.maximum(offset + offset_sd * draw[1], 0.0).astype(np.float32)
    gain.flags.writeable = off.flags.writeable = False
    return gain, off


def range_factor(range_m: np.ndarray, compensated_range: float, exponent: float) -> np.ndarray:
    """``f(R)``: 1 up to ``compensated_range``, ``(R_c / R)^exponent`` beyond; (p,) float32."""
    f = np.maximum(np.asarray(range_m, np.float32), np.float32(MIN_RANGE))
    np.divide(np.float32(compensated_range), f, out=f)
    f **= np.float32(exponent)  # as ``**`` (numpy's square for 2, its power otherwise), in place
    return np.minimum(np.float32(1.0), f, out=f)


def read_out(value: np.ndarray, range_m: np.ndarray, ring: np.ndarray, reading: ReadingModel, scale: float, offset: float,
             rng: np.random.Generator | None) -> np.ndarray:
    """The reading ``clip(g_k (a f(R))^gamma n - o_k, 0, 1)`` (module notes) of apparent reflectances ``value`` (p,);
    range_m (p,) m; ring (p,) laser ids; ``rng`` draws the per-return factor (needed when ``noise_sd`` > 0).
    Returns (p,) float32. Each step in place on one float32 array (the operations and their order as written)."""
    gain, off = laser_calibration(int(reading.unit_seed), float(scale), float(offset), float(reading.gain_sd), float(reading.offset_sd))
    k = np.asarray(ring, np.int64) & (MAX_RINGS - 1)  # ring mod MAX_RINGS (a power of two: the same for negative ids), without a division
    f = range_factor(range_m, reading.compensated_range, reading.exponent)
    if reading.response == 1.0:
        power = np.asarray(value, np.float32) * gain[k]
        power *= f
    else:
        power = np.maximum(np.asarray(value, np.float32), np.float32(0.0))
        power *= f
        power **= np.float32(reading.response)
        power *= gain[k]
    if reading.noise_sd > 0:
        if rng is None:
            raise ValueError("read_out: noise_sd > 0 needs a generator")
        factor = rng.standard_normal(len(power), dtype=np.float32)
        factor *= np.float32(reading.noise_sd)
        power *= np.exp(factor, out=factor)
    power -= off[k]
    return np.clip(power, np.float32(0.0), np.float32(1.0), out=power)


def reflectance(beam: np.ndarray, incidence_exponent: float = 1.0) -> np.ndarray:
    """``rho cos(theta)^k g`` of each point (``k``: ``incidence_exponent``, 1 for a Lambertian target);
    beam : (p,) BEAM_DTYPE; returns (p,) float32."""
    if incidence_exponent == 1.0:
        return beam["reflectivity"] * beam["cos_incidence"] * beam["gain"]
    if incidence_exponent == 0.0:  # cos^0 is exactly 1 (NaN's too), and rho times 1 is rho: the same bits
        return beam["reflectivity"] * beam["gain"]
    cos = np.maximum(beam["cos_incidence"], np.float32(0.0)) ** np.float32(incidence_exponent)
    return beam["reflectivity"] * cos * beam["gain"]


def lidar_intensity(range_m: np.ndarray, beam: np.ndarray, alpha: float, reference_range: float, reference_reflectivity: float = 1.0,
                    incidence_exponent: float = 1.0) -> np.ndarray:
    """The lidar equation ``rho cos g exp(-2 alpha R) / R^2`` over its value for the reference target.

    range_m : (p,) metres; alpha : 1/m atmospheric extinction; the reference is a Lambertian
    target of ``reference_reflectivity`` at normal incidence at ``reference_range`` metres.
    Returns (p,) float32 in 0..1 (clipped: nearer or brighter returns saturate).
    """
    r = np.maximum(np.asarray(range_m, np.float32), np.float32(MIN_RANGE))
    scale = np.float32(reference_range**2 / reference_reflectivity)
    power = reflectance(beam, incidence_exponent) * scale / (r * r)
    if alpha > 0:
        power *= np.exp(np.float32(-2.0 * alpha) * (r - np.float32(reference_range)))
    return np.minimum(power, np.float32(1.0))


def carla_intensity(range_m: np.ndarray, attenuation_rate: float) -> np.ndarray:
    """CARLA's intensity ``exp(-a R)``, (p,) float32 (RayCastLidar ComputeIntensity)."""
    return np.exp(np.float32(-attenuation_rate) * np.asarray(range_m, np.float32))


@dataclass(frozen=True)
class IntensityModel:
    """An intensity model's registry entry (``effects.intensity.model`` names one).

    value : ``value(range_m, beam, intensity) -> (p,) float32`` in 0..1 before the sensor's units (``scale``,
        ``steps``, ``offset``); range_m (p,) m, beam (p,) BEAM_DTYPE, ``intensity`` the ``effects.intensity`` section
    apparent : ``apparent(beam, intensity) -> (p,) float32`` the apparent reflectance the reading model
        (``effects.intensity.reading``) reads instead, unclipped; ``None``: the reading model does not read this model
    """

    value: Callable[..., np.ndarray]
    apparent: Callable[..., np.ndarray] | None = None


INTENSITY_MODELS: Registry[IntensityModel] = Registry("intensity model", "effects.intensity.model")


def register_intensity_model(name: str, model: IntensityModel) -> IntensityModel:
    """Make ``effects.intensity.model: name`` give each point ``model``'s value."""
    return INTENSITY_MODELS.register(name, model)


def _apparent_reflectance(beam, intensity):
    return reflectance(beam, intensity.incidence_exponent)


def _reflectance_value(range_m, beam, intensity):
    return np.clip(_apparent_reflectance(beam, intensity), 0.0, 1.0)


def _lidar_value(range_m, beam, intensity):
    return lidar_intensity(range_m, beam, intensity.alpha, intensity.reference_range, intensity.reference_reflectivity, intensity.incidence_exponent)


def _carla_value(range_m, beam, intensity):
    return carla_intensity(range_m, intensity.attenuation_rate)


register_intensity_model("reflectance", IntensityModel(_reflectance_value, _apparent_reflectance))
register_intensity_model("lidar", IntensityModel(_lidar_value))
register_intensity_model("carla", IntensityModel(_carla_value))


def compute_intensity(range_m: np.ndarray, beam: np.ndarray, intensity, ring: np.ndarray | None = None, rng: np.random.Generator | None = None) -> np.ndarray:
    """The configured intensity model (``config.IntensityConfig``) of each point, (p,) float32 in 0..1.

    Then, as the sensor reports it: times ``scale`` (clipped to 1) and, with ``steps`` > 0, rounded
    to a multiple of ``1 / steps`` (an 8-bit intensity: 255, so ``round(255 I)`` is the sensor's integer).
    With ``intensity.reading.enabled`` (:class:`ReadingModel`) the ``reflectance`` value is read by the
    lasers' gains and offsets instead (``ring`` (p,) laser ids and ``rng`` the frame's generator needed).
    """
    model = INTENSITY_MODELS.get(intensity.model)
    reading = getattr(intensity, "reading", None)
    if reading is not None and reading.enabled and model.apparent is not None:
        if ring is None:
            raise ValueError("compute_intensity: the reading model needs each point's ring")
        value = read_out(model.apparent(beam, intensity), range_m, ring, reading, intensity.scale, intensity.offset, rng)
        return sensor_units(value, 1.0, intensity.steps, 0.0)
    return sensor_units(model.value(range_m, beam, intensity), intensity.scale, intensity.steps, getattr(intensity, "offset", 0.0))


def sensor_units(value: np.ndarray, scale: float = 1.0, steps: int = 0, offset: float = 0.0) -> np.ndarray:
    """(p,) float32 intensities 0..1 times ``scale`` less ``offset`` (a receiver that reads weak returns as 0),
    clipped to 0..1, rounded to ``k / steps`` when ``steps`` > 0."""
    if scale != 1.0:
        value = np.minimum(np.asarray(value, np.float32) * np.float32(scale), np.float32(1.0))
    if offset:
        value = np.maximum(np.asarray(value, np.float32) - np.float32(offset), np.float32(0.0))
    if steps > 0:
        value = np.rint(np.asarray(value, np.float32) * np.float32(steps)) / np.float32(steps)
    return value


@dataclass(frozen=True)
class IntensityConfig:
    """``effects.intensity``: what a point's intensity (0..1) says."""

    model: Literal[INTENSITY_MODELS.names()] = field(default="reflectance", metadata=meta(help="rho cos g | lidar equation | CARLA exp(-a R)"))
    alpha: float = field(default=0.0,
                         metadata=meta("1/m", low=0, help="atmospheric extinction, two-way exp(-2 alpha R): `lidar` intensity and `threshold` drop"))
    reference_range: float = field(default=10.0,
                                   metadata=meta("m", low=0, low_open=True,
                                                 help="`lidar`: a target of reference_reflectivity at normal incidence here reads 1"))
    reference_reflectivity: float = field(default=1.0, metadata=meta("", 0, 1, low_open=True, help="`lidar`: the reflectivity that reads 1 at reference_range"))
    attenuation_rate: float = field(default=0.004, metadata=meta("1/m", low=0, help="`carla`: CARLA's atmosphere_attenuation_rate"))
    incidence_exponent: float = field(
        default=1.0, metadata=meta("", low=0, help="`reflectance` and `lidar`: rho cos(theta)^k; 1 Lambertian, 0 as real road returns read (KITTI, nuScenes)")
    )
    scale: float = field(default=1.0,
                         metadata=meta("", low=0, low_open=True,
                                       help="the model's value times this, clipped to 0..1 (Velodyne's 0..100 % diffuse in 0..255: 100 / 255)"))
    steps: int = field(default=0, metadata=meta(
        "", 0, 65535, help="quantise to k / steps as the sensor's integer intensity does (255: nuScenes 0..255; 100: KITTI 0.01); 0 = continuous"))
    offset: float = field(default=0.0,
                          metadata=meta("", 0, 1, high_open=True,
                                        help="subtracted after scale, clipped at 0: a receiver that reads weak returns as 0 (KITTI's car paint); 0 = none"))
    reading: ReadingModel = field(default_factory=ReadingModel)  # per-laser gain/offset reading apart from detection (module notes); opt-in


class Intensity(Effect):
    """Each point's intensity from the true geometry (:func:`compute_intensity`), written into the records after the drop."""

    name, section, config, order = "intensity", "intensity", IntensityConfig, 20

    def check(self, effects, spec=None) -> None:
        check_reading(effects.intensity.reading, effects.intensity.model)

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        chunk.intensity = compute_intensity(chunk.points["range"], chunk.beam, chunk.effects.intensity, chunk.points["ring"], rng)


register_effect(Intensity())
