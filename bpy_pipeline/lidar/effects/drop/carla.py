"""``carla``: CARLA's RayCastLidar drop-off.

A general rate dropped before tracing, independent of the hit; then, with ``I = exp(-a R)``, a
point above ``intensity_limit`` is kept and one below it is kept with probability
``(zero_intensity / intensity_limit) I + 1 - zero_intensity``. Two draws per point, as CARLA does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ....schema import meta
from ..intensity import carla_intensity
from .base import DropModel, register_drop_model


@dataclass(frozen=True)
class CarlaDrop:
    """``effects.drop.carla``: CARLA's RayCastLidar drop-off, with CARLA's defaults."""

    general_rate: float = field(default=0.45, metadata=meta("", 0, 1, help="dropoff_general_rate: rays lost whatever they hit"))
    intensity_limit: float = field(default=0.8, metadata=meta("", 0, 1, low_open=True, help="dropoff_intensity_limit: above it, never lost"))
    zero_intensity: float = field(default=0.4, metadata=meta("", 0, 1, help="dropoff_zero_intensity: probability of losing a zero-intensity point"))
    attenuation_rate: float = field(default=0.004, metadata=meta("", low=0, help="atmosphere_attenuation_rate: intensity exp(-a R), 1/m"))


def carla_keep_probability(intensity: np.ndarray, intensity_limit: float, zero_intensity: float) -> np.ndarray:
    """CARLA's intensity-based keep probability: 1 above the limit, ``(p0 / limit) I + 1 - p0`` below."""
    keep = np.float32(zero_intensity / intensity_limit) * intensity + np.float32(1.0 - zero_intensity)
    return np.where(intensity > intensity_limit, np.float32(1.0), keep)


def probability(points, beam, effects, models) -> np.ndarray:
    c = effects.drop.carla
    keep = carla_keep_probability(carla_intensity(points["range"], c.attenuation_rate), c.intensity_limit, c.zero_intensity)
    return np.float32(1.0) - np.float32(1.0 - c.general_rate) * keep


def mask(points, beam, effects, rng, models) -> np.ndarray:
    """The general drop, then the intensity-based one: two draws per point."""
    c, n = effects.drop.carla, len(points)
    keep = rng.random(n, dtype=np.float32) >= np.float32(c.general_rate)
    p_keep = carla_keep_probability(carla_intensity(points["range"], c.attenuation_rate), c.intensity_limit, c.zero_intensity)
    return keep & (rng.random(n, dtype=np.float32) < p_keep)


register_drop_model("carla", DropModel(probability, mask))
