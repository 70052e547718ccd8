"""LiDAR Pipeline: the Blender sidebar panel of bpy_pipeline (3D Viewport > Sidebar > LiDAR).

This folder is the extension's package root: ``scripts/build_extension.py`` stages it with
``bpy_pipeline/`` and ``assets_manifest/labels.yaml`` beside it, the manifest and the wheels,
and builds the zip with Blender's extension tool. Imports are relative: inside Blender the
package is ``bl_ext.<repository>.lidar_pipeline``.

Registration errors propagate (Blender reports them); what was registered before the error is
unregistered again, so enabling can be retried and register / unregister cycles stay clean.
"""

from __future__ import annotations

import bpy

from . import operators, panels, settings

_registered: list[type] = []


def register() -> None:
    try:
        for cls in (*settings.register(), *operators.CLASSES, *panels.CLASSES):
            bpy.utils.register_class(cls)
            _registered.append(cls)
        settings.attach()
    except BaseException:
        unregister()
        raise


def unregister() -> None:
    settings.detach()
    while _registered:
        bpy.utils.unregister_class(_registered.pop())
