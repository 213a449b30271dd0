"""Exact ranks of many rows at once: packed integer keys and one sort (compiled).

Histogram matching (:mod:`texsyn.ops.histogram`) gives each value the target of its rank,
equal values ranked by position. Here each value's order-preserving unsigned bits have their
low bits replaced by its position; one ``uint64`` sort of every row (NumPy's vectorised
integer sort, about 2.5 times faster than ``argsort``) then orders the values by their high
bits and position, and the rare runs of equal high bits whose values differ are sorted again
by full value. The result is the (value, position) order, so the bytes of a stable sort, on
any number of threads (``docs/determinism.md``). The kernels load with numba: they are used
once numba is loaded in the process, or for calls large enough to repay loading it
(``docs/performance.md``, "Start-up").
"""

from __future__ import annotations

import sys

import numpy as np

from .jit import LazyKernel, jit, prange
from .linalg import parallel_map, worker_count

__all__ = [
    "COMPILED_SCATTER_VALUES",
    "PARALLEL_RANK_VALUES",
    "compiled_ranks",
    "expect_ranks",
    "order_by_key",
    "scatter_by_key",
    "sorted_keys",
]


#: from this many values in one call the compiled ranks are used even when numba is not
#: loaded yet: they are about 10 ns a value faster, which repays numba's 0.4 s of loading
#: (``docs/performance.md``, "Start-up"); both give the same bytes
COMPILED_SCATTER_VALUES = 1 << 24


def compiled_ranks(size: int) -> bool:
    """Whether to rank with the compiled kernels: numba is loaded in this process already
    (loading a cached kernel then costs milliseconds), or the call is large enough to repay
    loading it."""
    return "numba" in sys.modules or size >= COMPILED_SCATTER_VALUES


def expect_ranks(values: int) -> bool:
    """Load the compiled rank kernels now when a computation will rank about ``values``
    values in all (each call may rank far fewer); returns whether they are used.

    :func:`compiled_ranks` decides call by call; an iterative method that ranks the same
    sizes many times (Heeger-Bergen's subbands, every iteration) knows its total in advance:
    from :data:`COMPILED_SCATTER_VALUES` values in all, loading numba once repays itself
    (the compiled ranks save about 10 ns a value on small rows and 90 ns on rows of 4M
    values, where NumPy's ``argsort`` and gathers miss the caches; ``docs/performance.md``,
    "Start-up"). Both give the same bytes.
    """
    if values >= COMPILED_SCATTER_VALUES and not compiled_ranks(0):
        _packed_keys_rows.compiled()  # imports numba: compiled_ranks is true from now on
    return compiled_ranks(values)


def sorted_keys(x: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Every row's packed sort keys (:func:`_packed_keys_rows`), sorted, and the position bits.

    ``x`` is a C-contiguous ``(B, N)`` float64 array; ``out``, a C-contiguous ``(B, N)``
    uint64 array the keys are written to (an iterative method reuses it from one call to the
    next instead of faulting in fresh pages, ``docs/performance.md``).

    One ``uint64`` sort replaces an ``argsort``: about 2.5 times faster (NumPy's vectorised
    integer sort), rows split over texsyn's worker threads.
    """
    shift = max(1, int(x.shape[1] - 1).bit_length())
    keys = _packed_keys(x, x.view(np.uint64), shift, out)
    workers = min(worker_count(), keys.shape[0])
    if workers <= 1 or keys.size < 1 << 15:
        keys.sort(axis=-1)
    else:
        bounds = np.linspace(0, keys.shape[0], workers + 1).astype(int)
        parallel_map(lambda b: keys[b[0] : b[1]].sort(axis=-1), zip(bounds[:-1], bounds[1:]))
    return keys, shift


@jit()
def _ordered_bits(value, bits):
    """An unsigned integer in the order of the float ``value`` (``bits`` its IEEE bits):
    ``-0.0`` as ``+0.0`` and every NaN last and equal, as NumPy's sorts compare them."""
    if value != value:
        return np.uint64(0xFFF8000000000000)
    if value == 0.0:
        return np.uint64(0x8000000000000000)
    if bits >> np.uint64(63):
        return ~bits
    return bits | np.uint64(0x8000000000000000)


@jit()
def _packed_keys_rows(x, bits, shift, keys, start, stop):
    """Sort keys of rows ``[start, stop)`` of ``x``: each value's :func:`_ordered_bits` with
    its low ``shift`` bits replaced by its position. Sorted, they order the values by their
    high bits and then by position; only values that share the high bits but differ below
    them are out of order (:func:`_canonical_row` sorts those runs)."""
    s = np.uint64(shift)
    for i in range(start, stop):
        for k in range(x.shape[1]):
            keys[i, k] = ((_ordered_bits(x[i, k], bits[i, k]) >> s) << s) | np.uint64(k)


@jit(parallel=True)
def _packed_keys_parallel(x, bits, shift, keys):
    """:func:`_packed_keys_rows` of every row, rows on numba's threads."""
    for i in prange(x.shape[0]):
        _packed_keys_rows(x, bits, shift, keys, i, i + 1)


@jit()
def _canonical_row(x, bits, keys, shift, order):
    """``order``: the positions of a row by value, then by position, from its sorted keys;
    returns whether two keys shared their high bits (equal values need that).

    Each run of keys with equal high bits is in position order; a run whose values are not
    all equal is sorted again, stably, by full value: such runs need two values within
    ``2^(shift - 52)`` relative of each other, rare and short in continuous data.
    """
    n = keys.size
    s = np.uint64(shift)
    mask = (np.uint64(1) << s) - np.uint64(1)
    runs = False
    k = 0
    while k < n:
        high = keys[k] >> s
        order[k] = np.int64(keys[k] & mask)
        if k + 1 == n or (keys[k + 1] >> s) != high:
            k += 1
            continue
        runs = True
        end = k + 1  # a run of equal high bits
        while end < n and (keys[end] >> s) == high:
            order[end] = np.int64(keys[end] & mask)
            end += 1
        first = x[order[k]]
        mixed = False
        for j in range(k + 1, end):
            if x[order[j]] != first and not (first != first and x[order[j]] != x[order[j]]):
                mixed = True
        if mixed:  # a stable sort of the run (in position order) by full value
            full = np.empty(end - k, dtype=np.uint64)
            for j in range(k, end):
                full[j - k] = _ordered_bits(x[order[j]], bits[order[j]])
            by_value = np.argsort(full, kind="mergesort")
            run = order[k:end].copy()
            for j in range(end - k):
                order[k + j] = run[by_value[j]]
        k = end
    return runs


#: adjacent key pairs :func:`_canonical_keys` checks at once for a shared high part; runs are
#: rare, so most blocks are passed over by one vectorised comparison
_TIE_BLOCK = 64


@jit()
def _ties_in(keys, start, s):
    """Whether a key of ``keys[start : start + _TIE_BLOCK]`` shares its high bits (above ``s``)
    with the next key. No early exit, and a window of a fixed length, so that the comparisons
    vectorise."""
    window = keys[start : start + _TIE_BLOCK + 1]
    found = False
    for k in range(_TIE_BLOCK):
        found |= ((window[k] ^ window[k + 1]) >> s) == 0
    return found


@jit()
def _canonical_keys(x, bits, keys, shift):
    """Put a row's sorted keys in the canonical order of :func:`_canonical_row`, in place.

    The keys of each run with equal high bits are in position order; a run whose values are
    not all equal is reordered, stably, by full value. Afterwards the keys' positions (low
    bits) are the row's positions by value, then by position, with no separate order array
    (which, for a large row, would be fresh pages at every call). Blocks of
    :data:`_TIE_BLOCK` keys without a run are passed over at once (:func:`_ties_in`).
    """
    n = keys.size
    s = np.uint64(shift)
    mask = (np.uint64(1) << s) - np.uint64(1)
    k = 0
    while k < n - 1:
        if k + _TIE_BLOCK < n and not _ties_in(keys, k, s):
            k += _TIE_BLOCK
            continue
        high = keys[k] >> s
        if (keys[k + 1] >> s) != high:
            k += 1
            continue
        end = k + 2  # a run of equal high bits
        while end < n and (keys[end] >> s) == high:
            end += 1
        first = x[np.int64(keys[k] & mask)]
        mixed = False
        for j in range(k + 1, end):
            value = x[np.int64(keys[j] & mask)]
            if value != first and not (first != first and value != value):
                mixed = True
        if mixed:  # a stable sort of the run (in position order) by full value
            full = np.empty(end - k, dtype=np.uint64)
            for j in range(k, end):
                position = np.int64(keys[j] & mask)
                full[j - k] = _ordered_bits(x[position], bits[position])
            by_value = np.argsort(full, kind="mergesort")
            run = keys[k:end].copy()
            for j in range(end - k):
                keys[k + j] = run[by_value[j]]
        k = end


@jit()
def _scatter_rows(x, bits, keys, shift, targets, rows, out, start, stop):
    """``out[i, order[k]] = targets[rows[i], k]`` for rows ``[start, stop)``, with each row's
    canonical order (:func:`_canonical_keys`, which rewrites the keys): the values in rank
    order, equal values by position. Each row of ``x`` is read before ``out``'s row is
    written, so ``out`` may be ``x``."""
    n = x.shape[1]
    mask = (np.uint64(1) << np.uint64(shift)) - np.uint64(1)
    for i in range(start, stop):
        key = keys[i]
        _canonical_keys(x[i], bits[i], key, shift)
        target = targets[rows[i]]
        row = out[i]
        # every value of the row is written below, in random order; writing the row in order
        # first brings its lines into the cache at streaming speed instead of one miss per
        # write (about 4 -> 2.3 ns a value on rows of 65536, never slower on longer ones)
        row[:] = 0.0
        for k in range(n):
            row[np.int64(key[k] & mask)] = target[k]


@jit(parallel=True)
def _scatter_parallel(x, bits, keys, shift, targets, rows, out):
    """:func:`_scatter_rows` of every row, rows on numba's threads."""
    for i in prange(x.shape[0]):
        _scatter_rows(x, bits, keys, shift, targets, rows, out, i, i + 1)


@jit()
def _order_rows(x, bits, keys, shift, order, runs, start, stop):
    """Every row's canonical order (:func:`_canonical_row`), ``(B, N)`` positions, and
    whether it may hold equal values."""
    for i in range(start, stop):
        runs[i] = _canonical_row(x[i], bits[i], keys[i], shift, order[i])


#: values from which the rank kernels run the rows on numba's threads (below, starting and
#: stopping them costs more than it saves, and much more on a loaded machine)
PARALLEL_RANK_VALUES = 1 << 20


#: values from which the rank kernels run the rows on numba's threads once their threaded
#: versions are loaded in the process: then a few rows of an image (the pixels of a 256 x 256
#: colour synthesis, after its bands) need not load the one-thread kernels as well
LOADED_PARALLEL_RANK_VALUES = 1 << 16


def _on_threads(x: np.ndarray, kernel: LazyKernel) -> bool:
    """Whether to rank the rows of ``x`` with ``kernel``, the threaded version."""
    if x.shape[0] <= 1 or worker_count() <= 1:
        return False
    return x.size >= PARALLEL_RANK_VALUES or (x.size >= LOADED_PARALLEL_RANK_VALUES and kernel.loaded)


def _packed_keys(x: np.ndarray, bits: np.ndarray, shift: int, out: np.ndarray | None = None) -> np.ndarray:
    """The packed sort keys of every row (:func:`_packed_keys_rows`), in ``out`` when given."""
    keys = np.empty(x.shape, dtype=np.uint64) if out is None else out
    if keys.shape != x.shape or keys.dtype != np.uint64 or not keys.flags.c_contiguous:
        raise ValueError(f"keys must be a C-contiguous uint64 array of shape {x.shape}")
    if _on_threads(x, _packed_keys_parallel):
        _packed_keys_parallel(x, bits, shift, keys)
    else:
        _packed_keys_rows(x, bits, shift, keys, 0, x.shape[0])
    return keys


def scatter_by_key(x, keys, shift: int, targets, rows, out: np.ndarray | None = None) -> np.ndarray:
    """``out[i, order[k]] = targets[rows[i], k]`` with every row's canonical order (:func:`_scatter_rows`).

    The keys are scratch: the positions of runs of equal high bits are reordered in place.

    ``out`` may be ``x`` itself: each row is read (only where its keys tie) before it is
    written, and rows are independent.

    Parameters
    ----------
    x : ndarray of float64, shape (B, N), C-contiguous
        The values ranked.
    keys, shift
        :func:`sorted_keys` of ``x``.
    targets : ndarray, shape (T, N)
        Ascending values; row ``i`` of the result takes those of row ``rows[i]``.
    rows : ndarray of int64, shape (B,)
    out : ndarray of float64, shape (B, N), C-contiguous, optional
        Where to write the result (a new array by default).
    """
    bits = x.view(np.uint64)
    out = np.empty_like(x) if out is None else out
    if _on_threads(x, _scatter_parallel):
        _scatter_parallel(x, bits, keys, shift, targets, rows, out)
    else:
        _scatter_rows(x, bits, keys, shift, targets, rows, out, 0, x.shape[0])
    return out


def order_by_key(x, keys, shift: int) -> tuple[np.ndarray, np.ndarray]:
    """Every row's canonical order, ``(B, N)`` positions, and whether the row may hold equal
    values (rows are few here: one thread). ``keys, shift``: :func:`sorted_keys` of ``x``."""
    bits = x.view(np.uint64)
    order = np.empty(x.shape, dtype=np.int64)
    runs = np.zeros(x.shape[0], dtype=np.bool_)
    _order_rows(x, bits, keys, shift, order, runs, 0, x.shape[0])
    return order, runs
