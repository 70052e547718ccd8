"""``python -m bpy_pipeline.cli.tiles DATASET OUT [--size M] [--overlap M] [--points N] ...``: every frame of a dataset
folder (its PLY files) cut into training tiles by :func:`bpy_pipeline.io.tiles.export_tiles`."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..geometry.tiles import SAMPLING_METHODS
from ..io.tiles import TileSettings, export_tiles


def main(argv: list[str] | None = None) -> int:
    """Tile every frame of a dataset folder (its PLY files) into ``OUT/<frame>/``."""
    from ..io.ply import read_ply

    parser = argparse.ArgumentParser(prog="python -m bpy_pipeline.cli.tiles", description="Tile every frame of a dataset folder for training.")
    parser.add_argument("dataset", type=Path)
    parser.add_argument("out", type=Path)
    defaults = TileSettings()
    parser.add_argument("--size", type=float, default=defaults.size)
    parser.add_argument("--overlap", type=float, default=defaults.overlap)
    parser.add_argument("--points", type=int, default=defaults.points)
    parser.add_argument("--method", default=defaults.method, choices=SAMPLING_METHODS)
    parser.add_argument("--class-aware", action="store_true")
    parser.add_argument("--max-range", type=float, default=defaults.max_range)
    parser.add_argument("--coarse", action="store_true", help="segment.npy in the coarse classes of labels.yaml")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    settings = TileSettings(args.size, args.overlap, args.points, args.method, args.class_aware, args.max_range, coarse=args.coarse)
    plys = sorted((args.dataset / "ply").glob("*.ply"))
    if not plys:
        raise SystemExit(f"{args.dataset}: no ply/*.ply frames (run with output.formats including ply)")
    for k, ply in enumerate(plys):
        rng = np.random.default_rng(np.random.SeedSequence([args.seed, k]))
        written = export_tiles(read_ply(ply), args.out, ply.stem, settings, rng)
        print(f"{ply.stem}: {len(written)} tiles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
