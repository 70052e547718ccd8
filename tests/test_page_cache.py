"""A run hands the page cache of its committed frames back one frame later, on a thread of its own (bpy_pipeline.io.page_cache): the pages of
a file on disk are dropped, the bytes stay the same, and a platform without ``posix_fadvise`` is left alone.
No timings here (benchmarks/bench_page_cache.py measures)."""

import hashlib
import os
import shutil
import subprocess
import threading

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.io import page_cache
from bpy_pipeline.io.page_cache import PageCacheRelease

needs_fadvise = pytest.mark.skipif(not PageCacheRelease.available(), reason="os.posix_fadvise is not on this platform")


def resident_pages(path) -> int:
    """How many of ``path``'s pages are in the page cache (util-linux ``fincore``)."""
    done = subprocess.run(["fincore", "--noheadings", "--raw", "--bytes", "--output", "PAGES", str(path)], capture_output=True, text=True, check=True)
    return int(done.stdout.split()[0])


@needs_fadvise
@pytest.mark.skipif(shutil.which("fincore") is None, reason="util-linux fincore is not installed")
def test_a_written_file_leaves_the_page_cache_once_the_next_frame_is_written(tmp_path):
    kind = subprocess.run(["stat", "--file-system", "--format", "%T", str(tmp_path)], capture_output=True, text=True).stdout.strip()
    if kind in ("tmpfs", "ramfs"):
        pytest.skip(f"{tmp_path} is on {kind}: its pages are the files themselves, never dropped")
    data = np.random.default_rng(0).integers(0, 256, 4 << 20, dtype=np.uint8)
    first, second = tmp_path / "first.bin", tmp_path / "second.bin"
    data.tofile(first)
    release = PageCacheRelease()
    release.written([first])  # its write-back starts; it stays cached until the next frame
    os.sync()  # the write-back done, as it is a frame later
    assert resident_pages(first) > 0
    data[::-1].tofile(second)
    release.written([second])
    assert resident_pages(first) == 0
    assert release.behind == [second]
    assert np.fromfile(first, np.uint8).tobytes() == data.tobytes()  # read back from disk: the same bytes


@needs_fadvise
@pytest.mark.bpy
def test_a_run_advises_each_frames_files_when_committed_and_again_one_frame_later_on_a_thread_it_stops(bpy_scene, tmp_path, monkeypatch):
    from bpy_pipeline import plan

    advised, threads = [], set()

    def advise(path):
        threads.add(threading.current_thread())
        advised.append(os.path.relpath(path, tmp_path / "out"))

    monkeypatch.setattr(page_cache, "advise_dont_need", advise)
    monkeypatch.setattr(page_cache, "MIN_BYTES", 0)  # every file of these small frames, an empty one too
    config = load_config(None, ["sensor.preset=vlp16", "output.formats=[ply, semantickitti]", "frames=3"])
    frames = list(plan.run_frames(config, tmp_path / "out"))
    files = [frame.files for frame in frames]
    assert all(len(f) == 4 for f in files)  # the PLY, the SemanticKITTI points and labels, the preview
    assert advised == files[0] + files[1] + files[0] + files[2] + files[1]
    assert len(threads) == 1 and all(t.name.startswith("page cache release") and not t.is_alive() for t in threads)
    for frame in frames:  # every file advised is on disk, whole: the digest of its record
        for rel in frame.files:
            assert hashlib.sha256((tmp_path / "out" / rel).read_bytes()).hexdigest() == frame.record["sha256"][rel]


def test_without_posix_fadvise_nothing_is_advised(tmp_path, monkeypatch):
    monkeypatch.delattr(os, "posix_fadvise", raising=False)
    monkeypatch.setattr(page_cache, "advise_dont_need", lambda path: pytest.fail(f"advised {path}"))
    release = PageCacheRelease()
    release.written([tmp_path / "a.bin"])
    release.written_later([tmp_path / "a.bin"])
    release.close()
    assert not release.available() and release.behind == [] and release._thread is None


@needs_fadvise
def test_files_under_a_mib_and_files_gone_are_left_alone(tmp_path, monkeypatch):
    advised = []
    monkeypatch.setattr(page_cache, "advise_dont_need", advised.append)
    small, large = tmp_path / "small.txt", tmp_path / "large.bin"
    small.write_bytes(b"x" * (page_cache.MIN_BYTES - 1))
    large.write_bytes(b"x" * page_cache.MIN_BYTES)
    release = PageCacheRelease()
    release.written([small, large, tmp_path / "gone.bin"])
    assert advised == [large] and release.behind == [large]
    monkeypatch.undo()
    page_cache.advise_dont_need(tmp_path / "gone.bin")  # no error: the advice only ever saves memory
