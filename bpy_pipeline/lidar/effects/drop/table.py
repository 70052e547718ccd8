"""``table``: a drop probability over (range, incidence angle) fitted to real scans (a model file), bilinear between bins."""

from __future__ import annotations

import numpy as np

from ....errors import InputError
from .base import DropModel, register_drop_model


def probability(points, beam, effects, models) -> np.ndarray:
    if models is None or models.drop_table is None:
        raise InputError("effects.drop.model_file: the table drop model needs a model file holding a drop table (python -m bpy_pipeline fit)")
    return models.drop_table.lookup(points["range"], beam["cos_incidence"])


register_drop_model("table", DropModel(probability, fitted="drop_table"))
