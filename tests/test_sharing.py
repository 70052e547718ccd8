"""The calling thread takes its share of a pool's work (bpy_pipeline/lidar/cast/sharing.py)."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.sharing import share
from bpy_pipeline.buffers import SceneBuffers


def test_the_caller_works_beside_the_pool():
    """Two items that each wait for the other: they finish only when two threads run them at once, one of them
    the caller (a pool of one worker alone could not; the caller only waiting, as pool.map does, would hang)."""
    both = threading.Barrier(2, timeout=10)
    caller = threading.get_ident()

    def item(k):
        both.wait()
        return threading.get_ident()

    with ThreadPoolExecutor(1) as pool:
        ran_on = share(pool, item, range(2), threads=2)
    assert caller in ran_on and len(set(ran_on)) == 2


def test_results_in_item_order_whoever_runs_them():
    with ThreadPoolExecutor(3) as pool:
        out = share(pool, lambda k: (time.sleep(0.001 * (k % 3)), k * k)[1], range(40), threads=4)
    assert out == [k * k for k in range(40)]


def test_every_thread_stopped_before_the_first_failure_is_raised():
    finished = []

    def item(k):
        if k in (3, 5):
            raise ValueError(f"item {k}")
        time.sleep(0.01)
        finished.append(k)
        return k

    with ThreadPoolExecutor(1) as pool:
        with pytest.raises(ValueError, match="item 3"):
            share(pool, item, range(8), threads=2)
        running = len(finished)
        time.sleep(0.05)
    assert len(finished) == running  # nothing ran on after the raise
    assert 6 not in finished and 7 not in finished  # no item started after the failure


def test_one_thread_or_no_pool_runs_here_in_order():
    caller = threading.get_ident()
    assert share(None, lambda k: (k, threading.get_ident()), range(3), threads=2) == [(k, caller) for k in range(3)]
    with ThreadPoolExecutor(2) as pool:
        assert share(pool, lambda k: threading.get_ident(), range(3), threads=1) == [caller] * 3


def test_a_caster_scans_on_the_calling_thread_too():
    """A caster's parts run on the calling thread and its pool's (threads - 1) workers: the same records as one thread."""
    v = np.array([[x, y, z] for x in (-10, 10) for y in (-10, 10) for z in (-3, 5)], float)
    t = np.array([[0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
    buffers = SceneBuffers.from_meshes({"room": (v, t)})
    rng = np.random.default_rng(0)
    d = rng.normal(size=(200_000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    seen = set()
    one, two = RayCaster(buffers, np.eye(4), threads=1), RayCaster(buffers, np.eye(4), threads=2)
    original = two.map

    def watched(fn, items):
        return original(lambda item: (seen.add(threading.get_ident()), fn(item))[1], items)

    two.map = watched
    a, b = one.intersect(np.zeros(3), d), two.intersect(np.zeros(3), d)
    assert threading.get_ident() in seen and len(seen) == 2
    for field in ("ray", "distance", "triangle"):
        assert np.array_equal(getattr(a, field), getattr(b, field))
