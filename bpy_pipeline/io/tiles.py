"""A training export for large static scans: tiles sampled to N points, as Pointcept / S3DIS-style folders. Pure.

``export_tiles(points, out, name, settings, rng)`` cuts one cloud (a frame's POINT_DTYPE records,
e.g. a railway station's 23 M-point scan) into tiles (:mod:`bpy_pipeline.geometry.tiles`) and
writes each as a Pointcept folder (:func:`~.npy.write_npy_folder`: coord, strength, segment,
instance; ``segment`` in the coarse classes of labels.yaml with ``coarse``, named in ``coarse.json``)
plus ``core.npy`` ((n,) bool: the point lies in the tile's own core, not in the overlap it shares
with a neighbour)::

    OUT/<name>/<name>_x<i>_y<j>/{coord,strength,segment,instance,core}.npy
    OUT/<name>/tiles.json        per tile: key, bounds (m), points before and after sampling,
                                 class histogram of its core before sampling ({"class id": count})

Pointcept's S3DIS reader takes ``Area_k/room/`` folders the same way (name an area per scan).
A whole dataset folder: ``python -m bpy_pipeline.cli.tiles DATASET OUT --size 10 --overlap 2
--points 8192 --method fps --class-aware --max-range 60``; each frame's PLY becomes ``OUT/<frame>/``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..schema import check_ranges, meta
from ..geometry.tiles import SAMPLING_METHODS, sample, tiles
from .atomic import atomic_write
from .npy import write_npy_folder
from ..yaml_text import load_yaml


@dataclass(frozen=True)
class TileSettings:
    """size, overlap (m, in plan); points per tile (0: keep all); method ``random`` | ``fps``; class_aware;
    max_range (m from the sensor, the ``range`` field; 0: no crop); min_points: tiles with fewer core points are skipped."""

    size: float = field(default=10.0, metadata=meta("m", low=0, low_open=True))
    overlap: float = field(default=0.0, metadata=meta("m", low=0, help="below size"))
    points: int = field(default=8192, metadata=meta("", low=0, help="0: keep every point"))
    method: str = "random"
    class_aware: bool = False
    max_range: float = field(default=0.0, metadata=meta("m", low=0, help="0: no crop"))
    min_points: int = 1
    coarse: bool = False  # segment.npy holds the coarse classes of labels.yaml (coarse.json names them)

    def check(self) -> None:
        """``InputError`` naming the key: the fields' ranges (their metadata), the overlap below the size, a known method."""
        check_ranges(self, "tiles")
        if self.overlap >= self.size:
            raise InputError(f"tiles.overlap: must stay below size ({self.size} m), got {self.overlap}")
        if self.method not in SAMPLING_METHODS:
            raise InputError(f"tiles.method: must be one of {', '.join(SAMPLING_METHODS)}, got {self.method!r}")


def coarse_classes(path: Path | None = None) -> tuple[list[str], np.ndarray]:
    """The coarse level of the class table: its class names (index = coarse segment id) and a ``(raw ids,)``
    int32 lookup from raw ``semantic`` to coarse segment (-1 for unlabeled and ignored classes).
    A class the ``coarse`` section does not list is its own coarse class."""

    from ..labels import LABELS_PATH

    raw = load_yaml(Path(path or LABELS_PATH).read_text())
    names = {int(k): v for k, v in raw["labels"].items()}
    ignored = {int(k) for k, v in raw["learning_map"].items() if int(v) == 0}
    mapping = {str(k).replace("_", " ").lower(): str(v) for k, v in (raw.get("coarse") or {}).items()}
    coarse: list[str] = []
    lookup = np.full(max(names) + 1, -1, np.int32)
    for raw_id, name in sorted(names.items()):
        if raw_id in ignored:
            continue
        target = mapping.get(name.lower(), name)
        if target not in coarse:
            coarse.append(target)
        lookup[raw_id] = coarse.index(target)
    return coarse, lookup


def export_tiles(points: np.ndarray, out: str | Path, name: str, settings: TileSettings, rng: np.random.Generator) -> list[dict]:
    """Write the tiles of ``points`` ((n,) POINT_DTYPE) under ``out/name``; returns the per-tile index (also ``tiles.json``)."""
    settings.check()
    lookup = None
    if settings.coarse:
        coarse, lookup = coarse_classes()
        root = Path(out) / name
        root.mkdir(parents=True, exist_ok=True)
        with atomic_write(root / "coarse.json") as tmp:
            tmp.write_text(json.dumps({"names": coarse}, indent=1))
    if settings.max_range > 0:
        points = points[points["range"] <= settings.max_range]
    root = Path(out) / name
    xy = np.column_stack([points["x"], points["y"]]).astype(float)
    index = []
    for tile in tiles(xy, settings.size, settings.overlap):
        if tile.core.sum() < settings.min_points:
            continue
        chosen = points[tile.window]
        keep = np.arange(len(chosen))
        if settings.points:
            xyz = np.column_stack([chosen["x"], chosen["y"], chosen["z"]])
            keep = sample(xyz, settings.points, settings.method, rng, chosen["semantic"] if settings.class_aware else None)
        stem = f"{name}_x{tile.key[0]}_y{tile.key[1]}"
        write_npy_folder(root / stem, chosen[keep])
        if lookup is not None:  # the coarse level replaces the fine training ids
            with atomic_write(root / stem / "segment.npy") as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, lookup[chosen["semantic"][keep]])
        with atomic_write(root / stem / "core.npy") as tmp:
            with open(tmp, "wb") as f:
                np.save(f, tile.core[keep])
        classes, counts = np.unique(chosen["semantic"][tile.core], return_counts=True)
        index.append({"tile": stem, "key": list(tile.key), "bounds": [round(b, 4) for b in tile.bounds], "window_points": int(len(chosen)),
                      "core_points": int(tile.core.sum()), "written_points": int(len(keep)),
                      "core_histogram": {str(int(c)): int(k) for c, k in zip(classes, counts)}})
    with atomic_write(root / "tiles.json") as tmp:
        tmp.write_text(json.dumps({"name": name, "settings": settings.__dict__, "tiles": index}, indent=1))
    return index
