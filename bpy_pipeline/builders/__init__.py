"""Scene builders: the registry (:data:`BUILDERS`) and the built-in builders, one module each.

Adding a builder is one new module that defines its parameters dataclass and calls
:func:`register_builder`, plus its name in the import line below. The modules here are pure;
each builder's ``build`` imports its Blender code from :mod:`bpy_pipeline.scenes` when called.
"""

from .base import BUILDERS, Builder, BuildContext, BuildResult, Distribution, build_scene, register_builder
from . import railway, primitives, blend, parking, industrial_hall, street, real_scan  # noqa: F401  (registration)

__all__ = ["BUILDERS", "Builder", "BuildContext", "BuildResult", "Distribution", "build_scene", "register_builder"]
