"""The per-point record every scan returns and every writer reads."""

import numpy as np

POINT_DTYPE = np.dtype(
    [
        ("x", "<f4"),  # metres, sensor frame unless the output asks for world
        ("y", "<f4"),
        ("z", "<f4"),
        ("intensity", "<f4"),  # 0..1
        ("semantic", "<u2"),  # raw class id from assets_manifest/labels.yaml
        ("instance", "<u4"),  # object instance id, 0 for none
        ("ring", "<u2"),  # laser channel
        ("time", "<f8"),  # seconds from frame start
        ("range", "<f4"),  # metres along the beam (total path length after mirrors)
        ("bounces", "u1"),  # 0 direct, k after k mirror reflections
    ]
)


def empty_points(n: int = 0) -> np.ndarray:
    """A zeroed ``(n,)`` array of :data:`POINT_DTYPE`."""
    return np.zeros(n, POINT_DTYPE)


# What the trace knows about each point beyond its record, for the effects (intensity, drop, noise).
BEAM_DTYPE = np.dtype(
    [
        ("cos_incidence", "<f4"),  # |cos| of the angle between the last ray and the surface normal
        ("reflectivity", "<f4"),  # lidar_reflectivity of the object finally hit, 0..1
        # one-way factors met (a mirror's reflectivity, a glass pass's 1 - reflectivity) times, with
        # beam divergence, the share of the footprint's energy this return carries; 1 for a plain direct return
        ("gain", "<f4"),
        # unit vector (output frame) along which the reported point moves when its measured range
        # changes: the emitted ray, or the last segment for points reported at their true position
        ("direction", "<f4", (3,)),
    ]
)
