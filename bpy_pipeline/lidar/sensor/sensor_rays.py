"""The configured sensor's rays as they enter the scene, kept across a run's frames (:class:`SensorRays`). Pure.

A plain sensor's rays are its pattern's, in chunks of :data:`CHUNK_RAYS`. A mirror sensor's rays
(``sensor.reflector``) leave through its own mirrors: traced through them once and kept while the
sensor stays the same (a rosette's rays change every frame and are traced again), with the
mirror-edge drop mask made once beside them. A plain sensor's rays whose pattern is the same every
frame (every pattern but the rosette) are made once too, up to :data:`MAX_KEPT_RAYS`, and handed
out read-only: directions, rings and firing times are the pattern's, frame after frame, with no
rebuild (a moving sensor's per-ray poses come from those times).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from .grid import image_shape
from .mirror_sensor import MirrorFrame, load_edge_mask, reflect_patterns
from .patterns import PATTERNS
from .sensors import iter_pattern, ray_count
from .rays import Pattern

CHUNK_RAYS = 1 << 18  # rays generated and traced at a time: bounds memory for 23-million-ray scans
MAX_KEPT_MIRROR_RAYS = 1 << 22  # a mirror sensor's rays up to this many are traced through its mirrors once and kept
MAX_KEPT_RAYS = 1 << 21  # a plain sensor's rays up to this many (34 B each: 71 MB) are made once per run and kept


@dataclass
class SensorRays:
    """The rays of a config's ``sensor`` section (``.spec``, ``.reflector``), kept by a run across frames.

    config : anything with a ``sensor`` section (a :class:`~bpy_pipeline.config.Config`)
    cached : a mirror sensor's {key: {"rays": the reflected :class:`Pattern`, "mask": the edge mask}} of the
        last two keys asked for (a rosette's rays change every frame: its key is the frame)
    kept : a plain sensor's chunks of rays, made once (:meth:`patterns`), ``None`` until then
    """

    config: object
    cached: dict = field(default_factory=dict)
    kept: list | None = None

    def _kept(self, spec) -> list[Pattern]:
        if self.kept is None:
            chunks = list(iter_pattern(spec, CHUNK_RAYS, 0))
            for chunk in chunks:
                for array in (chunk.directions, chunk.ring, chunk.time, chunk.origins):
                    if array is not None:
                        array.flags.writeable = False  # shared by every frame of the run
            self.kept = chunks
        return self.kept

    def _mirror_sensor(self, frame: int) -> dict:
        spec, reflector = self.config.sensor.spec, self.config.sensor.reflector
        edge = reflector.edge_drop
        measured = Path(edge.mask) if edge.mask not in ("none", "generated") else None
        key = (frame if PATTERNS.get(spec.pattern).per_frame else 0, measured and measured.exists() and measured.stat().st_mtime_ns)
        entry = self.cached.get(key)
        if entry is None:
            traced = MirrorFrame.of(reflector, spec, key[0])
            mask = None
            if edge.mask == "generated":
                mask = traced.edge_drop_mask(spec, edge.probability, edge.beam_diameter)
            elif measured is not None:
                mask = load_edge_mask(measured, image_shape(spec), "sensor.reflector.edge_drop.mask")
            entry = {"rays": traced.reflected(reflector), "mask": mask}
            # a new dict holding the newest key before this one and this one: a frame finishing on another
            # thread (plan.run_frames) asks for its own frame's rays while the next frame asks for its
            self.cached = {**dict(list(self.cached.items())[-1:]), key: entry}
        return entry

    def patterns(self, frame: int = 0) -> Iterable[Pattern]:
        """The rays of frame ``frame`` (sensor frame) in chunks; a mirror sensor's leave from its mirrors
        with per-ray origins, lost rays left out."""
        spec, reflector = self.config.sensor.spec, self.config.sensor.reflector
        if not reflector.enabled:
            if PATTERNS.get(spec.pattern).per_frame or ray_count(spec) > MAX_KEPT_RAYS:
                return iter_pattern(spec, CHUNK_RAYS, frame)
            return self._kept(spec)
        if ray_count(spec) > MAX_KEPT_MIRROR_RAYS:
            return reflect_patterns(iter_pattern(spec, CHUNK_RAYS, frame), reflector)
        return [self._mirror_sensor(frame)["rays"]]

    def edge_mask(self, frame: int = 0) -> np.ndarray | None:
        """``(rows, columns)`` float32 mirror-edge drop probabilities of the sensor's own mirrors; ``None`` when off."""
        reflector = self.config.sensor.reflector
        if not reflector.enabled or reflector.edge_drop.mask == "none":
            return None
        return self._mirror_sensor(frame)["mask"]
