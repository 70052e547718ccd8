"""Synthetic point records for writer and reader tests."""

import numpy as np

from bpy_pipeline.lidar.points import empty_points


def random_points(n: int, rng: np.random.Generator, extent: float = 100.0, instances: int = 2**32) -> np.ndarray:
    """``(n,)`` POINT_DTYPE records with every field drawn: x y z in +-``extent`` m, instance ids below ``instances``."""
    pts = empty_points(n)
    for name in "xyz":
        pts[name] = rng.uniform(-extent, extent, n)
    pts["intensity"] = rng.uniform(0, 1, n)
    pts["semantic"] = rng.integers(0, 26, n)
    pts["instance"] = rng.integers(0, instances, n, dtype=np.uint64)
    pts["ring"] = rng.integers(0, 128, n)
    pts["time"] = rng.uniform(0, 0.1, n)
    pts["range"] = rng.uniform(0.5, 120, n)
    pts["bounces"] = rng.integers(0, 4, n)
    return pts
