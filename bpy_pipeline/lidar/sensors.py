"""Sensor specifications, presets and their ray patterns (sensor frame: x forward, y left, z up).

A :class:`SensorSpec` says what a sensor fires; :func:`sensor_pattern` turns it into a
:class:`Pattern` of unit ray directions with the channel (ring) and firing time of each ray.
Presets live in ``sensors.yaml`` beside this file and are overridable field by field.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np
import yaml

from ..errors import InputError
from ..schema import from_dict

PRESETS_PATH = Path(__file__).with_name("sensors.yaml")
DEFAULT_PRESET = "vlp16"


@dataclass(frozen=True)
class SensorSpec:
    """What a sensor fires. Angles in degrees, ranges in metres, rates in Hz.

    ``name`` is the preset it started from (``preset`` in YAML; ``custom`` for none).
    ``spinning``: ``channels`` beams at ``elevations_deg`` (or spread uniformly over
    ``vertical_fov_deg`` when no table is given), swept in azimuth over ``horizontal_fov_deg``
    in steps of ``horizontal_resolution_deg``, one sweep per ``1 / rotation_hz`` seconds.
    Azimuth 0 is +x (forward) and grows towards +y (left).
    """

    name: str = field(default="custom", metadata={"key": "preset"})
    description: str = ""
    pattern: Literal["spinning"] = "spinning"
    channels: int = 16
    vertical_fov_deg: tuple[float, float] = (-15.0, 15.0)
    elevations_deg: list[float] = field(default_factory=list)
    horizontal_fov_deg: tuple[float, float] = (-180.0, 180.0)
    horizontal_resolution_deg: float = 0.2
    rotation_hz: float = 10.0
    min_range: float = 0.5
    max_range: float = 100.0


@dataclass(frozen=True)
class Pattern:
    """The rays of one frame.

    directions : (n, 3) float64 unit vectors, sensor frame
    ring : (n,) uint16 channel index
    time : (n,) float64 seconds from frame start at which each ray fires
    """

    directions: np.ndarray
    ring: np.ndarray
    time: np.ndarray

    def __len__(self) -> int:
        return len(self.directions)


@lru_cache(maxsize=1)
def presets() -> dict[str, dict]:
    """Preset name -> field mapping, as read from ``sensors.yaml``."""
    return yaml.safe_load(PRESETS_PATH.read_text())


def resolve_sensor(section: dict, where: str = "sensor") -> SensorSpec:
    """A preset (``section["preset"]``) with the other keys of ``section`` overriding its fields."""
    section = dict(section or {})
    name = section.setdefault("preset", DEFAULT_PRESET)
    if name == "custom":
        base = {}
    elif name in presets():
        base = presets()[name]
    else:
        raise InputError(f"{where}.preset: unknown sensor {name!r}; allowed: custom, {', '.join(presets())}")
    spec = from_dict(SensorSpec, base | section, where)
    check_sensor(spec, where)
    return spec


def check_sensor(spec: SensorSpec, where: str = "sensor") -> None:
    """``InputError`` naming the field when a spec cannot describe a real sensor."""
    if not 0 <= spec.min_range < spec.max_range:
        raise InputError(f"{where}.min_range: must be >= 0 and below {where}.max_range ({spec.min_range} >= {spec.max_range})")
    if spec.channels < 1:
        raise InputError(f"{where}.channels: must be >= 1, got {spec.channels}")
    if spec.elevations_deg and len(spec.elevations_deg) != spec.channels:
        raise InputError(f"{where}.elevations_deg: lists {len(spec.elevations_deg)} angles for {spec.channels} channels")
    if not all(-90 <= e <= 90 for e in (*spec.elevations_deg, *spec.vertical_fov_deg)):
        raise InputError(f"{where}.vertical_fov_deg: elevations must lie in -90..90 degrees")
    if spec.vertical_fov_deg[0] > spec.vertical_fov_deg[1]:
        raise InputError(f"{where}.vertical_fov_deg: expected [min, max], got {list(spec.vertical_fov_deg)}")
    lo, hi = spec.horizontal_fov_deg
    if not lo < hi <= lo + 360:
        raise InputError(f"{where}.horizontal_fov_deg: expected [min, max] with min < max <= min + 360, got {[lo, hi]}")
    if not 0 < spec.horizontal_resolution_deg <= hi - lo:
        raise InputError(f"{where}.horizontal_resolution_deg: must lie in (0, {hi - lo}], got {spec.horizontal_resolution_deg}")
    if spec.rotation_hz <= 0:
        raise InputError(f"{where}.rotation_hz: must be > 0, got {spec.rotation_hz}")


def elevations(spec: SensorSpec) -> np.ndarray:
    """``(channels,)`` float64 beam elevations in degrees, ring 0 first (lowest for uniform fans)."""
    if spec.elevations_deg:
        return np.asarray(spec.elevations_deg, float)
    return np.linspace(spec.vertical_fov_deg[0], spec.vertical_fov_deg[1], spec.channels)


def azimuths(spec: SensorSpec) -> np.ndarray:
    """``(columns,)`` float64 azimuths in degrees, in firing order."""
    lo, hi = spec.horizontal_fov_deg
    full_circle = np.isclose(hi - lo, 360.0)
    count = int(round((hi - lo) / spec.horizontal_resolution_deg)) + (0 if full_circle else 1)
    return lo + np.arange(count) * spec.horizontal_resolution_deg


def spherical_directions(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """``(n, 3)`` unit vectors for matching ``(n,)`` azimuths and elevations in degrees."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def sensor_pattern(spec: SensorSpec) -> Pattern:
    """All rays of one frame, column by column (every channel of a column fires together)."""
    el = elevations(spec)
    az = azimuths(spec)
    column_time = np.arange(len(az)) / (len(az) * spec.rotation_hz) * ((spec.horizontal_fov_deg[1] - spec.horizontal_fov_deg[0]) / 360.0)
    az_grid, el_grid = np.meshgrid(az, el, indexing="ij")  # (columns, channels)
    directions = spherical_directions(az_grid.ravel(), el_grid.ravel())
    ring = np.tile(np.arange(len(el), dtype=np.uint16), len(az))
    time = np.repeat(column_time, len(el))
    return Pattern(directions, ring, time)


def spec_summary(spec: SensorSpec) -> dict:
    """Key figures of a spec for listings and the manifest."""
    el = elevations(spec)
    return {
        "name": spec.name,
        "pattern": spec.pattern,
        "channels": spec.channels,
        "elevation_deg": [round(float(el.min()), 3), round(float(el.max()), 3)],
        "columns": len(azimuths(spec)),
        "rays_per_frame": len(azimuths(spec)) * spec.channels,
        "rotation_hz": spec.rotation_hz,
        "range_m": [spec.min_range, spec.max_range],
        **({"description": spec.description} if spec.description else {}),
    }


def replace(spec: SensorSpec, **changes) -> SensorSpec:
    """A copy of ``spec`` with ``changes`` applied and checked."""
    new = dataclasses.replace(spec, **changes)
    check_sensor(new)
    return new
