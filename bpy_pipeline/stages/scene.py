"""The scene stages: build (the builder, then its population), pose (where the sensor is) and export
(the evaluated scene as buffers). Build and export call into Blender when they run."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..builders.base import BUILDERS, BuildContext, BuildResult
from ..config import Config
from ..errors import InputError
from ..frame import Frame, Run, frame_rng
from ..lidar.sensor.sensors import frame_time
from .view import frames_per_scene, scene_trajectory, scene_view, sensor_pose, sensor_poses


def build_populated(scene, context: BuildContext) -> BuildResult:
    """Build ``scene`` (a :class:`~bpy_pipeline.config.SceneConfig`) with its builder, then place its population."""
    result = BUILDERS.get(scene.builder).build(scene.params, context)
    population = getattr(scene, "population", None)
    if population is None or not population.kinds:
        return result
    from ..population.scene import populate

    if result.show is not None:  # the population is placed among what Blender holds
        result.show()

    # the population stands outside the builder's dynamic collection
    return dataclasses.replace(populate(population, context, result), dynamic=None, dynamic_parts=None)


def build_frame_scene(config: Config, index: int = 0, rng=None, keep: dict | None = None) -> BuildResult:
    """Build the scene that frame ``index`` of a run scans (the panel's Build scene: frame 0).

    rng : the generator of the frame the scene is built for (``frame_rng(config.seed, index)`` when ``None``)
    keep : the builder's state across calls (parking and industrial_hall keep their static scene there)
    """
    per_scene = frames_per_scene(config)
    rng = frame_rng(config.seed, index) if rng is None else rng
    return build_populated(config.scene, BuildContext(rng, scene_view(config, index, per_scene), {} if keep is None else keep, sensor_poses(config)))


def build_stage(frame: Frame, run: Run) -> None:
    """Build the frame's scene unless the scene built for an earlier frame serves it (or the run scans the open scene).

    Frame k scans the scene built for frame k - k mod n (n: :func:`~.view.frames_per_scene`), from that
    frame's generator, so a run started at any frame builds the same scene as the full run. The frame's
    ``scene`` is the run's current :class:`~bpy_pipeline.builders.base.BuildResult` either way.
    """
    config = run.config
    per_scene = frames_per_scene(config)
    first = frame.index - frame.index % per_scene
    if run.build and run.scene_frame != first:
        rng = frame.rng if first == frame.index else frame_rng(config.seed, first)
        run.sensor_poses = sensor_poses(config) if run.sensor_poses is None else run.sensor_poses
        context = BuildContext(rng, scene_view(config, first, per_scene), run.keep, run.sensor_poses, run.in_blender)
        run.result = build_populated(config.scene, context)
        run.scene_frame = first
        run.trajectory = None
        frame.built = True
    if run.trajectory is None:
        run.trajectory = scene_trajectory(config)
    frame.scene = run.result


def pose_stage(frame: Frame, run: Run) -> None:
    """The sensor's pose at the frame's start, and per ray for a moving sensor."""
    trajectory, spec = run.trajectory, run.config.sensor.spec
    if trajectory is None:
        frame.place(sensor_pose(run.config, frame.index))
        return
    trajectory.check_frames(frame.index + 1, frame_time(spec))
    pose_at = trajectory.frame_poses(frame.index, frame_time(spec))
    frame.place(pose_at([0.0])[0], pose_at, trajectory)


def reach(frame: Frame, config: Config) -> float:
    """m: how far the sensor of ``config`` can reach from where it is at the frame's start (its range, plus the
    stretch of path it covers during the frame when it moves)."""
    out = config.sensor.spec.max_range
    if frame.trajectory is not None:
        out += frame.trajectory.reach(frame.index, frame_time(config.sensor.spec))
    return out


def export_stage(frame: Frame, run: Run) -> None:
    """The evaluated scene as buffers: every object the sensor can reach during the frame.

    A builder whose result names its ``dynamic`` collection (:class:`~bpy_pipeline.builders.base.BuildResult`) has its
    static world exported once, whole, while its ``static_world`` token stays the same (kept in ``run.static_world``),
    and only that collection's objects every frame, those within reach (from the builder's arrays when it gives them,
    ``dynamic_parts``): the frame's buffers are the static world's, then those. The rays, limited to the sensor's
    range, do the culling the export would do.
    """
    from ..blender.export import export_scene, parts_buffers

    max_range = reach(frame, run.config)
    centre = frame.pose[:3, 3]
    scene = frame.scene
    if scene.dynamic is not None:
        if run.static_world is None or run.static_world[0] is not scene.static_world:
            static = export_scene(run.table, run.rules, skip=scene.dynamic)
            bounds = (static.vertices.min(axis=0), static.vertices.max(axis=0)) if len(static.vertices) else None
            run.static_world = (scene.static_world, static, bounds)
        _, static, bounds = run.static_world
        if scene.dynamic_parts is not None:
            dynamic = parts_buffers(run.table, scene.dynamic_parts, run.rules, keep_within=(centre, max_range))
        else:
            dynamic = export_scene(run.table, run.rules, keep_within=(centre, max_range), only=scene.dynamic)
        frame.buffers = static.joined(dynamic)
        near = len(frame.buffers.triangles) > len(static.triangles) or (
            bounds is not None and float(np.linalg.norm(np.clip(centre, *bounds) - centre)) <= max_range
        )
        if near or not len(frame.buffers.triangles):
            return
    else:
        frame.buffers = export_scene(run.table, run.rules, keep_within=(centre, max_range))
        if len(frame.buffers.triangles) or not len(export_scene(run.table, run.rules).triangles):
            return
    where = [round(float(v), 2) for v in centre]
    raise InputError(
        f"sensor: no object of the scene lies within max_range ({max_range} m) of the sensor at {where} in frame {frame.index}; move the sensor or raise "
        "sensor.max_range"
    )

