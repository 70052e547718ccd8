"""Scene builders: the registry (:data:`BUILDERS`) and the built-in builders, one package each.

A builder's package ``builders/<name>/`` holds ``params.py`` (its parameters dataclass, ``check``,
``build`` and :func:`register_builder`), its pure geometry (``layout.py`` and other modules) and its
Blender side, marked by the file name: ``scene.py``, ``scene_*.py`` and ``*_nodes.py`` import bpy,
every other file is pure. ``build`` imports the package's ``scene`` when called. The package
re-exports its ``params`` (``bpy_pipeline.builders.<name>`` was that module before). Adding a builder
is one new package plus its name in the import line below.
"""

from .base import BUILDERS, Builder, BuildContext, BuildResult, build_scene, register_builder
from . import railway, primitives, blend, parking, industrial_hall, street, real_scan  # noqa: F401  (registration)

__all__ = ["BUILDERS", "Builder", "BuildContext", "BuildResult", "build_scene", "register_builder"]
