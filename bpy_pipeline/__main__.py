"""``python -m bpy_pipeline COMMAND ...``: tools around the pipeline (``run.py`` generates frames).

Commands:

``sensors [list]``
    The sensor presets, one line each: pattern, channels, elevation range, columns, rays a
    frame, rate and range.
``sensors show NAME [--rays FILE.npy]``
    One preset's resolved fields and summary; ``--rays`` saves the ray directions of a full
    frame as ``(n, 3)`` float32 in the sensor frame (x forward, y left, z up).

Each command is a ``_add_<name>(subparsers)`` function that registers its parser and sets
``func`` (``args -> exit code``); add new commands the same way. Bad input (``InputError``)
prints one line and exits with code 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import yaml

from .errors import InputError
from .lidar import sensors


_LINE = "{:<16} {:<11} {:>8}  {:>17}  {:>7}  {:>11}  {:>8}  {:>9}"


def preset_line(name: str) -> str:
    """One listing line of a preset's key figures."""
    s = sensors.spec_summary(sensors.resolve_sensor({"preset": name}))
    el_lo, el_hi = s["elevation_deg"]
    lo, hi = s["range_m"]
    return _LINE.format(
        name, s["pattern"], s["channels"], f"{el_lo:+.2f}..{el_hi:+.2f}", s["columns"], f"{s['rays_per_frame']:,}",
        f"{1.0 / s['frame_time_s']:g}", f"{lo:g}-{hi:g}",
    )


def list_sensors(args) -> int:
    print(_LINE.format("preset", "pattern", "channels", "elevation deg", "columns", "rays/frame", "rate Hz", "range m"))
    for name in sensors.presets():
        print(preset_line(name))
    return 0


def show_sensor(args) -> int:
    names = list(sensors.presets())
    if args.name not in names:
        raise InputError(f"sensors show: unknown preset {args.name!r}; allowed: {', '.join(names)}")
    spec = sensors.resolve_sensor({"preset": args.name}, where=args.name)
    print(yaml.safe_dump({"fields": sensors.spec_fields(spec), "summary": sensors.spec_summary(spec)}, sort_keys=False, width=100, default_flow_style=None), end="")
    if args.rays:
        n = save_rays(spec, args.rays)
        print(f"rays: {n:,} directions (float32, sensor frame) written to {args.rays}")
    return 0


def save_rays(spec: sensors.SensorSpec, path: str | Path, chunk_rays: int = 1 << 20) -> int:
    """Write a full frame's ray directions as an ``(n, 3)`` float32 ``.npy``, chunk by chunk, atomically."""
    path = Path(path)
    total = sensors.ray_count(spec)
    tmp = path.with_name(path.name + ".tmp")
    try:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=(total, 3))
    except OSError as err:
        raise InputError(f"--rays: cannot write {path} ({err.strerror or err})") from None
    try:
        start = 0
        for part in sensors.iter_pattern(spec, chunk_rays):
            out[start : start + len(part)] = part.directions
            start += len(part)
        out.flush()
        del out
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return total


def _add_sensors(sub) -> None:
    p = sub.add_parser("sensors", help="list the sensor presets or show one", description="List the sensor presets or show one.")
    p.set_defaults(func=list_sensors)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.add_parser("list", help="one line per preset (the default)").set_defaults(func=list_sensors)
    show = actions.add_parser("show", help="one preset's resolved fields and summary")
    show.add_argument("name", metavar="NAME", help="preset name")
    show.add_argument("--rays", metavar="FILE.npy", help="save its ray directions for a full frame, (n, 3) float32, sensor frame")
    show.set_defaults(func=show_sensor)


COMMANDS = [_add_sensors]


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bpy_pipeline", description="Tools around the bpy_pipeline LiDAR generator (frames: run.py).")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in COMMANDS:
        add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 on bad input)."""
    args = parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        return args.func(args)
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code


if __name__ == "__main__":
    sys.exit(main())
