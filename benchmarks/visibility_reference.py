"""The reference the boxes' visibility cast is measured against: a caster per object, each tracing its own rays.

Used by ``benchmarks/bench_writers.py`` (its speed against :func:`bpy_pipeline.lidar.cast.visibility.visibility`)
and ``tests/test_boxes.py`` (both give the same counts).
"""

from __future__ import annotations

import numpy as np

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry.boxes import instance_triangles
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.rays import Pattern
from bpy_pipeline.lidar.cast.scanner import trace_beams
from bpy_pipeline.lidar.cast.visibility import MAX_SAMPLES, SAMPLE_SPACING, Coverage, subset_buffers, surface_samples


def visibility_per_object(
    buffers: SceneBuffers,
    boxes: np.ndarray,
    patterns,
    pose: np.ndarray,
    min_range: float,
    max_range: float,
    cell_deg: float = 1.0,
    caster: RayCaster | None = None,
    surfaces=None,
    rng: np.random.Generator | None = None,
) -> None:
    """:func:`~bpy_pipeline.lidar.cast.visibility.visibility` the earlier way, kept as its reference (tests/test_boxes.py, bench_writers.py):
    a caster per object and a loop over the objects, each tracing its own rays. Same arguments and results
    (up to the draws of glass that reflects a fraction of beams).

    Fill ``truncation``, ``visible`` and ``unoccluded`` of world-frame ``boxes`` in place.

    patterns : the sensor's rays (one :class:`Pattern` or an iterable of chunks), sensor frame
    pose : (4, 4) sensor-to-world transform at frame start
    cell_deg : coverage cell for truncation (about the pattern's coarsest angular spacing): the
        rays passing an object mark the directions they cover, taken from the sensor's centre
        to where they pass it (so rays leaving from the sensor's own mirrors count right)
    caster : a :class:`RayCaster` of ``buffers`` in the sensor's frame, if one exists already
    surfaces, rng : the scanner's rules for mirrors and glass and a generator for glass that
        reflects a fraction of beams (:func:`~bpy_pipeline.lidar.cast.scanner.trace_beams`)
    Only the rays that pass within an object's bounding sphere are traced, once through the
    whole scene and once against the object alone, both the scanner's way (glass passed
    through, no mirror bounces), so a car's windows count the same in both.
    """
    if len(boxes) == 0:
        return
    caster = caster or RayCaster(buffers, frame=pose)
    instance_of_triangle = instance_triangles(buffers)
    objects = buffers.objects
    members = [[r for r in range(len(objects)) if objects.instance[r] == box["instance"]] for box in boxes]
    # bounding spheres in the sensor frame
    centres = (boxes["centre"] - pose[:3, 3]) @ pose[:3, :3]
    radii = np.linalg.norm(boxes["size"], axis=1) / 2 + 1e-3
    alone = [(RayCaster(sub, frame=pose), sub) for sub in (subset_buffers(buffers, rows) for rows in members)]
    visible = np.zeros(len(boxes), np.int64)
    unoccluded = np.zeros(len(boxes), np.int64)
    seen = [[] for _ in range(len(boxes))]  # per object: where the rays passing it are, seen from the sensor
    for chunk in [patterns] if isinstance(patterns, Pattern) else patterns:
        origins = np.zeros((len(chunk), 3)) if chunk.origins is None else chunk.origins
        # a cone test from the sensor's centre first (all objects at once), widened by the farthest
        # ray origin, then the exact ray-sphere test on the rays it lets through
        shift = 0.0 if chunk.origins is None else float(np.linalg.norm(origins, axis=1).max())
        reach = radii + shift
        distance = np.linalg.norm(centres, axis=1)
        cos_limit = np.where(distance > reach, np.sqrt(np.clip(1.0 - (reach / np.maximum(distance, 1e-12)) ** 2, 0.0, 1.0)), -2.0)
        towards = chunk.directions @ (centres / np.maximum(distance, 1e-12)[:, None]).T  # (n, k)
        cone = towards >= cos_limit[None]
        for k in range(len(boxes)):
            candidates = np.flatnonzero(cone[:, k])
            if len(candidates) == 0:
                continue
            offset = centres[k] - origins[candidates]
            along = np.einsum("ij,ij->i", offset, chunk.directions[candidates])
            miss2 = np.einsum("ij,ij->i", offset, offset) - along**2
            passing = (miss2 <= radii[k] ** 2) & (along >= -radii[k]) & (along - radii[k] <= max_range)
            near = candidates[passing]
            if len(near) == 0:
                continue
            o = origins[near] if chunk.origins is not None else np.zeros(3)
            d = chunk.directions[near]
            seen[k].append(o + along[passing, None] * d)  # the ray's point closest to the object's centre
            beams = trace_beams(caster, buffers, o, d, min_range, max_range, max_bounces=0, surfaces=surfaces, rng=rng)
            hit_instance = instance_of_triangle[beams.triangle]
            visible[k] += int(np.count_nonzero((hit_instance == boxes["instance"][k]) & (beams.bounces == 0)))
            lone = trace_beams(*alone[k], o, d, min_range, max_range, max_bounces=0, surfaces=surfaces, rng=rng)
            unoccluded[k] += len(lone.ray)  # the object alone: every return is on it
    boxes["visible"] = visible
    boxes["unoccluded"] = unoccluded
    for k, rows in enumerate(members):
        triangles = buffers.vertices[buffers.triangles[np.isin(buffers.triangle_object, rows)]]  # (m, 3, 3)
        total = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1).sum() / 2
        samples, area = surface_samples(triangles, max(SAMPLE_SPACING, float(np.sqrt(total / MAX_SAMPLES))), area_bound=True)
        samples = (samples - pose[:3, 3]) @ pose[:3, :3]
        distance = np.linalg.norm(samples, axis=1)
        inside = (distance >= min_range) & (distance <= max_range)
        if seen[k]:  # the directions the rays passing the object cover, from the sensor's centre
            inside &= Coverage(np.concatenate(seen[k]), cell_deg).covers(samples)
        else:
            inside[:] = False
        total = area.sum()
        boxes["truncation"][k] = float(1.0 - area[inside].sum() / total) if total > 0 else 1.0
