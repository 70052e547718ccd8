"""``rosette``: two counter-rotating Risley prisms (Livox).

The beam's deflection from +x is the sum of two vectors of ``deflection_deg`` turning at
``rotor_hz`` (paraxial model); one shot every ``1 / point_rate_hz`` seconds over ``frame_time_s``
(0: ``1 / rotation_hz``). The pattern never repeats within a run: frame ``k`` continues where frame
``k - 1`` stopped. Every ray is ring 0.
"""

from __future__ import annotations

import math

import numpy as np

from ....errors import InputError
from .base import RayPattern, register_pattern, sampled_extent
from ..rays import Pattern


def frame_time(spec) -> float:
    return spec.frame_time_s if spec.frame_time_s > 0 else 1.0 / spec.rotation_hz


def count(spec) -> int:
    return int(round(spec.point_rate_hz * frame_time(spec)))


def check(spec, where: str) -> None:
    d1, d2 = spec.deflection_deg
    if d1 < 0 or d2 < 0 or not 0 < d1 + d2 <= 90:
        raise InputError(f"{where}.deflection_deg: two angles >= 0 with 0 < sum <= 90, got {list(spec.deflection_deg)}")


def resolution(spec) -> tuple[float, float]:
    """The mean spacing over a frame: ``sqrt(field solid angle / rays)``."""
    theta = math.radians(sum(spec.deflection_deg))
    solid = 2 * math.pi * (1 - math.cos(theta))
    step = math.degrees(math.sqrt(solid / count(spec)))
    return step, step


def rays(spec):
    (f1, f2), (d1, d2) = spec.rotor_hz, spec.deflection_deg
    rate, period = spec.point_rate_hz, frame_time(spec)

    def chunk(start: int, stop: int, frame: int):
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


register_pattern("rosette", RayPattern(rays, count, resolution, check, lambda spec: "point_rate_hz", frame_time=frame_time, per_frame=True,
                                       extent=sampled_extent))
