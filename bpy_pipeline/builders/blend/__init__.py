"""The ``blend`` builder. ``params`` (the ``scene`` section, its check, ``build``, the registration): pure; ``scene``: Blender (bpy).

The package's names are its ``params``' (``bpy_pipeline.builders.blend`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
