"""``file``: user-defined directions from ``rays_file`` (an ``(n, 3)`` ``.npy``), normalised on load.

Every ray is ring 0 and fires at time 0 (the file says nothing about either).
"""

from __future__ import annotations

import math

import numpy as np

from .base import RayPattern, register_pattern, sampled_extent
from ..rays import Pattern, load_rays


def count(spec) -> int:
    return len(load_rays(spec.rays_file))


def check(spec, where: str) -> None:
    load_rays(spec.rays_file, f"{where}.rays_file")


def rays(spec):
    directions = load_rays(spec.rays_file)

    def chunk(start: int, stop: int, frame: int):
        n = stop - start
        return Pattern(directions[start:stop].copy(), np.zeros(n, np.uint16), np.zeros(n))

    return chunk


register_pattern("file", RayPattern(rays, count, lambda spec: (math.nan, math.nan), check, lambda spec: "rays_file", extent=sampled_extent))
