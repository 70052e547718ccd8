"""Where each format puts a frame inside the output folder, and one writer per format name.

Output folder layout (docs/datasets.md, "What is in the folder")::

    OUT/ply/NNNNNN.ply
    OUT/sequences/SS/velodyne/NNNNNN.bin, OUT/sequences/SS/labels/NNNNNN.label
    OUT/las/NNNNNN.las
    OUT/npy/NNNNNN/{coord,strength,segment,instance}.npy
    OUT/preview/NNNNNN.png

Each ``write_frame_<format>(out_dir, frame_index, points (n,) POINT_DTYPE, sequence=0) -> list[Path]``
writes one frame and returns the written paths (only SemanticKITTI uses ``sequence``);
:mod:`.formats` registers them as writers.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from .las import write_las
from .npy import write_npy_folder
from .ply import write_ply
from .preview import write_preview
from .semantickitti import write_semantickitti


def frame_stem(frame_index: int) -> str:
    """``NNNNNN``: the frame index, zero-padded to six digits; ``InputError`` for a negative index."""
    if isinstance(frame_index, bool) or not isinstance(frame_index, (int, np.integer)) or frame_index < 0:
        raise InputError(f"frame index: expected an integer >= 0, got {frame_index!r}")
    return f"{int(frame_index):06d}"


def write_frame_ply(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, sequence: int = 0) -> list[Path]:
    """``OUT/ply/NNNNNN.ply`` (all fields)."""
    return [write_ply(Path(out_dir) / "ply" / f"{frame_stem(frame_index)}.ply", points)]


def write_frame_semantickitti(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, sequence: int = 0) -> list[Path]:
    """``OUT/sequences/SS/velodyne/NNNNNN.bin`` and ``OUT/sequences/SS/labels/NNNNNN.label``."""
    frame_stem(frame_index)
    return list(write_semantickitti(out_dir, sequence, frame_index, points))


def write_frame_las(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, sequence: int = 0) -> list[Path]:
    """``OUT/las/NNNNNN.las`` (LAS 1.4, point format 6, extra bytes for the other fields)."""
    return [write_las(Path(out_dir) / "las" / f"{frame_stem(frame_index)}.las", points)]


def write_frame_npy(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, sequence: int = 0) -> list[Path]:
    """``OUT/npy/NNNNNN/{coord,strength,segment,instance}.npy`` (Pointcept layout)."""
    return write_npy_folder(Path(out_dir) / "npy" / frame_stem(frame_index), points)


def write_frame_preview(out_dir: str | os.PathLike, frame_index: int, points: np.ndarray, color_lut: np.ndarray, boxes: np.ndarray | None = None,
                        names: dict | None = None) -> Path:
    """``OUT/preview/NNNNNN.png``: perspective and top view coloured by ``color_lut`` (k, 3) uint8, ``boxes`` drawn, a legend of ``names``."""
    return write_preview(Path(out_dir) / "preview" / f"{frame_stem(frame_index)}.png", points, color_lut, boxes=boxes, names=names)

