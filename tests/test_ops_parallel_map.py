"""``texsyn.ops.linalg.parallel_map``: the loop's results and errors on any number of workers."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from texsyn.ops import linalg


@pytest.mark.parametrize("workers", [1, 2])
def test_results_in_item_order_and_the_first_items_error(monkeypatch, workers):
    monkeypatch.setattr(linalg, "worker_count", lambda: workers)
    assert linalg.parallel_map(lambda i: (time.sleep(0.002 * (4 - i)), i)[1], range(5)) == list(range(5))
    started, finished = threading.Event(), []

    def item(i: int) -> int:
        if i == 0:  # fails last in time (after item 1 has started), first in item order
            started.wait(timeout=1.0 if workers > 1 else 0.0)
            raise ValueError("item 0")
        if i == 1:
            started.set()
            time.sleep(0.05)
            finished.append(i)
            return i
        raise KeyError(i)

    with pytest.raises(ValueError, match="item 0"):
        linalg.parallel_map(item, range(4))
    # on the pool, the item running when the first failed was awaited: nothing left writing
    assert finished == ([1] if workers > 1 else [])


def test_a_later_items_error_waits_for_the_running_items(monkeypatch):
    monkeypatch.setattr(linalg, "worker_count", lambda: 2)
    started, finished = threading.Event(), []

    def item(i: int) -> int:
        if i == 2:  # on the pool, still running when item 1 fails
            started.set()
            time.sleep(0.05)
            finished.append(i)
            return i
        started.wait(timeout=1.0)
        if i == 1:
            raise ValueError("item 1")
        return i

    with pytest.raises(ValueError, match="item 1"):
        linalg.parallel_map(item, range(3))
    assert finished == [2]  # awaited: nothing of the call left writing after its error


def test_a_map_inside_a_map_runs_in_the_pools_thread_without_deadlock(monkeypatch):
    """Every worker mapping again used to wait for work queued behind itself (a deadlock)."""
    monkeypatch.setattr(linalg, "worker_count", lambda: 2)
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((300, 64)), rng.standard_normal((64, 700))

    def outer(i: int) -> tuple[list[int], np.ndarray]:
        inner = linalg.parallel_map(lambda j: 10 * i + j, range(4))
        return inner, linalg.matmul(a, b)

    pool = ThreadPoolExecutor(max_workers=1)  # the test's own guard against a hang
    try:
        results = pool.submit(linalg.parallel_map, outer, range(6)).result(timeout=30)
    finally:
        pool.shutdown(wait=False)
    assert [inner for inner, _ in results] == [[10 * i + j for j in range(4)] for i in range(6)]
    reference = linalg.matmul(a, b)
    assert all(np.array_equal(product, reference) for _, product in results)


def test_one_item_per_worker_runs_on_the_helpers_and_awaits_every_item(monkeypatch):
    monkeypatch.setattr(linalg, "worker_count", lambda: 3)
    threads = linalg.parallel_map(lambda i: threading.get_ident(), range(3))
    assert threads[0] == threading.get_ident() and len(set(threads)) == 3
    finished = []

    def item(i: int) -> int:
        if i == 0:
            raise ValueError("item 0")
        time.sleep(0.05)
        finished.append(i)
        if i == 2:
            raise KeyError(i)
        return i

    with pytest.raises(ValueError, match="item 0"):
        linalg.parallel_map(item, range(3))
    assert sorted(finished) == [1, 2]  # both helpers' items awaited, the first item's error raised
    with pytest.raises(KeyError):
        linalg.parallel_map(item, [1, 2])
    # a call made from inside a call: the caller's thread finds the helpers busy and takes the
    # pool, a helper runs it itself: no deadlock
    nested = linalg.parallel_map(lambda i: linalg.parallel_map(lambda j: 10 * i + j, range(2)), range(2))
    assert nested == [[0, 1], [10, 11]]


class _Interrupted(Exception):
    pass


def test_an_interruption_while_waiting_for_a_helper_awaits_it_and_leaves_the_helpers_sound(monkeypatch):
    # Ctrl-C in a Python session while the caller waits for a helper's item (half of a
    # Portilla-Simoncelli stack): the item was not awaited, the next call took its result
    # as its own, and the call after that waited for ever
    import signal

    def interrupt(signum, frame):
        raise _Interrupted()

    monkeypatch.setattr(linalg, "worker_count", lambda: 2)
    previous = signal.signal(signal.SIGUSR1, interrupt)
    finished = []

    def slow(i: int) -> tuple[str, int]:
        if i == 1:
            time.sleep(0.3)
            finished.append(i)
        return ("slow", i)

    main = threading.main_thread().ident
    assert main == threading.get_ident()
    timer = threading.Timer(0.1, signal.pthread_kill, (main, signal.SIGUSR1))
    try:
        timer.start()
        with pytest.raises(_Interrupted):
            linalg.parallel_map(slow, range(2))
    finally:
        timer.join()
        signal.signal(signal.SIGUSR1, previous)
    assert finished == [1]  # awaited: nothing of the call left writing after its exception
    guard = ThreadPoolExecutor(max_workers=1)  # the test's own guard against a hang
    try:
        for name in ("fast", "again"):
            call = guard.submit(linalg.parallel_map, lambda i, name=name: (name, i), range(2))
            assert call.result(timeout=10) == [(name, 0), (name, 1)]
    finally:
        guard.shutdown(wait=False)
