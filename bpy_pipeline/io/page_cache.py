"""A run's own files leave the page cache once they are on their way to disk.

Left to itself, Linux keeps every page a run writes: dirty until its flusher writes it back (some
30 s later), then cached until memory runs short. The ego street writes about 12 MB a frame, so a
100-frame job leaves 1.2 GB of its own output in memory, pushes out what the user had cached (their
training data, say), and takes a page never used before for every 4 kB it writes. On a virtual
machine that gives freed memory back to its host (as this project's does), the first touch of such
a page is a fault in the host, and the kernel's copy into it can cost several times the copy into a
page used a moment ago (``benchmarks/bench_page_cache.py``, docs/performance.md).

:class:`PageCacheRelease` does what ``dd oflag=nocache`` and PostgreSQL's ``backend_flush_after``
do: ``posix_fadvise(POSIX_FADV_DONTNEED)`` on a frame's large files (1 MiB and more: a street
frame's points and PLY) right after they are committed starts their write-back, and the same call
one frame later, when they are on disk, hands their pages back, so the next frame's writes reuse
them. The calls run on a thread of their own: starting a write-back can wait for the disk, and the
run does not. The bytes on disk are the same; a file still being written back is simply left
cached. Where ``os.posix_fadvise`` does not exist (Windows, macOS) nothing is done.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

MIN_BYTES = 1 << 20  # smaller files (texts, previews, images) hold few pages: left to the kernel's flusher


def _size(path: Path) -> int:
    """``path``'s size in bytes, 0 when it cannot be read."""
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def advise_dont_need(path: Path) -> None:
    """``posix_fadvise(DONTNEED)`` on the whole of ``path``: start writing its dirty pages back and drop its clean ones.
    A file that is gone or cannot be opened is left alone (this only ever saves memory)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    except OSError:
        pass
    finally:
        os.close(fd)


@dataclass
class PageCacheRelease:
    """Hands back the page cache of the files of each committed frame, one frame after they were written.

    behind : the files of the last call of :meth:`written`, whose pages the next call drops
    """

    behind: list[Path] = field(default_factory=list)
    _thread: ThreadPoolExecutor | None = field(default=None, repr=False)  # where :meth:`written_later` calls :meth:`written`

    @staticmethod
    def available() -> bool:
        """Whether this platform has ``posix_fadvise`` (Linux and most Unix systems)."""
        return hasattr(os, "posix_fadvise")

    def written(self, paths: Iterable[Path]) -> None:
        """``paths``, just written, start on their way to disk; the pages of the files of the call before, on disk by
        now, are handed back. Files under :data:`MIN_BYTES` are left to the kernel."""
        if not self.available():
            return
        large = [path for path in paths if _size(path) >= MIN_BYTES]
        for path in large + self.behind:
            advise_dont_need(path)
        self.behind = large

    def written_later(self, paths: Iterable[Path]) -> None:
        """:meth:`written` on a thread of its own (made on the first call), in the order of the calls: starting a write-back
        can wait for the disk's queue, and the run does not wait for it (a slow disk leaves pages cached a little longer)."""
        if not self.available():
            return
        if self._thread is None:
            self._thread = ThreadPoolExecutor(1, "page cache release")
        self._thread.submit(self.written, list(paths))

    def close(self) -> None:
        """Wait for the calls :meth:`written_later` queued, and stop its thread."""
        if self._thread is not None:
            self._thread.shutdown()
            self._thread = None
