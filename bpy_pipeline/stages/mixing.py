"""The real-scan background's stages: background, place, cast, effects, annotate (``scene.builder: real_scan``).

No Blender scene: each stage runs one of the mixing steps (:data:`~bpy_pipeline.mixing.frame.MIX_STEPS`)
on the frame's :class:`~bpy_pipeline.mixing.frame.MixState` (``frame.mixed``): the real sweep read
and its firings recovered, the objects placed and meshed in numpy, every real firing cast at
them, the configured effects (``effects``: the sensor preset's fitted drop and noise unless
``effects.ideal``) and noise injections on the inserted returns only, then the boxes.
"""

from __future__ import annotations

import numpy as np

from ..builders.base import BuildResult
from ..frame import Frame, Run
from ..geometry.boxes import boxes_in_frame, keep_boxes
from ..geometry.transforms import transform_points
from ..io.real_scans import read_real_scan
from ..mixing.firings import recover_firings
from ..mixing.frame import MixState, mix_annotate, mix_background, mix_cast, mix_effects, mix_place, scan_paths
from ..mixing.section import RealScanScene
from .view import sensor_pose


def kept_scan(section: RealScanScene, index: int, keep: dict):
    """``(scan, firings)`` of frame ``index``'s file, read once while frames keep using the same file
    (held in the run's ``keep``: reading and firing recovery draw nothing, so reuse gives the same bytes)."""
    paths = scan_paths(section)
    path = paths[index % len(paths)]
    key = (str(path), path.stat().st_mtime_ns if path.exists() else None, section.format, section.preset)
    held = keep.get("real_scan")
    if held is None or held[0] != key:
        scan = read_real_scan(path, section.format or None)
        keep.clear()
        held = keep["real_scan"] = (key, scan, recover_firings(scan, section.preset or None))
    return held[1], held[2]


def background_stage(frame: Frame, run: Run) -> None:
    """The frame's real sweep (kept by the run while frames share its file) as its background, the sensor where the config puts it."""
    config = run.config
    section = config.scene.params
    scan, firings = kept_scan(section, frame.index, run.keep)
    frame.mixed = MixState(section, frame.rng, config.effects, run.threads, run.table, scan, firings, frame.index)
    mix_background(frame.mixed)
    frame.place(sensor_pose(config, frame.index))


def place_stage(frame: Frame, run: Run) -> None:
    """The objects to insert and their meshes; the frame's buffers are theirs (sensor frame)."""
    mix_place(frame.mixed)
    frame.buffers = frame.mixed.buffers


def cast_stage(frame: Frame, run: Run) -> None:
    """Every real firing cast at the inserted objects."""
    mix_cast(frame.mixed)


def effects_stage(frame: Frame, run: Run) -> None:
    """The inserted returns' effects and injections, then the frame's points in the output frame."""
    mix_effects(frame.mixed)
    points = frame.mixed.points
    if run.config.output.frame == "world":
        xyz = transform_points(np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64), frame.pose)
        points["x"], points["y"], points["z"] = xyz.T
    frame.points = points


def annotate_stage(frame: Frame, run: Run) -> None:
    """The boxes (inserted objects, real boxes, labelled vehicles) and the frame's record of the mixing
    (``frame.scene``: headings and info); the box labels kept when a box format is asked for."""
    mixed = frame.mixed
    mix_annotate(mixed)
    frame.scene = BuildResult({int(b["instance"]): float(b["heading"]) for b in mixed.boxes}, mixed.info)
    frame.built = True
    config = run.config
    section = config.output.boxes
    if section.formats:
        boxes = mixed.boxes[np.isin(mixed.boxes["class_name"], list(section.classes))]
        boxes = keep_boxes(boxes, section.min_points, section.min_points_default) if len(boxes) else boxes
        frame.boxes = boxes if config.output.frame == "sensor" else boxes_in_frame(boxes, np.linalg.inv(frame.pose))


MIXING_STAGES = (background_stage, place_stage, cast_stage, effects_stage, annotate_stage)


def real_scan_stage(frame: Frame, run: Run) -> None:
    """The whole real-scan frame in one call (the builder's single stage before the frame plan): :data:`MIXING_STAGES` in turn."""
    for stage in MIXING_STAGES:
        stage(frame, run)
