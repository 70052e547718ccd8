"""Ray patterns: the registry (:data:`PATTERNS`) and the built-in patterns, one module each.

Adding a pattern is one module that defines a :class:`RayPattern` and calls :func:`register_pattern`,
plus its name in the import line below.
"""

from .base import PATTERNS, RayPattern, register_pattern
from . import scanning, camera, rosette, file, profile  # noqa: F401  (registration)

__all__ = ["PATTERNS", "RayPattern", "register_pattern"]
