"""The shared Blender side (bpy): the export to scene buffers, version differences, objects and tags, node-group helpers,
boxes by nodes, people, the robot arm, asset files, curves, the camera rendering; and :func:`build_scene`.

Each builder's own Blender side lives in its package (``builders/<name>/scene.py``, ``*_nodes.py``), the
population's in :mod:`bpy_pipeline.population.scene`; the registry entries and parameters are pure
(:mod:`bpy_pipeline.builders`).
"""

from __future__ import annotations

import numpy as np

from ..builders.base import BuildContext, BuildResult
from ..builders.base import build_scene as _build


def build_scene(scene_config, rng: np.random.Generator, view=None, keep: dict | None = None) -> BuildResult:
    """Build ``scene_config.builder`` with its parameters, drawing randomness from ``rng`` only.

    view : optional :class:`~bpy_pipeline.geometry.lod.SensorView` (where the scene will be scanned
        from, and how finely)
    keep : state kept across frames (parking and industrial_hall keep their static structure there
        and only move and re-pose what changes); a new dict builds from nothing
    """
    return _build(scene_config.builder, scene_config.params, BuildContext(rng, view, {} if keep is None else keep))
