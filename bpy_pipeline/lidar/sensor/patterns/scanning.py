"""``spinning`` and ``terrestrial``: a head turning through columns while its rows fire.

``spinning``: a rotating multi-beam lidar (Velodyne, Hesai, Ouster): every channel of a column
fires together, columns fire one after another as the head turns; a column's ``time`` is its
azimuth offset from the start of the sweep over ``360 * rotation_hz``.
``terrestrial``: a static terrestrial laser scanner: a mirror sweeps each vertical profile (the
fast axis) while the head turns once per ``1 / rotation_hz`` seconds (the slow axis), so the rays
of a column fire one after another, bottom to top; ``sampling_factor`` divides both steps.
Rays come column-major (every row of column 0, then column 1, ...). Rings count from the lowest
beam up unless an explicit ``elevations_deg`` table gives another order.
"""

from __future__ import annotations

import math

import numpy as np

from ....errors import InputError
from .base import RayPattern, channels, check_rows, derive_columns, derive_rows, register_pattern
from ..rays import Pattern


def _is_window(spec) -> bool:
    lo, hi = spec.horizontal_fov_deg
    return not math.isclose(hi - lo, 360.0)


def azimuth_step(spec) -> float:
    return spec.horizontal_resolution_deg / spec.sampling_factor


def elevation_step(spec) -> float | None:
    if spec.elevations_deg:
        return None
    if spec.vertical_resolution_deg > 0:
        return spec.vertical_resolution_deg / (spec.sampling_factor if spec.pattern == "terrestrial" else 1.0)
    lo, hi = spec.vertical_fov_deg
    return (hi - lo) / (spec.channels - 1) if spec.channels > 1 else None


def elevations(spec) -> np.ndarray:
    if spec.elevations_deg:
        return np.asarray(spec.elevations_deg, float)
    lo, hi = spec.vertical_fov_deg
    if spec.vertical_resolution_deg > 0:
        return np.minimum(lo + np.arange(spec.channels) * elevation_step(spec), 90.0)
    return np.linspace(lo, hi, spec.channels)


def column_count(spec) -> int:
    """Columns of a sweep: one revolution's firings, or both edges of a window."""
    lo, hi = spec.horizontal_fov_deg
    step = azimuth_step(spec)
    if not _is_window(spec):
        return max(1, math.ceil(360.0 / step - 1e-6))
    return math.floor((hi - lo) / step + 1e-6) + 1


def azimuths(spec) -> np.ndarray:
    lo, hi = spec.horizontal_fov_deg
    step = azimuth_step(spec)
    k = np.arange(column_count(spec))
    return hi - k * step if spec.spin == "cw" else lo + k * step


def count(spec) -> int:
    if spec.horizontal_resolution_deg <= 0 or spec.sampling_factor <= 0:
        return 0
    return column_count(spec) * spec.channels


def derive(spec, section: dict, where: str) -> dict:
    changes = derive_columns(spec, section, where, window=_is_window(spec))
    if not spec.elevations_deg and spec.vertical_resolution_deg > 0 and spec.sampling_factor > 0:  # (a table's rows: sensors._derive)
        lo, hi = spec.vertical_fov_deg
        step = spec.vertical_resolution_deg / (spec.sampling_factor if spec.pattern == "terrestrial" else 1.0)
        rows = int(math.floor((hi - lo) / step + 1e-6)) + 1 if hi >= lo else 0
        return changes | derive_rows(spec, section, where, rows, "vertical_resolution_deg")
    return changes


def check(spec, where: str) -> None:
    check_rows(spec, where)
    lo, hi = spec.horizontal_fov_deg
    if not 0 < spec.horizontal_resolution_deg <= hi - lo:
        raise InputError(f"{where}.horizontal_resolution_deg: must lie in (0, {hi - lo}], got {spec.horizontal_resolution_deg}")


def density_key(spec) -> str:
    return "sampling_factor" if spec.sampling_factor != 1 else "horizontal_resolution_deg"


def rays(spec):
    """Column-major rays: a column fires at ``column * step / (360 rotation_hz)``; a terrestrial
    scanner's rows one after another within the column."""
    el, az = np.radians(elevations(spec)), np.radians(azimuths(spec))
    cos_el, sin_el, cos_az, sin_az = np.cos(el), np.sin(el), np.cos(az), np.sin(az)
    rows = len(el)
    column_period = azimuth_step(spec) / (360.0 * spec.rotation_hz)
    row_period = column_period / rows if spec.pattern == "terrestrial" else 0.0

    def chunk(start: int, stop: int, frame: int):
        i = np.arange(start, stop)
        col, row = np.divmod(i, rows)
        directions = np.empty((len(i), 3))
        np.multiply(cos_el[row], cos_az[col], out=directions[:, 0])
        np.multiply(cos_el[row], sin_az[col], out=directions[:, 1])
        directions[:, 2] = sin_el[row]
        time = col * column_period + row * row_period
        return Pattern(directions, row.astype(np.uint16), time)

    return chunk


def resolution(spec) -> tuple[float, float | None]:
    return azimuth_step(spec), elevation_step(spec)


SCANNING = RayPattern(rays, count, resolution, check, density_key, azimuth_step, elevation_step, elevations, azimuths, derive, rings=channels, image=True)
register_pattern("spinning", SCANNING)
register_pattern("terrestrial", SCANNING)
