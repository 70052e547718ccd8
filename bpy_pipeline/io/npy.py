"""Pointcept-style NPY folders: one folder per frame, one ``.npy`` file per attribute.

Folder contents (Pointcept's ``DefaultDataset`` asset names)::

    coord.npy     (n, 3) float32   x y z, metres
    strength.npy  (n, 1) float32   intensity, 0..1
    segment.npy   (n,)   int32     training id - 1 (``learning_map`` of assets_manifest/labels.yaml):
                                   0..K-1, and -1 (Pointcept's ignore index) for unlabeled and ghost points
    instance.npy  (n,)   int32     instance id of "things" (labels.yaml ``things``); -1 (ignored) for
                                   stuff classes and where the point record says 0 (no instance)

ring, time, range and bounces are not part of the layout and are not kept.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, path_argument
from ..lidar.points import POINT_DTYPE
from ._records import as_points, chunks
from .atomic import atomic_dir
from .class_maps import ClassMaps, load_class_maps

NPY_FILES = ("coord", "strength", "segment", "instance")
IGNORE_INDEX = -1


def write_npy_folder(folder: str | os.PathLike, points: np.ndarray, maps: ClassMaps | None = None) -> list[Path]:
    """Write ``points`` as a Pointcept frame folder (see the module docstring for the files).

    Parameters
    ----------
    folder : str or PathLike
        The frame folder; it appears atomically (written under a temporary name, then renamed),
        replacing an existing folder of the same name as a whole.
    points : (n,) POINT_DTYPE
        Points (``n`` may be 0); ``instance`` must fit int32 (< 2**31).
    maps : the class table's maps (default: :func:`~.class_maps.load_class_maps`)

    Returns
    -------
    paths : list of Path
        ``[coord.npy, strength.npy, segment.npy, instance.npy]`` inside ``folder``.
    """
    folder = Path(folder)
    pts = as_points(points, str(folder))
    maps = load_class_maps() if maps is None else maps
    n = len(pts)
    if n and int(pts["instance"].max()) > np.iinfo(np.int32).max:
        raise InputError(f"{folder}: Pointcept instance.npy is int32; got instance ids up to {int(pts['instance'].max())}")
    columns = {  # name -> (dtype, shape of a row, the rows of a slice of the points)
        "coord": (np.float32, (3,), lambda s: np.stack([pts["x"][s], pts["y"][s], pts["z"][s]], axis=1).astype(np.float32)),
        "strength": (np.float32, (1,), lambda s: pts["intensity"][s].astype(np.float32).reshape(-1, 1)),
        "segment": (np.int32, (), lambda s: maps.segment(pts["semantic"][s])),
        "instance": (np.int32, (), lambda s: np.where((pts["instance"][s] == 0) | ~maps.things[pts["semantic"][s]], IGNORE_INDEX,
                                                      pts["instance"][s].astype(np.int64)).astype(np.int32)),
    }
    with atomic_dir(folder) as tmp:
        for name in NPY_FILES:  # the bytes of np.save, written a chunk at a time
            dtype, row, rows = columns[name]
            with open(tmp / f"{name}.npy", "wb") as f:
                np.lib.format.write_array_header_1_0(f, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False, "shape": (n, *row)})
                for part in chunks(n):
                    rows(part).tofile(f)
    return [folder / f"{name}.npy" for name in NPY_FILES]


def read_npy_folder(folder: str | os.PathLike, maps: ClassMaps | None = None) -> np.ndarray:
    """Read a Pointcept frame folder as ``(n,)`` :data:`POINT_DTYPE`.

    ``coord.npy`` is required; ``strength``, ``segment`` and ``instance`` are read when
    present. Negative segment and instance values (Pointcept's ignore index) become 0
    (unlabeled, no instance). ``segment`` is taken as is (another dataset's ids), or, with
    ``maps`` (a folder this package wrote), turned back into raw ids (the first raw id of each
    training id; ignored points are unlabeled). ring, time, range and bounces are zero.
    ``InputError`` naming the file for a missing coord file or mismatched shapes.
    """
    folder = Path(path_argument(folder, "folder"))
    coord_path = folder / "coord.npy"
    if not coord_path.is_file():
        raise InputError(f"{coord_path}: missing; a Pointcept frame folder needs coord.npy")
    coord = np.load(coord_path, allow_pickle=False)
    if coord.ndim != 2 or coord.shape[1] != 3:
        raise InputError(f"{coord_path}: expected shape (n, 3), got {coord.shape}")
    n = len(coord)
    out = np.zeros(n, POINT_DTYPE)
    out["x"], out["y"], out["z"] = coord.T
    for name, field in (("strength", "intensity"), ("segment", "semantic"), ("instance", "instance")):
        path = folder / f"{name}.npy"
        if not path.is_file():
            continue
        values = np.load(path, allow_pickle=False)
        if values.shape not in ((n,), (n, 1)):
            raise InputError(f"{path}: expected shape ({n},) or ({n}, 1) to match coord.npy, got {values.shape}")
        values = values.reshape(n)
        if field == "intensity":
            out[field] = values
        elif field == "semantic" and maps is not None:
            out[field] = maps.raw_of_segment(values)
        else:
            out[field] = np.where(values < 0, 0, values)
    return out


def write_index(out_dir: str | os.PathLike, records: list[dict], config) -> list[Path]:
    """Pointcept split lists ``OUT/npy_{train,val,test}.json`` by ``output.split`` (:mod:`.splits`); none for an empty split.

    Each lists frame folders relative to ``OUT`` (``npy/NNNNNN``): Pointcept's ``DefaultDataset`` with
    ``data_root=OUT`` and ``split="npy_train.json"`` reads such a file as its list of frames.
    """
    import json

    from .atomic import atomic_write
    from .splits import split_indices

    written = []
    for name, frames in split_indices([r["index"] for r in records], config.output.split, config.frames).items():
        path = Path(out_dir) / f"npy_{name}.json"
        if not frames:
            path.unlink(missing_ok=True)
            continue
        with atomic_write(path) as tmp:
            tmp.write_text(json.dumps([f"npy/{i:06d}" for i in frames]) + "\n")
        written.append(path)
    return written
