"""The ``street`` builder. ``params`` (the ``scene`` section, its check, the ego station, ``build``, the registration), ``layout``
(the intersection, its road users and their placement), ``dressing``, ``vegetation``: pure; ``scene``, ``scatter_nodes``: Blender (bpy).

The package's names are its ``params``' (``bpy_pipeline.builders.street`` was that module before the builders became packages).
"""

from .params import *  # noqa: F403
