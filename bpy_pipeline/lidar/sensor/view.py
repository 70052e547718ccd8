"""How finely a sensor sees a scene, for level-of-detail code: a spec's :class:`~bpy_pipeline.geometry.lod.SensorView`. Pure."""

from __future__ import annotations

import numpy as np

from ...geometry.lod import SensorView, view_from_steps
from .sensors import SensorSpec, angular_resolution, elevations


def view_of(spec: SensorSpec, positions) -> SensorView:
    """The :class:`~bpy_pipeline.geometry.lod.SensorView` of a sensor of ``spec`` at ``positions`` ((k, 3), m):
    its azimuth step and its elevation step (an uneven elevation table: its coarsest gap)."""
    azimuth, elevation = angular_resolution(spec)
    if elevation is None:
        table = np.sort(elevations(spec))
        elevation = float(np.diff(table).max()) if len(table) > 1 else azimuth
    return view_from_steps(azimuth, elevation, spec.max_range, positions)
