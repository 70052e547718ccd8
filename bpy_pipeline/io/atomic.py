"""Write files and folders under a temporary name, then rename: nothing half-written under a final name.

DESIGN.md, "Bad input": a frame that fails leaves no half-written file behind. Every writer in
:mod:`bpy_pipeline.io` writes to a temporary sibling of its destination and renames it into place
only when the write succeeded. The temporary name lives in the destination folder (so the rename
stays on one file system and is atomic), starts with ``.`` and ends with ``.tmp``, so globs such
as ``*.ply`` and most file browsers skip it.
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def temporary_sibling(path: Path, suffix: str = ".tmp") -> Path:
    """A fresh, unused name next to ``path``: ``.<name>.<random hex><suffix>``."""
    path = Path(path)
    return path.with_name(f".{path.name}.{secrets.token_hex(4)}{suffix}")


def remove(path: Path) -> None:
    """Remove a file, symlink or folder tree if it exists; never raises for a missing path."""
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


@contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary file path next to ``path``; rename it onto ``path`` when the block succeeds.

    Parent folders are created. The block must create the yielded file (the context manager does
    not). On any exception, ``KeyboardInterrupt`` included, the temporary file is removed, the
    exception propagates and an existing file at ``path`` is left untouched.

    Example::

        with atomic_write(out / "a.bin") as tmp:
            data.tofile(tmp)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_sibling(path)
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"{path}: nothing was written to the temporary file {tmp.name}")
        os.replace(tmp, path)
    except BaseException:
        remove(tmp)
        raise


@contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a fresh temporary folder next to ``path``; rename it onto ``path`` when the block succeeds.

    Like :func:`atomic_write`, for a folder of files (Pointcept NPY frames). An existing
    ``path`` is first renamed aside and removed only after the new folder is in place, so
    ``path`` never holds a mix of old and new files; between the two renames ``path`` is
    briefly absent. On any exception the temporary folder is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_sibling(path)
    tmp.mkdir()
    try:
        yield tmp
        if path.exists() or path.is_symlink():
            old = temporary_sibling(path, ".old.tmp")
            os.replace(path, old)
            try:
                os.replace(tmp, path)
            except BaseException:
                os.replace(old, path)
                raise
            remove(old)
        else:
            os.replace(tmp, path)
    except BaseException:
        remove(tmp)
        raise
