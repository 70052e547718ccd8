"""What a ray-drop model is: its registry entry (``effects.drop.model`` names one).

A drop model gives each traced point the probability of being lost (:attr:`DropModel.probability`);
the points are then drawn once each from the frame's generator, unless the model draws itself
(:attr:`DropModel.mask`, CARLA's two draws). A model's own parameters are a dataclass it owns:
built-in models keep their historic sections (``effects.drop.carla``, ``effects.drop.threshold``,
the flat ``effects.drop.probability``); any other model reads ``effects.drop.params``, validated
against its dataclass. Adding a model is one module that calls :func:`register_drop_model`, plus
its name in the import line of this package's ``__init__``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ....registry import Registry


@dataclass(frozen=True)
class DropModel:
    """A drop model's registry entry.

    probability : ``probability(points, beam, effects, models) -> (p,) float32`` loss probability of each
        point (POINT_DTYPE records, BEAM_DTYPE facts, the config's ``effects``, the fitted models of
        ``effects.drop.model_file`` or ``None``); ``None`` for a model that drops nothing
    mask : ``mask(points, beam, effects, rng, models) -> (p,) bool`` survivors, for a model that draws
        otherwise than once per point against its probability (``None``: that one draw)
    params : the dataclass of ``effects.drop.params`` for a model that takes parameters there
    fitted : the ``FittedModels`` attribute a model file may give this model (``None``: none)
    inline : ``inline(drop) -> bool``: the config gives the parameters inline as well (an error with a model file)
    """

    probability: Callable[..., np.ndarray | None]
    mask: Callable[..., np.ndarray] | None = None
    params: type | None = None
    fitted: str | None = None
    inline: Callable[..., bool] = lambda drop: False
    inline_keys: str = ""


DROP_MODELS: Registry[DropModel] = Registry("drop model", "effects.drop.model")


def register_drop_model(name: str, model: DropModel) -> DropModel:
    """Make ``effects.drop.model: name`` drop points with ``model``."""
    return DROP_MODELS.register(name, model)
