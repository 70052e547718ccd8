"""Geometry Nodes groups kept on disk between runs, so a run's first build appends a group that the same code made
before instead of making it again node by node.

Making a group costs Blender an update of the whole tree at every link: the parking level's 297 links take 66 ms
of its 0.13-0.2 s, the railway's seven groups about 0.15 s; appending a kept one takes about 6 ms.

A group is kept in ``<folder>/<Blender version>/<name>.v<version>.<code digest>.blend`` with the groups it uses.
The digest covers every Python file of the package, so changed code never meets a group the old code made.
``<folder>`` is ``$BPY_PIPELINE_CACHE/node_groups``, or ``$XDG_CACHE_HOME/bpy_pipeline/node_groups``
(``~/.cache/...``; in Blender's extension, its user folder); ``BPY_PIPELINE_CACHE=""`` keeps nothing. A cache
that cannot be read or written is passed over: the group is made as before (a file that fails to load is
removed, to be written again).
"""

from __future__ import annotations

import functools
import hashlib
import os
import secrets
from pathlib import Path

import bpy

ENV = "BPY_PIPELINE_CACHE"
PACKAGE = Path(__file__).resolve().parents[1]


def folder() -> Path | None:
    """Where groups are kept, or ``None`` when ``$BPY_PIPELINE_CACHE`` is set empty. Inside Blender's extension
    (package ``bl_ext.<repo>.<id>.bpy_pipeline``), the extension's own user folder, as Blender's rules ask."""
    chosen = os.environ.get(ENV)
    if chosen is not None:
        return Path(chosen) / "node_groups" if chosen else None
    if __package__.startswith("bl_ext."):
        return Path(bpy.utils.extension_path_user(__package__.rsplit(".", 2)[0], path="node_groups"))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "bpy_pipeline" / "node_groups"


@functools.cache
def code_digest() -> str:
    """sha256 (hex, 16 digits) of the package's Python files, names and bytes (about 10 ms; once a process)."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        digest.update(str(path.relative_to(PACKAGE)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def path_of(name: str, version: int) -> Path | None:
    """The file group ``name`` of builder version ``version`` is kept in (``None``: nothing is kept)."""
    root = folder()
    return None if root is None else root / bpy.app.version_string.replace(" ", "_") / f"{name}.v{version}.{code_digest()}.blend"


def load(name: str, version: int) -> bpy.types.NodeTree | None:
    """Group ``name`` appended from its kept file (with the groups it uses), or ``None``: no file, a file that
    does not load, or a group of one of its names already in the session (the append would rename it)."""
    path = path_of(name, version)
    if path is None or not path.is_file():
        return None
    before = set(bpy.data.libraries)
    try:
        with bpy.data.libraries.load(str(path), link=False) as (source, target):
            names = list(source.node_groups)
            clash = name not in names or any(n in bpy.data.node_groups for n in names)
            target.node_groups = [] if clash else names
    except Exception:  # a damaged or foreign file: made again, and kept anew
        path.unlink(missing_ok=True)
        return None
    finally:
        for library in set(bpy.data.libraries) - before:  # the appended groups are local: the file is not referenced
            bpy.data.libraries.remove(library)
    return None if clash else bpy.data.node_groups.get(name)


def keep(group: bpy.types.NodeTree, version: int) -> None:
    """Write ``group`` (and the groups it uses) to its file unless it is there; written whole or not at all."""
    path = path_of(group.name, version)
    if path is None or path.is_file():
        return
    temporary = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        bpy.data.libraries.write(str(temporary), {group}, fake_user=True)
        os.replace(temporary, path)
    except OSError:
        temporary.unlink(missing_ok=True)
