"""Checks of user geometry before it is traced: meshes and poses that lie are refused with one line.

Pure numpy; every function raises :class:`~bpy_pipeline.errors.InputError` naming ``where``.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

RIGID_TOLERANCE = 1e-6  # a pose's rotation must be orthonormal with determinant +1 to this, its last row (0, 0, 0, 1)


def _array(value, where: str) -> np.ndarray:
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as err:  # ragged nested lists
        raise InputError(f"{where}: not an array ({str(err).splitlines()[0]})") from None


def check_mesh(vertices, triangles, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3) float64, triangles (m, 3) int64)`` of a user mesh, checked.

    vertices : (n, 3) real numbers, all finite (metres)
    triangles : (m, 3) integers, each in ``0 .. n - 1``
    """
    v, t = _array(vertices, f"{where} vertices"), _array(triangles, f"{where} triangles")
    if v.ndim != 2 or v.shape[1] != 3 or v.dtype.kind not in "fiu":
        raise InputError(f"{where} vertices: expected an (n, 3) array of numbers, got shape {v.shape} of {v.dtype}")
    bad = ~np.isfinite(v.astype(np.float64)).all(axis=1)
    if bad.any():
        raise InputError(f"{where} vertices: vertex {int(np.flatnonzero(bad)[0])} is not finite ({v[bad][0].tolist()}); {int(bad.sum())} of {len(v)} are not")
    if t.ndim != 2 or t.shape[1] != 3:
        raise InputError(f"{where} triangles: expected an (m, 3) array of vertex indices, got shape {t.shape}")
    if t.size and t.dtype.kind not in "iu":
        raise InputError(f"{where} triangles: expected integer vertex indices, got {t.dtype}")
    if t.size and (int(t.min()) < 0 or int(t.max()) >= len(v)):
        raise InputError(f"{where} triangles: indices {int(t.min())} .. {int(t.max())} for {len(v)} vertices (allowed 0 .. {len(v) - 1})")
    return v.astype(np.float64), t.astype(np.int64)


def check_pose(pose, where: str = "pose") -> np.ndarray:
    """A ``(4, 4)`` rigid transform as float64: finite, rotation orthonormal with determinant +1 and last row
    ``(0, 0, 0, 1)``, each to :data:`RIGID_TOLERANCE`."""
    p = _array(pose, where)
    if p.shape != (4, 4) or p.dtype.kind not in "fiu":
        raise InputError(f"{where}: expected a (4, 4) rigid transform of numbers, got shape {p.shape} of {p.dtype}")
    p = p.astype(np.float64)
    if not np.isfinite(p).all():
        raise InputError(f"{where}: holds non-finite values")
    r = p[:3, :3]
    error = max(float(np.abs(r.T @ r - np.eye(3)).max()), abs(float(np.linalg.det(r)) - 1.0), float(np.abs(p[3] - [0, 0, 0, 1]).max()))
    if error > RIGID_TOLERANCE:
        raise InputError(
            f"{where}: not a rigid transform (rotation orthonormal with determinant +1, last row 0 0 0 1) to {RIGID_TOLERANCE:g}; off by {error:.3g}"
        )
    return p


def check_fraction(value, where: str) -> float:
    """A finite number in 0..1 (a reflectivity, a probability)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a number in 0..1, got {value!r}") from None
    if not 0.0 <= x <= 1.0:  # NaN fails too
        raise InputError(f"{where}: expected a number in 0..1, got {value!r}")
    return x
