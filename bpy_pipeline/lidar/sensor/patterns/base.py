"""What a ray pattern is: the registry entry that owns everything that differs from one pattern to another.

A pattern turns a :class:`~bpy_pipeline.lidar.sensor.sensors.SensorSpec` into rays. Its entry answers,
for a spec of that pattern: the rays (a chunk generator), how many, at what angular resolution,
at which elevations and azimuths, how its fields are derived and checked, how long a frame lasts
and whether its frames form a rows x columns image. :mod:`bpy_pipeline.lidar.sensor.sensors` only
looks the entry up by ``spec.pattern``. Adding a pattern is one module that defines its entry and
calls :func:`register_pattern`, plus its name in the import line of this package's ``__init__``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ....errors import InputError
from ....registry import Registry

MAX_RINGS = 65536  # ring ids are uint16

ChunkMaker = Callable[[int, int, int], "object"]  # (start, stop, frame) -> Pattern


def one_revolution(spec) -> float:
    """Seconds a frame lasts: ``1 / rotation_hz``."""
    return 1.0 / spec.rotation_hz


def no_rows(spec) -> np.ndarray:
    return np.zeros(0)


def no_changes(spec, section: dict, where: str) -> dict:
    return {}


def one_ring(spec) -> int:
    return 1


@dataclass(frozen=True)
class RayPattern:
    """A ray pattern's registry entry. Every callable takes the spec (``SensorSpec``) first.

    rays : ``rays(spec) -> chunk(start, stop, frame) -> Pattern``: rays ``start .. stop - 1`` of frame ``frame``
    count : ``count(spec) -> int`` rays of one frame, without generating them
    resolution : ``resolution(spec) -> (azimuth step, elevation step or None)`` in degrees, the
        spacing level-of-detail code follows (``None``: uneven rows; ``nan``: no such spacing)
    azimuth_step, elevation_step : degrees between columns and between evenly spaced rows (``None`` if uneven)
    elevations, azimuths : ``(rows,)`` and ``(columns,)`` degrees, in ring and firing order (empty without rows)
    check : ``check(spec, where)``: ``InputError`` naming the field the pattern cannot use
    derive : ``derive(spec, section, where) -> {field: value}`` the fields that follow from others
    frame_time : seconds one frame lasts
    rings : how many ring ids its rays carry
    image : True when its frames form a rows x columns image (range images, mirror-edge masks)
    per_frame : True when frame k's rays differ from frame 0's (a rosette continues where it stopped)
    density_key : ``density_key(spec) -> field`` most likely to blame for too many rays
    extent : ``extent(spec) -> (elevations, azimuths)`` degrees whose extremes a listing shows
        (``None``: :attr:`elevations` and :attr:`azimuths`)
    """

    rays: Callable[..., ChunkMaker]
    count: Callable[..., int]
    resolution: Callable[..., tuple]
    check: Callable[..., None]
    density_key: Callable[..., str]
    azimuth_step: Callable[..., float] = lambda spec: spec.horizontal_resolution_deg / spec.sampling_factor
    elevation_step: Callable[..., float | None] = lambda spec: None
    elevations: Callable[..., np.ndarray] = no_rows
    azimuths: Callable[..., np.ndarray] = no_rows
    derive: Callable[..., dict] = no_changes
    frame_time: Callable[..., float] = one_revolution
    rings: Callable[..., int] = one_ring
    image: bool = False
    per_frame: bool = False
    extent: Callable[..., tuple] | None = None


PATTERNS: Registry[RayPattern] = Registry("ray pattern", "sensor.pattern")


def register_pattern(name: str, pattern: RayPattern) -> RayPattern:
    """Make ``sensor.pattern: name`` fire the rays of ``pattern``."""
    return PATTERNS.register(name, pattern)


# ----------------------------------------------------------------------------- shared by the row-and-column patterns
def derive_columns(spec, section: dict, where: str, window: bool) -> dict:
    """``horizontal_resolution_deg`` from ``columns`` (a ``window`` spans both edges) or ``firing_rate_hz``;
    naming both a step and what derives it with values that disagree raises ``InputError``."""
    if spec.columns > 0 and spec.firing_rate_hz > 0:
        raise InputError(f"{where}.columns: give either columns or firing_rate_hz, not both")
    step = None
    if spec.columns > 0:
        lo, hi = spec.horizontal_fov_deg
        if window and spec.columns < 2:
            raise InputError(f"{where}.columns: a {hi - lo:g} deg window needs at least 2 columns (its two edges), got {spec.columns}")
        step = (hi - lo) / (spec.columns - 1 if window else spec.columns)  # a window's columns span it edge to edge
    elif spec.firing_rate_hz > 0 and spec.rotation_hz > 0:
        step = 360.0 * spec.rotation_hz / spec.firing_rate_hz
    if step is None or step <= 0:
        return {}
    given = section.get("horizontal_resolution_deg")
    if isinstance(given, (int, float)) and not math.isclose(float(given), step, rel_tol=1e-9, abs_tol=1e-12):
        driver = "columns" if spec.columns > 0 else "firing_rate_hz"
        raise InputError(f"{where}.horizontal_resolution_deg: {given} disagrees with {driver} (which gives {step:.6g} deg); give one of them")
    return {"horizontal_resolution_deg": step}


def derive_rows(spec, section: dict, where: str, rows: int | None, source: str) -> dict:
    """``channels`` from ``rows`` (counted from ``source``); a disagreeing ``channels`` raises ``InputError``."""
    if rows is None:
        return {}
    given = section.get("channels")
    if isinstance(given, int) and not isinstance(given, bool) and given != rows:
        if source == "elevations_deg":
            raise InputError(f"{where}.elevations_deg: lists {rows} angles for {given} channels")
        raise InputError(f"{where}.channels: {given} disagrees with vertical_resolution_deg (which gives {rows} rows); give one of them")
    return {"channels": rows}


def check_rows(spec, where: str) -> None:
    """Rows and the horizontal field of a pattern fired in rows and columns (each angle within -90..90: the fields' metadata)."""
    if spec.channels < 1:
        raise InputError(f"{where}.channels: must be >= 1, got {spec.channels}")
    if spec.channels > MAX_RINGS:
        key = "channels" if spec.vertical_resolution_deg <= 0 or spec.elevations_deg else "vertical_resolution_deg"
        if key != "channels" and spec.pattern == "terrestrial" and spec.sampling_factor != 1:
            key = "sampling_factor"
        raise InputError(f"{where}.{key}: gives {spec.channels} rows, more than the {MAX_RINGS} ring ids of uint16; coarsen it")
    if spec.elevations_deg and len(spec.elevations_deg) != spec.channels:
        raise InputError(f"{where}.elevations_deg: lists {len(spec.elevations_deg)} angles for {spec.channels} channels")
    if spec.vertical_fov_deg[0] > spec.vertical_fov_deg[1]:
        raise InputError(f"{where}.vertical_fov_deg: expected [min, max], got {list(spec.vertical_fov_deg)}")
    lo, hi = spec.horizontal_fov_deg
    if not lo < hi <= lo + 360:
        raise InputError(f"{where}.horizontal_fov_deg: expected [min, max] with min < max <= min + 360, got {[lo, hi]}")


def channels(spec) -> int:
    return spec.channels


def sampled_extent(spec) -> tuple[np.ndarray, np.ndarray]:
    """Elevations and azimuths (degrees) of every ray of frame 0, for patterns without rows."""
    entry = PATTERNS.get(spec.pattern)
    sample = entry.rays(spec)(0, entry.count(spec), 0).directions  # frame 0 whole (lidar.sensor.sensors.sensor_pattern)
    return np.degrees(np.arcsin(np.clip(sample[:, 2], -1, 1))), np.degrees(np.arctan2(sample[:, 1], sample[:, 0]))
