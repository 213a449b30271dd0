"""Matrix products whose rounding does not depend on the number of threads.

OpenBLAS splits a product differently with one thread than with several (its single-thread
path blocks the inner dimension differently, and ``dot``/``gemv`` add per-thread partial
sums), so ``A @ B`` can differ in the last bits between ``OPENBLAS_NUM_THREADS=1`` and the
default, and which kernels do so depends on the processor. A texture synthesis amplifies
such bits (a nearest-patch choice flips, an iteration diverges), so the same seed would not
give the same bytes. texsyn therefore fixes the order of every reduction itself
(``docs/determinism.md``):

- while texsyn computes (:func:`fixed_order`, entered by every public method and
  function), the BLAS libraries run one thread, so each BLAS or LAPACK call has the
  single-thread reduction order whatever the machine's thread settings;
- the large products that dominate the run time (patch searches, sparse coding) go
  through :func:`matmul`, which cuts the product into tiles of a fixed shape and multiplies
  the tiles concurrently on a thread pool. Each tile is an ordinary single-thread BLAS call,
  so its bytes depend on the tile shape only, never on the number of workers: all cores are
  used and the result is the same with 1, 2 or 64 of them.

Numba ``prange`` loops in texsyn write independent outputs (no cross-iteration sums), and the
FFTs (NumPy's pocketfft) are single-threaded, so neither depends on the thread count.

Why this module is long: it is the one place that knows how BLAS and texsyn's threads meet:
the BLAS thread setting (:func:`fixed_order`), texsyn's thread pool and its helper threads
(:func:`parallel_map`), the tiled products that rely on both (:func:`matmul`), and NumPy's
own float32 product for compiled kernels that run without the GIL (:func:`cblas_sgemm`).
"""

from __future__ import annotations

import functools
import inspect
import os
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager
from typing import TypeVar

import numpy as np

__all__ = [
    "add_product",
    "cblas_sgemm",
    "fixed_order",
    "matmul",
    "parallel_map",
    "stop_thread_pool",
    "worker_count",
    "BLOCK_ROWS",
    "BLOCK_COLUMNS",
    "THREADS_VARIABLE",
]

#: the environment variable that caps texsyn's own threads (:func:`worker_count`); a batch
#: worker sets it to 1 (``docs/batch.md``)
THREADS_VARIABLE = "TEXSYN_NUM_THREADS"

#: rows of the left operand in one block of :func:`matmul` (part of the rounding contract:
#: changing it may change results in the last bits)
BLOCK_ROWS = 256
#: columns of the right operand in one tile of :func:`matmul` (part of the contract too)
BLOCK_COLUMNS = 2048
#: products smaller than this many multiply-adds are computed on the calling thread
_PARALLEL_MIN_WORK = 1 << 22

_lock = threading.Lock()
_depth = 0
#: (setter, thread count) of every BLAS library set by the first entrant (:func:`_enter`)
_saved: list[tuple[Callable[[int], object], int]] = []
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()
#: :func:`parallel_map`'s helper threads (one call at a time uses them: ``_helpers_lock``)
_helpers: list = []
_helpers_lock = threading.Lock()
#: marks texsyn's own worker threads (:func:`_mark_worker_thread`)
_worker_thread = threading.local()

F = TypeVar("F", bound=Callable)


def _enter() -> None:
    """First entrant, from whichever thread: set every loaded BLAS library (NumPy's,
    SciPy's...) to one thread.

    The count of an OpenBLAS built on its own threads (``pthreads``, the wheels' build) is
    one value for the whole process, whichever thread sets it, and its thread pool serves
    every thread; :func:`_process_wide_setter` sets it directly. threadpoolctl would
    ignore the call from any thread but the first one that set the count while that thread
    lives (its "controlling thread"): a web server's or a batch worker's thread entering
    after the main thread had run anything kept two threads and gave other bytes than the
    command line (``tests/test_ops_linalg_threads.py``). The count stays at one until the
    last caller, from any thread, leaves, so the pool's workers and every thread inside
    compute with it; a count set per thread would not do: the last setter's value holds
    for all of them.
    """
    global _depth
    with _lock:
        if _depth == 0:
            from threadpoolctl import ThreadpoolController

            # made anew each time: libraries loaded since the last call are included
            for lib in ThreadpoolController().lib_controllers:
                if lib.user_api == "blas":
                    setter = _process_wide_setter(lib)
                    _saved.append((setter, lib.num_threads))
                    setter(1)
        _depth += 1


def _exit() -> None:
    """Last leaver, from whichever thread: give every BLAS library back the thread count it
    had."""
    global _depth
    with _lock:
        _depth -= 1
        if _depth == 0:
            while _saved:
                setter, threads = _saved.pop()
                setter(threads)


def _process_wide_setter(lib) -> Callable[[int], object]:
    """The setter of ``lib``'s thread count (a threadpoolctl controller): OpenBLAS's own
    ``openblas_set_num_threads`` where its threads are its own (``pthreads``), found under
    the wheels' symbol names; threadpoolctl's otherwise (an OpenMP build's count is the
    calling thread's, which threadpoolctl sets from any thread)."""
    if lib.internal_api == "openblas" and getattr(lib, "threading_layer", "") == "pthreads":
        setter = _openblas_setter(lib.filepath)
        if setter is not None:
            return setter
    return lib.set_num_threads


@functools.cache
def _openblas_setter(path: str) -> Callable[[int], object] | None:
    """``openblas_set_num_threads`` of the library at ``path`` (C interface), under the names
    the builds give it (the ``scipy_`` prefix and ``64_`` suffix of NumPy's and SciPy's
    wheels), or None."""
    import ctypes

    try:
        library = ctypes.CDLL(path)
    except OSError:
        return None
    for prefix in ("", "scipy_"):
        for suffix in ("", "64_"):
            setter = getattr(library, f"{prefix}openblas_set_num_threads{suffix}", None)
            if setter is not None:
                setter.argtypes = [ctypes.c_int]
                setter.restype = None
                return setter
    return None


#: ``cblas_sgemm``'s codes for row-major arrays and untransposed operands (``cblas.h``)
CBLAS_ROW_MAJOR, CBLAS_NO_TRANS = 101, 111


@functools.cache
def cblas_sgemm():
    """NumPy's own float32 matrix product, ``cblas_sgemm`` of the OpenBLAS its wheels bundle (or
    of another OpenBLAS the process has loaded), as a ctypes function that compiled kernels
    can call without the GIL; None where no OpenBLAS is found under these names.

    ``sgemm(CBLAS_ROW_MAJOR, CBLAS_NO_TRANS, CBLAS_NO_TRANS, m, n, k, alpha, a, lda, b, ldb,
    beta, c, ldc)`` with the arrays' addresses; its integers are 64-bit for the ``64_`` symbols
    (an ILP64 build, NumPy's wheels), 32-bit otherwise. It is the function ``a @ b`` runs for
    float32 arrays, with the thread count :func:`fixed_order` sets (one while texsyn computes).
    """
    import ctypes

    from threadpoolctl import ThreadpoolController

    libraries = [
        lib.filepath
        for lib in ThreadpoolController().lib_controllers
        if lib.user_api == "blas" and lib.internal_api == "openblas"
    ]
    # NumPy's first (its wheels keep it in numpy.libs), then any other OpenBLAS loaded
    libraries.sort(key=lambda path: not os.path.basename(os.path.dirname(path)).startswith("numpy"))
    for path in libraries:
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for name, integer in (
            ("scipy_cblas_sgemm64_", ctypes.c_int64),
            ("cblas_sgemm64_", ctypes.c_int64),
            ("scipy_cblas_sgemm", ctypes.c_int),
            ("cblas_sgemm", ctypes.c_int),
        ):
            if hasattr(library, name):
                code, real, address = ctypes.c_int, ctypes.c_float, ctypes.c_void_p
                prototype = ctypes.CFUNCTYPE(
                    None, code, code, code, integer, integer, integer, real, address, integer,
                    address, integer, real, address, integer,
                )  # fmt: skip
                return prototype((name, library))
    return None


@contextmanager
def _fixed_order_context() -> Iterator[None]:
    _enter()
    try:
        yield
    finally:
        _exit()


def fixed_order(func: F | None = None):
    """Run ``func`` (or a ``with`` block) with every BLAS call in its single-thread order.

    Use as a decorator of public entry points, or as ``with fixed_order():``. Re-entrant
    and thread-safe: the BLAS thread count is set to one when the first caller enters and
    restored when the last one leaves. A decorated generator function holds the setting
    only while it computes, not while its consumer runs between frames.

    Parameters
    ----------
    func : callable, optional
        Function or generator function to wrap.
    """
    if func is None:
        return _fixed_order_context()
    if inspect.isgeneratorfunction(func):

        @functools.wraps(func)
        def generator_wrapper(*args, **kwargs):
            with _fixed_order_context():
                gen = func(*args, **kwargs)
            try:
                while True:
                    with _fixed_order_context():
                        item = next(gen)
                    yield item
            except StopIteration:
                return
            finally:
                with _fixed_order_context():
                    gen.close()

        return generator_wrapper  # type: ignore[return-value]

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with _fixed_order_context():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def worker_count() -> int:
    """Threads texsyn's own parallel loops may use: the CPUs this process may run on, at most
    ``TEXSYN_NUM_THREADS`` when that is a positive integer (read on every call)."""
    try:
        cpus = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        cpus = max(1, os.cpu_count() or 1)
    cap = os.environ.get(THREADS_VARIABLE, "").strip()
    if cap.isdigit() and int(cap) >= 1:
        return min(cpus, int(cap))
    return cpus


def parallel_map(function: Callable, items) -> list:
    """``[function(item) for item in items]`` on texsyn's thread pool, results in item order.

    For work that releases the GIL (NumPy sorts, FFTs, BLAS): each item is computed the same
    way whichever thread runs it, so the results do not depend on the number of workers. The
    calling thread computes the first item itself while the pool takes the others (one
    hand-over fewer per call: a search cut in parts makes one call per block of queries). An error
    is the first failing item's in item order, as in the loop; before it is raised, the
    items not started are cancelled and the running ones awaited (no work of the call goes
    on writing into the caller's arrays behind its exception).

    A call of at most one item per worker goes to helper threads instead of the pool
    (:class:`_Helper`, a cheaper hand-over), unless another call is using them. Called from
    one of texsyn's own worker threads (``function`` itself mapping, or a :func:`matmul`
    inside it), the items run in that thread, one after the other: waiting on the workers
    from inside one could leave every worker waiting for work queued behind itself.
    """
    items = list(items)
    workers = worker_count()
    if len(items) <= 1 or workers == 1 or _on_worker_thread():
        return [function(item) for item in items]
    if len(items) <= workers and _helpers_lock.acquire(blocking=False):
        try:  # one item per thread: the helpers' hand-over, cheaper than the pool's futures
            return _on_helpers(function, items)
        finally:
            _helpers_lock.release()
    pool = _thread_pool()
    rest = [pool.submit(function, item) for item in items[1:]]
    try:
        first = function(items[0])
        return [first, *(future.result() for future in rest)]
    except BaseException:
        for future in rest:
            future.cancel()
        wait(rest)
        raise


class _Helper:
    """A thread that runs one item at a time for :func:`parallel_map`, handed over by two locks
    (a wait on a lock releases the GIL; no future, no queue: about 10 µs a hand-over against
    the pool's 70 on a 2-core virtual machine; a caller making hundreds of such calls a second
    keeps workers in a compiled loop instead: :class:`texsyn.ops.search.BoundedParallelSearch`)."""

    def __init__(self) -> None:
        self._go = threading.Lock()
        self._go.acquire()
        self._done = threading.Lock()
        self._done.acquire()
        self._job: tuple[Callable, object] | None = None
        self._result: tuple[bool, object] = (True, None)
        threading.Thread(target=self._serve, name="texsyn-helper", daemon=True).start()

    def _serve(self) -> None:
        _mark_worker_thread()
        while True:
            self._go.acquire()
            if self._job is None:  # retired (:meth:`retire`)
                return
            function, item = self._job
            try:
                self._result = (True, function(item))
            except BaseException as error:  # handed to the caller
                self._result = (False, error)
            self._job = None
            self._done.release()

    def start(self, function: Callable, item: object) -> None:
        self._job = (function, item)
        self._go.release()

    def finish(self) -> tuple[bool, object]:
        self._done.acquire()
        result, self._result = self._result, (True, None)
        return result

    def retire(self) -> None:
        """Wait until the item handed over is done, then end the thread: after an exception
        raised in :meth:`finish` (a signal's), whether its wait took the lock is unknown."""
        while self._job is not None:
            time.sleep(0.001)
        self._go.release()


def _on_helpers(function: Callable, items: list) -> list:
    """:func:`parallel_map` of at most one item per worker: the caller computes the first item,
    a helper thread each other one; every item is awaited before an error is raised."""
    while len(_helpers) < len(items) - 1:
        _helpers.append(_Helper())
    busy = _helpers[: len(items) - 1]
    for helper, item in zip(busy, items[1:]):
        helper.start(function, item)
    try:
        first: tuple[bool, object] = (True, function(items[0]))
    except BaseException as error:
        first = (False, error)
    results = [first]
    for index, helper in enumerate(busy):
        try:
            results.append(helper.finish())
        except BaseException:
            # raised by a signal during the wait (Ctrl-C in a Python session): the helpers
            # not yet waited for are awaited all the same (nothing of the call goes on
            # writing behind the exception) and replaced, so that no later call takes their
            # result as its own
            del _helpers[index : len(busy)]
            for stale in busy[index:]:
                stale.retire()
            raise
    for ok, value in results:
        if not ok:
            raise value  # type: ignore[misc]
    return [value for _, value in results]


def stop_thread_pool() -> None:
    """End the threads of texsyn's pool (:func:`parallel_map`, :func:`matmul`) once their work
    is done; a later call starts new ones. The command line calls it before it ends the
    process (:func:`texsyn.cli.app.exit_process`)."""
    global _pool
    with _pool_lock:
        pool, _pool = _pool, None
    if pool is not None:
        pool.shutdown(wait=True)


def _thread_pool() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(
                max_workers=worker_count(),
                thread_name_prefix="texsyn-matmul",
                initializer=_mark_worker_thread,
            )
        return _pool


def _mark_worker_thread() -> None:
    """Mark the calling thread as one of texsyn's own workers (the pool's, the helpers')."""
    _worker_thread.inside = True


def _on_worker_thread() -> bool:
    """Whether the calling thread is one of texsyn's own workers: a map from it runs in it (no
    nesting: waiting on the workers from inside one could leave them all waiting)."""
    return getattr(_worker_thread, "inside", False)


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for a 2-D ``a``, with rounding independent of the number of threads.

    The product is cut into tiles of :data:`BLOCK_ROWS` rows of ``a`` by
    :data:`BLOCK_COLUMNS` columns of ``b``; each tile is one single-thread BLAS product, and
    the tiles are shared among the workers of a thread pool (BLAS releases the GIL). The
    bytes of the result depend on the tile shape only, never on how many workers there are
    or which tile each one takes.

    Parameters
    ----------
    a : ndarray, shape (m, k)
    b : ndarray, shape (k, n) or (k,)

    Returns
    -------
    ndarray, shape (m, n) or (m,)
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.ndim != 2:
        raise ValueError(f"matmul needs a 2-D left operand, got shape {a.shape}")
    m, k = a.shape
    n = 1 if b.ndim == 1 else b.shape[1]
    column_starts = [0] if b.ndim == 1 else range(0, n, BLOCK_COLUMNS)
    tiles = [(r, c) for r in range(0, m, BLOCK_ROWS) for c in column_starts]
    with _fixed_order_context():
        if len(tiles) == 1:
            return a @ b
        out = np.empty((m,) + b.shape[1:], dtype=np.result_type(a, b))

        def run(share: list[tuple[int, int]]) -> None:
            for r, c in share:
                rows = slice(r, r + BLOCK_ROWS)
                if b.ndim == 1:
                    np.matmul(a[rows], b, out=out[rows])
                else:
                    cols = slice(c, c + BLOCK_COLUMNS)
                    np.matmul(a[rows], b[:, cols], out=out[rows, cols])

        workers = min(worker_count(), len(tiles)) if m * k * n >= _PARALLEL_MIN_WORK else 1
        if workers == 1 or _on_worker_thread():  # (inside the pool: no nested map, parallel_map)
            run(tiles)
        else:
            list(_thread_pool().map(run, [tiles[i::workers] for i in range(workers)]))
        return out


#: inner dimension up to which :func:`add_product` calls BLAS itself: a single block of it in
#: OpenBLAS's products (its blocks hold hundreds), so the product is summed whole before it is
#: added, as ``out += a @ b`` adds it
ADD_PRODUCT_MAX_INNER = 64
#: outputs smaller than this go through NumPy (a ctypes call costs a few microseconds)
_ADD_PRODUCT_MIN_SIZE = 1 << 14


def add_product(out: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``out += a @ b`` without the product's temporary array: one BLAS call that adds it.

    For float32 row-major operands with an inner dimension of at most
    :data:`ADD_PRODUCT_MAX_INNER`, ``cblas_sgemm`` with ``beta = 1`` (:func:`cblas_sgemm`):
    BLAS sums each entry's products in a register, then adds it to ``out`` with one rounding,
    the bits of ``out += a @ b`` (``tests/test_ops_linalg_add_product.py``), without writing
    and reading back an array of the size of ``out`` (issue 20: 0.3 ms of a 12x65536 output).
    Other arrays, small ones, a single row or column (NumPy multiplies those with
    ``sgemv``, whose sums are not ``sgemm``'s: a 1x3 by 3x65536 product differs in
    thousands of values), operands that may overlap ``out``, or no ``cblas_sgemm``:
    ``out += a @ b``. Like ``@``, one BLAS thread
    inside :func:`fixed_order`.

    Parameters
    ----------
    out : ndarray, shape (m, n)
        Updated in place.
    a : ndarray, shape (m, k)
    b : ndarray, shape (k, n)

    Returns
    -------
    ndarray
        ``out``.
    """
    m, n = out.shape
    k = a.shape[1]
    direct = (
        out.dtype == a.dtype == b.dtype == np.float32
        and k <= ADD_PRODUCT_MAX_INNER
        and m * n >= _ADD_PRODUCT_MIN_SIZE
        and m > 1  # a row or a column: NumPy's product is sgemv, whose sums differ
        and n > 1
        and a.shape == (m, k)
        and b.shape == (k, n)
        and all(
            x.strides[1] == 4 and x.strides[0] % 4 == 0 and x.strides[0] >= 4 * x.shape[1]
            for x in (out, a, b)
        )
        and out.flags.writeable
        and not (np.may_share_memory(out, a) or np.may_share_memory(out, b))
    )
    sgemm = cblas_sgemm() if direct else None
    if sgemm is None:
        out += a @ b
        return out
    with _fixed_order_context():
        sgemm(
            CBLAS_ROW_MAJOR, CBLAS_NO_TRANS, CBLAS_NO_TRANS, m, n, k, 1.0,
            a.ctypes.data, a.strides[0] // 4, b.ctypes.data, b.strides[0] // 4,
            1.0, out.ctypes.data, out.strides[0] // 4,
        )  # fmt: skip
    return out


def _reset_after_fork() -> None:
    """In a forked child the pool's threads do not exist: start a new pool and new locks."""
    global _pool, _lock, _pool_lock, _helpers, _helpers_lock
    _pool = None
    _lock = threading.Lock()
    _pool_lock = threading.Lock()
    _helpers = []
    _helpers_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reset_after_fork)
