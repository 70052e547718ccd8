"""Sensor specifications, presets and their ray patterns (sensor frame: x forward, y left, z up).

A :class:`SensorSpec` says what a sensor fires; :func:`sensor_pattern` turns it into a
:class:`Pattern` of unit ray directions with the channel (ring) and firing time of each ray,
and :func:`iter_pattern` yields the same rays in bounded chunks (a terrestrial scan has
tens of millions). Presets live in ``sensors.yaml`` beside this file and are overridable
field by field (:func:`resolve_sensor`).

Patterns (``SensorSpec.pattern``) are registered in :mod:`bpy_pipeline.lidar.sensor.patterns`, one module
each (spinning and terrestrial scanners, pinhole and grid flash cameras, Risley-prism rosettes,
directions from a file); this module holds the presets and the spec, and asks the spec's pattern
for everything that differs between patterns.

Ring ids: spinning and terrestrial sensors count rings from the lowest beam up (as the
Velodyne drivers and nuScenes do) unless an explicit ``elevations_deg`` table gives another
order; flash cameras use the image row, 0 at the top.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterator, Literal

import numpy as np

from ...errors import InputError
from ...schema import from_dict, key_of, meta
from .patterns import PATTERNS
from .patterns.base import derive_rows
from .rays import Pattern
from ...yaml_text import load_yaml

PRESETS_PATH = Path(__file__).with_name("sensors.yaml")
DEFAULT_PRESET = "vlp16"
MAX_RAYS = 1_000_000_000  # per frame; beyond this a pattern is a typo, not a sensor
FLASH_PATTERNS = ("pinhole", "grid")  # the patterns of flash cameras: one image a frame, every pixel at once


@dataclass(frozen=True)
class SensorSpec:
    """What a sensor fires. Angles in degrees, ranges and heights in metres, rates in Hz.

    ``name`` is the preset it started from (``preset`` in YAML; ``custom`` for none).

    Rows (beams, image rows), for ``spinning``, ``terrestrial``, ``pinhole`` and ``grid``:
    ``channels`` of them, at ``elevations_deg`` when that table is given, else spread over
    ``vertical_fov_deg`` (both ends included for spinning and terrestrial sensors, pixel
    centres for ``grid``; ``pinhole`` derives its vertical fov from ``fy = fx``).
    ``vertical_resolution_deg`` > 0 (spinning, terrestrial) sets the row step instead and
    ``channels`` follows from it.

    Columns, over ``horizontal_fov_deg`` (azimuth 0 is +x, growing towards +y): one every
    ``horizontal_resolution_deg``, which ``columns`` > 0 (columns per sweep or image width)
    or ``firing_rate_hz`` > 0 (columns fired per second: the step then follows the spin,
    ``360 * rotation_hz / firing_rate_hz``) derive instead. A full circle fires the columns
    of one revolution, a partial fov includes both edges. ``spin`` is the direction of the
    sweep seen from above: ``cw`` (azimuth decreasing from the fov's upper edge, as Velodyne,
    Hesai and Ouster sensors turn) or ``ccw`` (increasing from its lower edge).
    ``sampling_factor`` (spinning: azimuth only; terrestrial: both axes) divides the angular
    steps: 1 is the nominal resolution, 1.5 gives 1.5x the rays per axis, 0.5 half.

    ``rotation_hz``: sweeps (spinning, terrestrial) or frames (pinhole, grid, file) per second.
    ``mount_height``: the optical centre sits this far above the configured sensor
    position (a tripod over its station point; :func:`mount_offset`).
    ``rotor_hz``, ``deflection_deg``, ``point_rate_hz``, ``frame_time_s``: ``rosette`` only
    (``frame_time_s`` 0 means ``1 / rotation_hz``). ``rays_file``: ``file`` only.
    Fields a pattern does not use are ignored by it.
    """

    name: str = field(default="custom", metadata={"key": "preset"})
    description: str = ""
    pattern: str = "spinning"  # a name of lidar/sensor/patterns (PATTERNS)
    channels: int = field(default=16, metadata=meta(""))
    vertical_fov_deg: tuple[float, float] = field(default=(-15.0, 15.0), metadata=meta("deg", -90, 90))
    elevations_deg: list[float] = field(default_factory=list, metadata=meta("deg", -90, 90))
    horizontal_fov_deg: tuple[float, float] = field(default=(-180.0, 180.0), metadata=meta("deg"))
    horizontal_resolution_deg: float = field(default=0.2, metadata=meta("deg"))
    rotation_hz: float = field(default=10.0, metadata=meta("Hz", low=0, low_open=True))
    min_range: float = field(default=0.5, metadata=meta("m"))
    max_range: float = field(default=100.0, metadata=meta("m"))
    vertical_resolution_deg: float = field(default=0.0, metadata=meta("deg", low=0, help="0: from channels"))
    columns: int = field(default=0, metadata=meta("", low=0, help="0: from horizontal_resolution_deg"))
    firing_rate_hz: float = field(default=0.0, metadata=meta("Hz", low=0, help="0: from horizontal_resolution_deg"))
    sampling_factor: float = field(default=1.0, metadata=meta("", low=0, low_open=True, help="1: the nominal resolution"))
    spin: Literal["ccw", "cw"] = "ccw"
    mount_height: float = field(default=0.0, metadata=meta("m", low=0, help="above the station point"))
    rotor_hz: tuple[float, float] = field(default=(121.57, -77.73), metadata=meta("Hz"))
    deflection_deg: tuple[float, float] = field(default=(9.6, 9.6), metadata=meta("deg"))
    point_rate_hz: float = field(default=100000.0, metadata=meta("Hz", low=0, low_open=True))
    frame_time_s: float = field(default=0.0, metadata=meta("s", low=0, help="0: 1 / rotation_hz"))
    rays_file: str = ""


# ----------------------------------------------------------------------------- presets and overrides
# a preset's effects profile, where its numbers come from, the real sensor's return modes; not SensorSpec fields
PROFILE_KEYS = ("effects", "sources", "return_modes")


@lru_cache(maxsize=1)
def _presets_file() -> dict[str, dict]:
    return load_yaml(PRESETS_PATH.read_text())


def presets() -> dict[str, dict]:
    """Preset name -> SensorSpec field mapping, as read from ``sensors.yaml`` (without the profile keys)."""
    return {name: {k: v for k, v in fields.items() if k not in PROFILE_KEYS} for name, fields in _presets_file().items()}


def preset_effects(name: str) -> dict:
    """The effects profile of preset ``name`` (an ``effects`` section as in a config; ``{}`` for ``custom``).

    What the sensor adds to the ideal scan: range noise, ray drop, intensity scale and steps, fitted
    to a real scan of that sensor or taken from its datasheet (:func:`preset_sources` says which).
    A copy: changing it changes nothing else.
    """
    return copy.deepcopy(_presets_file().get(name, {}).get("effects") or {})


def preset_sources(name: str) -> dict[str, str]:
    """Dotted effects key (``noise.sigma``) -> where the profile's number comes from (a fit, a datasheet)."""
    return dict(_presets_file().get(name, {}).get("sources") or {})


# Fields that decide the same quantity: when an override names one of a group, the preset's
# other members of that group stop applying (``vertical_fov_deg`` also replaces a preset's
# elevation table by a uniform fan of the same channel count).
_AZIMUTH_GROUP = ("horizontal_resolution_deg", "columns", "firing_rate_hz")
_ROW_GROUP = ("channels", "elevations_deg", "vertical_resolution_deg")
_UNSET = {"columns": 0, "firing_rate_hz": 0.0, "elevations_deg": [], "vertical_resolution_deg": 0.0}


def resolve_sensor(section: dict, where: str = "sensor") -> SensorSpec:
    """A preset (``section["preset"]``) with the other keys of ``section`` overriding its fields.

    Derived fields are recomputed, so a spec never carries a stale value: ``channels`` from an
    elevation table or ``vertical_resolution_deg``, ``horizontal_resolution_deg`` from
    ``columns`` or ``firing_rate_hz``. Naming both a derived field and what derives it with
    values that disagree raises ``InputError``.
    """
    section = dict(section or {})
    name = section.setdefault("preset", DEFAULT_PRESET)
    if name == "custom":
        base = {}
    elif isinstance(name, str) and name in presets():
        base = presets()[name]
    else:
        raise InputError(f"{where}.preset: unknown sensor {name!r}; allowed: custom, {', '.join(presets())}")
    return _build(base, section, where)


def spec_fields(spec: SensorSpec) -> dict:
    """The fields of ``spec`` as plain YAML-ready data, keyed as in YAML (``preset`` for ``name``)."""

    def plain(value):
        return [plain(v) for v in value] if isinstance(value, (list, tuple)) else value

    return {key_of(f): plain(getattr(spec, f.name)) for f in dataclasses.fields(SensorSpec)}


def _build(base: dict, section: dict, where: str) -> SensorSpec:
    merged = dict(base) | section
    for group in (_AZIMUTH_GROUP, _ROW_GROUP):
        if any(k in section for k in group):
            for k in group:
                if k not in section and k in _UNSET:
                    merged[k] = _UNSET[k]
    if "vertical_fov_deg" in section and "elevations_deg" not in section:
        merged["elevations_deg"] = []
    spec = from_dict(SensorSpec, merged, where)
    spec = _derive(spec, section, where)
    check_sensor(spec, where)
    return spec


def _derive(spec: SensorSpec, section: dict, where: str) -> SensorSpec:
    """The fields that follow from others: an elevation table's rows, then the pattern's own."""
    pattern = PATTERNS.get(spec.pattern, f"{where}.pattern")
    changes = derive_rows(spec, section, where, len(spec.elevations_deg), "elevations_deg") if spec.elevations_deg else {}
    changes |= pattern.derive(spec, section, where)
    return dataclasses.replace(spec, **changes) if changes else spec


def check_sensor(spec: SensorSpec, where: str = "sensor") -> None:
    """``InputError`` naming the field when a spec cannot describe a real sensor (beyond its fields' ranges, the schema's)."""
    pattern = PATTERNS.get(spec.pattern, f"{where}.pattern")
    if not 0 <= spec.min_range < spec.max_range:
        raise InputError(f"{where}.min_range: must be >= 0 and below {where}.max_range ({spec.min_range} >= {spec.max_range})")
    pattern.check(spec, where)
    rays = ray_count(spec)
    if rays < 1:
        raise InputError(f"{where}.pattern: the {spec.pattern} pattern fires no rays with these fields")
    if rays > MAX_RAYS:
        raise InputError(f"{where}.{pattern.density_key(spec)}: gives {rays:,} rays a frame, more than {MAX_RAYS:,}; coarsen it")


def check_flash(spec: SensorSpec, where: str) -> None:
    """``InputError`` naming ``where`` unless ``spec`` is a flash camera (a pinhole or grid image)."""
    if spec.pattern not in FLASH_PATTERNS:
        raise InputError(f"{where}: needs a flash camera (pattern {' or '.join(FLASH_PATTERNS)}), not the {spec.pattern} pattern")


# ----------------------------------------------------------------------------- geometry of a spec
def frame_time(spec: SensorSpec) -> float:
    """Seconds one frame lasts (``1 / rotation_hz``; a rosette's ``frame_time_s`` when set)."""
    return PATTERNS.get(spec.pattern).frame_time(spec)


def azimuth_step(spec: SensorSpec) -> float:
    """Degrees between successive columns as fired (after ``sampling_factor``)."""
    return PATTERNS.get(spec.pattern).azimuth_step(spec)


def elevation_step(spec: SensorSpec) -> float | None:
    """Degrees between rows where they are evenly spaced (after ``sampling_factor``), else ``None``."""
    return PATTERNS.get(spec.pattern).elevation_step(spec)


def angular_resolution(spec: SensorSpec) -> tuple[float, float | None]:
    """``(azimuth step, elevation step)`` in degrees, the spacing level-of-detail code should follow.

    A pinhole camera reports its pitch at the image centre, a rosette its mean spacing over a
    frame (``sqrt(fov solid angle / rays)``), a file ``(nan, nan)``; uneven tables give ``None``.
    """
    return PATTERNS.get(spec.pattern).resolution(spec)


def elevations(spec: SensorSpec) -> np.ndarray:
    """``(rows,)`` float64 elevations in degrees, in ring order (empty for patterns without rows)."""
    return PATTERNS.get(spec.pattern).elevations(spec)


def azimuths(spec: SensorSpec) -> np.ndarray:
    """``(columns,)`` float64 azimuths in degrees, in firing order (cameras: image columns, left first)."""
    return PATTERNS.get(spec.pattern).azimuths(spec)


def ray_count(spec: SensorSpec) -> int:
    """Rays of one frame, without generating them."""
    return PATTERNS.get(spec.pattern).count(spec)


def rings(spec: SensorSpec) -> int:
    """How many ring ids the sensor's rays carry."""
    return PATTERNS.get(spec.pattern).rings(spec)


def spherical_directions(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """``(n, 3)`` unit vectors for matching ``(n,)`` azimuths and elevations in degrees."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def mount_offset(spec: SensorSpec) -> np.ndarray:
    """``(3,)`` float64 world offset of the optical centre from the configured position (``[0, 0, mount_height]``)."""
    return np.array([0.0, 0.0, spec.mount_height])


def sensor_pattern(spec: SensorSpec, frame: int = 0) -> Pattern:
    """All rays of one frame (``frame`` matters only to non-repetitive patterns: rosettes).

    Filled chunk by chunk into preallocated arrays, so the peak memory is the result's own
    (34 bytes a ray) plus one chunk.
    """
    total = ray_count(spec)
    out = Pattern(np.empty((total, 3)), np.empty(total, np.uint16), np.empty(total))
    start = 0
    for part in iter_pattern(spec, _FILL_CHUNK, frame):
        stop = start + len(part)
        out.directions[start:stop], out.ring[start:stop], out.time[start:stop] = part.directions, part.ring, part.time
        start = stop
    return out


_FILL_CHUNK = 1 << 20


def iter_pattern(spec: SensorSpec, chunk_rays: int, frame: int = 0) -> Iterator[Pattern]:
    """The rays of :func:`sensor_pattern`, same order and values, in chunks of at most ``chunk_rays``.

    Memory stays bounded by the chunk whatever the scan's size (a 0.05 deg terrestrial scan
    is 23 million rays).
    """
    if chunk_rays < 1:
        raise ValueError(f"chunk_rays must be >= 1, got {chunk_rays}")
    chunk = PATTERNS.get(spec.pattern).rays(spec)
    total = ray_count(spec)
    for start in range(0, total, chunk_rays):
        yield chunk(start, min(start + chunk_rays, total), frame)


def spec_summary(spec: SensorSpec) -> dict:
    """Key figures of a spec for listings and the manifest (plain JSON-ready data)."""
    pattern = PATTERNS.get(spec.pattern)
    rays, channels = ray_count(spec), pattern.rings(spec)
    columns = len(pattern.azimuths(spec)) or rays
    el, az = (pattern.extent or (lambda s: (pattern.elevations(s), pattern.azimuths(s))))(spec)
    h_step, v_step = angular_resolution(spec)
    period = frame_time(spec)
    summary = {
        "name": spec.name,
        "pattern": spec.pattern,
        "channels": channels,
        "elevation_deg": [round(float(el.min()), 3), round(float(el.max()), 3)],
        "azimuth_deg": [round(float(az.min()), 3), round(float(az.max()), 3)],
        "columns": columns,
        "rays_per_frame": rays,
        "azimuth_step_deg": None if math.isnan(h_step) else round(h_step, 6),
        "elevation_step_deg": None if v_step is None or math.isnan(v_step) else round(v_step, 6),
        "rotation_hz": spec.rotation_hz,
        "frame_time_s": period,
        "rays_per_second": round(rays / period, 3),
        "range_m": [spec.min_range, spec.max_range],
    }
    if spec.mount_height:
        summary["mount_height_m"] = spec.mount_height
    if spec.description:
        summary["description"] = spec.description
    return summary
