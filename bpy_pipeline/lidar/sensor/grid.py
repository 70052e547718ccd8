"""The range-image grid of a rows x columns sensor: image shape and the pixel of each ray or point.

Spinning and terrestrial sensors fire ``channels`` rings in every column; their frames form an
image of ``channels`` rows by ``columns`` columns (128 x 2048 for an Ouster OS1-128 at 2048
columns). The layout, the same for every image this package reads or writes (range images,
mirror-edge drop masks):

- row 0 is the highest beam (as Ouster's range images), rows go down in elevation;
- column ``c`` is the ``c``-th column fired in the frame (``spin: cw`` sensors fire from the
  upper edge of ``horizontal_fov_deg`` down, so column 0 of a full circle is at azimuth 180 deg).

A point's pixel follows from what its record keeps: its ``ring`` and its firing ``time``
(column ``c`` fires at ``c * column_period``, plus ``row * column_period / rows`` within the
column for a terrestrial scanner), so points can be placed after effects dropped some of them.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from .patterns import PATTERNS
from .sensors import SensorSpec, azimuth_step, azimuths, elevations

def check_grid(spec: SensorSpec, where: str) -> None:
    """``InputError`` naming ``where`` when the sensor's frames do not form a rows x columns image."""
    if not PATTERNS.get(spec.pattern).image:
        images = [name for name, pattern in PATTERNS.items() if pattern.image]
        raise InputError(f"{where}: needs a sensor whose frames are a rows x columns image ({' or '.join(images)}), not the {spec.pattern} pattern")


def image_shape(spec: SensorSpec) -> tuple[int, int]:
    """``(rows, columns)`` of one frame's image."""
    return int(spec.channels), len(azimuths(spec))


def ring_rows(spec: SensorSpec) -> np.ndarray:
    """``(channels,)`` int64 image row of each ring: rows by falling elevation (ties keep ring order)."""
    order = np.argsort(-elevations(spec), kind="stable")  # rings, highest first
    rows = np.empty(len(order), np.int64)
    rows[order] = np.arange(len(order))
    return rows


def column_period(spec: SensorSpec) -> float:
    """Seconds between two columns' first firings."""
    return azimuth_step(spec) / (360.0 * spec.rotation_hz)


def pixels(spec: SensorSpec, ring: np.ndarray, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(row, column)`` (n,) int64 image pixel of rays or points from their ``ring`` (n,) and firing ``time`` (n,) s.

    Within a column a terrestrial scanner's rows fire ``column_period / rows`` apart, so the
    column is the floor of ``time / column_period`` plus half a row step (exact for both patterns).
    """
    rows, columns = image_shape(spec)
    column = np.floor(np.asarray(time, np.float64) / column_period(spec) + 0.5 / rows).astype(np.int64)
    return ring_rows(spec)[np.asarray(ring, np.int64)], np.clip(column, 0, columns - 1)
