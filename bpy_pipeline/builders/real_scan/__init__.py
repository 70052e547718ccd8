"""The ``real_scan`` builder. ``params`` (the ``scene`` section's check, ``build``, the registration): pure. No Blender side: the real-scan frame
plan (:mod:`bpy_pipeline.stages.mixing`) makes its frames.

The package's names are its ``params``' (``bpy_pipeline.builders.real_scan`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
