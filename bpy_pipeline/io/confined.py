"""Paths read from inside a folder (a dataset's intents and records, a glTF's buffer URIs) kept inside it.

A file the project reads names other files by relative paths: an intent or a record of ``OUT`` names
the frame's files, a glTF names its buffers. Such a name is trusted only when it stays inside its
folder: relative, no component leaving it (``..``), no symlink on the way pointing out of it, and, to
be read, a regular file of bounded size (never ``/dev/zero`` or a FIFO, which read for ever).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path


def inside(folder: str | os.PathLike, name) -> Path | None:
    """``folder / name`` when ``name`` is a relative path (a ``str``) that stays inside ``folder`` with every
    symlink of its parent folders resolved, else ``None``. The last component is not followed: removing the
    path removes a symlink, not its target."""
    if not isinstance(name, str) or not name or "\x00" in name or os.path.isabs(name):
        return None
    root = os.path.realpath(folder)
    path = Path(folder) / name
    parent = os.path.realpath(path.parent)
    if path.name in ("", ".", "..") or not (parent == root or parent.startswith(root + os.sep)):
        return None
    return path


def readable_inside(folder: str | os.PathLike, name, max_bytes: int) -> tuple[Path | None, str]:
    """``(path, "")`` when ``name`` names a regular file of at most ``max_bytes`` inside ``folder`` (symlinks
    followed, the target inside too); else ``(None, why)`` in a few words."""
    path = inside(folder, name)
    if path is None:
        return None, "not a relative path inside its folder"
    root, real = os.path.realpath(folder), os.path.realpath(path)
    if not real.startswith(root + os.sep):
        return None, "a link pointing outside its folder"
    try:
        info = os.stat(real)
    except OSError as err:
        return None, f"cannot be read ({err.strerror or err})"
    if not stat.S_ISREG(info.st_mode):
        return None, "not a regular file"
    if info.st_size > max_bytes:
        return None, f"{info.st_size:,} bytes, more than the {max_bytes:,} allowed"
    return path, ""


def refuse_output_over_input(out, inputs, option: str = "--out") -> None:
    """:class:`~bpy_pipeline.errors.InputError` when the file ``out`` is one of ``inputs`` (the same path once
    links are resolved): a command never writes its result over what it reads."""
    from ..errors import InputError

    target = os.path.realpath(out)
    for given in inputs:
        if given and os.path.realpath(given) == target:
            raise InputError(f"{option}: {out} is the input {given}; write to a file of its own (nothing was written)")
