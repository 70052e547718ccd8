"""``scene.builder: blend``: the user's own .blend file, labelled by custom properties and name rules."""

from __future__ import annotations

from pathlib import Path

import bpy

from ..errors import InputError


def build(params) -> None:
    """Open ``params.path`` as the current file."""
    path = Path(params.path).expanduser()
    if not path.is_file():
        raise InputError(f"scene.path: {path} does not exist or is not a file")
    if path.suffix.lower() != ".blend":
        raise InputError(f"scene.path: {path} is not a .blend file")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path.resolve()), load_ui=False)
    except RuntimeError as err:
        raise InputError(f"scene.path: Blender cannot open {path} ({str(err).strip().splitlines()[-1]})") from None
