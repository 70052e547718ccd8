"""``scene.builder: real_scan``: a real scan as the background, synthetic objects cast in by its own firings.

No Blender scene: the frame's one stage (:func:`real_scan_stage`) reads the scan, places and
meshes the objects in numpy, casts every real firing at them (bpy_pipeline.mixing) and applies
the configured effects (``effects``: the sensor preset's fitted drop and noise unless
``effects.ideal``) to the inserted returns only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mixing.section import RealScanScene
from .base import Builder, BuildContext, BuildResult, register_builder


def check(params: RealScanScene, where: str) -> None:
    from ..geometry.objects import OBJECT_TYPES
    from ..io.real_scans import FORMATS

    if not params.path:
        raise InputError(f"{where}.path: the real_scan builder needs the path of a scan file ({', '.join(FORMATS)}), a folder of them or a glob pattern")
    if params.format and params.format not in FORMATS:
        raise InputError(f"{where}.format: {params.format!r} is not one of {', '.join(FORMATS)}")
    for k, o in enumerate(params.objects):
        if o.type not in OBJECT_TYPES and not Path(o.type).suffix.lower() in (".ply", ".obj"):
            raise InputError(f"{where}.objects[{k}].type: {o.type!r} is not one of {', '.join(OBJECT_TYPES)} or a .ply / .obj mesh file")
        if any(s < 0 for s in o.size):
            raise InputError(f"{where}.objects[{k}].size: must be >= 0 (0: the type's nominal size), got {list(o.size)}")
    for k, r in enumerate(params.remove):
        if any(s <= 0 for s in r.size):
            raise InputError(f"{where}.remove[{k}].size: must be > 0, got {list(r.size)}")
    if params.max_range < 0:
        raise InputError(f"{where}.max_range: must be >= 0, got {params.max_range}")


def build(params: RealScanScene, context: BuildContext) -> BuildResult:
    """Nothing to build in Blender: :func:`real_scan_stage` makes the frame."""
    return BuildResult()


def kept_scan(section: RealScanScene, index: int, keep: dict):
    """``(scan, firings)`` of frame ``index``'s file, read once while frames keep using the same file
    (held in the run's ``keep``: reading and firing recovery draw nothing, so reuse gives the same bytes)."""
    from ..io.real_scans import read_real_scan
    from ..mixing.firings import recover_firings
    from ..mixing.frame import scan_paths

    paths = scan_paths(section)
    path = paths[index % len(paths)]
    key = (str(path), path.stat().st_mtime_ns if path.exists() else None, section.format, section.preset)
    held = keep.get("real_scan")
    if held is None or held[0] != key:
        scan = read_real_scan(path, section.format or None)
        keep.clear()
        held = keep["real_scan"] = (key, scan, recover_firings(scan, section.preset or None))
    return held[1], held[2]


def real_scan_stage(frame, run) -> None:
    """The whole frame of a real scan: points (output frame), boxes, a stand-in for the buffers (the inserted objects)."""
    from ..io import boxes as box_labels
    from ..mixing import mix_frame
    from ..pipeline import sensor_pose

    config = run.config
    section = config.scene.params
    mixed = mix_frame(section, frame.rng, config.effects, run.threads, run.table, *kept_scan(section, frame.index, run.keep), frame=frame.index)
    frame.pose = sensor_pose(config, frame.index)
    frame.pose_at = frame.pose
    frame.buffers = mixed.buffers
    frame.scene = BuildResult({int(b["instance"]): float(b["heading"]) for b in mixed.boxes}, mixed.info)
    points = mixed.points
    if config.output.frame == "world":
        from ..geometry.transforms import transform_points

        xyz = transform_points(np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64), frame.pose)
        points["x"], points["y"], points["z"] = xyz.T
    frame.points = points
    section = config.output.boxes
    if section.formats:
        boxes = mixed.boxes[np.isin(mixed.boxes["class_name"], list(section.classes))]
        boxes = box_labels.keep_boxes(boxes, section.min_points, section.min_points_default) if len(boxes) else boxes
        frame.boxes = boxes if config.output.frame == "sensor" else box_labels.boxes_in_frame(boxes, np.linalg.inv(frame.pose))


# the nuScenes sweep's sensor by default (give sensor.preset: hdl64e for KITTI scans)
register_builder("real_scan", Builder(RealScanScene, build, check, sensor={"preset": "hdl32e"}, boxes=True, stages=((real_scan_stage, "scan"),)))
