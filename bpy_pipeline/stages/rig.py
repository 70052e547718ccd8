"""A sensor rig's stages: one stage runs the single-sensor stages for each member, then the platform's
buffers, the merged cloud and the merged boxes (:mod:`bpy_pipeline.rig` holds the rig's pure parts).

Member k's frame has its own generator (:func:`~bpy_pipeline.rig.member_rng`) and its pose on the
platform, and goes through the same stages a single-sensor run of that sensor uses (export within
its range, scan, effects, its boxes), so its bytes are those of that run.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..config import Config, SensorConfig
from ..frame import Frame, Run, StageFunction
from ..geometry.boxes import boxes_in_frame, keep_boxes
from ..lidar.sensor.sensors import frame_time
from ..lidar.cast.visibility import occlusion_levels
from ..rig import RigFrame, member_rng, merge_clouds, merged_boxes
from .annotate import world_boxes
from .scan import effects_stage, scan_stage
from .scene import export_stage


def member_config(config: Config, k: int) -> Config:
    """The single-sensor config of sensor ``k`` of the rig of ``config`` (its pose comes from the rig, not from it)."""
    member = config.sensor.rig[k]
    sensor = SensorConfig(member.spec, position=member.position, rotation_deg=member.rotation_deg, divergence=config.sensor.divergence)
    return dataclasses.replace(config, sensor=sensor)


def rig_members(run: Run) -> list[Run]:
    """One single-sensor :class:`~bpy_pipeline.frame.Run` per sensor of the run's rig (they scan the run's scene, never build)."""
    return [Run(member_config(run.config, k), build=False, table=run.table, threads=run.threads, log=run.log) for k in range(len(run.config.sensor.rig))]


def member_boxes_stage(frame: Frame, run: Run) -> None:
    """A member's boxes in the world, none dropped yet (:func:`merged_boxes_stage` merges them, then keeps each
    member's where it holds their minimum points, in its frame)."""
    frame.boxes = world_boxes(frame.buffers, run.config, frame.pose, frame.points, frame.scene.headings, frame.index, frame.rng, run.rays, skip_unseen=True,
                              caster=frame.caster, direct_returns=frame.direct_returns)


def each_member(*stages: tuple[str | None, StageFunction]) -> StageFunction:
    """A stage that runs ``stages`` (``(timing, stage)`` pairs; ``None``: a stage that times its own
    parts) for each sensor of the rig on its own frame, then the platform's buffers (everything any
    sensor reaches, for the record and the merged boxes). Each member's timings are its own; the
    frame's add them up, timing by timing."""

    def members_stage(frame: Frame, run: Run) -> None:
        from ..blender.export import export_scene

        config = run.config
        if not run.members:
            run.members = rig_members(run)
        frame.rig = RigFrame(config.sensor.rig)
        reach = 0.0
        for k, (sensor, member) in enumerate(zip(config.sensor.rig, run.members)):
            matrix = sensor.matrix()
            sub = Frame(frame.index, member.config, member_rng(config.seed, frame.index, k), scene=frame.scene, built=frame.built)
            if frame.moving:
                sub.place(frame.pose @ matrix, lambda t, m=matrix: frame.pose_at(t) @ m, frame.trajectory)
            else:
                sub.place(frame.pose @ matrix)
            for timing, stage in stages:
                start = time.perf_counter()
                stage(sub, member)
                if timing is not None:
                    sub.timings[timing] = sub.timings.get(timing, 0.0) + time.perf_counter() - start
            for timing, took in sub.timings.items():
                frame.timings[timing] = frame.timings.get(timing, 0.0) + took
            frame.rig.frames.append(sub)
            reach = max(
                reach,
                float(np.linalg.norm(matrix[:3, 3]))
                + sensor.spec.max_range
                + (0.0 if frame.trajectory is None else frame.trajectory.reach(frame.index, frame_time(sensor.spec))),
            )
        start = time.perf_counter()
        frame.buffers = export_scene(run.table, run.rules, keep_within=(frame.pose[:3, 3], reach))
        frame.timings["export"] = frame.timings.get("export", 0.0) + time.perf_counter() - start

    return members_stage


def merge_stage(frame: Frame, run: Run) -> None:
    """The merged cloud with each point's sensor index (:data:`~bpy_pipeline.rig.RIG_POINT_DTYPE`; the platform frame, or the world)."""
    world = run.config.output.frame == "world"
    frame.rig.to_merged = None if world else [s.matrix() for s in run.config.sensor.rig]
    frame.points = merge_clouds([sub.points for sub in frame.rig.frames], frame.rig.to_merged)


def merged_boxes_stage(frame: Frame, run: Run) -> None:
    """Boxes of the merged cloud, kept where the sensors together hold their minimum points; each member's
    kept where it alone holds them (in its frame: the sensor's, or the world)."""
    section = run.config.output.boxes
    unfiltered = [sub.boxes for sub in frame.rig.frames]
    for sub in frame.rig.frames:
        kept = keep_boxes(sub.boxes, section.min_points, section.min_points_default)
        sub.boxes = boxes_in_frame(kept, sub.pose if sub.config.output.frame == "sensor" else np.eye(4))
    merged = merged_boxes(unfiltered, section.min_points, section.min_points_default)
    merged["occlusion"] = occlusion_levels(merged["visible"], merged["unoccluded"], section.occlusion_levels)
    frame.boxes = boxes_in_frame(merged, frame.pose if run.config.output.frame == "sensor" else np.eye(4))


def members_stage_of(config: Config, with_boxes: bool) -> StageFunction:
    """The rig's per-member stage: export, scan, effects (and its boxes when ``with_boxes``)."""
    stages = [("export", export_stage), ("scan", scan_stage), (None, effects_stage)]
    if with_boxes:
        stages.append(("boxes", member_boxes_stage))
    return each_member(*stages)
