"""Scene builders (bpy): each turns its config section into tagged objects in the current scene."""

from __future__ import annotations

import numpy as np

from dataclasses import dataclass, field

from . import blend, primitives, railway

BUILDERS = {"railway": railway.build, "primitives": primitives.build, "blend": blend.build}
SENSOR_AWARE = {"railway"}  # builders whose level of detail follows the sensor: they take a `view`


@dataclass
class FrameState:
    """What a re-randomising builder tells the pipeline about its frame.

    headings : {instance id: yaw in radians} of the objects that get 3D boxes (car bodies, people's
        facing, robot arms' vertical plane)
    info : plain data for the manifest (counts, placement log)
    """

    headings: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


def _frame_builders() -> dict:
    from .industrial_hall import IndustrialHall
    from .parking import ParkingGarage

    return {"parking": ParkingGarage, "industrial_hall": IndustrialHall}


_BUILT: dict = {}  # builder name -> (params, the built scene) of a builder that re-randomises in place


def built_scene(builder: str):
    """The scene object ``builder`` (parking, industrial_hall) keeps between frames, or ``None``."""
    built = _BUILT.get(builder)
    return None if built is None else built[1]


def reset_built_scenes() -> None:
    """Forget the scenes built for re-randomisation; the next frame builds its scene anew."""
    _BUILT.clear()


def build_scene(scene_config, rng: np.random.Generator, view=None):
    """Build ``scene_config.builder`` with its parameters, drawing randomness from ``rng`` only.

    view : optional :class:`~bpy_pipeline.geometry.lod.SensorView` (where the scene will be scanned
        from, and how finely), passed to the builders of :data:`SENSOR_AWARE` and to parking and
        industrial_hall (which place their objects around the sensor)
    Returns what the builder returns (the railway builder: its layout; parking and
    industrial_hall: a :class:`FrameState`). Parking and industrial_hall build their static
    structure once and, for every later frame with the same parameters, only move and re-pose
    what changes; their result depends on ``rng`` and ``view`` alone, not on earlier frames.
    """
    frame_builders = _frame_builders()
    if scene_config.builder in frame_builders:
        built = _BUILT.get(scene_config.builder)
        if built is None or built[0] != scene_config.params or not built[1].alive():
            _BUILT.clear()
            built = (scene_config.params, frame_builders[scene_config.builder](scene_config.params))
            _BUILT[scene_config.builder] = built
        return built[1].randomize(rng, view)
    _BUILT.clear()
    if scene_config.builder in SENSOR_AWARE:
        return BUILDERS[scene_config.builder](scene_config.params, rng, view)
    return BUILDERS[scene_config.builder](scene_config.params, rng)
