"""Range noise (``effects.noise``): Gaussian along the beam, a per-ring range bias, angular jitter.

Gaussian along the beam with sigma ``constant``, growing with ``range`` (``sigma + sigma_per_metre R``), from a
``table`` over (range, incidence angle) or from an ``mlp`` over it (both fitted to real scans, :mod:`.models`): the
sigma models are a registry (:data:`NOISE_MODELS`; a new one is a :func:`register_noise_model` call);
a fixed per-ring range bias (``ring_bias``, metres per ring, as each laser of a multi-beam sensor has its own);
angular jitter (``angular_jitter_deg``, one sigma in azimuth and in elevation; the point turns about the sensor at
its range, the small-angle view of a beam pointing slightly off). The last effect on a chunk: it moves the points
that remain after drop and weather.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Literal

import numpy as np

from ...errors import InputError
from ...registry import Registry
from ...schema import meta
from ..points import POINT_DTYPE
from . import effects_kernels
from .base import Chunk, Effect, register_effect
from .models import FittedModels, check_model_file


@dataclass(frozen=True)
class NoiseModel:
    """A range-noise model's registry entry (``effects.noise.model`` names one).

    sigma : ``sigma(points, beam, noise, models) -> float | (p,) float32``: the range noise sigma (m) of each point
        (POINT_DTYPE records, BEAM_DTYPE facts, the ``effects.noise`` section, the fitted models of its
        ``model_file`` or ``None``); a float when every point has the same
    fitted : the ``FittedModels`` attribute a model file may give this model (``None``: none)
    inline : ``inline(noise) -> bool``: the section gives the parameters inline as well (an error with a model file)
    inline_keys : those inline keys, for the message
    """

    sigma: Callable[..., np.ndarray | float]
    fitted: str | None = None
    inline: Callable[..., bool] = lambda noise: False
    inline_keys: str = ""


NOISE_MODELS: Registry[NoiseModel] = Registry("noise model", "effects.noise.model")


def register_noise_model(name: str, model: NoiseModel) -> NoiseModel:
    """Make ``effects.noise.model: name`` draw range noise with ``model``'s sigma."""
    return NOISE_MODELS.register(name, model)


def _range_sigma(points, beam, noise, models):
    sigma, slope = models.noise_range if models is not None and models.noise_range is not None else (noise.sigma, noise.sigma_per_metre)
    return np.float32(sigma) + np.float32(slope) * points["range"]


def _mlp_sigma(points, beam, noise, models):
    if models is None or models.noise_mlp is None:
        raise InputError("effects.noise.model_file: the mlp noise model needs a model file holding a noise mlp (python -m bpy_pipeline fit)")
    return models.noise_mlp.lookup(points["range"], beam["cos_incidence"])


def _table_sigma(points, beam, noise, models):
    if models is None or models.noise_table is None:
        raise InputError("effects.noise.model_file: the table noise model needs a model file holding a noise table (python -m bpy_pipeline fit)")
    return models.noise_table.lookup(points["range"], beam["cos_incidence"])


register_noise_model("constant", NoiseModel(lambda points, beam, noise, models: noise.sigma))
register_noise_model("range", NoiseModel(_range_sigma, "noise_range", lambda noise: (noise.sigma, noise.sigma_per_metre) != (0.0, 0.0),
                                         "sigma / sigma_per_metre"))
register_noise_model("table", NoiseModel(_table_sigma, "noise_table"))
register_noise_model("mlp", NoiseModel(_mlp_sigma, "noise_mlp"))


@dataclass(frozen=True)
class NoiseConfig:
    """``effects.noise``: Gaussian range noise along the beam, per-ring bias, angular jitter."""

    model: Literal[NOISE_MODELS.names()] = "constant"  # a name of NOISE_MODELS
    sigma: float = field(default=0.0, metadata=meta("m", low=0, help="Gaussian along the beam (`range`: at zero range)"))
    sigma_per_metre: float = field(default=0.0, metadata=meta("", low=0, help="m of sigma per m of range (`range`)"))
    model_file: str = field(default="", metadata=meta(help="a file of `python -m bpy_pipeline fit`: `range` and `table` take their parameters from it"))
    ring_bias: list[float] = field(default_factory=list, metadata=meta("m", help="added to every range of ring k (one per ring, or none)"))
    angular_jitter_deg: float = field(default=0.0, metadata=meta("deg", low=0, help="one sigma, in azimuth and in elevation"))


def noise_sigma(points: np.ndarray, beam: np.ndarray, noise, models: FittedModels | None = None) -> np.ndarray | float:
    """Range noise sigma (m) of each point by the model ``noise.model`` names: a float for ``constant``, else (p,) float32."""
    return NOISE_MODELS.get(noise.model).sigma(points, beam, noise, models)


_NONE32 = np.zeros(0, np.float32)
_NO_RINGS = np.zeros(0, np.uint16)


def perturb(points: np.ndarray, beam: np.ndarray, noise, rng: np.random.Generator, models: FittedModels | None = None) -> None:
    """Range noise, per-ring bias and angular jitter applied to ``points`` in place (sensor frame).

    The range moves by ``N(0, sigma) + bias[ring]`` (clamped at 0) and the point moves as much
    along its beam (``beam["direction"]``: the emitted ray, or the last segment of a point at its
    true position behind mirrors), so ``x y z`` and ``range`` stay consistent. With jitter the
    point first turns by ``N(0, jitter)`` in azimuth and in elevation about the sensor's origin
    (tangent-plane step, length kept).
    """
    n = len(points)
    sigma = noise_sigma(points, beam, noise, models)
    has_noise = np.any(np.asarray(sigma) > 0)
    jitter = math.radians(noise.angular_jitter_deg)
    if n == 0 or not (has_noise or noise.ring_bias or jitter > 0):
        return
    if noise.ring_bias:
        bias = np.asarray(noise.ring_bias, np.float32)
        ring = points["ring"]
        if ring.max() >= len(bias):
            raise InputError(f"effects.noise.ring_bias: {len(bias)} values but the scan has ring {int(ring.max())}; give one per ring")
    fits = (
        jitter == 0
        and points.dtype == POINT_DTYPE
        and points.flags.c_contiguous
        and (np.isscalar(sigma) or (sigma.dtype == np.float32 and sigma.shape == (n,)))
    )
    kernels = effects_kernels.compiled() if fits else None
    if kernels is not None:  # the same operations in one compiled pass over the records (effects_kernels.py)
        draw = rng.standard_normal(n, dtype=np.float32) if has_noise else _NONE32
        sigmas = _NONE32 if np.isscalar(sigma) else np.ascontiguousarray(sigma)
        one = np.float32(sigma) if np.isscalar(sigma) else np.float32(0)
        biases, rings = (bias, np.ascontiguousarray(ring)) if noise.ring_bias else (_NONE32, _NO_RINGS)
        kernels.move_along_beam(points, beam["direction"], draw, one, sigmas, biases, rings)
        return
    old = points["range"]
    new = old.copy()
    if has_noise:
        draw = rng.standard_normal(n, dtype=np.float32)
        draw *= np.float32(sigma) if np.isscalar(sigma) else sigma
        new += draw
    if noise.ring_bias:
        new += bias[ring]
    np.maximum(new, np.float32(0), out=new)
    if jitter > 0:
        # p' = p + |p| (a e_az + e e_el), with e_az = (-y, x, 0) / rho and e_el = (-x z, -y z, rho^2) / (rho |p|)
        # orthonormal to p, so |p'| = |p| sqrt(1 + a^2 + e^2): divided by that, the length is kept;
        # beams along z (rho ~ 0) keep still
        x, y, z = (np.ascontiguousarray(points[k]) for k in "xyz")  # packed records: strided math is slower
        a, e = rng.standard_normal((2, n), dtype=np.float32) * np.float32(jitter)
        rho2 = x * x
        rho2 += y * y
        rho = np.sqrt(rho2)
        length = np.sqrt(rho2 + z * z)
        still = rho <= np.float32(1e-6) * length
        if still.any():
            a[still], e[still], rho[still] = 0.0, 0.0, 1.0
        stretch = a * a
        stretch += e * e
        stretch += np.float32(1)
        np.sqrt(stretch, out=stretch)
        keep = np.float32(1) / stretch
        e /= rho  # elevation step per unit of (-x z, -y z, rho^2)
        a *= length
        a /= rho  # azimuth step per unit of (-y, x, 0)
        ez = e * z
        points["x"] = (x - y * a - x * ez) * keep
        points["y"] = (y + x * a - y * ez) * keep
        points["z"] = (z + rho2 * e) * keep
    step = new - old
    direction = beam["direction"]
    for axis, k in enumerate("xyz"):
        points[k] += step * direction[:, axis]
    points["range"] = new


class Noise(Effect):
    """Range noise, ring bias and angular jitter on the points that remain (:func:`perturb`)."""

    name, section, config, order = "noise", "noise", NoiseConfig, 50

    def check(self, effects, spec=None) -> None:
        from ..sensor.sensors import rings

        noise = effects.noise
        count = None if spec is None else rings(spec)
        if noise.ring_bias and count is not None and len(noise.ring_bias) != count:
            raise InputError(f"effects.noise.ring_bias: one value per ring ({count} for this sensor), got {len(noise.ring_bias)}")
        check_model_file("noise", noise, {name: (model.fitted, model.inline(noise), model.inline_keys) for name, model in NOISE_MODELS.items() if model.fitted})

    def prepare(self, effects, models: dict) -> None:
        if models["noise"] is not None and models["noise"].noise_table is not None:
            models["noise"].noise_table._raster  # build the lookup raster once, before the threads share it

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        perturb(chunk.records, chunk.beam, chunk.effects.noise, rng, chunk.models["noise"])


register_effect(Noise())
