"""The effects' arithmetic passes compiled (numba, optional): the same bytes as the numpy path.

Only what is plain float32 arithmetic moves here: the random numbers are drawn by numpy from the
chunk's generator exactly as the numpy path draws them, and the transcendental functions (the
threshold drop's ``log`` and ``exp``) stay numpy's (numba's ``logf`` is not numpy's SIMD one, so
their last bits could differ). Each kernel computes what the numpy path computes, operation for
operation in the same order, float32 throughout, no fused multiply-add (``fastmath`` off), so both
give the same bytes (``tests/test_effects_kernels.py``).

:func:`compiled` returns the kernels, or ``None`` without numba or with
``BPY_PIPELINE_SCAN_KERNEL=numpy`` (the variable that chooses the scan's path chooses this one too).
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

from ...compiled import compiled_wanted


def compiled() -> SimpleNamespace | None:
    """The compiled effects kernels, or ``None`` (no numba, or ``BPY_PIPELINE_SCAN_KERNEL=numpy``)."""
    if not compiled_wanted():
        return None
    return _kernels()


@cache
def _kernels() -> SimpleNamespace:
    import numba
    import numpy as np

    jit = numba.njit(nogil=True, cache=True, error_model="numpy", fastmath=False)

    @jit
    def move_along_beam(points, direction, draw, sigma, sigmas, bias, ring):
        """Range noise and per-ring bias of :func:`.apply.perturb` (no jitter), in place.

        points : (p,) POINT_DTYPE records; direction : (p, 3) float32 (the beam facts' directions)
        draw : (p,) float32 standard normal draws, or (0,) for no noise; sigma : float32 one sigma for
        all, used when ``sigmas`` is (0,), else (p,) float32 per point; bias : (b,) float32 per ring or (0,)
        The numpy path's order: ``new = range + draw * sigma + bias[ring]``, ``max(new, 0)``, then each
        of x, y, z ``+= (new - range) * direction``.
        """
        n = points.shape[0]
        noisy = draw.shape[0] != 0
        per_point = sigmas.shape[0] != 0
        biased = bias.shape[0] != 0
        zero = np.float32(0.0)
        for i in range(n):
            record = points[i]
            old = record.range
            new = old
            if noisy:
                step = draw[i] * (sigmas[i] if per_point else sigma)
                new = np.float32(new + step)
            if biased:
                new = np.float32(new + bias[ring[i]])
            if not (new >= zero or new != new):  # np.maximum(new, 0): keeps NaN and -0.0 as numpy does
                new = zero
            step = np.float32(new - old)
            record.x = np.float32(record.x + np.float32(step * direction[i, 0]))
            record.y = np.float32(record.y + np.float32(step * direction[i, 1]))
            record.z = np.float32(record.z + np.float32(step * direction[i, 2]))
            record.range = new

    return SimpleNamespace(move_along_beam=move_along_beam)
