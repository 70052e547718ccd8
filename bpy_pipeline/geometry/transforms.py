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


KITTI_SENSOR_HEIGHT = 1.73  # m: KITTI's Velodyne above the road, where the stock detection configs' ranges and anchors expect the ground


def output_pose(frame: str, pose: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """``(4, 4)`` world pose of the points' frame ``output.frame`` for a sensor at ``pose`` (4, 4).

    ``sensor``: the sensor's pose; ``world``: identity; ``kitti``: level, x along the sensor's heading (its x axis
    projected on the ground), origin :data:`KITTI_SENSOR_HEIGHT` above the ground (the builders' world z = 0) under
    ``origin`` (m, the sensor frame: the KITTI camera's position, ``output.kitti.camera.position``, where KITTI's
    camera and LiDAR stand together), so the ground lies at z = -1.73 m as in KITTI, whatever the sensor's height or tilt.
    """
    pose = np.asarray(pose, float)
    if frame == "sensor":
        return pose
    if frame == "world":
        return np.eye(4)
    if frame == "kitti":
        yaw = np.arctan2(pose[1, 0], pose[0, 0])
        x, y, _ = pose[:3, :3] @ np.asarray(origin, float) + pose[:3, 3]
        return pose_matrix([x, y, KITTI_SENSOR_HEIGHT], [0.0, 0.0, np.degrees(yaw)])
    raise ValueError(f"output.frame: {frame!r} is not one of sensor, world, kitti")


def sensor_to_output(frame: str, pose: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray | None:
    """``(4, 4)`` sensor-frame -> ``output.frame`` transform of a sensor at ``pose`` (``origin``: as :func:`output_pose`);
    ``None`` for ``sensor`` (no move)."""
    if frame == "sensor":
        return None
    return np.asarray(pose, float) if frame == "world" else np.linalg.solve(output_pose(frame, pose, origin), np.asarray(pose, float))
