"""Ray drop (``effects.drop``): which traced points the sensor loses, by the model ``effects.drop.model`` names.

The models are a registry of their own (:data:`.drop.DROP_MODELS`, one module each: ``none``, ``uniform``,
``carla``, ``threshold``, ``table``, ``mlp``); this effect draws each point once against its model's loss
probability (or lets the model draw, CARLA's two draws) and keeps the survivors. It runs after the intensity
(the drop sees the true range, as the receiver does) and before the weather.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...schema import from_dict, meta
from .base import Chunk, Effect, register_effect
from .drop import DROP_MODELS
from .drop.carla import CarlaDrop
from .drop.threshold import ThresholdDrop
from .models import FittedModels, check_model_file, fitted_models


@dataclass(frozen=True)
class DropConfig:
    """``effects.drop``: the model (lidar/effects/drop, a registry) and its parameters."""

    model: str = field(default="none", metadata=meta(help="a name of lidar/effects/drop (DROP_MODELS)"))
    probability: float = field(default=0.0, metadata=meta("", 0, 1, help="for `uniform`: the share of returns dropped"))
    carla: CarlaDrop = field(default_factory=CarlaDrop)
    threshold: ThresholdDrop = field(default_factory=ThresholdDrop)
    params: dict = field(default_factory=dict, metadata=meta(help="for a model that takes its parameters here (its own dataclass checks them)"))
    model_file: str = field(default="",
                            metadata=meta(help="a file of `python -m bpy_pipeline fit`: `uniform`, `threshold` and `table` take their parameters from it"))


def drop_probability(points: np.ndarray, beam: np.ndarray, effects, models: FittedModels | None = None) -> np.ndarray | None:
    """Probability that each traced point is lost, (p,) float32, for the configured model
    (:mod:`.drop`); ``None`` for a model that drops nothing. ``models``: those of
    ``effects.drop.model_file``, read here when not given."""
    models = fitted_models(effects.drop, "effects.drop.model_file") if models is None else models
    return DROP_MODELS.get(effects.drop.model).probability(points, beam, effects, models)


def drop_mask(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, models: FittedModels | None = None) -> np.ndarray | None:
    """(p,) bool, True for the points that survive the configured drop model; ``None`` keeps all.

    One draw per point against its probability, unless the model draws itself (``carla``: twice).
    """
    model = DROP_MODELS.get(effects.drop.model)
    if len(points) == 0 or model.probability(points[:0], beam[:0], effects, models) is None:
        return None
    if model.mask is not None:
        return model.mask(points, beam, effects, rng, models)
    return rng.random(len(points), dtype=np.float32) >= drop_probability(points, beam, effects, models)


class Drop(Effect):
    """The configured drop model's survivors (:func:`drop_mask`); the drop decision sees ``chunk.detection`` when given."""

    name, section, config, order = "drop", "drop", DropConfig, 30

    def check(self, effects, spec=None) -> None:
        drop = effects.drop
        if drop.threshold.range_at_80 and drop.threshold.range_at_80 <= drop.threshold.range_at_10:
            raise InputError(
                f"effects.drop.threshold.range_at_80: must exceed range_at_10 ({drop.threshold.range_at_10} m), or be 0, got {drop.threshold.range_at_80}"
            )
        model = DROP_MODELS.get(drop.model)
        if model.params is not None:
            from_dict(model.params, drop.params, "effects.drop.params")
        elif drop.params:
            raise InputError(f"effects.drop.params: the {drop.model} drop model takes no params")
        check_model_file("drop", drop, {drop.model: (model.fitted, model.inline(drop), model.inline_keys)} if model.fitted else {})

    def prepare(self, effects, models: dict) -> None:
        if models["drop"] is not None and models["drop"].drop_table is not None:
            models["drop"].drop_table._raster  # build the lookup raster once, before the threads share it

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        seen = chunk.beam
        if chunk.detection is not None:  # the drop decision sees these reflectivities, the reading the beam's (mixing/paint.py)
            seen = chunk.beam.copy()
            seen["reflectivity"] = chunk.detection
        chunk.keep(drop_mask(chunk.points, seen, chunk.effects, rng, chunk.models["drop"]))


register_effect(Drop())
