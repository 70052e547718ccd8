"""The rays of a frame as a value (:class:`Pattern`) and ray directions read from files. Pure numpy.

The bottom of :mod:`bpy_pipeline.lidar`: the ray patterns (:mod:`.patterns`) make :class:`Pattern` s,
:mod:`.sensors` re-exports these names, and nothing here imports either.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ...errors import InputError


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
