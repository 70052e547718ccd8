"""Scene builders (bpy): each turns its config section into tagged objects in the current scene."""

from __future__ import annotations

import numpy as np

from . import blend, primitives, railway

BUILDERS = {"railway": railway.build, "primitives": primitives.build, "blend": blend.build}


def build_scene(scene_config, rng: np.random.Generator) -> None:
    """Build ``scene_config.builder`` with its parameters, drawing randomness from ``rng`` only."""
    BUILDERS[scene_config.builder](scene_config.params, rng)
