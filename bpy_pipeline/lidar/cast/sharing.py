"""Work split over a thread pool with the calling thread taking its share. Pure Python.

A scan hands its parts (rays, records, effects chunks) to a pool of threads and waits. When the caller
only waits, the system wakes the pool's threads and may place them both on one core for the few
milliseconds a part takes (Linux tends to put a woken thread near the thread that woke it, and the caller
sleeps right after): the parts then run one after the other on one core while the other core idles.
On this project's two-core machine that happened in about half the frames of a run (the os1_128 box's
scan stage read 15 ms in those against 8 ms in the others; docs/performance.md). Here the
caller works too: it takes parts in turn with ``threads - 1`` of the pool's threads, so it keeps its
core and the one woken thread takes the other.

Each part's result is its own (the parts are independent and write where they are told), so which
thread runs a part never changes a byte.
"""

from __future__ import annotations

import threading
from concurrent.futures import Executor
from typing import Callable, Iterable, TypeVar

T = TypeVar("T")
R = TypeVar("R")


def share(pool: Executor | None, fn: Callable[[T], R], items: Iterable[T], threads: int) -> list[R]:
    """``[fn(item) for item in items]``, on ``threads`` threads: the caller's and ``threads - 1`` of ``pool``'s.

    Items are taken in order, one at a time, by whichever thread is free; results come back in item
    order. After a failure (an interrupt included) no further item is started; every thread is waited
    for before this returns or raises, so no part is still running afterwards, and the error of the
    first failed item in item order is raised. Without a pool, with one thread or with at most one
    item, the items run here in order.
    """
    items = list(items)
    if pool is None or threads <= 1 or len(items) <= 1:
        return [fn(item) for item in items]
    results: list = [None] * len(items)
    errors: dict[int, BaseException] = {}
    order = iter(range(len(items)))
    lock = threading.Lock()

    def work() -> None:
        while True:
            with lock:
                k = None if errors else next(order, None)
            if k is None:
                return
            try:
                results[k] = fn(items[k])
            except BaseException as err:  # raised by the caller, after every thread has stopped
                with lock:
                    errors[k] = err

    helpers = [pool.submit(work) for _ in range(min(threads, len(items)) - 1)]
    try:
        work()
    finally:
        for helper in helpers:
            helper.result()
    if errors:
        raise errors[min(errors)]
    return results
