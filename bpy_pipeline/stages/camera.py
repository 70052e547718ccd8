"""The camera stage: KITTI's ``image_2`` rendered by Blender from ``output.kitti.camera`` (in the plan when it asks for a rendering)."""

from __future__ import annotations

from ..frame import Frame, Run


def camera_stage(frame: Frame, run: Run) -> None:
    """Render the frame's camera view, coloured by class, into ``frame.images["image_2"]``."""
    from ..blender.camera_render import class_colors, render_camera

    frame.images["image_2"] = render_camera(run.config.output.kitti.camera, frame.pose, class_colors(frame.buffers, run.table.color_lut()))
