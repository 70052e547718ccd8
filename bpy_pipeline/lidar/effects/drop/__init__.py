"""Ray-drop models: the registry (:data:`DROP_MODELS`) and the built-in models, one module each."""

from .base import DROP_MODELS, DropModel, register_drop_model
from . import none, uniform, carla, threshold, table, mlp  # noqa: F401  (registration)

__all__ = ["DROP_MODELS", "DropModel", "register_drop_model"]
