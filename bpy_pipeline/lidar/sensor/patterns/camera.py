"""``pinhole`` and ``grid``: a flash (focal-plane array) camera of ``columns`` x ``channels`` pixels.

Every pixel fires at ``t = 0``, row-major from the top-left pixel; rings are image rows, 0 at the top.
``pinhole`` puts pixel centres on a flat image plane (``fx = fy = columns / (2 tan(hfov / 2))``, as
CARLA's depth cameras do), so the angle per pixel shrinks towards the edges and the vertical field
follows from ``fy``; ``grid`` spaces pixel centres uniformly in azimuth and elevation.
"""

from __future__ import annotations

import math

import numpy as np

from ....errors import InputError
from .base import RayPattern, channels, check_rows, derive_columns, register_pattern
from ..rays import Pattern


def focal(spec) -> float:
    half = math.radians((spec.horizontal_fov_deg[1] - spec.horizontal_fov_deg[0]) / 2)
    return spec.columns / (2.0 * math.tan(half))


def pinhole_y(spec) -> np.ndarray:
    """``(columns,)`` image-plane y (left) of pixel centres at unit depth, left column first."""
    return -((np.arange(spec.columns) + 0.5) - spec.columns / 2) / focal(spec)


def pinhole_z(spec) -> np.ndarray:
    """``(channels,)`` image-plane z (up) of pixel centres at unit depth, top row first (fy = fx)."""
    return (spec.channels / 2 - (np.arange(spec.channels) + 0.5)) / focal(spec)


def azimuth_step(spec) -> float:
    lo, hi = spec.horizontal_fov_deg
    return (hi - lo) / spec.columns


def count(spec) -> int:
    return spec.columns * spec.channels


def derive(spec, section: dict, where: str) -> dict:
    """``horizontal_resolution_deg`` from the image width; a camera given an angle step or a firing rate in its place is
    refused naming that key (a preset's ``columns`` stop applying once either is given: they decide the same thing)."""
    named = [key for key in ("horizontal_resolution_deg", "firing_rate_hz") if key in section]
    if spec.columns < 1 and named:
        raise InputError(f"{where}.{named[0]}: a {spec.pattern} camera's image width is {where}.columns (pixels), not an angle step or a rate; "
                         f"give {where}.columns instead")
    return derive_columns(spec, section, where, window=False)


def check(spec, where: str) -> None:
    check_rows(spec, where)
    lo, hi = spec.horizontal_fov_deg
    if spec.columns < 1:
        raise InputError(f"{where}.columns: a {spec.pattern} camera needs its image width in pixels (>= 1), got {spec.columns}")
    if spec.pattern == "pinhole" and (hi - lo >= 180 or not math.isclose(lo, -hi, abs_tol=1e-9)):
        raise InputError(f"{where}.horizontal_fov_deg: a pinhole camera needs [-a, a] with a < 90, got {[lo, hi]}; turn it with sensor.rotation_deg")
    if spec.pattern == "grid" and spec.vertical_fov_deg[0] >= spec.vertical_fov_deg[1]:
        raise InputError(f"{where}.vertical_fov_deg: a grid camera needs min < max, got {list(spec.vertical_fov_deg)}")


def density_key(spec) -> str:
    return "columns"


def _chunks(spec, directions_of):
    def chunk(start: int, stop: int, frame: int):
        row, col = np.divmod(np.arange(start, stop), spec.columns)
        return Pattern(directions_of(row, col), row.astype(np.uint16), np.zeros(len(row)))

    return chunk


# ----------------------------------------------------------------------------- pinhole
def pinhole_rays(spec):
    y, z = pinhole_y(spec), pinhole_z(spec)

    def directions_of(row, col):
        out = np.empty((len(row), 3))
        out[:, 0] = 1.0
        out[:, 1] = y[col]
        out[:, 2] = z[row]
        return out / np.sqrt(1.0 + out[:, 1] ** 2 + out[:, 2] ** 2)[:, None]

    return _chunks(spec, directions_of)


def pinhole_resolution(spec) -> tuple[float, float]:
    """The pitch at the image centre."""
    pitch = math.degrees(math.atan(1.0 / focal(spec)))
    return pitch, pitch


def pinhole_elevations(spec) -> np.ndarray:
    """The rows where they cross the optical axis' vertical plane (y = 0; off it a row's elevation falls)."""
    return np.degrees(np.arctan(pinhole_z(spec)))


def pinhole_azimuths(spec) -> np.ndarray:
    return np.degrees(np.arctan(pinhole_y(spec)))


def pinhole_extent(spec) -> tuple[np.ndarray, np.ndarray]:
    """The extreme rows nearest the axis column, and the extreme columns (a column's azimuth is its own)."""
    y, z = pinhole_y(spec), pinhole_z(spec)
    return np.degrees(np.arctan(z[[0, -1]] / np.sqrt(1 + np.min(y**2)))), np.degrees(np.arctan(y[[0, -1]]))


register_pattern("pinhole", RayPattern(pinhole_rays, count, pinhole_resolution, check, density_key, azimuth_step, lambda spec: None, pinhole_elevations,
                                       pinhole_azimuths, derive, rings=channels, extent=pinhole_extent))


# ----------------------------------------------------------------------------- grid
def grid_elevation_step(spec) -> float:
    lo, hi = spec.vertical_fov_deg
    return (hi - lo) / spec.channels


def grid_elevations(spec) -> np.ndarray:
    """Pixel-centre rows, top first."""
    lo, hi = spec.vertical_fov_deg
    return hi - (np.arange(spec.channels) + 0.5) * (hi - lo) / spec.channels


def grid_azimuths(spec) -> np.ndarray:
    lo, hi = spec.horizontal_fov_deg
    return hi - (np.arange(spec.columns) + 0.5) * (hi - lo) / spec.columns


def grid_rays(spec):
    el, az = np.radians(grid_elevations(spec)), np.radians(grid_azimuths(spec))
    cos_el, sin_el, cos_az, sin_az = np.cos(el), np.sin(el), np.cos(az), np.sin(az)

    def directions_of(row, col):
        out = np.empty((len(row), 3))
        np.multiply(cos_el[row], cos_az[col], out=out[:, 0])
        np.multiply(cos_el[row], sin_az[col], out=out[:, 1])
        out[:, 2] = sin_el[row]
        return out

    return _chunks(spec, directions_of)


def grid_resolution(spec) -> tuple[float, float]:
    return azimuth_step(spec), grid_elevation_step(spec)


register_pattern("grid", RayPattern(grid_rays, count, grid_resolution, check, density_key, azimuth_step, grid_elevation_step, grid_elevations, grid_azimuths,
                                    derive, rings=channels))
