"""The frame: one value handed from stage to stage (pose, scene, buffers, points, boxes, timings).

A stage is a function ``stage(frame, run) -> None`` that fills in its part of the frame
(:mod:`bpy_pipeline.pipeline` lists them in order); a frame holds everything one frame's writers
and its record need, so a stage is testable alone and a frame range needs no hidden state.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

import numpy as np


@dataclass
class Frame:
    """One frame of a run.

    index : frame index in the run (0-based)
    config : the run's :class:`~bpy_pipeline.config.Config`
    rng : the frame's generator (``pipeline.frame_rng(seed, index)``); every random draw of the frame
    scene : what the builder reported when this frame built the scene (``None`` when it scans a scene
        built for an earlier frame, or the user's scene as it is)
    pose : (4, 4) float64 sensor-to-world transform at the frame's start (mount height included)
    pose_at : ``pose_at(t (n,) s) -> (n, 4, 4)`` per-ray poses of a moving sensor (the static pose otherwise)
    trajectory : the moving sensor's :class:`~bpy_pipeline.lidar.platform.Trajectory`, ``None`` when static
    buffers : the exported :class:`~bpy_pipeline.buffers.SceneBuffers`
    caster : the scan's :class:`~bpy_pipeline.lidar.raycast.RayCaster` of ``buffers`` at ``pose`` (the boxes reuse it)
    chunks : the scan's ``(points, beam)`` chunks, consumed by the effects stage
    points : (p,) POINT_DTYPE records in the output frame (sensor or world)
    boxes : (b,) BOX_DTYPE box labels in the output frame, ``None`` when no box format is asked for
    files : paths of the frame's files relative to the output folder, once written
    timings : seconds per timed stage
    """

    index: int
    config: Any
    rng: np.random.Generator
    scene: Any = None
    pose: np.ndarray | None = None
    pose_at: Callable | None = None
    trajectory: Any = None
    buffers: Any = None
    caster: Any = None
    chunks: Iterable | None = None
    points: np.ndarray | None = None
    boxes: np.ndarray | None = None
    files: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    record: dict = field(default_factory=dict)
    images: dict[str, np.ndarray] = field(default_factory=dict)  # {name: (h, w, 3) uint8}: camera renderings (KITTI's image_2)
    rig: Any = None  # a sensor rig's per-sensor frames (:class:`~bpy_pipeline.rig.RigFrame`), ``None`` for one sensor

    @property
    def stem(self) -> str:
        """``NNNNNN``: the six-digit file stem of the frame."""
        return f"{self.index:06d}"
