"""The ``primitives`` builder. ``params`` (the ``scene`` section, its check, ``build``, the registration): pure (its meshes are the shared
:mod:`~bpy_pipeline.geometry.primitives`); ``scene``: Blender (bpy).

The package's names are its ``params``' (``bpy_pipeline.builders.primitives`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
