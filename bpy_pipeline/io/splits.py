"""The train/val split of a dataset's frames, shared by every index (KITTI and OpenPCDet ImageSets, Pointcept lists).

Each frame gets a key drawn from ``(seed, frame index)`` alone, and the ``val_fraction`` of the
frames with the smallest keys form the validation set, so the split depends only on the seed and
on which frames exist, never on the order they were made in, the workers or a resume.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

SPLIT_STREAM = 0x5B117  # a stream of the seed used by nothing else


def split_frames(indices, seed: int, val_fraction: float) -> tuple[list[int], list[int]]:
    """``(train, val)`` sorted frame indices of ``indices``; ``round(val_fraction * n)`` frames in val, at least one from n = 2 on."""
    if not 0.0 <= float(val_fraction) < 1.0:
        raise InputError(f"output.kitti.val_fraction: must be >= 0 and < 1, got {val_fraction}")
    indices = sorted(int(i) for i in indices)
    n = len(indices)
    count = int(round(val_fraction * n))
    if val_fraction > 0 and n >= 2:
        count = min(max(count, 1), n - 1)
    keys = [np.random.default_rng([int(seed), SPLIT_STREAM, i]).random() for i in indices]
    val = sorted(indices[k] for k in np.argsort(keys, kind="stable")[:count])
    chosen = set(val)
    return [i for i in indices if i not in chosen], val
