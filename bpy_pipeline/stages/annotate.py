"""The annotate stage: 3D box labels with truncation and occlusion (semantic labels come with the scan). No Blender.

The boxes are fitted around each labelled object's triangles (:mod:`bpy_pipeline.geometry.boxes`);
their truncation and occlusion come from one visibility cast of the sensor's own rays
(:mod:`bpy_pipeline.lidar.cast.visibility`), here, before any writer runs: writers only write.
"""

from __future__ import annotations

import numpy as np

from ..buffers import SceneBuffers
from ..config import Config
from ..frame import Frame, Run
from ..geometry.boxes import boxes_in_frame, count_points, fit_boxes, keep_boxes
from ..geometry.transforms import output_pose
from ..lidar.sensor.sensor_rays import SensorRays
from ..lidar.sensor.sensors import angular_resolution
from ..lidar.cast.visibility import occlusion_levels, visibility
from ..rig import out_of_reach
from .view import scan_surfaces


def world_boxes(buffers: SceneBuffers, config: Config, pose: np.ndarray, points: np.ndarray, headings: dict | None = None, frame: int = 0,
                rng: np.random.Generator | None = None, rays: SensorRays | None = None, skip_unseen: bool = False, caster=None,
                direct_returns: np.ndarray | None = None) -> np.ndarray:
    """Every box of ``output.boxes.classes`` in the world frame with truncation, occlusion and its points, none dropped
    (:func:`sensor_boxes` keeps those with their minimum points and moves them into the points' frame).

    headings : {instance: yaw} from the builder (others get their footprint's heading)
    skip_unseen : leave out of the visibility trace the boxes no ray of the sensor can pass near (outside its
        field of view or range, :func:`~bpy_pipeline.rig.out_of_reach`): they get what the trace would give them
        (truncation 1, no visible or unoccluded ray); a rig's narrow sensors see a few of a street's boxes each
    caster : the scan's :class:`~bpy_pipeline.lidar.cast.raycast.RayCaster` of ``buffers`` at ``pose``, reused by the cast (built when ``None``)
    direct_returns : the scan's ``frame.direct_returns`` (:func:`~.scan.counts_direct_returns`), which give the ``visible``
        counts and the ``unoccluded`` rays whose first hit is the box's object when every object of a box's instance is
        of a box class (:func:`boxes_hold_their_instances`)
    """
    section = config.output.boxes
    boxes = fit_boxes(buffers, section.classes, headings)
    if len(boxes):
        spec = config.sensor.spec
        patterns = (rays or SensorRays(config)).patterns(frame)
        steps = [v for v in angular_resolution(spec) if v is not None and np.isfinite(v)]
        cell = float(np.clip(max(steps) if steps else 1.0, 0.2, 5.0))
        near = np.ones(len(boxes), bool)
        # no draw depends on which boxes are traced
        if skip_unseen and not config.sensor.reflector.enabled and config.effects.mirrors.glass.reflect_fraction in (0.0, 1.0):
            near = ~out_of_reach(spec, pose, boxes["centre"], np.linalg.norm(boxes["size"], axis=1) / 2 + 1e-3)
            boxes["truncation"] = 1.0
        traced = boxes[near]
        if direct_returns is not None and not boxes_hold_their_instances(buffers, traced, section.classes):
            direct_returns = None
        visibility(buffers, traced, patterns, pose, spec.min_range, spec.max_range, cell, caster=caster, surfaces=scan_surfaces(config), rng=rng,
                   direct_returns=direct_returns)
        boxes[near] = traced
        boxes["occlusion"] = occlusion_levels(boxes["visible"], boxes["unoccluded"], section.occlusion_levels)
        count_points(boxes, points)
    return boxes


def boxes_hold_their_instances(buffers: SceneBuffers, boxes: np.ndarray, classes) -> bool:
    """Whether every object sharing an instance with one of ``boxes`` is of one of ``classes``, so each box (fitted
    around its instance's objects of those classes, :func:`~bpy_pipeline.geometry.boxes.fit_boxes`) holds every
    object of its instance. A return from any of them then comes from a ray that passes the box's bounding sphere, as
    the visibility trace's rays do; a rider's box without the motorcycle it shares an instance with does not."""
    objects = buffers.objects
    wanted = {str(c) for c in classes}
    return all(objects.class_names[r] in wanted for r in np.flatnonzero(np.isin(objects.instance, boxes["instance"])))


def labelled_boxes(buffers: SceneBuffers, config: Config, pose: np.ndarray, points: np.ndarray, headings: dict | None = None, frame: int = 0,
                   rng: np.random.Generator | None = None, rays: SensorRays | None = None, caster=None,
                   direct_returns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(boxes, thin)``: the frame's 3D box labels (:data:`~bpy_pipeline.geometry.boxes.BOX_DTYPE`) with their class's
    minimum points, and the boxes with fewer but some (KITTI's DontCare regions: objects seen, too thin to label), both
    in the frame of the points (:func:`world_boxes`, then the points' frame)."""
    section = config.output.boxes
    boxes = world_boxes(buffers, config, pose, points, headings, frame, rng, rays, caster=caster, direct_returns=direct_returns)
    kept = keep_boxes(boxes, section.min_points, section.min_points_default) if len(boxes) else boxes
    thin = boxes[(boxes["points"] > 0) & ~np.isin(boxes["instance"], kept["instance"])]
    points_pose = output_pose(config.output.frame, pose, config.output.kitti.camera.position)
    return boxes_in_frame(kept, points_pose), boxes_in_frame(thin, points_pose)


def sensor_boxes(*args, **kwargs) -> np.ndarray:
    """The frame's 3D box labels in the frame of the points, thin boxes dropped (:func:`labelled_boxes`' first)."""
    return labelled_boxes(*args, **kwargs)[0]


frame_boxes = sensor_boxes  # the name pipeline.py gave it (mixing's boxes are mixing.frame.mixed_boxes)


def annotate_stage(frame: Frame, run: Run) -> None:
    """The frame's 3D box labels and its thin boxes (in the plan when a box format is asked for)."""
    frame.boxes, frame.thin_boxes = labelled_boxes(frame.buffers, run.config, frame.pose, frame.points, frame.scene.headings, frame.index, frame.rng, run.rays,
                                                   frame.caster, frame.direct_returns)
