"""Write files and folders under a temporary name, then rename: nothing half-written under a final name.

docs/datasets.md, "How a frame is committed": a frame that fails leaves no half-written file behind. Every writer in
:mod:`bpy_pipeline.io` writes to a temporary sibling of its destination and renames it into place
only when the write succeeded. The temporary name lives in the destination folder (so the rename
stays on one file system and is atomic), starts with ``.`` and ends with ``.tmp``, so globs such
as ``*.ply`` and most file browsers skip it.

Digests while writing: inside :func:`digests_while_writing`, a file a writer writes through
:func:`hashed_open` (into the temporary file :func:`atomic_write` gave it) gets its sha256 computed
from the bytes as they are written; when :func:`atomic_write` renames it into place, the digest is
recorded under the final path, if the file on disk holds exactly as many bytes as went through the
hash (anything written past the hashing handle leaves the file without a digest: the caller then
reads it back). The dataset's commit uses it instead of reading every file again.
"""

from __future__ import annotations

import contextvars
import hashlib
import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

# {"done": {final path: sha256 hex}, "open": {temporary path: (sha256 hex, bytes)}} of the innermost digests_while_writing block
_DIGESTS: contextvars.ContextVar[dict | None] = contextvars.ContextVar("bpy_pipeline_digests", default=None)


def _key(path) -> str:
    return os.path.abspath(os.fspath(path))


@contextmanager
def digests_while_writing() -> Iterator[dict[str, str]]:
    """Yield ``{absolute final path: sha256 hex}``, filled as files written through :func:`hashed_open`
    inside :func:`atomic_write` are renamed into place within the block (threads started with
    :func:`contextvars.copy_context` of the block record into it too)."""
    state = {"done": {}, "open": {}}
    token = _DIGESTS.set(state)
    try:
        yield state["done"]
    finally:
        _DIGESTS.reset(token)


WRITE_SLICE = 1 << 20  # bytes handed to the kernel per write call (see HashedFile)


class HashedFile:
    """A binary file opened for writing whose bytes also go through sha256 (:func:`hashed_open`).

    ``write(data)`` takes bytes or any contiguous buffer (a numpy array's ``memoryview``). It is hashed in one call (or,
    for the file's first write, ``write(data, digest)`` takes ``digest``, a sha256 object of exactly ``data``'s bytes, in
    place of hashing them again: bytes several files hold, hashed once) and
    handed to the kernel in calls of :data:`WRITE_SLICE` bytes: at times, one write call of 2 MB or more cost this
    project's machine (Linux 6.18, ext4) about ten times the kernel time of the same bytes in calls of 1 MB or less
    (``benchmarks/bench_write_calls.py``, docs/performance.md); slices were never slower. Each call lets other
    threads take the interpreter, so the slices are as large as that allows. The file's bytes and digest are the same.
    """

    def __init__(self, path):
        self.path = path
        self.raw = open(path, "wb")
        self.digest = hashlib.sha256()
        self.size = 0

    def write(self, data, digest=None) -> int:
        if hasattr(data, "view") and hasattr(data, "dtype"):  # a numpy array: its raw bytes, as ndarray.tofile writes them
            import numpy as np

            data = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
        view = memoryview(data).cast("B")
        if digest is None:
            self.digest.update(view)
        elif self.size:
            raise ValueError(f"{self.path}: a digest of the data written is taken only for a file's first write")
        else:
            self.digest = digest.copy()
        for start in range(0, len(view), WRITE_SLICE):
            self.raw.write(view[start : start + WRITE_SLICE])
        self.size += len(view)
        return len(view)

    def close(self) -> None:
        if self.raw.closed:
            return
        self.raw.close()
        state = _DIGESTS.get()
        if state is not None:
            state["open"][_key(self.path)] = (self.digest.hexdigest(), self.size)

    def __enter__(self) -> "HashedFile":
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is not None:
            self.raw.close()  # nothing recorded for a failed write
            return
        self.close()


def hashed_open(path) -> HashedFile:
    """Open ``path`` (an :func:`atomic_write` temporary file) for writing, hashing what is written."""
    return HashedFile(path)


def write_text_hashed(path, text: str) -> None:
    """Write ``text`` to ``path`` (an :func:`atomic_write` temporary file) with the bytes ``Path.write_text`` writes
    (the locale's encoding, or UTF-8 in Python's UTF-8 mode; newlines as ``os.linesep``), hashed as written."""
    import locale
    import sys

    encoding = "utf-8" if sys.flags.utf8_mode else locale.getpreferredencoding(False)
    with hashed_open(path) as handle:
        handle.write((text.replace("\n", os.linesep) if os.linesep != "\n" else text).encode(encoding))


def temporary_sibling(path: Path, suffix: str = ".tmp") -> Path:
    """A fresh, unused name next to ``path``: ``.<name>.<random hex><suffix>``."""
    path = Path(path)
    return path.with_name(f".{path.name}.{secrets.token_hex(4)}{suffix}")


def temporary_files(folder: Path) -> list[Path]:
    """The files in ``folder`` named as :func:`temporary_sibling` names them: what writes a kill cut short left behind."""
    return [path for path in Path(folder).glob(".*.tmp") if path.is_file()]


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
        state = _DIGESTS.get()
        hashed = state["open"].pop(_key(tmp), None) if state is not None else None
        os.replace(tmp, path)
        if hashed is not None and os.stat(path).st_size == hashed[1]:
            state["done"][_key(path)] = hashed[0]
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
