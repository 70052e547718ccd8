"""``uniform``: each point lost with ``effects.drop.probability`` (the parking paper drew up to 0.3 %),
or the probability of a model file."""

from __future__ import annotations

import numpy as np

from .base import DropModel, register_drop_model


def probability(points, beam, effects, models) -> np.ndarray:
    p = models.uniform if models is not None and models.uniform is not None else effects.drop.probability
    return np.full(len(points), p, np.float32)


register_drop_model("uniform", DropModel(probability, fitted="uniform", inline=lambda drop: drop.probability != 0.0, inline_keys="probability"))
