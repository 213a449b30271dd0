"""Kwatra's seam costs of a stack of overlaps, compiled: the bytes of the NumPy expressions.

:func:`texsyn.ops.graphcut.kwatra_costs` (Kwatra et al. 2003; Tartavel et al. 2013, eq. 8)
is written with NumPy arrays; a graph-cut pass of the ``sparse`` method costs some two
thousand overlaps at once, where NumPy's dozen temporaries of the whole stack cost more
than the arithmetic. Here each overlap is costed value by value with NumPy's operations in
NumPy's order: the channel sums from 0 and the pairwise summation of the mean denominator
(:func:`numpy_sum`), so the bytes are the same, on any number of threads
(``docs/methods/sparse.md``, "Performance").
"""

from __future__ import annotations

import numpy as np

from .jit import jit, prange
from .linalg import worker_count

__all__ = ["kwatra_costs_stack", "numpy_sum"]

#: values of a stack from which its overlaps are costed on numba's threads
_PARALLEL_VALUES = 1 << 15

#: NumPy's pairwise summation adds blocks of at most this many values with eight partial sums
_PAIRWISE_BLOCK = 128


@jit()
def _pairwise_block(values, start, n):
    """NumPy's pairwise sum of ``values[start:start + n]``, ``n <= 128``: sequential from 0
    below eight values, else eight partial sums added pairwise, then the tail."""
    if n < 8:
        total = 0.0
        for i in range(start, start + n):
            total += values[i]
        return total
    r = values[start : start + 8].copy()
    stop = start + n - n % 8
    for i in range(start + 8, stop, 8):
        for j in range(8):
            r[j] += values[i + j]
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for i in range(stop, start + n):
        total += values[i]
    return total


@jit()
def numpy_sum(values):
    """``numpy.add.reduce(values)`` of a contiguous 1-D array: NumPy's pairwise summation
    (halves rounded down to multiples of 8 above 128 values, :func:`_pairwise_block` below),
    added to the identity 0. The recursion runs on an explicit stack of nodes."""
    starts = np.empty(128, dtype=np.int64)
    sizes = np.empty(128, dtype=np.int64)
    expanded = np.zeros(128, dtype=np.bool_)
    sums = np.empty(128)
    top, depth = 0, 0
    starts[0], sizes[0], expanded[0] = 0, values.size, False
    while top >= 0:
        n = sizes[top]
        if n <= _PAIRWISE_BLOCK:
            sums[depth] = _pairwise_block(values, starts[top], n)
            depth += 1
            top -= 1
        elif expanded[top]:  # both halves summed: left, then right on the sum stack
            sums[depth - 2] = sums[depth - 2] + sums[depth - 1]
            depth -= 1
            top -= 1
        else:
            expanded[top] = True
            half = n // 2
            half -= half % 8
            first = starts[top]
            starts[top + 1], sizes[top + 1], expanded[top + 1] = first + half, n - half, False
            starts[top + 2], sizes[top + 2], expanded[top + 2] = first, half, False
            top += 2
    return 0.0 + sums[0]


@jit()
def _kwatra_costs_rows(a, b, cost_h, cost_v, start, stop):
    """:func:`kwatra_costs_stack` of the overlaps ``[start, stop)``, value by value with
    NumPy's operations in NumPy's order (the channel sums from 0, the mean denominator by
    :func:`numpy_sum`), into ``cost_h`` and ``cost_v``."""
    h, w, channels = a.shape[1], a.shape[2], a.shape[3]
    n = h * (w - 1) + (h - 1) * w
    diff = np.empty((h, w))
    den = np.empty(n)
    for k in range(start, stop):
        for r in range(h):
            for c in range(w):
                total = 0.0
                for ch in range(channels):
                    d = a[k, r, c, ch] - b[k, r, c, ch]
                    total += d * d
                diff[r, c] = total
        m = 0
        for r in range(h):
            for c in range(w - 1):
                total = 0.0
                for ch in range(channels):
                    da = a[k, r, c, ch] - a[k, r, c + 1, ch]
                    db = b[k, r, c, ch] - b[k, r, c + 1, ch]
                    total += da * da + db * db
                den[m] = total
                m += 1
        for r in range(h - 1):
            for c in range(w):
                total = 0.0
                for ch in range(channels):
                    da = a[k, r, c, ch] - a[k, r + 1, c, ch]
                    db = b[k, r, c, ch] - b[k, r + 1, c, ch]
                    total += da * da + db * db
                den[m] = total
                m += 1
        eps = 1e-3 * (numpy_sum(den) / n) + 1e-12
        m = 0
        for r in range(h):
            for c in range(w - 1):
                cost_h[k, r, c] = (diff[r, c] + diff[r, c + 1]) / (den[m] + eps)
                m += 1
        for r in range(h - 1):
            for c in range(w):
                cost_v[k, r, c] = (diff[r, c] + diff[r + 1, c]) / (den[m] + eps)
                m += 1


@jit(parallel=True)
def _kwatra_costs_parallel(a, b, cost_h, cost_v, n_chunks):
    """:func:`_kwatra_costs_rows` over ``n_chunks`` chunks of the stack on numba's threads."""
    count = a.shape[0]
    size = (count + n_chunks - 1) // n_chunks
    for c in prange(n_chunks):
        _kwatra_costs_rows(a, b, cost_h, cost_v, c * size, min(count, (c + 1) * size))


def kwatra_costs_stack(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kwatra's costs of a stack of overlaps ``(S, h, w, C)``, ``w >= 2``: ``(S, h, w-1)`` and
    ``(S, h-1, w)``, the bytes of :func:`texsyn.ops.graphcut.kwatra_costs` of each overlap
    (``tests/test_sparse.py``), the stack split among numba's threads."""
    count, h, w = a.shape[:3]
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    cost_h = np.empty((count, h, w - 1))
    cost_v = np.empty((count, h - 1, w))
    workers = worker_count()
    if workers > 1 and count > 1 and a.size >= _PARALLEL_VALUES:
        _kwatra_costs_parallel(a, b, cost_h, cost_v, min(workers, count))
    else:
        _kwatra_costs_rows(a, b, cost_h, cost_v, 0, count)
    return cost_h, cost_v
