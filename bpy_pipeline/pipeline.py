"""Config -> frames on disk: the names this module held before the frame plan, importable from here this round.

The frame plan is :mod:`bpy_pipeline.plan` (``plan(config) -> tuple[Stage, ...]``: single sensor, rig or
real-scan background; :func:`run_frames`, :func:`run`), its values :mod:`bpy_pipeline.frame`
(:class:`Frame`, :class:`Run`) and its stages :mod:`bpy_pipeline.stages`. New code imports from there;
api.py, cli.py and parallel.py still import this module this round (nothing below them does).
"""

from __future__ import annotations

from .frame import Frame, Run, frame_rng, versions  # noqa: F401
from .lidar.effects import apply_effects  # noqa: F401
from .lidar.sensor_rays import CHUNK_RAYS, MAX_KEPT_MIRROR_RAYS, SensorRays  # noqa: F401
from .plan import LONG_STAGE_S, MAX_INDICES_PER_KEPT, Stage, empty_reason, labelled_objects, make_frame, plan, run, run_frames  # noqa: F401
from .stages.annotate import annotate_stage, frame_boxes, sensor_boxes, world_boxes  # noqa: F401
from .stages.camera import camera_stage  # noqa: F401
from .stages.rig import member_config  # noqa: F401
from .stages.scan import MAX_RESERVED_POINTS, collect_points, effects_stage, moving_objects, scan_buffers, scan_stage  # noqa: F401
from .stages.scene import build_frame_scene, build_stage, export_stage, pose_stage  # noqa: F401
from .stages.view import frames_per_scene, scan_surfaces, scene_trajectory, scene_view, sensor_pose  # noqa: F401



def _annotate_if_asked(frame: Frame, run: Run) -> None:
    if run.config.output.boxes.formats:
        annotate_stage(frame, run)


def _camera_if_asked(frame: Frame, run: Run) -> None:
    if run.config.output.kitti.camera.render and "kitti" in run.config.output.boxes.formats:
        camera_stage(frame, run)


# The single-sensor stages as the (stage, timing) pairs this module listed, each asking whether it runs
# (plan.plan(config) leaves such stages out instead, and gives a rig's and a real scan's plans).
STAGES = ((build_stage, "build"), (pose_stage, "build"), (export_stage, "export"), (scan_stage, "scan"), (effects_stage, None), (_annotate_if_asked, "boxes"), (_camera_if_asked, "camera"))


def sensor_rays(config, frame: int = 0):
    """The sensor's rays of frame ``frame`` as they enter the scene (sensor frame), in chunks."""
    return SensorRays(config).patterns(frame)


def edge_mask(config, frame: int = 0):
    """``(rows, columns)`` mirror-edge drop probabilities of the sensor's own mirrors; ``None`` when off."""
    return SensorRays(config).edge_mask(frame)
