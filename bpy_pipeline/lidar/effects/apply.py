"""Sensor effects applied to point records after the trace: materials, intensity, ray drop, weather, range noise.

Every effect is one module with one interface (:class:`.base.Effect`: its config section, its ``check`` and
``apply(chunk, rng)``) registered in :data:`.base.EFFECTS` by the import line below; :func:`apply_effects` runs
them in their order on every chunk of points. :mod:`.materials`, :mod:`.intensity`, :mod:`.ray_drop` (the drop
models: :mod:`.drop`, a registry, one module per model), :mod:`.weather` (one module per kind) and :mod:`.noise`;
the fitted models and their files are in :mod:`.models`.

Each effect is a small model chosen in the config (``config.EffectsConfig``), takes the
explicit ``numpy.random.Generator`` of the frame, and can be switched off. A sensor preset's
profile (``effects`` in ``sensors.yaml``, fitted to a real scan or from a datasheet) fills what the
config does not give, unless ``effects.ideal: true`` (docs/realism.md). Points are in the
sensor frame, so a beam's direction is the point's direction from the origin (the scanner
reports mirrored returns along the emitted beam at the total path length).

Intensity (``effects.intensity.model``)
    ``reflectance``: ``rho cos(theta) g``, the object's ``lidar_reflectivity`` times the cosine
    of incidence times the mirror gain ``g`` (product of the reflectivities of the mirrors met),
    which is what range-compensated sensors report ("calibrated reflectivity").
    ``lidar``: the lidar equation for an extended Lambertian target,
    ``P ~ rho cos(theta) g exp(-2 alpha R) / R^2``, normalised so that a target of
    ``reference_reflectivity`` at normal incidence at ``reference_range`` reads 1 (nearer or
    brighter returns saturate at 1, as a receiver does).
    ``carla``: CARLA's ``exp(-a R)`` (``attenuation_rate`` a, CARLA's 0.004 per metre by default).
    Then as the sensor writes it: ``cos^k`` instead of ``cos`` (``incidence_exponent``), times
    ``scale`` clipped to 1, rounded to ``k / steps`` (255: an 8-bit intensity; 100: KITTI).

Ray drop (``effects.drop.model``)
    ``none``; ``uniform`` (each point lost with ``probability``; the parking paper drew up to
    0.3 %); ``carla`` (CARLA's RayCastLidar: a general rate dropped before tracing,
    independent of the hit, then with ``I = exp(-a R)`` a point above ``intensity_limit`` is
    kept and one below it is kept with probability ``(zero_intensity / intensity_limit) I +
    1 - zero_intensity``); ``threshold`` (a physical detection threshold: the received power
    ``rho cos g exp(-2 alpha R) / R^n`` against a sensitivity set by a datasheet's range at 10 %
    and 80 % reflectivity, so dark objects vanish nearer than bright ones); ``table`` (a drop
    probability over (range, incidence angle) fitted to real scans, bilinear between bins); ``mlp``
    (the same fitted by a small perceptron over the bins, as the Raphael paper does).

Range noise (``effects.noise``)
    Gaussian along the beam with sigma ``constant``, growing with ``range`` (``sigma +
    sigma_per_metre R``), from a ``table`` over (range, incidence angle) or from an ``mlp`` over it; a fixed per-ring
    range bias (``ring_bias``, metres per ring, as each laser of a multi-beam sensor has its
    own); angular jitter (``angular_jitter_deg``, one sigma in azimuth and in elevation; the
    point turns about the sensor at its range, the small-angle view of a beam pointing
    slightly off).

Fitted models (files written by ``python -m bpy_pipeline fit``, see :mod:`bpy_pipeline.lidar.fit.fitting`): with
``effects.drop.model_file`` the ``uniform``, ``threshold`` and ``table`` drop models take their
parameters from the file, with ``effects.noise.model_file`` the ``range`` and ``table`` noise
models do.
"""

from __future__ import annotations

import os
from concurrent.futures import Executor, ThreadPoolExecutor

import numpy as np

from ..cast.sharing import share
from .base import Chunk, ordered_effects
from . import materials, intensity, ray_drop, weather, noise  # noqa: F401  (registration: the effects)
from .drop.threshold import ThresholdModel
from .intensity import carla_intensity, compute_intensity, lidar_intensity
from .models import BinnedTable, FittedModels, MODEL_FORMAT, MODEL_VERSION, fitted_models, read_model_file, write_model_file
from .noise import noise_sigma, perturb
from .ray_drop import drop_mask, drop_probability

__all__ = ["apply_effects", "CHUNK_POINTS", "BinnedTable", "FittedModels", "MODEL_FORMAT", "MODEL_VERSION", "fitted_models", "read_model_file",
           "write_model_file", "noise_sigma", "perturb", "drop_mask", "drop_probability", "ThresholdModel", "carla_intensity", "compute_intensity",
           "lidar_intensity"]

CHUNK_POINTS = 1 << 16  # records per work item: a chunk's fields stay in cache across the passes over it


def apply_effects(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, threads: int | None = None, objects=None,
                  pool: Executor | None = None,
                  detection: np.ndarray | None = None) -> np.ndarray:
    """The configured effects (``config.EffectsConfig``) in a fixed order; returns new records.

    points : (p,) POINT_DTYPE records (sensor frame); beam : (p,) BEAM_DTYPE facts of the same points
    The registered effects (:func:`.base.ordered_effects`): 1. materials; 2. intensity of the true geometry; 3. ray
    drop (it sees the true range, as the receiver does); 4. weather (``effects.weather``, :mod:`.weather`:
    attenuation, scatterer returns, the noise floor); 5. range noise, ring bias and angular jitter on the points
    that remain. The chunk's generator is consumed in that order.
    The points go through in chunks of :data:`CHUNK_POINTS` on ``threads`` threads (default: every core;
    1: in this thread): this one and others of ``pool`` (an executor the caller keeps, e.g. the run's: no
    threads started per call) or else started for the call (:func:`bpy_pipeline.lidar.cast.sharing.share`). Chunk k draws from its
    own generator, seeded by the k-th of one draw of seeds from ``rng``, so the same generator state gives
    the same bytes however the threads run.
    ``objects``: the scene's ObjectTable, for ``effects.materials.objects`` (per-object reflectance models).
    ``detection``: (p,) float32 reflectivities the drop decision sees instead of the beam's (None: the beam's), the
    reading still the beam's (``scene.car_paint`` parts' ``detection``, mixing/paint.py).
    """
    models = {"drop": fitted_models(effects.drop, "effects.drop.model_file"), "noise": fitted_models(effects.noise, "effects.noise.model_file")}
    effects_in_order = ordered_effects()
    for effect in effects_in_order:
        effect.prepare(effects, models)
    starts = range(0, max(len(points), 1), CHUNK_POINTS)
    seeds = rng.integers(0, 2**63, size=len(starts), dtype=np.int64)

    def run(k: int) -> np.ndarray:
        part = slice(starts[k], starts[k] + CHUNK_POINTS)
        chunk = Chunk(points[part], beam[part], effects, models, objects, None if detection is None else detection[part])
        rng = np.random.Generator(np.random.PCG64(seeds[k]))
        for effect in effects_in_order:
            effect.apply(chunk, rng)
        return chunk.records

    if len(starts) == 1:
        return run(0)
    threads = threads or os.cpu_count() or 1
    if pool is not None or threads == 1:
        parts = share(pool, run, range(len(starts)), threads)
    else:
        with ThreadPoolExecutor(threads - 1, "effects") as own:
            parts = share(own, run, range(len(starts)), threads)
    raw = np.dtype((np.void, points.dtype.itemsize))
    return np.concatenate([p.view(raw) for p in parts]).view(points.dtype)
