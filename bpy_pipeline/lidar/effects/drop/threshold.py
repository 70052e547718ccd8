"""``threshold``: a physical detection threshold.

The received power ``rho cos g exp(-2 alpha R) / R^n`` against a sensitivity set by a datasheet's
range at 10 % and 80 % reflectivity (or fitted by ``python -m bpy_pipeline fit``), so dark objects
vanish nearer than bright ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ....schema import meta
from ..intensity import MIN_RANGE, reflectance
from .base import DropModel, register_drop_model


@dataclass(frozen=True)
class ThresholdDrop:
    """``effects.drop.threshold``: a detection threshold from a datasheet's ranges (normal incidence, 50 % detection)."""

    range_at_10: float = field(default=40.0,
                               metadata=meta("m", low=0, low_open=True, help="for a 10 % reflectivity target (Ouster OS1: 40; sparse 3D camera: 10)"))
    range_at_80: float = field(default=120.0, metadata=meta("m", help="for an 80 % target (0: unknown, the lidar equation's R^2 decides)"))
    softness: float = field(default=0.1, metadata=meta("", low=0, help="width of the transition in ln(received power); 0 for a hard cut"))
    floor: float = field(default=0.0,
                         metadata=meta("", 0, 1, high_open=True, help="share of returns lost whatever the target (a fitted scan's near-range drop); 0: none"))


@dataclass(frozen=True)
class ThresholdModel:
    """Detection against a receiver sensitivity: a point returns when its received power
    ``P = a exp(-2 alpha R) / R^n`` (``a = rho cos g``, the apparent reflectance) exceeds
    ``sensitivity``; ``softness`` > 0 blurs the step into ``p = 1 / (1 + (P / s)^(-1 / softness))``,
    a logistic in ``ln P`` of width ``softness`` (0: a hard step). ``n`` is 2 for targets larger
    than the beam (the lidar equation).
    """

    sensitivity: float
    exponent: float = field(default=2.0, metadata=meta(""))
    softness: float = field(default=0.0, metadata=meta(""))
    alpha: float = field(default=0.0, metadata=meta(""))

    @classmethod
    def from_datasheet(cls, range_at_10: float, range_at_80: float = 0.0, softness: float = 0.0, alpha: float = 0.0) -> "ThresholdModel":
        """The model whose 50 % detection range is ``range_at_10`` for a 10 % target and
        ``range_at_80`` for an 80 % one (normal incidence). With one figure the exponent is the
        lidar equation's 2; with both it is the one that puts both on the threshold
        (``ln(8 exp(-2 alpha (R80 - R10))) / ln(R80 / R10)``: 1.89 for an Ouster OS1's 40 m / 120 m).
        """
        if range_at_80 > 0:
            exponent = (math.log(8.0) - 2.0 * alpha * (range_at_80 - range_at_10)) / math.log(range_at_80 / range_at_10)
        else:
            exponent = 2.0
        return cls(0.1 * math.exp(-2.0 * alpha * range_at_10) / range_at_10**exponent, exponent, softness, alpha)

    def range_at(self, reflectivity: float) -> float:
        """Range (m) at which a target of ``reflectivity`` at normal incidence is seen half the time."""
        lo, hi = 1e-3, 1e6
        for _ in range(200):  # bisection: exp(-2 alpha R) / R^n falls monotonically with R
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if reflectivity * math.exp(-2 * self.alpha * mid) / mid**self.exponent > self.sensitivity else (lo, mid)
        return math.sqrt(lo * hi)

    def detection_probability(self, apparent_reflectance: np.ndarray, range_m: np.ndarray) -> np.ndarray:
        """(p,) float32 probability that each point returns (apparent reflectance ``a``, range in m)."""
        r = np.maximum(np.asarray(range_m, np.float32), np.float32(MIN_RANGE))
        log_p = np.log(np.maximum(np.asarray(apparent_reflectance, np.float32), np.float32(1e-12))) - np.float32(self.exponent) * np.log(r)
        if self.alpha > 0:
            log_p -= np.float32(2.0 * self.alpha) * r
        z = log_p - np.float32(math.log(self.sensitivity))
        if self.softness <= 0:
            return (z >= 0).astype(np.float32)
        return np.float32(1.0) / (np.float32(1.0) + np.exp(np.clip(-z / np.float32(self.softness), -80, 80)))

    def to_dict(self) -> dict:
        return {
            "sensitivity": float(self.sensitivity), "exponent": float(self.exponent), "softness": float(self.softness), "alpha": float(self.alpha),
            "range_at_10": round(self.range_at(0.1), 3), "range_at_80": round(self.range_at(0.8), 3),  # for reading only
        }


def threshold_model(effects, models=None) -> ThresholdModel:
    """The ``threshold`` drop model: fitted (model file) or from the config's datasheet figures."""
    if models is not None and models.threshold is not None:
        return models.threshold
    t = effects.drop.threshold
    return ThresholdModel.from_datasheet(t.range_at_10, t.range_at_80, t.softness, effects.intensity.alpha)


def probability(points, beam, effects, models) -> np.ndarray:
    """``1 - (1 - floor) P(detect)``: lost below the threshold, and ``floor`` of the rest lost anyway.
    The apparent reflectance is the intensity model's (``rho cos^k g``, ``effects.intensity.incidence_exponent``):
    what the sensor reports is what a fit on its intensities saw."""
    keep = threshold_model(effects, models).detection_probability(reflectance(beam, effects.intensity.incidence_exponent), points["range"])
    floor = effects.drop.threshold.floor
    if floor > 0:
        keep *= np.float32(1.0 - floor)
    return np.float32(1.0) - keep


register_drop_model("threshold", DropModel(probability, fitted="threshold", inline=lambda drop: drop.threshold != ThresholdDrop(), inline_keys="threshold"))
