"""The part workers of the proven search (texsyn.ops.search.BoundedParallelSearch).

They hand jobs through memory to threads that stay in a compiled loop; the answers must be
the ones of the search without them, whatever the block sizes, and the threads must end.
"""

import threading
import time

import numpy as np
import pytest

import texsyn.ops.search as search
from texsyn.ops.jit import atomic_load, atomic_store, jit
from texsyn.ops.linalg import CBLAS_NO_TRANS, CBLAS_ROW_MAJOR, cblas_sgemm, fixed_order
from texsyn.ops.search import BoundedNearestIndex, nearest_rows, nearest_rows_bounded


def _bank(rng, k, d):
    return rng.random((k, 4)) @ rng.random((4, d)) + 0.05 * rng.random((k, d))


def _blocks(rng, bank, sizes):
    for m in sizes:
        rows = rng.integers(0, len(bank), m)
        queries = bank[rows] + 0.02 * rng.standard_normal((m, bank.shape[1]))
        seeds = np.stack([rows, rng.integers(-1, len(bank), m)], axis=1)
        yield queries, seeds


def _part_threads():
    return [t for t in threading.enumerate() if t.name == "texsyn-part"]


@pytest.fixture
def three_parts(monkeypatch):
    monkeypatch.setattr(search, "worker_count", lambda: 3)
    monkeypatch.setattr(search, "WORKER_PAIRS", 0)


@pytest.mark.parametrize("spin_reads", [search.SPIN_READS, 1])
def test_workers_give_the_answers_of_the_search_without_them(three_parts, monkeypatch, spin_reads):
    # spin_reads=1: the workers sleep after every job and are woken for the next one
    monkeypatch.setattr(search, "SPIN_READS", spin_reads)
    rng = np.random.default_rng(0)
    bank = _bank(rng, 4096, 40)
    index = BoundedNearestIndex(bank, dims=12, extra=12, chunk=512)
    bands = lambda m: np.full((m, 1), 1e-3)  # noqa: E731
    with fixed_order(), index.parallel_search(60, 2) as workers:
        assert workers.active and workers.n_parts == 3 and len(_part_threads()) == 2
        done = 0
        for queries, seeds in _blocks(rng, bank, [1, 7, 60, 33, 61, 300, 2]):
            got = index.query(queries, bands(len(queries)), seeds, members=True, workers=workers)
            want = index.query(queries, bands(len(queries)), seeds, members=True)
            for a, b in zip(got[:3], want[:3], strict=True):
                assert np.array_equal(a, b)
            for i, count in enumerate(got[2][:, 0]):  # the same members, whatever the parts
                assert sorted(got[3][i, :count]) == sorted(want[3][i, :count])
            # blocks of the index's 256 queries at most; more than 60: not the workers'
            done += sum(min(256, len(queries) - start) <= 60 for start in range(0, len(queries), 256))
        assert workers._job == done
    assert not _part_threads()


def test_wei_levoy_wavefronts_with_workers_give_the_plain_search_bytes(three_parts, monkeypatch):
    import texsyn
    import texsyn.methods.wei_levoy as wl

    ex = np.stack([texsyn.data.exemplar(n, size=64) for n in ("grass", "gravel", "brick")], -1)
    params = {"levels": 2, "window": 5, "parent_window": 3}
    jobs = []
    run = search.BoundedParallelSearch.run
    monkeypatch.setattr(search.BoundedParallelSearch, "run", lambda self, *a: (jobs.append(1), run(self, *a)))
    got = texsyn.make_method("wei_levoy", **params).fit(ex).sample_with_map((72, 80), rng=3)
    assert len(jobs) > 50  # the finest level's wavefronts went to the workers
    monkeypatch.setattr(wl, "BOUNDED_SEARCH_ROWS", 10**9)
    want = texsyn.make_method("wei_levoy", **params).fit(ex).sample_with_map((72, 80), rng=3)
    assert np.array_equal(got.image, want.image) and np.array_equal(got.source_map, want.source_map)
    assert not _part_threads()


@pytest.mark.parametrize("missing", ["cblas_sgemm", "os_yield"])
def test_without_numpys_sgemm_or_sched_yield_there_are_no_workers_and_the_same_answers(
    three_parts, monkeypatch, missing
):
    rng = np.random.default_rng(1)
    bank = _bank(rng, 3072, 30)
    norms = np.sum(bank * bank, axis=1)
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    queries, seeds = next(_blocks(rng, bank, [40]))
    with fixed_order():
        with index.parallel_search(40, 2) as workers:
            fast = nearest_rows_bounded(queries, bank, norms, index, seeds, workers=workers)
        monkeypatch.setattr(search, missing, lambda: None)  # (cblas_sgemm: NumPy's products, per chunk)
        with index.parallel_search(40, 2) as workers:
            assert not workers.active and not _part_threads()
            plain = nearest_rows_bounded(queries, bank, norms, index, seeds, workers=workers)
        assert np.array_equal(fast, plain) and np.array_equal(fast, nearest_rows(queries, bank, norms))


def test_a_failing_worker_is_reported_and_the_others_end(three_parts, monkeypatch):
    def broken(*args):
        raise MemoryError("no memory for the worker")

    monkeypatch.setattr(search, "_part_worker", broken)
    monkeypatch.setattr(search, "SPIN_READS", 1)
    rng = np.random.default_rng(2)
    bank = _bank(rng, 4096, 20)
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    queries, seeds = next(_blocks(rng, bank, [30]))
    with pytest.raises(RuntimeError, match="search worker failed"):
        with fixed_order(), index.parallel_search(30, 2) as workers:
            for _ in range(100):  # (the parts of a worker not started yet are the caller's)
                index.query(queries, np.zeros((30, 1)), seeds, workers=workers)
                time.sleep(0.01)
    assert not _part_threads()


@jit(nogil=True)
def _wait_for_flag(flag, limit):
    """Spin until ``flag[0]`` is set (or ``limit`` reads), then report the reads in ``flag[1]``."""
    reads = 0
    while atomic_load(flag, 0) == 0 and reads < limit:
        reads += 1
    atomic_store(flag, 1, reads + 1)


def test_a_compiled_kernel_spinning_on_an_atomic_load_sees_another_threads_store():
    _wait_for_flag(np.ones(8, dtype=np.int64), 1)  # compiled (or loaded) before the race
    flag = np.zeros(8, dtype=np.int64)
    limit = 1 << 62  # without the atomic load the compiler may read the flag once: no end
    thread = threading.Thread(target=_wait_for_flag, args=(flag, limit), daemon=True)
    thread.start()
    atomic_store(flag, 0, 1)  # (a plain store from Python)
    thread.join(timeout=30)
    assert not thread.is_alive() and 0 < flag[1] < limit
    plain = np.zeros(8, dtype=np.int64)
    _wait_for_flag.py_func(plain, 5)  # as Python: plain reads and writes
    assert plain[1] == 6


def test_cblas_sgemm_is_numpys_float32_product():
    sgemm = cblas_sgemm()
    if sgemm is None:
        pytest.skip("NumPy's BLAS is not an OpenBLAS with the wheels' symbols")
    rng = np.random.default_rng(3)
    a = rng.random((43, 33), dtype=np.float32)
    b = rng.random((33, 5000), dtype=np.float32)
    out = np.empty((43, 700), dtype=np.float32)
    with fixed_order():
        sgemm(
            CBLAS_ROW_MAJOR, CBLAS_NO_TRANS, CBLAS_NO_TRANS, 43, 700, 33, 1.0, a.ctypes.data, 33,
            b[:, 1000:].ctypes.data, 5000, 0.0, out.ctypes.data, 700,
        )  # fmt: skip
        assert np.array_equal(out, a @ b[:, 1000:1700])


def _index_and_block(seed):
    rng = np.random.default_rng(seed)
    bank = _bank(rng, 4096, 20)
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    queries, seeds = next(_blocks(rng, bank, [30]))
    return index, queries, -np.ones_like(seeds)  # no seeds: every part searched in earnest


def test_the_caller_searches_the_parts_no_worker_has_claimed(three_parts, monkeypatch):
    # a worker that the system does not run (other processes on the cores) costs no wait
    release = threading.Event()
    monkeypatch.setattr(search, "_part_worker", lambda *args: release.wait(10) or True)
    index, queries, seeds = _index_and_block(4)
    bands = np.full((30, 1), 1e-3)
    answers = []
    with fixed_order():
        want = index.query(queries, bands, seeds)
        with index.parallel_search(30, 2) as workers:
            caller = threading.Thread(
                target=lambda: answers.append(index.query(queries, bands, seeds, workers=workers)),
                daemon=True,
            )
            caller.start()
            caller.join(timeout=5)
            finished = not caller.is_alive()
            release.set()
            caller.join(timeout=10)
    assert finished and workers._job == 1
    assert all(np.array_equal(a, b) for a, b in zip(answers[0], want, strict=True))
    assert not _part_threads()


def test_an_error_in_part_0_waits_for_the_parts_the_workers_claimed(three_parts, monkeypatch):
    from texsyn.ops.jit import atomic_compare_exchange

    def slow_worker(control, *args):  # claims its job, then takes 0.2 s over it
        while control[search._JOB] == control[search._CLAIMED]:
            if control[search._STOP]:
                return True
            time.sleep(0.001)
        job = control[search._JOB]
        assert atomic_compare_exchange(control, search._CLAIMED, job - 1, job)
        time.sleep(0.2)
        control[search._DONE] = job
        return False

    def failing_part(p):
        while not np.all(workers._control[:, search._CLAIMED] == 1):
            time.sleep(0.001)
        raise ValueError("part 0 failed")

    monkeypatch.setattr(search, "_part_worker", slow_worker)
    index, _, _ = _index_and_block(5)
    with index.parallel_search(30, 2) as workers:
        with pytest.raises(ValueError, match="part 0 failed"):
            workers.run(30, failing_part)
        # no worker goes on writing into the buffers behind the error
        assert np.all(workers._control[:, search._DONE] == 1)
    assert not _part_threads()


def test_workers_of_another_index_are_refused(three_parts):
    index, queries, seeds = _index_and_block(6)
    other, _, _ = _index_and_block(7)
    with fixed_order(), other.parallel_search(30, 2) as workers:
        with pytest.raises(ValueError, match="another index"):
            index.query(queries, np.full((30, 1), 1e-3), seeds, workers=workers)


def test_the_workers_may_be_entered_again(three_parts):
    index, queries, seeds = _index_and_block(8)
    bands = np.full((30, 1), 1e-3)
    with fixed_order():
        want = index.query(queries, bands, seeds)[0]
        workers = index.parallel_search(30, 2)
        for _ in range(2):
            with workers:
                assert np.array_equal(index.query(queries, bands, seeds, workers=workers)[0], want)
                assert workers._job == 1 and len(_part_threads()) == 2
            assert not _part_threads()


def test_a_thread_that_cannot_start_stops_those_started(three_parts, monkeypatch):
    rng = np.random.default_rng(4)
    bank = _bank(rng, 4096, 20)
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    workers = index.parallel_search(30, 2)
    assert workers.n_parts == 3
    start = threading.Thread.start
    started = []

    def start_once(thread):
        if thread.name == "texsyn-part" and started:
            raise RuntimeError("can't start new thread")
        started.append(thread)
        start(thread)

    monkeypatch.setattr(threading.Thread, "start", start_once)
    with pytest.raises(RuntimeError, match="can't start new thread"):
        workers.__enter__()
    assert len(started) == 1 and not started[0].is_alive() and not _part_threads()
