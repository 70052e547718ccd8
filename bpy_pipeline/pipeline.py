"""Config -> frames on disk: build, export, scan, effects, write; one seeded generator per frame.

Each frame is written into a hidden staging folder and moved into place only when every
format of it has been written, so a failure never leaves a partial frame. ``manifest.json``
is rewritten after every frame and records the resolved config, versions, and per frame its
files, point count, sensor pose and timings.
"""

from __future__ import annotations

import platform
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from . import __version__
from .buffers import SceneBuffers
from .config import Config, config_to_dict, sensor_trajectory
from .errors import InputError
from .geometry.transforms import pose_matrix, transform_points
from .io import WRITERS, write_manifest, write_preview
from .io.range_image import write_frame_range_image
from .labels import load_class_table, parse_rules
from .lidar.divergence import scan_footprint_chunks
from .lidar.effects import apply_effects
from .lidar.platform import Trajectory
from .lidar.grid import image_shape
from .lidar.mirror_sensor import MirrorFrame, drop_at_edges, load_edge_mask, reflect_patterns
from .lidar.raycast import RayCaster
from .lidar.points import POINT_DTYPE
from .lidar.scanner import Surfaces, scan_chunks
from .lidar.sensors import Pattern, angular_resolution, frame_time, iter_pattern, mount_offset, ray_count, spec_summary


CHUNK_RAYS = 1 << 18  # rays generated and traced at a time: bounds memory for 23-million-ray scans
MAX_RESERVED_POINTS = 1 << 25  # point records reserved up front (address space only; pages fill as points come)


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


def scene_stations(config: Config) -> np.ndarray:
    """``(n, 4, 4)`` level frames of the scanner stations the scene defines (railway ``scene.stations``:
    x along the track, z up); n = 0 when it defines none or the sensor follows a trajectory."""
    from .config import RailwayScene

    if config.sensor.trajectory is not None or not isinstance(config.scene.params, RailwayScene):
        return np.zeros((0, 4, 4))
    from .geometry.railway_layout import station_frames

    return station_frames(config.scene.params)


def sensor_pose(config: Config, frame: int = 0) -> np.ndarray:
    """``(4, 4)`` sensor-to-world transform of frame ``frame``, raised by the preset's mount height.

    The configured position and rotation; in a scene with stations, station ``frame mod n``
    instead, its frame turned by ``sensor.rotation_deg`` (so yaw 0 looks along the track).
    """
    stations = scene_stations(config)
    if len(stations):
        pose = stations[frame % len(stations)] @ pose_matrix((0.0, 0.0, 0.0), config.sensor.rotation_deg)
    elif getattr(config.scene.params, "place_sensor", False):  # parking, industrial_hall: the scene's own station
        from .geometry.indoor import scene_station

        pose = scene_station(config.scene.params, frame) @ pose_matrix((0.0, 0.0, 0.0), config.sensor.rotation_deg)
    else:
        pose = pose_matrix(config.sensor.position, config.sensor.rotation_deg)
    pose[:3, 3] += mount_offset(config.sensor.spec)
    return pose


def scene_view(config: Config, first: int, count: int):
    """The :class:`~.geometry.lod.SensorView` of frames ``first`` .. ``first + count - 1`` (static sensors;
    ``None`` for a moving one, whose builders then model at a fixed detail)."""
    if config.sensor.trajectory is not None:
        return None
    from .geometry.lod import view_of

    frames = range(first, min(first + count, config.frames))
    return view_of(config.sensor.spec, [sensor_pose(config, f)[:3, 3] for f in frames])


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


MAX_KEPT_MIRROR_RAYS = 1 << 22  # a mirror sensor's rays up to this many are traced through its mirrors once and kept
_MIRROR_SENSOR: dict = {}  # the last mirror sensor seen: {"key": ..., "rays": Pattern, "mask": (rows, columns) or None}


def _mirror_sensor(config: Config, frame: int) -> dict:
    """The sensor's rays after its own mirrors and its edge-drop mask, kept while the sensor stays the same.

    Both are the same every frame (a rosette's rays are not: they are traced again each frame),
    so a run traces the sensor's mirrors once, not once a frame.
    """
    spec, reflector = config.sensor.spec, config.sensor.reflector
    edge = reflector.edge_drop
    measured = Path(edge.mask) if edge.mask not in ("none", "generated") else None
    key = (reflector, repr(spec), frame if spec.pattern == "rosette" else 0, measured and measured.exists() and measured.stat().st_mtime_ns)
    if _MIRROR_SENSOR.get("key") != key:
        _MIRROR_SENSOR.clear()
        traced = MirrorFrame.of(reflector, spec, key[2])
        mask = None
        if edge.mask == "generated":
            mask = traced.edge_drop_mask(spec, edge.probability, edge.beam_diameter)
        elif measured is not None:
            mask = load_edge_mask(measured, image_shape(spec), "sensor.reflector.edge_drop.mask")
        _MIRROR_SENSOR.update(key=key, rays=traced.reflected(reflector), mask=mask)
    return _MIRROR_SENSOR


def sensor_rays(config: Config, frame: int = 0) -> Iterable[Pattern]:
    """The sensor's rays of frame ``frame`` as they enter the scene (sensor frame), in chunks.

    A mirror sensor's (``sensor.reflector``) leave from its mirrors with per-ray origins; lost
    rays are left out.
    """
    spec, reflector = config.sensor.spec, config.sensor.reflector
    if not reflector.enabled:
        return iter_pattern(spec, CHUNK_RAYS, frame)
    if ray_count(spec) > MAX_KEPT_MIRROR_RAYS:
        return reflect_patterns(iter_pattern(spec, CHUNK_RAYS, frame), reflector)
    return [_mirror_sensor(config, frame)["rays"]]


def edge_mask(config: Config, frame: int = 0) -> np.ndarray | None:
    """``(rows, columns)`` float32 mirror-edge drop probabilities of the sensor's own mirrors; ``None`` when off."""
    reflector = config.sensor.reflector
    if not reflector.enabled or reflector.edge_drop.mask == "none":
        return None
    return _mirror_sensor(config, frame)["mask"]


def scan_buffers(buffers: SceneBuffers, config: Config, rng: np.random.Generator, frame: int = 0, trajectory: Trajectory | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Scan exported buffers with the configured sensor and effects: ``(points, pose (4, 4))``.

    frame : frame index: a moving sensor's frame k starts k frame times along its path (and a
        rosette's pattern continues where frame k - 1 stopped)
    trajectory : the moving sensor's path (:func:`scene_trajectory`); built from the config's
        waypoints when ``None``, and needed for a trajectory along a curve of the scene
    A moving sensor casts each ray from its pose at that ray's firing time; ``pose`` is its pose at
    the frame's start, and points come out in the sensor frame of that pose (motion compensated,
    as nuScenes does), so a static object stays where it is whatever the motion.
    Each chunk of rays is traced, given its effects and moved to the output frame before the
    next is traced, so memory holds the final point records and one chunk's work, no more.
    """
    buffers.check()
    spec = config.sensor.spec
    if config.sensor.trajectory is None:
        pose = pose_at = sensor_pose(config, frame)
    else:
        trajectory = trajectory or sensor_trajectory(config.sensor)
        trajectory.check_frames(frame + 1, frame_time(spec))
        pose_at = trajectory.frame_poses(frame, frame_time(spec))
        pose = pose_at(np.zeros(1))[0]
    caster = RayCaster(buffers, frame=pose)
    ghost = load_class_table().id_of("reflection") if config.effects.mirrors.label == "reflection" else None
    options = {"max_bounces": config.effects.mirrors.max_bounces, "ghost_semantic": ghost, "ideal": config.effects.mirrors.ideal, "chunk_rays": CHUNK_RAYS}
    patterns = sensor_rays(config, frame)  # a mirror sensor's leave through its own mirrors
    if config.sensor.divergence.active:
        chunks = scan_footprint_chunks(caster, buffers, patterns, pose_at, config.sensor.divergence, spec.min_range, spec.max_range, **options, surfaces=scan_surfaces(config), rng=rng)
    else:
        chunks = scan_chunks(caster, buffers, patterns, pose_at, spec.min_range, spec.max_range, **options, surfaces=scan_surfaces(config), rng=rng)
    mask = edge_mask(config, frame)

    def finished(chunks):
        for points, beam in chunks:
            if mask is not None:  # returns lost where the beam split on an edge of the sensor's own mirrors
                keep = drop_at_edges(points, mask, spec, rng)
                points, beam = points[keep], beam[keep]
            points = apply_effects(points, beam, config.effects, rng)
            if config.output.frame == "world":
                xyz = transform_points(np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64), pose)
                points["x"], points["y"], points["z"] = xyz.T
            yield points

    return collect_points(finished(chunks), ray_count(spec)), pose


def collect_points(parts: Iterable[np.ndarray], expected: int) -> np.ndarray:
    """The :data:`POINT_DTYPE` records of ``parts`` in one ``(p,)`` array, copied in as they come.

    expected : the most points likely (the ray count); that many (at most
    :data:`MAX_RESERVED_POINTS`) are reserved up front, so the parts are never all held twice:
    the operating system maps the reserved pages only as points fill them. More points than
    reserved double the reserve.
    """
    out, n = np.empty(min(max(expected, 1), MAX_RESERVED_POINTS), POINT_DTYPE), 0
    for part in parts:
        if n + len(part) > len(out):
            grown = np.empty(max(2 * len(out), n + len(part)), POINT_DTYPE)
            grown[:n] = out[:n]
            out = grown
        out[n : n + len(part)] = part
        n += len(part)
    return out[:n]


def frame_boxes(buffers: SceneBuffers, config: Config, pose: np.ndarray, points: np.ndarray, headings: dict | None = None, frame: int = 0, rng: np.random.Generator | None = None) -> np.ndarray:
    """The frame's 3D box labels (:data:`~.io.boxes.BOX_DTYPE`) in the frame of the points, thin boxes dropped.

    headings : {instance: yaw} from the builder (others get their footprint's heading)
    Truncation and occlusion come from the sensor's own rays at ``pose`` (io/boxes.py).
    """
    from .io import boxes as box_labels

    section = config.output.boxes
    boxes = box_labels.fit_boxes(buffers, section.classes, headings)
    if len(boxes):
        spec = config.sensor.spec
        patterns = sensor_rays(config, frame)
        steps = [v for v in angular_resolution(spec) if v is not None and np.isfinite(v)]
        cell = float(np.clip(max(steps) if steps else 1.0, 0.2, 5.0))
        box_labels.visibility(buffers, boxes, patterns, pose, spec.min_range, spec.max_range, cell, surfaces=scan_surfaces(config), rng=rng)
        boxes["occlusion"] = box_labels.occlusion_levels(boxes["visible"], boxes["unoccluded"], section.occlusion_levels)
        box_labels.count_points(boxes, points)
        boxes = box_labels.keep_boxes(boxes, section.min_points, section.min_points_default)
    return box_labels.boxes_in_frame(boxes, pose if config.output.frame == "sensor" else np.eye(4))


def write_frame(out_dir: Path, index: int, points: np.ndarray, config: Config, boxes: np.ndarray | None = None) -> list[str]:
    """Write one frame in every configured format (and its box labels), all or nothing; returns paths relative to ``out_dir``."""
    staging = out_dir / f".frame_{index:06d}.tmp"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        written = []
        if boxes is not None and config.output.boxes.formats:
            from .io.boxes import write_frame_boxes

            written += write_frame_boxes(staging, index, boxes, points, config.output.boxes.formats, config.output.boxes.names)
        for name in config.output.formats:
            if name == "range_image":  # organised by the sensor's rings and columns
                written += write_frame_range_image(staging, index, points, config.sensor.spec, load_class_table().color_lut())
            else:
                written += WRITERS[name](staging, index, points, config.output.sequence)
        if config.output.preview:
            path = staging / "preview" / f"{index:06d}.png"
            write_preview(path, points, load_class_table().color_lut())
            written.append(path)
        relative = [Path(p).relative_to(staging) for p in written]
        for rel in relative:
            (out_dir / rel).parent.mkdir(parents=True, exist_ok=True)
            (staging / rel).replace(out_dir / rel)
        return [str(rel) for rel in relative]
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def prepare_output(out_dir: Path) -> Path:
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"--out: {out_dir} exists and is not a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"--out: cannot create {out_dir} ({err.strerror or err})") from None
    return out_dir


@dataclass(frozen=True)
class FrameResult:
    """One frame on disk.

    index : frame index; points : (p,) POINT_DTYPE records as written; pose : (4, 4) float64
    sensor-to-world transform; manifest : the run manifest as written after this frame
    """

    index: int
    points: np.ndarray
    pose: np.ndarray
    manifest: dict


def run(config: Config, out_dir: str | Path, log=print, build: bool = True) -> dict:
    """Generate ``config.frames`` frames into ``out_dir``; returns the manifest."""
    manifest = {}
    for frame in run_frames(config, out_dir, build):
        manifest = frame.manifest
        timings = manifest["frames"][-1]["timings_s"]
        log(f"frame {frame.index + 1}/{config.frames}: {len(frame.points)} points, " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()))
    return manifest


def build_frame_scene(config: Config, index: int = 0, rng: np.random.Generator | None = None):
    """Build the scene that frame ``index`` of :func:`run_frames` scans (the panel's Build scene: frame 0).

    rng : the frame's generator (``frame_rng(config.seed, index)`` when ``None``)
    Returns what the builder returns.
    """
    from .scenes import build_scene

    per_scene = max(len(scene_stations(config)), 1)
    rng = frame_rng(config.seed, index) if rng is None else rng
    return build_scene(config.scene, rng, scene_view(config, index, per_scene))


def run_frames(config: Config, out_dir: str | Path, build: bool = True) -> Iterator[FrameResult]:
    """The frames of :func:`run`, one at a time: each is on disk, manifest included, when it is yielded.

    Stopping early (``close()``, or dropping the iterator) keeps every frame already yielded.
    ``build=False`` scans the current scene as it is instead of building ``config.scene`` for
    each frame (the Blender panel's "my scene", or a built scene the user has edited since).
    """
    from .export import export_scene
    table = load_class_table()
    extra_rules = parse_rules(config.labels.name_rules, "labels.name_rules", table.names)
    out_dir = prepare_output(out_dir)
    manifest = {
        "config": config_to_dict(config),
        "seed": config.seed,
        "versions": versions(),
        "sensor": spec_summary(config.sensor.spec),
        "class_table": {int(k): v for k, v in table.names.items()},
        "frames": [],
    }
    stations = len(scene_stations(config))
    per_scene = max(stations, 1)  # a scene with n stations is built once and scanned from each in turn
    for index in range(config.frames):
        rng = frame_rng(config.seed, index)
        timings = {}
        start = time.perf_counter()
        built = None
        if build and index % per_scene == 0:
            built = build_frame_scene(config, index, rng)
        headings, scene_info = getattr(built, "headings", None), getattr(built, "info", None)
        trajectory = scene_trajectory(config)
        timings["build"] = time.perf_counter() - start
        start = time.perf_counter()
        period, max_range = frame_time(config.sensor.spec), config.sensor.spec.max_range
        if trajectory is None:
            sensor_range = (sensor_pose(config, index)[:3, 3], max_range)
        else:  # everything the sensor can reach from anywhere along this frame's stretch of path
            trajectory.check_frames(index + 1, period)
            sensor_range = (trajectory.frame_poses(index, period)(np.zeros(1))[0, :3, 3], max_range + trajectory.reach(index, period))
        buffers = export_scene(table, extra_rules, keep_within=sensor_range)
        timings["export"] = time.perf_counter() - start
        start = time.perf_counter()
        points, pose = scan_buffers(buffers, config, rng, index, trajectory)
        timings["scan"] = time.perf_counter() - start
        boxes = None
        if config.output.boxes.formats:
            start = time.perf_counter()
            boxes = frame_boxes(buffers, config, pose, points, headings, index, rng)
            timings["boxes"] = time.perf_counter() - start
        start = time.perf_counter()
        files = write_frame(out_dir, index, points, config, boxes)
        if boxes is not None:
            from .io.boxes import write_image_sets

            write_image_sets(out_dir, range(index + 1), config.output.boxes.formats)
        timings["write"] = time.perf_counter() - start
        manifest["frames"].append(
            {
                "index": index,
                "files": files,
                "points": int(len(points)),
                "triangles": int(len(buffers.triangles)),
                "sensor_pose": pose.tolist(),
                **({"station": index % stations} if stations else {}),
                **({} if trajectory is None else {"trajectory": trajectory.frame_info(index, period)}),
                "timings_s": {k: round(v, 4) for k, v in timings.items()},
                "objects": buffers.objects.rows(),
                **({} if scene_info is None else {"scene": scene_info}),
                **({} if boxes is None else {"boxes": [{"class": str(b["class_name"]), "instance": int(b["instance"]), "points": int(b["points"]), "visible": int(b["visible"]), "unoccluded": int(b["unoccluded"]), "occlusion": int(b["occlusion"]), "truncation": round(float(b["truncation"]), 4)} for b in boxes]}),
            }
        )
        write_manifest(out_dir, manifest)
        yield FrameResult(index, points, pose, manifest)
