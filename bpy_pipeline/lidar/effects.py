"""Sensor effects applied to point records after the trace: ray drop and range noise.

Every effect takes an explicit ``numpy.random.Generator`` and can be switched off; points
are in the sensor frame, so a beam's direction is the point's direction from the origin.
"""

from __future__ import annotations

import numpy as np


def drop_uniform(points: np.ndarray, probability: float, rng: np.random.Generator) -> np.ndarray:
    """Each point lost independently with ``probability``."""
    if probability <= 0:
        return points
    return points[rng.random(len(points)) >= probability]


def range_noise(points: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of ``sigma`` metres along each beam; ``range`` and ``x y z`` move together."""
    if sigma <= 0 or len(points) == 0:
        return points
    points = points.copy()
    old = points["range"].astype(np.float64)
    new = np.maximum(old + rng.normal(0.0, sigma, len(points)), 0.0)
    scale = new / np.where(old > 0, old, 1.0)
    for axis in "xyz":
        points[axis] = points[axis] * scale
    points["range"] = new
    return points


def apply_effects(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator) -> np.ndarray:
    """The configured effects (``config.EffectsConfig``) in a fixed order: drop, then noise.

    points : (p,) POINT_DTYPE records (sensor frame); beam : (p,) BEAM_DTYPE facts of the same points
    """
    if effects.drop.model == "uniform":
        points = drop_uniform(points, effects.drop.probability, rng)
    return range_noise(points, effects.noise.sigma, rng)
