"""Intensity models: what a point's intensity (0..1) says (``effects.intensity.model``).

``reflectance``: ``rho cos(theta) g``, the object's ``lidar_reflectivity`` times the cosine of
incidence times the mirror gain ``g`` (product of the reflectivities of the mirrors met), which is
what range-compensated sensors report ("calibrated reflectivity"). ``lidar``: the lidar equation for
an extended Lambertian target, ``P ~ rho cos(theta) g exp(-2 alpha R) / R^2``, normalised so that a
target of ``reference_reflectivity`` at normal incidence at ``reference_range`` reads 1 (nearer or
brighter returns saturate at 1, as a receiver does). ``carla``: CARLA's ``exp(-a R)``.
"""

from __future__ import annotations

import numpy as np

MIN_RANGE = 1e-3  # m: ranges are clamped here before dividing by them


def reflectance(beam: np.ndarray, incidence_exponent: float = 1.0) -> np.ndarray:
    """``rho cos(theta)^k g`` of each point (``k``: ``incidence_exponent``, 1 for a Lambertian target);
    beam : (p,) BEAM_DTYPE; returns (p,) float32."""
    if incidence_exponent == 1.0:
        return beam["reflectivity"] * beam["cos_incidence"] * beam["gain"]
    cos = np.maximum(beam["cos_incidence"], np.float32(0.0)) ** np.float32(incidence_exponent)
    return beam["reflectivity"] * cos * beam["gain"]


def lidar_intensity(range_m: np.ndarray, beam: np.ndarray, alpha: float, reference_range: float, reference_reflectivity: float = 1.0, incidence_exponent: float = 1.0) -> np.ndarray:
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


def compute_intensity(range_m: np.ndarray, beam: np.ndarray, intensity) -> np.ndarray:
    """The configured intensity model (``config.IntensityConfig``) of each point, (p,) float32 in 0..1.

    Then, as the sensor reports it: times ``scale`` (clipped to 1) and, with ``steps`` > 0, rounded
    to a multiple of ``1 / steps`` (an 8-bit intensity: 255, so ``round(255 I)`` is the sensor's integer).
    """
    if intensity.model == "lidar":
        value = lidar_intensity(range_m, beam, intensity.alpha, intensity.reference_range, intensity.reference_reflectivity, intensity.incidence_exponent)
    elif intensity.model == "carla":
        value = carla_intensity(range_m, intensity.attenuation_rate)
    else:
        value = np.clip(reflectance(beam, intensity.incidence_exponent), 0.0, 1.0)
    return sensor_units(value, intensity.scale, intensity.steps, getattr(intensity, "offset", 0.0))


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
