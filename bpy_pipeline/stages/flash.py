"""The flash stage: a flash camera's depth and intensity images cast from the frame's exported scene
(``output.formats: [flash_image]``; the writer, :mod:`bpy_pipeline.io.rig_outputs`, only writes them). No Blender."""

from __future__ import annotations

from ..frame import Frame, Run
from ..io.rig_outputs import FLASH_RETURNS, FLASH_SEPARATION, FLASH_SUB_RAYS, flash_image_array
from ..lidar.cast.flash_returns import flash_images
from ..lidar.sensor.sensors import FLASH_PATTERNS
from .view import scan_surfaces


def flash_image(frame: Frame, config) -> object:
    """``(returns, rows, columns)`` FLASH_IMAGE_DTYPE of the flash camera of ``config`` at ``frame.pose`` in ``frame.buffers``."""
    images = flash_images(frame.buffers, config.sensor.spec, frame.pose, FLASH_SUB_RAYS, FLASH_SEPARATION, FLASH_RETURNS, scan_surfaces(config),
                          config.threads or None)
    return flash_image_array(images)


def flash_stage(frame: Frame, run: Run) -> None:
    """The sensor's flash image (file suffix ``""``)."""
    frame.flash[""] = flash_image(frame, run.config)


def rig_flash_stage(frame: Frame, run: Run) -> None:
    """The flash images of a rig's flash cameras (file suffix ``_sK``: sensor K), each from its own frame."""
    for k, sub in enumerate(frame.rig.frames):
        if sub.config.sensor.spec.pattern in FLASH_PATTERNS:
            frame.flash[f"_s{k}"] = flash_image(sub, sub.config)
