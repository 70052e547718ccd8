"""``none``: every traced point returns."""

from .base import DropModel, register_drop_model

register_drop_model("none", DropModel(lambda points, beam, effects, models: None))
