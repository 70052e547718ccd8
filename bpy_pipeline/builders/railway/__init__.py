"""The ``railway`` builder. ``params`` (the ``scene`` section, its check, ``build``, the registration), ``layout`` (the planned tracks, supports and
wires), ``alignment``, ``catenary``, ``parts``, ``trackside``, ``terrain``, ``assets``: pure; ``scene``, ``scene_assets``, ``track_nodes``,
``catenary_nodes``: Blender (bpy).

The package's names are its ``params``' (``bpy_pipeline.builders.railway`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
