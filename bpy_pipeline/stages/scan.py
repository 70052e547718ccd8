"""The scan stages: cast the sensor's rays at the frame's buffers (lazily, in chunks) and give each chunk
its effects (mirror-edge drop, drop, noise, intensity) on its way into the frame's point records. No Blender."""

from __future__ import annotations

import itertools
import time
from typing import Iterable, Iterator

import numpy as np

from ..buffers import SceneBuffers
from ..config import Config, sensor_trajectory
from ..frame import Frame, Run
from ..geometry.clearance import enclosing_instance
from ..geometry.transforms import sensor_to_output, transform_points
from ..lidar.effects.divergence import scan_footprint_chunks
from ..lidar.effects.apply import apply_effects
from ..lidar.sensor.mirror_sensor import drop_at_edges
from ..lidar.sensor.platform import Trajectory
from ..lidar.points import POINT_DTYPE
from ..lidar.cast.scanner import scan_chunks
from ..lidar.sensor.sensor_rays import CHUNK_RAYS
from ..lidar.sensor.sensors import ray_count
from .scene import pose_stage
from .view import scan_surfaces

MAX_RESERVED_POINTS = 1 << 25  # point records reserved up front (address space only; pages fill as points come)


def moving_objects(frame: Frame) -> np.ndarray | None:
    """``(k,)`` bool per row of ``frame.buffers.objects``: the objects the builder placed for this frame
    (those it gives 3D boxes: cars, robots, people, road users), traced by a small caster of their own
    while the rest of the scene's is kept (:class:`~bpy_pipeline.lidar.cast.raycast.CasterCache`). ``None`` when
    the scene placed none. A function of the frame alone, so frame k gives the same bytes after
    frame k - 1 as alone."""
    if not frame.scene.headings:
        return None
    return np.isin(frame.buffers.objects.instance, np.fromiter(frame.scene.headings, np.int64))


def scan_stage(frame: Frame, run: Run) -> None:
    """The scan's ``(points, beam)`` chunks (lazy: the effects stage traces them one at a time)."""
    if not len(frame.buffers.triangles):
        frame.buffers.check()  # "nothing to scan"; the caster checks the rest before it uses an index
    config, spec = run.config, run.config.sensor.spec
    if frame.scene.dynamic is not None and run.static_world is not None:  # the static world exported once, first in the buffers
        token, static, _ = run.static_world
        moving = np.arange(len(frame.buffers.objects)) >= len(static.objects)
        caster = run.casters.caster(frame.buffers, frame.pose, moving, key=token, follow=True)  # its Embree scene built once
    else:
        caster = run.casters.caster(frame.buffers, frame.pose, moving_objects(frame))
    frame.caster = caster
    ghost = run.table.id_of("reflection") if config.effects.mirrors.label == "reflection" else None
    options = {"max_bounces": config.effects.mirrors.max_bounces, "ghost_semantic": ghost, "ideal": config.effects.mirrors.ideal, "chunk_rays": CHUNK_RAYS,
               "surfaces": scan_surfaces(config), "rng": frame.rng}
    patterns = run.rays.patterns(frame.index)  # a mirror sensor's leave through its own mirrors
    pose = frame.pose_at if frame.moving else frame.pose  # the scanner casts a static sensor's rays from one pose
    if config.sensor.divergence.active:
        frame.chunks = scan_footprint_chunks(caster, frame.buffers, patterns, pose, config.sensor.divergence, spec.min_range, spec.max_range, **options)
    else:  # with each return's ray when the boxes take their counts from them
        frame.chunks = scan_chunks(caster, frame.buffers, patterns, pose, spec.min_range, spec.max_range, with_rays=counts_direct_returns(config, frame),
                                   **options)


def counts_direct_returns(config: Config, frame: Frame) -> bool:
    """Whether the effects stage keeps, per ray, the instance of its return that met no mirror (``frame.direct_returns``,
    :func:`add_direct_returns`), so the boxes take from the scan their ``visible`` rays and the ``unoccluded``
    ones whose return is the box's object (:func:`~bpy_pipeline.lidar.cast.visibility.visibility`'s ``direct_returns``)
    instead of tracing again the rays that pass them. It does when boxes are asked for and that
    trace would cast the scan's own rays from the scan's pose and make the same draws: a sensor that stands still
    during the frame (the boxes' trace casts from the frame's first pose), one ray a firing (no beam divergence), rays
    from the sensor's centre (none of its own mirrors) and glass that reflects all of the beams it meets or none (no
    draw: the boxes' trace would draw again from the frame's generator). Every return of the scan with no mirror met
    lies on the first object its ray meets, as the trace's do, so the counts are the same. The scan then yields each
    return's ray with it (:func:`~bpy_pipeline.lidar.cast.scanner.scan_chunks`' ``with_rays``)."""
    mirrors = config.effects.mirrors
    return (bool(config.output.boxes.formats) and not frame.moving and not config.sensor.divergence.active and not config.sensor.reflector.enabled
            and mirrors.glass.reflect_fraction in (0.0, 1.0))


def add_direct_returns(table: np.ndarray, ray: np.ndarray, instance: np.ndarray) -> np.ndarray:
    """``table``, per ray of the scan the instance of its return that met no mirror (-1 for none), with the returns
    ``(d,)`` ``ray`` and their ``(d,)`` ``instance`` written in; a new, longer table (-1 beyond the old end) when a ray
    lies beyond its end."""
    if len(ray) and int(ray.max()) >= len(table):
        table = np.concatenate([table, np.full(int(ray.max()) + 1 - len(table), -1, np.int64)])
    table[ray] = instance
    return table


def timed_pulls(items: Iterable, timings: dict, key: str) -> Iterator:
    """``items`` one at a time, the seconds spent making each (pulling it) added to ``timings[key]``."""
    items = iter(items)
    while True:
        start = time.perf_counter()
        item = next(items, None)
        timings[key] = timings.get(key, 0.0) + time.perf_counter() - start
        if item is None:
            return
        yield item


def effects_stage(frame: Frame, run: Run) -> None:
    """Trace each chunk, give it its effects and move it to the output frame before the next is traced,
    so memory holds the final point records and one chunk's work, no more.

    Times its own two parts: tracing the chunks (the lazy scan, with its point records) adds to
    ``frame.timings["scan"]``, the rest (effects, limits, the output frame, collecting) to ``["effects"]``."""
    start, traced = time.perf_counter(), frame.timings.get("scan", 0.0)
    config, spec = run.config, run.config.sensor.spec
    mask = run.rays.edge_mask(frame.index)
    direct = np.full(ray_count(spec), -1, np.int64) if counts_direct_returns(config, frame) else None
    to_output = sensor_to_output(config.output.frame, frame.pose, config.output.kitti.camera.position)

    def finished(chunks):
        nonlocal direct
        for points, beam, *ray in chunks:
            if direct is not None:  # the instance of each return that met no mirror, at its ray
                hit = points["bounces"] == 0
                direct = add_direct_returns(direct, ray[0][hit], points["instance"][hit])
            if mask is not None:  # returns lost where the beam split on an edge of the sensor's own mirrors
                keep = drop_at_edges(points, mask, config.sensor.spec, frame.rng)
                points, beam = points[keep], beam[keep]
            # the run's threads
            points = apply_effects(points, beam, config.effects, frame.rng, threads=run.threads, objects=frame.buffers.objects, pool=run.casters.pool)
            inside = (points["range"] >= spec.min_range) & (points["range"] <= spec.max_range)
            if not inside.all():  # noise never pushes a return past the sensor's limits: such returns are dropped
                points = points[inside]
            if to_output is not None:
                xyz = transform_points(np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64), to_output)
                points["x"], points["y"], points["z"] = xyz.T
            yield points

    frame.points = collect_points(finished(timed_pulls(frame.chunks, frame.timings, "scan")), ray_count(config.sensor.spec))
    frame.chunks = None
    warn_enclosed(frame, run)
    frame.direct_returns = direct
    frame.timings["effects"] = frame.timings.get("effects", 0.0) + time.perf_counter() - start - (frame.timings["scan"] - traced)


def warn_enclosed(frame: Frame, run: Run) -> None:
    """Warn, naming the frame, when its sensor stands enclosed by one object (:func:`~bpy_pipeline.geometry.clearance.enclosing_instance`):
    inside a solid its scan shows that solid's inside, not the scene. A warning, not a refusal: a user's scene may be
    meant to be scanned from a small room or a box; the builders' own scenes keep every solid clear of the sensor."""
    points = frame.points
    found = enclosing_instance(points["range"], points["instance"], ray_count(run.config.sensor.spec))
    if found is None or run.log is None:
        return
    instance, share = found
    names = [name for name, i in zip(frame.buffers.objects.names, frame.buffers.objects.instance) if int(i) == instance]
    where = [round(float(v), 2) for v in frame.pose[:3, 3]]
    run.log(f"warning: frame {frame.index}: the sensor at {where} stands enclosed by {names[0] if names else f'instance {instance}'}: "
            f"{share:.0%} of its rays return from it, most within a few metres; move the sensor or the object")


def collect_points(parts: Iterable[np.ndarray], expected: int) -> np.ndarray:
    """The :data:`POINT_DTYPE` records of ``parts`` in one ``(p,)`` array, copied in as they come.

    expected : the most points likely (the ray count); that many (at most
    :data:`MAX_RESERVED_POINTS`) are reserved up front, so the parts are never all held twice:
    the operating system maps the reserved pages only as points fill them. More points than
    reserved double the reserve. A single part of contiguous, writeable :data:`POINT_DTYPE` records
    is returned as it is (the effects stage's parts are new arrays, never pooled memory: callers give
    parts they own). Records are copied as raw bytes (numpy copies a structured array
    field by field, 15x slower: 16 ms for a 611 k-point frame); a part of another dtype field by field.
    """
    raw = np.dtype((np.void, POINT_DTYPE.itemsize))
    parts = iter(parts)
    first = next(parts, None)
    if first is None:
        return np.empty(0, POINT_DTYPE)
    second = next(parts, None)
    if second is None and first.dtype == POINT_DTYPE and first.flags.c_contiguous and first.flags.writeable:
        return first  # one part (a scan of up to CHUNK_RAYS rays): it is the frame's records, no copy
    out, n = np.empty(min(max(expected, 1), MAX_RESERVED_POINTS), POINT_DTYPE), 0
    for part in itertools.chain([first], [] if second is None else [second], parts):
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


def scan_buffers(buffers: SceneBuffers, config: Config, rng: np.random.Generator, frame: int = 0,
                 trajectory: Trajectory | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Scan exported buffers with the configured sensor and effects: ``(points, pose (4, 4))``.

    frame : frame index: a moving sensor's frame k starts k frame times along its path (and a
        rosette's pattern continues where frame k - 1 stopped)
    trajectory : the moving sensor's path (:func:`~.view.scene_trajectory`); built from the config's
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
