"""The ground of a railway as a height field along the alignment: flat, in a cutting, and undulating. Pure numpy.

The ground strip ``width`` m wide follows the alignment; its height (m, from formation level) is the
cross-section's ground (:meth:`~.railway_layout.CrossSection.surface` beyond the ballast: the
formation under the track, an embankment's foot or a cutting's slopes and top), plus an
undulation of amplitude ``roughness`` beyond the slopes: three plane waves of wavelengths
``wavelength``, /2 and /4 (amplitudes 1, 1/2, 1/4, normalised) with directions and phases drawn
from the run's generator. It fades in over 5 m from the slopes' outer edge, so the track, the
masts and the stations stand where the cross-section says.
"""

from __future__ import annotations

import numpy as np

FADE = 5.0  # m over which the undulation fades in beyond the slopes


def undulation(rng: np.random.Generator, wavelength: float):
    """``f(xy (n, 2)) -> (n,)`` a smooth field of unit amplitude (three plane waves) drawn from ``rng``."""
    angles = rng.uniform(0.0, 2 * np.pi, 3)
    phases = rng.uniform(0.0, 2 * np.pi, 3)
    k = 2 * np.pi / (wavelength / np.array([1.0, 2.0, 4.0]))
    weights = np.array([1.0, 0.5, 0.25]) / 1.75
    directions = np.column_stack([np.cos(angles), np.sin(angles)]) * k[:, None]

    def field(xy):
        return (weights * np.sin(np.asarray(xy, float) @ directions.T + phases)).sum(1)

    return field


def terrain_mesh(alignment, section, width: float, trim: tuple[float, float], roughness: float, wavelength: float, rng: np.random.Generator):
    """The ground strip between chainages ``trim`` as ``(vertices (n, 3) m world, triangles (m, 3) int32)``, a grid
    of about 1 m (finer across the slopes: every 0.25 m within them)."""
    s0, s1 = trim
    s = np.linspace(s0, s1, max(2, int(np.ceil(s1 - s0)) + 1))
    half = width / 2
    edge = section.embankment_toe_half
    inner = np.linspace(0.0, edge + 0.5, max(2, int(np.ceil((edge + 0.5) / 0.25)) + 1))
    outer = np.linspace(edge + 0.5, half, max(2, int(np.ceil(half - edge - 0.5)) + 1))[1:]
    right = np.concatenate([inner, outer])
    lateral = np.concatenate([-right[::-1], right[1:]])
    base = section.surface(lateral)
    base = np.where(np.abs(lateral) <= section.ballast_toe_half, 0.0, base)  # under the ballast: the formation
    field = undulation(rng, wavelength)
    n, m = len(s), len(lateral)
    points = alignment.point(s)
    left = alignment.lateral(s)
    xyz = points[:, None, :] + lateral[None, :, None] * left[:, None, :]
    fade = np.clip((np.abs(lateral) - edge) / FADE, 0.0, 1.0)
    heights = base[None, :] + roughness * fade[None, :] * field(xyz[..., :2].reshape(-1, 2)).reshape(n, m)
    xyz[..., 2] += heights
    i, j = np.meshgrid(np.arange(n - 1), np.arange(m - 1), indexing="ij")
    a = (i * m + j).ravel()
    quads = np.stack([a, a + m, a + m + 1, a + 1], 1)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)  # upward normals (x ahead, y left)
    return xyz.reshape(-1, 3), triangles
