"""Box label files read back (tests, tools): KITTI ``label_2`` and OpenPCDet custom labels, as :data:`BOX_DTYPE` arrays.

The boxes themselves are :mod:`bpy_pipeline.geometry.boxes` (fitting, frames, counts); their
truncation and occlusion are cast by the annotate stage (:mod:`bpy_pipeline.stages.annotate`, with
:mod:`bpy_pipeline.lidar.cast.visibility`) before any writer runs; the layouts are :mod:`.kitti`
(KITTI object layout), :mod:`.openpcdet` (OpenPCDet custom) and :mod:`.sustech` (SUSTechPOINTS).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..geometry.boxes import BOX_DTYPE, wrap_angle
from .kitti import KITTI_AXES


def read_kitti_labels(path: str | os.PathLike, tr: np.ndarray | None = None) -> np.ndarray:
    """Boxes (:data:`BOX_DTYPE`, LiDAR frame; ``class_name`` holds the KITTI type) of a KITTI ``label_2`` file.

    tr : (3, 4) ``Tr_velo_to_cam`` of the frame's calib (default: KITTI's axis change, a camera at
    the sensor looking along x). ``DontCare`` lines are skipped.
    """
    tr = np.hstack([KITTI_AXES, np.zeros((3, 1))]) if tr is None else np.asarray(tr, float)
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip() and not line.startswith("DontCare")]
    out = np.zeros(len(rows), BOX_DTYPE)
    for k, r in enumerate(rows):
        h, w, length = map(float, r[8:11])
        cam = np.array(list(map(float, r[11:14])))
        bottom = tr[:, :3].T @ (cam - tr[:, 3])
        axis = tr[:, :3].T @ [np.cos(float(r[14])), 0.0, -np.sin(float(r[14]))]  # the length axis, back in the LiDAR frame
        out[k]["class_name"] = r[0]
        out[k]["truncation"] = float(r[1])
        out[k]["occlusion"] = int(r[2])
        out[k]["size"] = (length, w, h)
        out[k]["centre"] = bottom + [0.0, 0.0, h / 2]
        out[k]["heading"] = wrap_angle(np.arctan2(axis[1], axis[0]))
    return out


def read_openpcdet_labels(path: str | os.PathLike) -> np.ndarray:
    """Boxes (:data:`BOX_DTYPE`; ``class_name`` holds the category name) from an OpenPCDet custom label file."""
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    out = np.zeros(len(rows), BOX_DTYPE)
    for k, r in enumerate(rows):
        values = list(map(float, r[:7]))
        out[k]["centre"], out[k]["size"], out[k]["heading"] = values[:3], values[3:6], values[6]
        out[k]["class_name"] = r[7]
    return out
