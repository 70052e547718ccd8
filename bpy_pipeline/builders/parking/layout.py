"""The parking level's layout with doorways in its long walls. Pure numpy.

:func:`level_layout` is :func:`~bpy_pipeline.geometry.indoor.parking_layout` (slabs, walls, pillars,
bays, ramp) with each of the two long walls (along the driveway, x) cut by ``wall_openings``
doorways, ``opening_width`` wide and ``opening_height`` high, centred at
x = -length / 2 + (j + 1) length / (wall_openings + 1), j = 0 .. wall_openings - 1. A cut wall is
``wall_openings + 1`` full-height segments and a lintel over each doorway, all boxes. The doorways
lead out of the level: nothing stands behind them, so beams through them hit nothing.

The boxes' order (the "Parking Level" group's instances have it too, :mod:`.level_nodes`): the
long walls' segments, segment j of the -y wall then of the +y wall, j = 0 .. wall_openings; the two
end walls (-x, +x); the lintels, doorway j's over the -y wall then the +y wall. Without doorways
that is the plain level's four walls, the same boxes, the same floats.
"""

from __future__ import annotations

import numpy as np

from ...geometry.indoor import ParkingLayout, parking_layout


def doorway_centres(p) -> np.ndarray:
    """(k,) the doorways' centres along x (m), k = ``p.wall_openings``."""
    half_x = p.length / 2
    return np.array([-half_x + (j + 1) * (p.length / (p.wall_openings + 1)) for j in range(p.wall_openings)], float)


def level_layout(p) -> ParkingLayout:
    """The level of ``ParkingScene`` ``p`` (:func:`~bpy_pipeline.geometry.indoor.parking_layout`) with its long walls' doorways."""
    layout = parking_layout(p)
    if p.wall_openings == 0:
        return layout
    t, h = p.wall_thickness, p.ceiling_height
    half = np.array([p.length / 2, p.driveway_width / 2 + p.bay_depth + 0.5])
    outer_x = half[0] + t
    centres, half_w = doorway_centres(p), p.opening_width / 2
    starts = np.concatenate([[-outer_x], centres + half_w])
    ends = np.concatenate([centres - half_w, [outer_x]])
    segments = [(np.array([(a + b) / 2, s * (half[1] + t / 2), h / 2]), np.array([(b - a) / 2, t / 2, h / 2]))
                for a, b in zip(starts, ends) for s in (-1, 1)]
    end_walls = layout.boxes["wall"][2:]  # the plain level's -x and +x walls
    lintels = [(np.array([c, s * (half[1] + t / 2), (p.opening_height + h) / 2]), np.array([half_w, t / 2, (h - p.opening_height) / 2]))
               for c in centres for s in (-1, 1)]
    layout.boxes["wall"] = segments + end_walls + lintels
    return layout
