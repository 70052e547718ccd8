"""Config -> frames on disk: each frame is a :class:`~.frame.Frame` passed through named stages.

    build -> pose -> export -> scan -> effects -> annotate -> write

``build`` comes before ``pose`` because a moving sensor may follow a curve of the built scene.
Each stage is a function ``stage(frame, run)``; :func:`run_frames` is a loop over a frame range.
A run can start at any frame: a scene that serves several frames (railway stations) is built
from the generator of the first frame it serves, so any frame alone gives the same bytes as in
the full run. What a run keeps across frames (the builder's static scene, the sensor's rays
through its own mirrors, the output dataset) is owned by a :class:`Run`, never by the module.
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from . import __version__
from .buffers import SceneBuffers
from .builders import BUILDERS, BuildContext
from .builders.population import build_populated
from .config import Config, sensor_trajectory
from .errors import InputError
from .frame import Frame
from .geometry.transforms import pose_matrix, transform_points
from .labels import ClassTable, load_class_table, parse_rules
from .lidar.divergence import scan_footprint_chunks
from .lidar.effects import apply_effects
from .lidar.grid import image_shape
from .lidar.patterns import PATTERNS
from .lidar.mirror_sensor import MirrorFrame, drop_at_edges, load_edge_mask, reflect_patterns
from .lidar.platform import Trajectory
from .lidar.points import POINT_DTYPE
from .lidar.raycast import CasterCache
from .lidar.scanner import Surfaces, scan_chunks
from .lidar.sensors import Pattern, angular_resolution, frame_time, iter_pattern, mount_offset, ray_count

CHUNK_RAYS = 1 << 18  # rays generated and traced at a time: bounds memory for 23-million-ray scans
MAX_RESERVED_POINTS = 1 << 25  # point records reserved up front (address space only; pages fill as points come)
MAX_KEPT_MIRROR_RAYS = 1 << 22  # a mirror sensor's rays up to this many are traced through its mirrors once and kept


def frame_rng(seed: int, frame: int) -> np.random.Generator:
    """The generator of frame ``frame`` of a run seeded with ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([seed, frame]))


def versions() -> dict:
    """Versions of everything that shapes the output."""
    import embreex
    import numpy

    out = {"bpy_pipeline": __version__, "python": platform.python_version(), "numpy": numpy.__version__}
    out["embreex"] = getattr(embreex, "__version__", "unknown")
    try:
        import bpy

        out["blender"] = bpy.app.version_string
    except ImportError:
        out["blender"] = None
    return out


# ----------------------------------------------------------------------------- sensor placement
def sensor_pose(config: Config, frame: int = 0) -> np.ndarray:
    """``(4, 4)`` sensor-to-world transform of frame ``frame``, raised by the preset's mount height.

    The configured position and rotation; in a scene that places the sensor (railway stations,
    the parking robot, the hall's mount) the scene's station of that frame instead, turned by
    ``sensor.rotation_deg`` (so yaw 0 looks along the track).
    """
    station = None if config.sensor.trajectory is not None else BUILDERS.get(config.scene.builder).station(config.scene.params, frame)
    if station is not None:
        pose = station @ pose_matrix((0.0, 0.0, 0.0), config.sensor.rotation_deg)
    else:
        pose = pose_matrix(config.sensor.position, config.sensor.rotation_deg)
    if not config.sensor.rig:  # a rig's platform: each sensor adds its own mount height (rig.RigSensor.matrix)
        pose[:3, 3] += mount_offset(config.sensor.spec)
    return pose


def frames_per_scene(config: Config) -> int:
    """How many frames in a row one built scene serves (a railway's stations: one line scanned from each)."""
    return BUILDERS.get(config.scene.builder).frames_per_scene(config.scene.params)


def scene_view(config: Config, first: int, count: int):
    """The :class:`~.geometry.lod.SensorView` of frames ``first`` .. ``first + count - 1`` (static sensors).
    A moving sensor: the :class:`~.geometry.lod.PlannedPath` of the whole run for a builder that
    ``follows_path`` (its scene serves every frame), else ``None`` (fixed detail)."""
    from .geometry.lod import planned_path, view_of

    if config.sensor.trajectory is not None:
        return planned_path(config.sensor, config.frames) if BUILDERS.get(config.scene.builder).follows_path else None

    from .rig import RigSensor, RigView, field_of_view

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


def scene_trajectory(config: Config) -> Trajectory | None:
    """The sensor's trajectory in the scene as built (a curve is read from it); ``None`` for a static sensor."""
    section = config.sensor.trajectory
    if section is None or not section.curve:
        return sensor_trajectory(config.sensor)
    from .scenes.curves import curve_polyline

    return sensor_trajectory(config.sensor, curve_polyline(section.curve))


def scan_surfaces(config: Config) -> Surfaces:
    """The scanner's rules for mirrors and glass from ``effects.mirrors``."""
    mirrors = config.effects.mirrors
    return Surfaces(mirrors.normal_return_deg, mirrors.glass.normal_return_deg, mirrors.glass.reflect_fraction, mirrors.glass.max_passes)


# ----------------------------------------------------------------------------- the sensor's rays
@dataclass
class SensorRays:
    """The configured sensor's rays as they enter the scene, kept by a run across frames.

    A mirror sensor's rays (``sensor.reflector``) are traced through its own mirrors once, and its
    edge-drop mask made once, while the sensor stays the same (a rosette's rays change every frame
    and are traced again). ``cached``: the key, the reflected :class:`Pattern` and the mask.
    """

    config: Config
    cached: dict = field(default_factory=dict)

    def _mirror_sensor(self, frame: int) -> dict:
        spec, reflector = self.config.sensor.spec, self.config.sensor.reflector
        edge = reflector.edge_drop
        measured = Path(edge.mask) if edge.mask not in ("none", "generated") else None
        key = (frame if PATTERNS.get(spec.pattern).per_frame else 0, measured and measured.exists() and measured.stat().st_mtime_ns)
        if self.cached.get("key") != key:
            traced = MirrorFrame.of(reflector, spec, key[0])
            mask = None
            if edge.mask == "generated":
                mask = traced.edge_drop_mask(spec, edge.probability, edge.beam_diameter)
            elif measured is not None:
                mask = load_edge_mask(measured, image_shape(spec), "sensor.reflector.edge_drop.mask")
            self.cached = {"key": key, "rays": traced.reflected(reflector), "mask": mask}
        return self.cached

    def patterns(self, frame: int = 0) -> Iterable[Pattern]:
        """The rays of frame ``frame`` (sensor frame) in chunks; a mirror sensor's leave from its mirrors
        with per-ray origins, lost rays left out."""
        spec, reflector = self.config.sensor.spec, self.config.sensor.reflector
        if not reflector.enabled:
            return iter_pattern(spec, CHUNK_RAYS, frame)
        if ray_count(spec) > MAX_KEPT_MIRROR_RAYS:
            return reflect_patterns(iter_pattern(spec, CHUNK_RAYS, frame), reflector)
        return [self._mirror_sensor(frame)["rays"]]

    def edge_mask(self, frame: int = 0) -> np.ndarray | None:
        """``(rows, columns)`` float32 mirror-edge drop probabilities of the sensor's own mirrors; ``None`` when off."""
        reflector = self.config.sensor.reflector
        if not reflector.enabled or reflector.edge_drop.mask == "none":
            return None
        return self._mirror_sensor(frame)["mask"]


def sensor_rays(config: Config, frame: int = 0) -> Iterable[Pattern]:
    """The sensor's rays of frame ``frame`` as they enter the scene (sensor frame), in chunks."""
    return SensorRays(config).patterns(frame)


def edge_mask(config: Config, frame: int = 0) -> np.ndarray | None:
    """``(rows, columns)`` mirror-edge drop probabilities of the sensor's own mirrors; ``None`` when off."""
    return SensorRays(config).edge_mask(frame)


# ----------------------------------------------------------------------------- the run and its stages
@dataclass
class Run:
    """What one run keeps across its frames.

    config : the run's config; build : build ``config.scene`` (``False``: scan the open scene as it is)
    table, rules : the class table and the name rules objects are labelled by
    keep : the builder's state across frames (:class:`~.builders.BuildContext`)
    rays : the sensor's rays (:class:`SensorRays`); scene_frame : the frame whose scene is built now
    trajectory : the moving sensor's path in the built scene (``None`` for a static sensor)
    threads : ray-casting threads (``None``: the cores available)
    casters : the static objects' caster kept from frame to frame (:class:`~.lidar.raycast.CasterCache`)
    log : where warnings and the lines of long stages go (``None``: nowhere)
    """

    config: Config
    build: bool = True
    table: ClassTable = field(default_factory=load_class_table)
    rules: list = field(default_factory=list)
    keep: dict = field(default_factory=dict)
    rays: SensorRays | None = None
    scene_frame: int | None = None
    trajectory: Trajectory | None = None
    threads: int | None = None
    log: Callable[[str], None] | None = None
    members: list = field(default_factory=list)  # a rig's sensors: one single-sensor Run each (rig.py)
    casters: CasterCache | None = None

    def __post_init__(self):
        self.rules = parse_rules(self.config.labels.name_rules, "labels.name_rules", self.table.names)
        self.rays = self.rays or SensorRays(self.config)
        self.threads = self.threads or self.config.threads or None
        self.casters = self.casters or CasterCache(self.threads)
        if self.config.sensor.rig and not self.members:
            self.members = [Run(member_config(self.config, k), build=False, table=self.table, threads=self.threads, log=self.log) for k in range(len(self.config.sensor.rig))]


def build_stage(frame: Frame, run: Run) -> None:
    """Build the frame's scene unless the scene built for an earlier frame serves it (or the run scans the open scene).

    Frame k scans the scene built for frame k - k mod n (n: :func:`frames_per_scene`), from that
    frame's generator, so a run started at any frame builds the same scene as the full run.
    """
    config = run.config
    per_scene = frames_per_scene(config)
    first = frame.index - frame.index % per_scene
    if run.build and run.scene_frame != first:
        rng = frame.rng if first == frame.index else frame_rng(config.seed, first)
        frame.scene = build_populated(config.scene, BuildContext(rng, scene_view(config, first, per_scene), run.keep))
        run.scene_frame = first
        run.trajectory = None
    if run.trajectory is None:
        run.trajectory = scene_trajectory(config)


def pose_stage(frame: Frame, run: Run) -> None:
    """The sensor's pose at the frame's start, and per ray for a moving sensor."""
    trajectory, spec = run.trajectory, run.config.sensor.spec
    if trajectory is None:
        frame.pose = sensor_pose(run.config, frame.index)
        frame.pose_at = frame.pose
        return
    trajectory.check_frames(frame.index + 1, frame_time(spec))
    frame.trajectory = trajectory
    frame.pose_at = trajectory.frame_poses(frame.index, frame_time(spec))
    frame.pose = frame.pose_at(np.zeros(1))[0]


def export_stage(frame: Frame, run: Run) -> None:
    """The evaluated scene as buffers: every object the sensor can reach during the frame."""
    from .export import export_scene

    if run.members:
        return rig_export_stage(frame, run)
    max_range = run.config.sensor.spec.max_range
    if frame.trajectory is not None:  # everything the sensor can reach from anywhere along this frame's stretch of path
        max_range += frame.trajectory.reach(frame.index, frame_time(run.config.sensor.spec))
    frame.buffers = export_scene(run.table, run.rules, keep_within=(frame.pose[:3, 3], max_range))
    if not len(frame.buffers.triangles) and len(export_scene(run.table, run.rules).triangles):
        where = [round(float(v), 2) for v in frame.pose[:3, 3]]
        raise InputError(f"sensor: no object of the scene lies within max_range ({max_range} m) of the sensor at {where} in frame {frame.index}; move the sensor or raise sensor.max_range")


def scan_stage(frame: Frame, run: Run) -> None:
    """The scan's ``(points, beam)`` chunks (lazy: the effects stage traces them one at a time)."""
    if run.members:
        return _each_member(scan_stage, frame, run)
    frame.buffers.check()
    config, spec = run.config, run.config.sensor.spec
    caster = frame.caster = run.casters.caster(frame.buffers, frame.pose, moving_objects(frame))
    ghost = run.table.id_of("reflection") if config.effects.mirrors.label == "reflection" else None
    options = {"max_bounces": config.effects.mirrors.max_bounces, "ghost_semantic": ghost, "ideal": config.effects.mirrors.ideal, "chunk_rays": CHUNK_RAYS, "surfaces": scan_surfaces(config), "rng": frame.rng}
    patterns = run.rays.patterns(frame.index)  # a mirror sensor's leave through its own mirrors
    if config.sensor.divergence.active:
        frame.chunks = scan_footprint_chunks(caster, frame.buffers, patterns, frame.pose_at, config.sensor.divergence, spec.min_range, spec.max_range, **options)
    else:
        frame.chunks = scan_chunks(caster, frame.buffers, patterns, frame.pose_at, spec.min_range, spec.max_range, **options)


def moving_objects(frame: Frame) -> np.ndarray | None:
    """``(k,)`` bool per row of ``frame.buffers.objects``: the objects the builder placed for this frame
    (those it gives 3D boxes: cars, robots, people, road users), traced by a small caster of their own
    while the rest of the scene's is kept (:class:`~.lidar.raycast.CasterCache`). ``None`` when the frame
    built nothing or placed none. A function of the frame alone, so frame k gives the same bytes after
    frame k - 1 as alone."""
    if frame.scene is None or not frame.scene.headings:
        return None
    return np.isin(frame.buffers.objects.instance, np.fromiter(frame.scene.headings, np.int64))


def effects_stage(frame: Frame, run: Run) -> None:
    """Trace each chunk, give it its effects and move it to the output frame before the next is traced,
    so memory holds the final point records and one chunk's work, no more."""
    if run.members:
        return rig_effects_stage(frame, run)
    config, spec = run.config, run.config.sensor.spec
    mask = run.rays.edge_mask(frame.index)

    def finished(chunks):
        for points, beam in chunks:
            if mask is not None:  # returns lost where the beam split on an edge of the sensor's own mirrors
                keep = drop_at_edges(points, mask, config.sensor.spec, frame.rng)
                points, beam = points[keep], beam[keep]
            points = apply_effects(points, beam, config.effects, frame.rng)
            inside = (points["range"] >= spec.min_range) & (points["range"] <= spec.max_range)
            if not inside.all():  # noise never pushes a return past the sensor's limits: such returns are dropped
                points = points[inside]
            if config.output.frame == "world":
                xyz = transform_points(np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64), frame.pose)
                points["x"], points["y"], points["z"] = xyz.T
            yield points

    frame.points = collect_points(finished(frame.chunks), ray_count(config.sensor.spec))
    frame.chunks = None


def annotate_stage(frame: Frame, run: Run) -> None:
    """The frame's 3D box labels, when a box format is asked for (semantic labels come with the scan)."""
    if run.members:
        return rig_annotate_stage(frame, run)
    if run.config.output.boxes.formats:
        headings = None if frame.scene is None else frame.scene.headings
        frame.boxes = frame_boxes(frame.buffers, run.config, frame.pose, frame.points, headings, frame.index, frame.rng, run.rays, frame.caster)


# ----------------------------------------------------------------------------- a sensor rig's stages
def member_config(config: Config, k: int) -> Config:
    """The single-sensor config of sensor ``k`` of the rig of ``config`` (its pose comes from the rig, not from it)."""
    import dataclasses

    from .config import SensorConfig

    member = config.sensor.rig[k]
    sensor = SensorConfig(member.spec, position=member.position, rotation_deg=member.rotation_deg, divergence=config.sensor.divergence)
    return dataclasses.replace(config, sensor=sensor)


def rig_export_stage(frame: Frame, run: Run) -> None:
    """Per sensor, its own frame (pose on the platform, generator, export within its range); the platform's
    buffers (everything any sensor reaches) for the frame's record and merged boxes."""
    from .export import export_scene
    from .rig import RigFrame, member_rng

    config = run.config
    sensors = config.sensor.rig
    frame.rig = RigFrame(sensors)
    reach = 0.0
    for k, (sensor, member) in enumerate(zip(sensors, run.members)):
        matrix = sensor.matrix()
        sub = Frame(frame.index, member.config, member_rng(config.seed, frame.index, k), scene=frame.scene)
        sub.pose = frame.pose @ matrix
        if frame.trajectory is None:
            sub.pose_at = sub.pose
        else:
            sub.trajectory = frame.trajectory
            sub.pose_at = lambda t, m=matrix: frame.pose_at(t) @ m
        start = time.perf_counter()
        export_stage(sub, member)
        sub.timings["export"] = time.perf_counter() - start
        frame.rig.frames.append(sub)
        reach = max(reach, float(np.linalg.norm(matrix[:3, 3])) + sensor.spec.max_range + (0.0 if frame.trajectory is None else frame.trajectory.reach(frame.index, frame_time(sensor.spec))))
    frame.buffers = export_scene(run.table, run.rules, keep_within=(frame.pose[:3, 3], reach))


def _each_member(stage, frame: Frame, run: Run) -> None:
    for sub, member in zip(frame.rig.frames, run.members):
        start = time.perf_counter()
        stage(sub, member)
        sub.timings[stage.__name__.removesuffix("_stage")] = sub.timings.get(stage.__name__.removesuffix("_stage"), 0.0) + time.perf_counter() - start


def rig_effects_stage(frame: Frame, run: Run) -> None:
    """Each sensor's points (its own frame, or the world), then the merged cloud with each point's sensor index
    (:data:`~.rig.RIG_POINT_DTYPE`; the platform frame, or the world)."""
    from .rig import merge_clouds

    _each_member(effects_stage, frame, run)
    world = run.config.output.frame == "world"
    frame.rig.to_merged = None if world else [s.matrix() for s in run.config.sensor.rig]
    frame.points = merge_clouds([sub.points for sub in frame.rig.frames], frame.rig.to_merged)


def rig_annotate_stage(frame: Frame, run: Run) -> None:
    """Boxes per sensor (kept where that sensor holds their minimum points) and merged (where the merged cloud does)."""
    from .io import boxes as box_labels
    from .rig import merged_boxes

    section = run.config.output.boxes
    if not section.formats and not run.config.output.skip_empty:
        return
    headings = None if frame.scene is None else frame.scene.headings
    unfiltered = []
    for sub, member in zip(frame.rig.frames, run.members):
        start = time.perf_counter()
        world = world_boxes(sub.buffers, member.config, sub.pose, sub.points, headings, sub.index, sub.rng, member.rays, skip_unseen=True, caster=sub.caster)
        unfiltered.append(world)
        kept = box_labels.keep_boxes(world, section.min_points, section.min_points_default)
        sub.boxes = box_labels.boxes_in_frame(kept, sub.pose if member.config.output.frame == "sensor" else np.eye(4))
        sub.timings["boxes"] = time.perf_counter() - start
    merged = merged_boxes(unfiltered, section.min_points, section.min_points_default)
    merged["occlusion"] = box_labels.occlusion_levels(merged["visible"], merged["unoccluded"], section.occlusion_levels)
    frame.boxes = box_labels.boxes_in_frame(merged, frame.pose if run.config.output.frame == "sensor" else np.eye(4))


def camera_stage(frame: Frame, run: Run) -> None:
    """KITTI's ``image_2`` rendered by Blender from ``output.kitti.camera`` (when it asks for a rendering)."""
    config = run.config
    if not config.output.kitti.camera.render or "kitti" not in config.output.boxes.formats or run.members:
        return
    from .scenes.camera import class_colors, render_camera

    frame.images["image_2"] = render_camera(config.output.kitti.camera, frame.pose, class_colors(frame.buffers, run.table.color_lut()))


# (stage, the timing it counts towards): the scan is lazy, so tracing is timed with the effects
STAGES: tuple[tuple[Callable[[Frame, Run], None], str | None], ...] = (
    (build_stage, "build"),
    (pose_stage, "build"),
    (export_stage, "export"),
    (scan_stage, "scan"),
    (effects_stage, "scan"),
    (annotate_stage, "boxes"),
    (camera_stage, "camera"),
)


LONG_STAGE_S = 3.0  # a stage that takes longer gets a line of its own


def make_frame(run: Run, index: int) -> Frame:
    """Frame ``index`` through every stage before writing, timed; the builder's warnings and long stages are logged."""
    frame = Frame(index, run.config, frame_rng(run.config.seed, index))
    for stage, timing in BUILDERS.get(run.config.scene.builder).stages or STAGES:
        start = time.perf_counter()
        stage(frame, run)
        took = time.perf_counter() - start
        if (timing != "boxes" or frame.boxes is not None) and (timing != "camera" or frame.images):  # stages that ran
            frame.timings[timing] = frame.timings.get(timing, 0.0) + took
        if run.log is not None and took > LONG_STAGE_S:
            run.log(f"note: frame {index}: {stage.__name__.removesuffix('_stage')} took {took:.1f} s")
    if run.log is not None and frame.scene is not None:
        for line in frame.scene.warnings:
            run.log(f"warning: frame {index}: {line}")
    return frame


# ----------------------------------------------------------------------------- building blocks also used alone
def scan_buffers(buffers: SceneBuffers, config: Config, rng: np.random.Generator, frame: int = 0, trajectory: Trajectory | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Scan exported buffers with the configured sensor and effects: ``(points, pose (4, 4))``.

    frame : frame index: a moving sensor's frame k starts k frame times along its path (and a
        rosette's pattern continues where frame k - 1 stopped)
    trajectory : the moving sensor's path (:func:`scene_trajectory`); built from the config's
        waypoints when ``None``, and needed for a trajectory along a curve of the scene
    A moving sensor casts each ray from its pose at that ray's firing time; ``pose`` is its pose at
    the frame's start, and points come out in the sensor frame of that pose (motion compensated,
    as nuScenes does), so a static object stays where it is whatever the motion.
    """
    run = Run(config, build=False, trajectory=trajectory or sensor_trajectory(config.sensor))
    out = Frame(frame, config, rng, buffers=buffers)
    for stage in (pose_stage, scan_stage, effects_stage):
        stage(out, run)
    return out.points, out.pose


def collect_points(parts: Iterable[np.ndarray], expected: int) -> np.ndarray:
    """The :data:`POINT_DTYPE` records of ``parts`` in one ``(p,)`` array, copied in as they come.

    expected : the most points likely (the ray count); that many (at most
    :data:`MAX_RESERVED_POINTS`) are reserved up front, so the parts are never all held twice:
    the operating system maps the reserved pages only as points fill them. More points than
    reserved double the reserve. Records are copied as raw bytes (numpy copies a structured array
    field by field, 15x slower: 16 ms for a 611 k-point frame); a part of another dtype field by field.
    """
    raw = np.dtype((np.void, POINT_DTYPE.itemsize))
    out, n = np.empty(min(max(expected, 1), MAX_RESERVED_POINTS), POINT_DTYPE), 0
    for part in parts:
        if n + len(part) > len(out):
            grown = np.empty(max(2 * len(out), n + len(part)), POINT_DTYPE)
            grown.view(raw)[:n] = out.view(raw)[:n]
            out = grown
        if part.dtype == POINT_DTYPE:
            out.view(raw)[n : n + len(part)] = np.ascontiguousarray(part).view(raw)
        else:
            out[n : n + len(part)] = part
        n += len(part)
    return out[:n]


def frame_boxes(buffers: SceneBuffers, config: Config, pose: np.ndarray, points: np.ndarray, headings: dict | None = None, frame: int = 0, rng: np.random.Generator | None = None, rays: SensorRays | None = None, caster=None) -> np.ndarray:
    """The frame's 3D box labels (:data:`~.io.boxes.BOX_DTYPE`) in the frame of the points, thin boxes dropped.

    headings : {instance: yaw} from the builder (others get their footprint's heading)
    Truncation and occlusion come from the sensor's own rays at ``pose``, one visibility cast for all
    objects (lidar/visibility.py); the boxes themselves are geometry/boxes.py.
    caster : the scan's :class:`~.lidar.raycast.RayCaster` of ``buffers`` at ``pose``, reused by that cast (built when ``None``)
    """
    from .geometry.boxes import boxes_in_frame, keep_boxes

    section = config.output.boxes
    boxes = world_boxes(buffers, config, pose, points, headings, frame, rng, rays, caster=caster)
    if len(boxes):
        boxes = keep_boxes(boxes, section.min_points, section.min_points_default)
    return boxes_in_frame(boxes, pose if config.output.frame == "sensor" else np.eye(4))


def world_boxes(buffers: SceneBuffers, config: Config, pose: np.ndarray, points: np.ndarray, headings: dict | None = None, frame: int = 0, rng: np.random.Generator | None = None, rays: SensorRays | None = None, skip_unseen: bool = False, caster=None) -> np.ndarray:
    """Every box of ``output.boxes.classes`` in the world frame with truncation, occlusion and its points, none dropped
    (:func:`frame_boxes` keeps those with their minimum points and moves them into the points' frame).

    skip_unseen : leave out of the visibility trace the boxes no ray of the sensor can pass near (outside its
        field of view or range, :func:`~.rig.out_of_reach`): they get what the trace would give them
        (truncation 1, no visible or unoccluded ray); a rig's narrow sensors see a few of a street's boxes each
    """
    from .io import boxes as box_labels

    section = config.output.boxes
    boxes = box_labels.fit_boxes(buffers, section.classes, headings)
    if len(boxes):
        spec = config.sensor.spec
        patterns = (rays or SensorRays(config)).patterns(frame)
        steps = [v for v in angular_resolution(spec) if v is not None and np.isfinite(v)]
        cell = float(np.clip(max(steps) if steps else 1.0, 0.2, 5.0))
        near = np.ones(len(boxes), bool)
        if skip_unseen and not config.sensor.reflector.enabled and config.effects.mirrors.glass.reflect_fraction in (0.0, 1.0):  # no draw depends on which boxes are traced
            from .rig import out_of_reach

            near = ~out_of_reach(spec, pose, boxes["centre"], np.linalg.norm(boxes["size"], axis=1) / 2 + 1e-3)
            boxes["truncation"] = 1.0
        traced = boxes[near]
        box_labels.visibility(buffers, traced, patterns, pose, spec.min_range, spec.max_range, cell, caster=caster, surfaces=scan_surfaces(config), rng=rng)
        boxes[near] = traced
        boxes["occlusion"] = box_labels.occlusion_levels(boxes["visible"], boxes["unoccluded"], section.occlusion_levels)
        box_labels.count_points(boxes, points)
    return boxes


def build_frame_scene(config: Config, index: int = 0, rng: np.random.Generator | None = None, keep: dict | None = None):
    """Build the scene that frame ``index`` of :func:`run_frames` scans (the panel's Build scene: frame 0).

    rng : the generator of the frame the scene is built for (``frame_rng(config.seed, index)`` when ``None``)
    keep : the builder's state across calls (parking and industrial_hall keep their static scene there)
    Returns the builder's :class:`~.builders.BuildResult`.
    """
    per_scene = frames_per_scene(config)
    rng = frame_rng(config.seed, index) if rng is None else rng
    return build_populated(config.scene, BuildContext(rng, scene_view(config, index, per_scene), {} if keep is None else keep))


# ----------------------------------------------------------------------------- runs
def run_frames(config: Config, out_dir: str | Path, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new", log: Callable[[str], None] | None = None) -> Iterator[Frame]:
    """The frames of a run, one at a time: each is committed to the dataset in ``out_dir`` when it is yielded.

    frames : the frame indices to make (default: all of ``config.frames``); any subset gives the same
        bytes per frame as the full run
    mode : ``new`` (refuse a folder holding another run), ``resume`` (same config and seed: skip
        committed frames) or ``overwrite`` (remove the old dataset first); see :mod:`.dataset`
    Stopping early (``close()``, or dropping the iterator) keeps every frame already yielded.
    ``build=False`` scans the current scene as it is instead of building ``config.scene`` (the Blender
    panel's "my scene", or a built scene the user has edited since).
    """
    from .dataset import Dataset

    output = config.output
    until_kept = output.skip_empty and output.frames_kept and (frames is None or list(frames) == list(range(config.frames)))  # a full run
    frames = range(config.frames) if frames is None else frames
    if until_kept:  # frame indices go on until `frames` frames are kept (at most MAX_INDICES_PER_KEPT per kept frame)
        frames = range(MAX_INDICES_PER_KEPT * config.frames)
    run = Run(config, build, log=log)
    with Dataset.open(out_dir, config, mode, log=log) as dataset:
        for index in frames:
            if until_kept and sum(1 for r in dataset.committed.values() if not r.get("skipped")) >= config.frames:
                break
            if dataset.has(index):
                continue
            frame = make_frame(run, index)
            reason = empty_reason(frame, run) if output.skip_empty else None
            if reason is not None:
                dataset.skip(frame, reason)
                if log is not None:
                    log(f"frame {index}: skipped ({reason})")
                continue
            dataset.commit(frame)
            yield frame
        else:
            if until_kept and log is not None:
                log(f"warning: output.frames_kept: {MAX_INDICES_PER_KEPT * config.frames} frame indices gave fewer than {config.frames} kept frames; the scene rarely holds {output.min_objects} labelled objects")


MAX_INDICES_PER_KEPT = 20  # output.frames_kept: frame indices tried per kept frame before giving up


def labelled_objects(frame: Frame, run: Run) -> int:
    """How many objects of ``output.boxes.classes`` the frame's cloud holds with their minimum points
    (its boxes when it has any, else counted from the points' instances)."""
    if frame.boxes is not None:
        return int(len(frame.boxes))
    section = run.config.output.boxes
    wanted = {run.table.id_of(c): section.min_points.get(c, section.min_points_default) for c in section.classes}
    points = frame.points
    keep = np.isin(points["semantic"], list(wanted)) & (points["instance"] > 0)
    instances, first, counts = np.unique(points["instance"][keep], return_index=True, return_counts=True)
    classes = points["semantic"][keep][first]
    return int(sum(1 for c, n in zip(classes, counts) if n >= wanted[int(c)]))


def empty_reason(frame: Frame, run: Run) -> str | None:
    """Why ``output.skip_empty`` skips the frame, ``None`` to keep it."""
    objects = labelled_objects(frame, run)
    need = run.config.output.min_objects
    return None if objects >= need else f"{objects} labelled object{'s' if objects != 1 else ''}, fewer than output.min_objects ({need})"


def run(config: Config, out_dir: str | Path, log=print, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new") -> dict:
    """Generate the frames ``frames`` (default: all) of ``config`` into ``out_dir``; returns the manifest (with its frames)."""
    from .io import read_dataset

    for frame in run_frames(config, out_dir, build, frames, mode, log):  # None: all (output.frames_kept: until enough are kept)
        log(f"frame {frame.index + 1}/{config.frames}: {len(frame.points)} points, " + ", ".join(f"{k} {v:.2f} s" for k, v in frame.timings.items()))
    return read_dataset(out_dir)
