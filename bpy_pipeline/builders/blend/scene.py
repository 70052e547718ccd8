"""``scene.builder: blend``: the user's own .blend file, labelled by custom properties and name rules."""

from __future__ import annotations

from pathlib import Path

import bpy

from ...errors import InputError


def _path(params) -> Path:
    path = Path(params.path).expanduser()
    if not path.is_file():
        raise InputError(f"scene.path: {path} does not exist or is not a file")
    if path.suffix.lower() != ".blend":
        raise InputError(f"scene.path: {path} is not a .blend file")
    return path.resolve()


def build(params) -> None:
    """Open ``params.path`` as the current file."""
    path = _path(params)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    except RuntimeError as err:
        raise InputError(f"scene.path: Blender cannot open {path} ({str(err).strip().splitlines()[-1]})") from None


class OpenedBlend:
    """The user's file opened once for a run: alive while it is Blender's current file and unchanged on disk."""

    def __init__(self, params):
        build(params)
        self.path = _path(params)
        self.stamp = self.path.stat().st_mtime_ns

    def alive(self) -> bool:
        return Path(bpy.data.filepath or "/").resolve() == self.path and self.path.exists() and self.path.stat().st_mtime_ns == self.stamp
