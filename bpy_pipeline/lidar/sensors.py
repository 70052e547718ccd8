"""Sensor specifications, presets and their ray patterns (sensor frame: x forward, y left, z up).

A :class:`SensorSpec` says what a sensor fires; :func:`sensor_pattern` turns it into a
:class:`Pattern` of unit ray directions with the channel (ring) and firing time of each ray,
and :func:`iter_pattern` yields the same rays in bounded chunks (a terrestrial scan has
tens of millions). Presets live in ``sensors.yaml`` beside this file and are overridable
field by field (:func:`resolve_sensor`).

Patterns (``SensorSpec.pattern``):

``spinning``
    A rotating multi-beam lidar (Velodyne, Hesai, Ouster): every channel of a column fires
    together, columns fire one after another as the head turns; a column's ``time`` is its
    azimuth offset from the start of the sweep over ``360 * rotation_hz``.
``terrestrial``
    A static terrestrial laser scanner: a mirror sweeps each vertical profile (the fast
    axis) while the head turns once per ``1 / rotation_hz`` seconds (the slow axis), so
    the rays of a column fire one after another, bottom to top.
``pinhole`` / ``grid``
    A flash (focal-plane array) camera of ``columns`` x ``channels`` pixels; every pixel
    fires at ``t = 0``. ``pinhole`` puts pixel centres on a flat image plane
    (``fx = fy = columns / (2 tan(hfov / 2))``, as CARLA's depth cameras do), so the angle
    per pixel shrinks towards the edges and the vertical fov follows from ``fy``;
    ``grid`` spaces pixel centres uniformly in azimuth and elevation.
``rosette``
    Two counter-rotating Risley prisms (Livox): the beam's deflection from +x is the sum of
    two vectors of ``deflection_deg`` turning at ``rotor_hz``; one shot every
    ``1 / point_rate_hz`` seconds over ``frame_time_s``. The pattern never repeats within
    a run: frame ``k`` continues where frame ``k - 1`` stopped (``frame`` argument).
``file``
    User-defined directions from ``rays_file`` (an ``(n, 3)`` ``.npy``), normalised on load;
    ring 0 and time 0 for every ray (the file says nothing about either).

Ring ids: spinning and terrestrial sensors count rings from the lowest beam up (as the
Velodyne drivers and nuScenes do) unless an explicit ``elevations_deg`` table gives another
order; flash cameras use the image row, 0 at the top.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Iterable, Iterator, Literal

import numpy as np
import yaml

from ..errors import InputError
from ..schema import from_dict, key_of

PRESETS_PATH = Path(__file__).with_name("sensors.yaml")
DEFAULT_PRESET = "vlp16"
PATTERNS = ("spinning", "terrestrial", "pinhole", "grid", "rosette", "file")
MAX_RAYS = 1_000_000_000  # per frame; beyond this a pattern is a typo, not a sensor
MAX_RINGS = 65536  # ring ids are uint16


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
    pattern: Literal["spinning", "terrestrial", "pinhole", "grid", "rosette", "file"] = "spinning"
    channels: int = 16
    vertical_fov_deg: tuple[float, float] = (-15.0, 15.0)
    elevations_deg: list[float] = field(default_factory=list)
    horizontal_fov_deg: tuple[float, float] = (-180.0, 180.0)
    horizontal_resolution_deg: float = 0.2
    rotation_hz: float = 10.0
    min_range: float = 0.5
    max_range: float = 100.0
    vertical_resolution_deg: float = 0.0
    columns: int = 0
    firing_rate_hz: float = 0.0
    sampling_factor: float = 1.0
    spin: Literal["ccw", "cw"] = "ccw"
    mount_height: float = 0.0
    rotor_hz: tuple[float, float] = (121.57, -77.73)
    deflection_deg: tuple[float, float] = (9.6, 9.6)
    point_rate_hz: float = 100000.0
    frame_time_s: float = 0.0
    rays_file: str = ""


@dataclass(frozen=True)
class Pattern:
    """The rays of one frame.

    directions : (n, 3) float64 unit vectors, sensor frame
    ring : (n,) uint16 channel index
    time : (n,) float64 seconds from frame start at which each ray fires
    origins : (n, 3) float64 ray origins, sensor frame, metres; ``None`` when every ray leaves
        the sensor's origin (a sensor looking through its own mirrors has per-ray origins)
    """

    directions: np.ndarray
    ring: np.ndarray
    time: np.ndarray
    origins: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.directions)


def pattern_chunks(patterns: Pattern | Iterable[Pattern], chunk_rays: int) -> Iterator[Pattern]:
    """One pattern, or consecutive chunks of one, cut into chunks of at most ``chunk_rays`` rays, in order."""
    for pattern in [patterns] if isinstance(patterns, Pattern) else patterns:
        for start in range(0, len(pattern), chunk_rays):
            s = slice(start, start + chunk_rays)
            yield Pattern(pattern.directions[s], pattern.ring[s], pattern.time[s], None if pattern.origins is None else pattern.origins[s])


# ----------------------------------------------------------------------------- presets and overrides
@lru_cache(maxsize=1)
def presets() -> dict[str, dict]:
    """Preset name -> field mapping, as read from ``sensors.yaml``."""
    return yaml.safe_load(PRESETS_PATH.read_text())


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


def replace(spec: SensorSpec, **changes) -> SensorSpec:
    """A copy of ``spec`` with ``changes`` (Python field names) applied, derived fields redone, checked."""
    keys = {f.name: key_of(f) for f in dataclasses.fields(SensorSpec)}
    unknown = sorted(set(changes) - set(keys))
    if unknown:
        raise InputError(f"sensor.{unknown[0]}: unknown field; allowed: {', '.join(keys)}")
    return _build(spec_fields(spec), {keys[k]: v for k, v in changes.items()}, "sensor")


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


def _disagree(a: float, b: float) -> bool:
    return not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


def _derive(spec: SensorSpec, section: dict, where: str) -> SensorSpec:
    changes = {}
    if spec.pattern not in ("rosette", "file"):
        if spec.columns > 0 and spec.firing_rate_hz > 0:
            raise InputError(f"{where}.columns: give either columns or firing_rate_hz, not both")
        step = None
        if spec.columns > 0:
            lo, hi = spec.horizontal_fov_deg
            window = spec.pattern in ("spinning", "terrestrial") and not math.isclose(hi - lo, 360.0)
            if window and spec.columns < 2:
                raise InputError(f"{where}.columns: a {hi - lo:g} deg window needs at least 2 columns (its two edges), got {spec.columns}")
            step = (hi - lo) / (spec.columns - 1 if window else spec.columns)  # a window's columns span it edge to edge
        elif spec.firing_rate_hz > 0 and spec.rotation_hz > 0:
            step = 360.0 * spec.rotation_hz / spec.firing_rate_hz
        if step is not None and step > 0:
            given = section.get("horizontal_resolution_deg")
            if isinstance(given, (int, float)) and _disagree(float(given), step):
                driver = "columns" if spec.columns > 0 else "firing_rate_hz"
                raise InputError(
                    f"{where}.horizontal_resolution_deg: {given} disagrees with {driver} (which gives {step:.6g} deg); give one of them"
                )
            changes["horizontal_resolution_deg"] = step
    rows = None
    if spec.elevations_deg:
        rows = len(spec.elevations_deg)
        source = "elevations_deg"
    elif spec.pattern in ("spinning", "terrestrial") and spec.vertical_resolution_deg > 0 and spec.sampling_factor > 0:
        lo, hi = spec.vertical_fov_deg
        step = spec.vertical_resolution_deg / (spec.sampling_factor if spec.pattern == "terrestrial" else 1.0)
        rows = int(math.floor((hi - lo) / step + 1e-6)) + 1 if hi >= lo else 0
        source = "vertical_resolution_deg"
    if rows is not None:
        given = section.get("channels")
        if isinstance(given, int) and not isinstance(given, bool) and given != rows:
            if source == "elevations_deg":
                raise InputError(f"{where}.elevations_deg: lists {rows} angles for {given} channels")
            raise InputError(f"{where}.channels: {given} disagrees with vertical_resolution_deg (which gives {rows} rows); give one of them")
        changes["channels"] = rows
    return dataclasses.replace(spec, **changes) if changes else spec


def check_sensor(spec: SensorSpec, where: str = "sensor") -> None:
    """``InputError`` naming the field when a spec cannot describe a real sensor."""
    if not 0 <= spec.min_range < spec.max_range:
        raise InputError(f"{where}.min_range: must be >= 0 and below {where}.max_range ({spec.min_range} >= {spec.max_range})")
    if spec.rotation_hz <= 0:
        raise InputError(f"{where}.rotation_hz: must be > 0, got {spec.rotation_hz}")
    if spec.mount_height < 0:
        raise InputError(f"{where}.mount_height: must be >= 0 (metres above the station point), got {spec.mount_height}")
    if spec.sampling_factor <= 0:
        raise InputError(f"{where}.sampling_factor: must be > 0 (1 = nominal resolution), got {spec.sampling_factor}")
    if spec.columns < 0:
        raise InputError(f"{where}.columns: must be >= 0 (0 = from horizontal_resolution_deg), got {spec.columns}")
    if spec.firing_rate_hz < 0:
        raise InputError(f"{where}.firing_rate_hz: must be >= 0 (0 = from horizontal_resolution_deg), got {spec.firing_rate_hz}")
    if spec.vertical_resolution_deg < 0:
        raise InputError(f"{where}.vertical_resolution_deg: must be >= 0 (0 = from channels), got {spec.vertical_resolution_deg}")
    if spec.frame_time_s < 0:
        raise InputError(f"{where}.frame_time_s: must be >= 0 (0 = 1 / rotation_hz), got {spec.frame_time_s}")
    if spec.pattern in ("spinning", "terrestrial", "grid", "pinhole"):
        _check_grid(spec, where)
    elif spec.pattern == "rosette":
        d1, d2 = spec.deflection_deg
        if d1 < 0 or d2 < 0 or not 0 < d1 + d2 <= 90:
            raise InputError(f"{where}.deflection_deg: two angles >= 0 with 0 < sum <= 90, got {list(spec.deflection_deg)}")
        if spec.point_rate_hz <= 0:
            raise InputError(f"{where}.point_rate_hz: must be > 0, got {spec.point_rate_hz}")
    elif spec.pattern == "file":
        load_rays(spec.rays_file, f"{where}.rays_file")
    rays = ray_count(spec)
    if rays < 1:
        raise InputError(f"{where}.pattern: the {spec.pattern} pattern fires no rays with these fields")
    if rays > MAX_RAYS:
        raise InputError(f"{where}.{_density_key(spec)}: gives {rays:,} rays a frame, more than {MAX_RAYS:,}; coarsen it")


def _density_key(spec: SensorSpec) -> str:
    """The field most likely to blame for too many rays or rows."""
    if spec.pattern in ("spinning", "terrestrial") and spec.sampling_factor != 1:
        return "sampling_factor"
    return {"pinhole": "columns", "grid": "columns", "rosette": "point_rate_hz"}.get(spec.pattern, "horizontal_resolution_deg")


def _check_grid(spec: SensorSpec, where: str) -> None:
    if spec.channels < 1:
        raise InputError(f"{where}.channels: must be >= 1, got {spec.channels}")
    if spec.channels > MAX_RINGS:
        key = "channels" if spec.vertical_resolution_deg <= 0 or spec.elevations_deg else "vertical_resolution_deg"
        if key != "channels" and spec.pattern == "terrestrial" and spec.sampling_factor != 1:
            key = "sampling_factor"
        raise InputError(f"{where}.{key}: gives {spec.channels} rows, more than the {MAX_RINGS} ring ids of uint16; coarsen it")
    if spec.elevations_deg and len(spec.elevations_deg) != spec.channels:
        raise InputError(f"{where}.elevations_deg: lists {len(spec.elevations_deg)} angles for {spec.channels} channels")
    if not all(-90 <= e <= 90 for e in spec.elevations_deg):
        raise InputError(f"{where}.elevations_deg: elevations must lie in -90..90 degrees")
    if not all(-90 <= e <= 90 for e in spec.vertical_fov_deg):
        raise InputError(f"{where}.vertical_fov_deg: elevations must lie in -90..90 degrees")
    if spec.vertical_fov_deg[0] > spec.vertical_fov_deg[1]:
        raise InputError(f"{where}.vertical_fov_deg: expected [min, max], got {list(spec.vertical_fov_deg)}")
    lo, hi = spec.horizontal_fov_deg
    if not lo < hi <= lo + 360:
        raise InputError(f"{where}.horizontal_fov_deg: expected [min, max] with min < max <= min + 360, got {[lo, hi]}")
    if spec.pattern in ("pinhole", "grid"):
        if spec.columns < 1:
            raise InputError(f"{where}.columns: a {spec.pattern} camera needs its image width in pixels (>= 1), got {spec.columns}")
        if spec.pattern == "pinhole" and (hi - lo >= 180 or not math.isclose(lo, -hi, abs_tol=1e-9)):
            raise InputError(f"{where}.horizontal_fov_deg: a pinhole camera needs [-a, a] with a < 90, got {[lo, hi]}; turn it with sensor.rotation_deg")
        if spec.pattern == "grid" and spec.vertical_fov_deg[0] >= spec.vertical_fov_deg[1]:
            raise InputError(f"{where}.vertical_fov_deg: a grid camera needs min < max, got {list(spec.vertical_fov_deg)}")
        return
    if not 0 < spec.horizontal_resolution_deg <= hi - lo:
        raise InputError(f"{where}.horizontal_resolution_deg: must lie in (0, {hi - lo}], got {spec.horizontal_resolution_deg}")


def load_numeric_npy(path, where: str, kinds: str, expected: str) -> np.ndarray:
    """An array from an ``.npy`` file whose dtype kind is one of ``kinds``; ``InputError`` naming ``where`` and the file."""
    try:
        array = np.load(path, allow_pickle=False)
    except OSError as err:
        raise InputError(f"{where}: cannot read {path} ({err.strerror or err})") from None
    except ValueError:
        raise InputError(f"{where}: {path} is not a numeric .npy array") from None
    if not isinstance(array, np.ndarray) or array.dtype.kind not in kinds:
        raise InputError(f"{where}: {path} holds {getattr(array, 'dtype', type(array).__name__)}, expected {expected}")
    return array


def load_rays(path: str, where: str = "sensor.rays_file") -> np.ndarray:
    """``(n, 3)`` float64 unit directions from an ``.npy`` file; ``InputError`` naming ``where`` and the file."""
    if not path:
        raise InputError(f"{where}: the file pattern needs the path of an (n, 3) .npy of ray directions")
    rays = load_numeric_npy(path, where, "iuf", "numbers")
    if rays.ndim != 2 or rays.shape[1] != 3:
        raise InputError(f"{where}: {path} has shape {rays.shape}, expected (n, 3) ray directions")
    if len(rays) == 0:
        raise InputError(f"{where}: {path} holds no rays")
    rays = rays.astype(np.float64)
    finite = np.isfinite(rays).all(axis=1)
    if not finite.all():
        raise InputError(f"{where}: {path} row {int(np.argmin(finite))} is not finite")
    norm = np.linalg.norm(rays, axis=1)
    if not (norm > 0).all():
        raise InputError(f"{where}: {path} row {int(np.argmin(norm > 0))} has zero length and names no direction")
    return rays / norm[:, None]


# ----------------------------------------------------------------------------- geometry of a spec
def frame_time(spec: SensorSpec) -> float:
    """Seconds one frame lasts: ``frame_time_s`` when set (rosette), else ``1 / rotation_hz``."""
    if spec.pattern == "rosette" and spec.frame_time_s > 0:
        return spec.frame_time_s
    return 1.0 / spec.rotation_hz


def azimuth_step(spec: SensorSpec) -> float:
    """Degrees between successive columns as fired (after ``sampling_factor``)."""
    if spec.pattern in ("pinhole", "grid"):
        lo, hi = spec.horizontal_fov_deg
        return (hi - lo) / spec.columns
    return spec.horizontal_resolution_deg / spec.sampling_factor


def elevation_step(spec: SensorSpec) -> float | None:
    """Degrees between rows where they are evenly spaced (after ``sampling_factor``), else ``None``."""
    if spec.pattern in ("spinning", "terrestrial") and not spec.elevations_deg:
        if spec.vertical_resolution_deg > 0:
            return spec.vertical_resolution_deg / (spec.sampling_factor if spec.pattern == "terrestrial" else 1.0)
        lo, hi = spec.vertical_fov_deg
        return (hi - lo) / (spec.channels - 1) if spec.channels > 1 else None
    if spec.pattern == "grid":
        lo, hi = spec.vertical_fov_deg
        return (hi - lo) / spec.channels
    return None


def angular_resolution(spec: SensorSpec) -> tuple[float, float | None]:
    """``(azimuth step, elevation step)`` in degrees, the spacing level-of-detail code should follow.

    A pinhole camera reports its pitch at the image centre, a rosette its mean spacing over a
    frame (``sqrt(fov solid angle / rays)``), a file ``(nan, nan)``; uneven tables give ``None``.
    """
    if spec.pattern == "pinhole":
        fx = _focal(spec)
        return math.degrees(math.atan(1.0 / fx)), math.degrees(math.atan(1.0 / fx))
    if spec.pattern == "rosette":
        theta = math.radians(sum(spec.deflection_deg))
        solid = 2 * math.pi * (1 - math.cos(theta))
        step = math.degrees(math.sqrt(solid / ray_count(spec)))
        return step, step
    if spec.pattern == "file":
        return math.nan, math.nan
    return azimuth_step(spec), elevation_step(spec)


def elevations(spec: SensorSpec) -> np.ndarray:
    """``(rows,)`` float64 elevations in degrees, in ring order.

    Spinning and terrestrial sensors: the beams (ring 0 lowest for uniform fans); ``grid``:
    pixel-centre rows, top first; ``pinhole``: the rows where they cross the optical axis'
    vertical plane (y = 0; off that plane a pinhole row's elevation falls towards the edges).
    Rosette and file patterns have no rows: an empty array.
    """
    if spec.pattern in ("spinning", "terrestrial"):
        if spec.elevations_deg:
            return np.asarray(spec.elevations_deg, float)
        lo, hi = spec.vertical_fov_deg
        if spec.vertical_resolution_deg > 0:
            return np.minimum(lo + np.arange(spec.channels) * elevation_step(spec), 90.0)
        return np.linspace(lo, hi, spec.channels)
    if spec.pattern == "grid":
        lo, hi = spec.vertical_fov_deg
        return hi - (np.arange(spec.channels) + 0.5) * (hi - lo) / spec.channels
    if spec.pattern == "pinhole":
        return np.degrees(np.arctan(_pinhole_z(spec)))
    return np.zeros(0)


def azimuths(spec: SensorSpec) -> np.ndarray:
    """``(columns,)`` float64 azimuths in degrees, in firing order (grid and pinhole: image columns, left first)."""
    lo, hi = spec.horizontal_fov_deg
    if spec.pattern == "grid":
        return hi - (np.arange(spec.columns) + 0.5) * (hi - lo) / spec.columns
    if spec.pattern == "pinhole":
        return np.degrees(np.arctan(_pinhole_y(spec)))
    if spec.pattern in ("rosette", "file"):
        return np.zeros(0)
    step = azimuth_step(spec)
    k = np.arange(_column_count(spec))
    return hi - k * step if spec.spin == "cw" else lo + k * step


def _column_count(spec: SensorSpec) -> int:
    """Columns of a spinning or terrestrial sweep: one revolution's firings, or both edges of a window."""
    lo, hi = spec.horizontal_fov_deg
    step = azimuth_step(spec)
    if math.isclose(hi - lo, 360.0):
        return max(1, math.ceil(360.0 / step - 1e-6))
    return math.floor((hi - lo) / step + 1e-6) + 1


def ray_count(spec: SensorSpec) -> int:
    """Rays of one frame, without generating them."""
    if spec.pattern in ("pinhole", "grid"):
        return spec.columns * spec.channels
    if spec.pattern == "rosette":
        return int(round(spec.point_rate_hz * frame_time(spec)))
    if spec.pattern == "file":
        return len(load_rays(spec.rays_file))
    if spec.horizontal_resolution_deg <= 0 or spec.sampling_factor <= 0:
        return 0
    return _column_count(spec) * spec.channels


def spherical_directions(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """``(n, 3)`` unit vectors for matching ``(n,)`` azimuths and elevations in degrees."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def mount_offset(spec: SensorSpec) -> np.ndarray:
    """``(3,)`` float64 world offset of the optical centre from the configured position (``[0, 0, mount_height]``)."""
    return np.array([0.0, 0.0, spec.mount_height])


def _focal(spec: SensorSpec) -> float:
    half = math.radians((spec.horizontal_fov_deg[1] - spec.horizontal_fov_deg[0]) / 2)
    return spec.columns / (2.0 * math.tan(half))


def _pinhole_y(spec: SensorSpec) -> np.ndarray:
    """``(columns,)`` image-plane y (left) of pixel centres at unit depth, left column first."""
    return -((np.arange(spec.columns) + 0.5) - spec.columns / 2) / _focal(spec)


def _pinhole_z(spec: SensorSpec) -> np.ndarray:
    """``(channels,)`` image-plane z (up) of pixel centres at unit depth, top row first (fy = fx)."""
    return (spec.channels / 2 - (np.arange(spec.channels) + 0.5)) / _focal(spec)


# ----------------------------------------------------------------------------- patterns
def _grid_rays(spec: SensorSpec) -> Callable[[int, int, int], Pattern]:
    """Spinning and terrestrial: column-major (every row of column 0, then column 1, ...)."""
    el, az = np.radians(elevations(spec)), np.radians(azimuths(spec))
    cos_el, sin_el, cos_az, sin_az = np.cos(el), np.sin(el), np.cos(az), np.sin(az)
    rows = len(el)
    step = azimuth_step(spec)
    column_period = step / (360.0 * spec.rotation_hz)
    row_period = column_period / rows if spec.pattern == "terrestrial" else 0.0

    def chunk(start: int, stop: int, frame: int) -> Pattern:
        i = np.arange(start, stop)
        col, row = np.divmod(i, rows)
        directions = np.empty((len(i), 3))
        np.multiply(cos_el[row], cos_az[col], out=directions[:, 0])
        np.multiply(cos_el[row], sin_az[col], out=directions[:, 1])
        directions[:, 2] = sin_el[row]
        time = col * column_period + row * row_period
        return Pattern(directions, row.astype(np.uint16), time)

    return chunk


def _camera_rays(spec: SensorSpec) -> Callable[[int, int, int], Pattern]:
    """Pinhole and grid: row-major image order from the top-left pixel; all fire at t = 0."""
    width = spec.columns
    if spec.pattern == "pinhole":
        y, z = _pinhole_y(spec), _pinhole_z(spec)

        def directions_of(row, col):
            out = np.empty((len(row), 3))
            out[:, 0] = 1.0
            out[:, 1] = y[col]
            out[:, 2] = z[row]
            return out / np.sqrt(1.0 + out[:, 1] ** 2 + out[:, 2] ** 2)[:, None]

    else:
        el, az = np.radians(elevations(spec)), np.radians(azimuths(spec))
        cos_el, sin_el, cos_az, sin_az = np.cos(el), np.sin(el), np.cos(az), np.sin(az)

        def directions_of(row, col):
            out = np.empty((len(row), 3))
            np.multiply(cos_el[row], cos_az[col], out=out[:, 0])
            np.multiply(cos_el[row], sin_az[col], out=out[:, 1])
            out[:, 2] = sin_el[row]
            return out

    def chunk(start: int, stop: int, frame: int) -> Pattern:
        row, col = np.divmod(np.arange(start, stop), width)
        return Pattern(directions_of(row, col), row.astype(np.uint16), np.zeros(len(row)))

    return chunk


def _rosette_rays(spec: SensorSpec) -> Callable[[int, int, int], Pattern]:
    """Two Risley prisms: deflection = d1 (cos p1, sin p1) + d2 (cos p2, sin p2), p = 2 pi f t (paraxial model)."""
    (f1, f2), (d1, d2) = spec.rotor_hz, spec.deflection_deg
    rate, period = spec.point_rate_hz, frame_time(spec)

    def chunk(start: int, stop: int, frame: int) -> Pattern:
        local = np.arange(start, stop) / rate
        t = frame * period + local
        p1 = 2 * np.pi * np.mod(f1 * t, 1.0)
        p2 = 2 * np.pi * np.mod(f2 * t, 1.0)
        dy = d1 * np.cos(p1) + d2 * np.cos(p2)
        dz = d1 * np.sin(p1) + d2 * np.sin(p2)
        off_axis = np.radians(np.hypot(dy, dz))
        around = np.arctan2(dz, dy)
        sin_off = np.sin(off_axis)
        directions = np.stack([np.cos(off_axis), sin_off * np.cos(around), sin_off * np.sin(around)], axis=-1)
        return Pattern(directions, np.zeros(len(local), np.uint16), local)

    return chunk


def _file_rays(spec: SensorSpec) -> Callable[[int, int, int], Pattern]:
    rays = load_rays(spec.rays_file)

    def chunk(start: int, stop: int, frame: int) -> Pattern:
        n = stop - start
        return Pattern(rays[start:stop].copy(), np.zeros(n, np.uint16), np.zeros(n))

    return chunk


_GENERATORS = {
    "spinning": _grid_rays,
    "terrestrial": _grid_rays,
    "pinhole": _camera_rays,
    "grid": _camera_rays,
    "rosette": _rosette_rays,
    "file": _file_rays,
}


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
    chunk = _GENERATORS[spec.pattern](spec)
    total = ray_count(spec)
    for start in range(0, total, chunk_rays):
        yield chunk(start, min(start + chunk_rays, total), frame)


def spec_summary(spec: SensorSpec) -> dict:
    """Key figures of a spec for listings and the manifest (plain JSON-ready data)."""
    rays = ray_count(spec)
    if spec.pattern in ("rosette", "file"):
        sample = sensor_pattern(spec).directions
        el = np.degrees(np.arcsin(np.clip(sample[:, 2], -1, 1)))
        az = np.degrees(np.arctan2(sample[:, 1], sample[:, 0]))
        channels, columns = 1, rays
    else:
        channels, az = spec.channels, azimuths(spec)
        columns = len(az)
        if spec.pattern == "pinhole":  # extreme rows nearest the axis column; azimuth depends on the column only
            y, z = _pinhole_y(spec), _pinhole_z(spec)
            el = np.degrees(np.arctan(z[[0, -1]] / np.sqrt(1 + np.min(y**2))))
            az = np.degrees(np.arctan(y[[0, -1]]))
        else:
            el = elevations(spec)
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
