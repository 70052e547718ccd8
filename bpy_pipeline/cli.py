"""The command line of run.py: ``[--config FILE] [--out DIR] [--seed N] [--frames N] [--set key.path=value ...]``.

Works the same under ``python run.py ...`` and ``blender --background --python run.py -- ...``
(Blender's own arguments come before ``--`` and are ignored).
"""

from __future__ import annotations

import argparse
import sys

from .errors import InputError


def script_arguments(argv: list[str]) -> list[str]:
    """The arguments meant for the script: after ``--`` when present (Blender's layout), else argv[1:]."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="run.py", description="Generate labeled LiDAR frames from a procedural Blender scene.")
    p.add_argument("--config", help="YAML config file (default: the embedded railway scene)")
    p.add_argument("--out", default="out", help="output folder (default: ./out)")
    p.add_argument("--seed", type=int, help="run seed (overrides the config)")
    p.add_argument("--frames", type=int, help="number of frames (overrides the config)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override one config key (repeatable)")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the pipeline; returns the process exit code (2 on bad input)."""
    args = parser().parse_args(script_arguments(sys.argv if argv is None else argv))
    overrides = list(args.set)
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    if args.frames is not None:
        overrides.append(f"frames={args.frames}")
    try:
        from .config import load_config

        config = load_config(args.config, overrides)
        try:
            import bpy
        except ImportError:
            raise InputError("bpy: Blender's Python module is not installed; pip install 'bpy==4.5.*' (Python 3.11), or run blender --background --python run.py -- ...") from None
        bpy.ops.wm.read_factory_settings(use_empty=True)
        from .pipeline import run

        run(config, args.out)
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    return 0
