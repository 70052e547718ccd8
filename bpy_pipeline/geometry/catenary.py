"""Wire sag between two attachment points. Pure numpy."""

from __future__ import annotations

import numpy as np


def parabolic_sag(start, end, sag: float, samples: int) -> np.ndarray:
    """``(samples, 3)`` points of a wire hanging between ``start`` and ``end`` (3,) metres.

    z(x) = z_line(x) - 4 s x (L - x) / L^2 with x the horizontal distance from ``start``,
    L the horizontal span and s the sag at mid-span (the railway thesis, section 4.1).
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    if samples < 3:
        raise ValueError("a sagging wire needs at least three samples")
    span = np.linalg.norm((end - start)[:2])
    if span == 0:
        raise ValueError("zero-length span: the two attachment points share x and y")
    u = np.linspace(0.0, 1.0, samples)
    points = start + u[:, None] * (end - start)
    points[:, 2] -= 4.0 * sag * u * (1.0 - u)
    return points
