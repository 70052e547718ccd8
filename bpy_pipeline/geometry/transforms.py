"""Rigid transforms: sensor poses and the world <-> sensor frame change. Pure numpy."""

from __future__ import annotations

import numpy as np


def euler_xyz_matrix(angles_deg) -> np.ndarray:
    """``(3, 3)`` rotation of Blender's XYZ Euler angles (degrees): R = Rz @ Ry @ Rx.

    For a sensor, (rx, ry, rz) are roll, pitch and yaw.
    """
    rx, ry, rz = np.radians(np.asarray(angles_deg, float))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def pose_matrix(position, rotation_deg) -> np.ndarray:
    """``(4, 4)`` float64 sensor-to-world transform from a position (m) and roll, pitch, yaw (deg)."""
    pose = np.eye(4)
    pose[:3, :3] = euler_xyz_matrix(rotation_deg)
    pose[:3, 3] = position
    return pose


def world_to_sensor(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """``(n, 3)`` world points into the sensor frame of ``pose`` (4, 4)."""
    return (points - pose[:3, 3]) @ pose[:3, :3]


def transform_points(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``(n, 3)`` points through a ``(4, 4)`` affine matrix."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def rotate(vectors: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``(n, 3)`` vectors turned by one ``(3, 3)`` rotation, or by ``(n, 3, 3)`` rotations, one per vector."""
    return vectors @ rotation.T if rotation.ndim == 2 else np.einsum("nij,nj->ni", rotation, vectors)
