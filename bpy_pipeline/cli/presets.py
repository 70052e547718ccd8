"""``bpy-pipeline sensors [list]`` and ``bpy-pipeline sensors show NAME [--rays FILE.npy]``: the sensor presets.

``list`` (the default) prints one line a preset: pattern, channels, elevation range, columns, rays a frame,
rate and range. ``show`` prints one preset's resolved fields and summary; ``--rays`` saves the ray directions
of a full frame as ``(n, 3)`` float32 in the sensor frame (x forward, y left, z up).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError
from ..lidar.sensor import sensors
from .subcommand import Command

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
    shown = {"fields": sensors.spec_fields(spec), "summary": sensors.spec_summary(spec), "effects": sensors.preset_effects(args.name),
             "sources": sensors.preset_sources(args.name)}
    print(yaml.safe_dump(shown, sort_keys=False, width=100, default_flow_style=None), end="")
    if args.rays:
        if Path(args.rays).is_dir() or not Path(args.rays).parent.is_dir():
            raise InputError(f"--rays: {args.rays} must be a file path in an existing folder (FILE.npy)")
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
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise InputError(f"--rays: cannot write {path} ({err.strerror or err})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return total



def arguments(p) -> None:
    p.set_defaults(func=list_sensors)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.add_parser("list", help="one line per preset (the default)").set_defaults(func=list_sensors)
    show = actions.add_parser("show", help="one preset's resolved fields and summary")
    show.add_argument("name", metavar="NAME", help="preset name")
    show.add_argument("--rays", metavar="FILE.npy", help="save its ray directions for a full frame, (n, 3) float32, sensor frame")
    show.set_defaults(func=show_sensor)


COMMAND = Command("sensors", "list the sensor presets or show one", "List the sensor presets or show one.", arguments)
