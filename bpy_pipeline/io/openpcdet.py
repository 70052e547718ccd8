"""OpenPCDet's custom-dataset layout (``pcdet/datasets/custom``), with train and val ImageSets.

Files (frame ``NNNNNN``)::

    openpcdet/points/NNNNNN.npy        (n, 4) float32: x y z (m, the points' frame), intensity (0..1)
    openpcdet/labels/NNNNNN.txt        x y z dx dy dz heading_angle category_name (box centre, length,
                                       width, height, yaw about z)
    openpcdet/ImageSets/{train,val,test}.txt  frame stems by output.split (:mod:`.splits`); none for an empty split

OpenPCDet's ``CustomDataset.get_label`` turns every line into a box and slices ``[:, :7]``, which
fails on an empty file, so frames without a box are written (their points can serve as negatives
elsewhere) but left out of the ImageSets. Category names are ``output.boxes.names`` or the class
name capitalised (Car, Person, RobotArm): OpenPCDet's ``CLASS_NAMES`` must list them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ._records import XYZI, XyziBlock, packed_columns
from .atomic import atomic_write, hashed_open, write_text_hashed
from .kitti import write_image_sets
from .splits import split_indices
from .sustech import label_type


def label_lines(boxes: np.ndarray, names: dict | None = None) -> list[str]:
    """OpenPCDet custom-dataset lines ``x y z dx dy dz heading_angle category_name``."""
    return [" ".join(f"{v:.4f}" for v in (*box["centre"], *box["size"], float(box["heading"]))) + f" {label_type(str(box['class_name']), names)}"
            for box in boxes]


def write_frame(out_dir: str | os.PathLike, stem: str, points: np.ndarray, boxes, names: dict | None = None, xyzi: XyziBlock | None = None) -> list[Path]:
    """``openpcdet/points/NNNNNN.npy`` and ``openpcdet/labels/NNNNNN.txt`` of one frame (the points' array from ``xyzi``,
    their :class:`~._records.XyziBlock`, when given)."""
    root = Path(out_dir) / "openpcdet"
    points_path, label = root / "points" / f"{stem}.npy", root / "labels" / f"{stem}.txt"
    block = xyzi.array if xyzi is not None else packed_columns(points, XYZI)
    with atomic_write(points_path) as tmp, hashed_open(tmp) as handle:  # hashed as written
        np.lib.format.write_array_header_1_0(handle, np.lib.format.header_data_from_array_1_0(block))  # np.save's bytes: its header (version 1.0 holds it),
        handle.write(block)  # then the array, without np.save's copy of it for a file object that is not a file
    with atomic_write(label) as tmp:
        write_text_hashed(tmp, "".join(line + "\n" for line in label_lines(boxes if boxes is not None else [], names)))
    return [points_path, label]


def write_index(out_dir: str | os.PathLike, records: list[dict], config) -> list[Path]:
    """``openpcdet/ImageSets/{train,val,test}.txt`` of the committed frames that hold a box, by ``output.split``."""
    with_boxes = [r["index"] for r in records if r.get("boxes")]
    return write_image_sets(out_dir, "openpcdet", split_indices(with_boxes, config.output.split, config.frames))
