"""The ``parking`` builder. ``params`` (the ``scene`` section, its check, ``build``, the registration): pure (its layout is the shared
:mod:`~bpy_pipeline.geometry.indoor`); ``scene``, ``level_nodes``: Blender (bpy).

The package's names are its ``params``' (``bpy_pipeline.builders.parking`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
