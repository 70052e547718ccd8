"""Where the sensor is and what the builder should model: the sensor's pose per frame, the scene's view
(level of detail), the moving sensor's path and the scanner's surface rules. No Blender."""

from __future__ import annotations

import numpy as np

from ..builders.base import BUILDERS
from ..config import Config, sensor_trajectory
from ..geometry.clearance import NO_POSES, PATH_STEP, SensorPoses
from ..geometry.lod import PathView, PlannedPath, path_view
from ..geometry.transforms import pose_matrix
from ..lidar.sensor.platform import Trajectory
from ..lidar.cast.scanner import MirrorGlassRules
from ..lidar.sensor.sensors import frame_time, mount_offset
from ..lidar.sensor.view import view_of
from ..rig import RigSensor, RigView, field_of_view


def sensor_pose(config: Config, frame: int = 0) -> np.ndarray:
    """``(4, 4)`` sensor-to-world transform of frame ``frame``, raised by the preset's mount height.

    The configured position and rotation; in a scene that places the sensor (railway stations,
    the parking robot, the hall's mount) the scene's station of that frame instead, turned by
    ``sensor.rotation_deg`` (so yaw 0 looks along the track). A rig's platform: each sensor adds
    its own mount height (:meth:`~bpy_pipeline.rig.RigSensor.matrix`).
    """
    station = None if config.sensor.trajectory is not None else BUILDERS.get(config.scene.builder).station(config.scene.params, frame)
    if station is not None:
        pose = station @ pose_matrix((0.0, 0.0, 0.0), config.sensor.rotation_deg)
    else:
        pose = pose_matrix(config.sensor.position, config.sensor.rotation_deg)
    if not config.sensor.rig:
        pose[:3, 3] += mount_offset(config.sensor.spec)
    return pose


def frames_per_scene(config: Config) -> int:
    """How many frames in a row one built scene serves (a railway's stations: one line scanned from each)."""
    return BUILDERS.get(config.scene.builder).frames_per_scene(config.scene.params)


def planned_path(sensor, frames: int) -> PlannedPath:
    """The :class:`~bpy_pipeline.geometry.lod.PlannedPath` of a config's ``sensor`` section (with a trajectory) over ``frames`` frames."""
    frames = int(frames)

    def follow(path: np.ndarray | None) -> PathView:
        spec = sensor.spec
        trajectory = sensor_trajectory(sensor, path)
        trajectory.check_frames(frames, frame_time(spec))
        view = view_of(spec, np.zeros((1, 3)))  # the spec's step and range
        return path_view(trajectory, frames, frame_time(spec), view.step, view.max_range, spec.rotation_hz)

    return PlannedPath(sensor, frames, follow)


def scene_view(config: Config, first: int, count: int):
    """The :class:`~bpy_pipeline.geometry.lod.SensorView` of frames ``first`` .. ``first + count - 1`` (static sensors;
    a rig's: a :class:`~bpy_pipeline.rig.RigView`). A moving sensor: the :class:`~bpy_pipeline.geometry.lod.PlannedPath`
    of the whole run for a builder that ``follows_path`` (its scene serves every frame), else ``None`` (fixed detail)."""
    if config.sensor.trajectory is not None:
        return planned_path(config.sensor, config.frames) if BUILDERS.get(config.scene.builder).follows_path else None
    frames = range(first, min(first + count, config.frames)) or range(first, first + 1)
    sensors = config.sensor.rig or (RigSensor(config.sensor.spec),)
    poses = [sensor_pose(config, f) @ (s.matrix() if config.sensor.rig else np.eye(4)) for f in frames for s in sensors]
    fields = tuple(field_of_view(s.spec, pose) for s, pose in zip(sensors * len(frames), poses))
    if not config.sensor.rig:
        view = view_of(config.sensor.spec, [sensor_pose(config, f)[:3, 3] for f in frames])
    else:  # the finest of the sensors, as far as the farthest reaches
        views = [view_of(s.spec, [p[:3, 3] for p in poses]) for s in sensors]
        view = min(views, key=lambda v: v.step)
        view = RigView(view.positions, view.step, max(v.max_range for v in views))
    return RigView(view.positions, view.step, view.max_range, fields)


def sensor_poses(config: Config) -> SensorPoses:
    """Every optical centre the run's sensors take (:class:`~bpy_pipeline.geometry.clearance.SensorPoses`): each frame's
    pose (a scene's stations, once each) times each rig member, or a moving sensor's path over the whole run sampled
    :data:`~bpy_pipeline.geometry.clearance.PATH_STEP` apart. A path along a curve of the scene is not known before the
    scene is built: none (the scan's enclosure check still warns)."""
    members = [s.matrix() for s in config.sensor.rig] or [np.eye(4)]
    section = config.sensor.trajectory
    if section is not None:
        if section.curve:
            return NO_POSES
        trajectory = sensor_trajectory(config.sensor)
        duration = min(config.frames * frame_time(config.sensor.spec), trajectory.duration)
        s0, s1 = trajectory.distance([0.0, duration])
        arc = np.unique(np.concatenate([np.linspace(s0, s1, int(np.ceil((s1 - s0) / PATH_STEP)) + 1),
                                        trajectory.arc[(trajectory.arc > s0) & (trajectory.arc < s1)]]))
        poses = trajectory.poses(np.interp(arc, trajectory.clock_arc, trajectory.clock_times) - trajectory.start_time)
        step = PATH_STEP
    else:
        stations = BUILDERS.get(config.scene.builder).stations(config.scene.params)
        frames = range(min(config.frames, stations) if stations else config.frames)
        poses = np.array([sensor_pose(config, f) for f in frames])
        step = 0.0
    points = np.concatenate([(poses @ m)[:, :3, 3] for m in members])
    return SensorPoses(np.unique(np.round(points, 6), axis=0), step=step)


def scene_trajectory(config: Config) -> Trajectory | None:
    """The sensor's trajectory in the scene as built (a curve is read from it); ``None`` for a static sensor."""
    section = config.sensor.trajectory
    if section is None or not section.curve:
        return sensor_trajectory(config.sensor)
    from ..blender.curves import curve_polyline

    return sensor_trajectory(config.sensor, curve_polyline(section.curve))


def scan_surfaces(config: Config) -> MirrorGlassRules:
    """The scanner's rules for mirrors and glass from ``effects.mirrors``."""
    mirrors = config.effects.mirrors
    return MirrorGlassRules(mirrors.normal_return_deg, mirrors.glass.normal_return_deg, mirrors.glass.reflect_fraction, mirrors.glass.max_passes)
