"""Where large temporary arrays live: freed memory kept for the next step, kept arrays in ordinary pages.

glibc's ``malloc`` gives the free memory at the top of its heap back to the system as soon
as it exceeds a threshold, and serves large blocks by ``mmap``; both thresholds start low
and rise with the largest block freed so far (its "dynamic" thresholds). An iterative
synthesis frees a few megabytes of temporaries at the end of every step and takes them
again in the next: the kernel then maps and zeroes every page anew (Portilla-Simoncelli,
256x256 colour: 2 500 to 5 500 page faults per iteration, about 0.35 s of system time in
50 iterations; ``docs/methods/portilla_simoncelli.md``, "Performance").

:func:`retained_heap` sets both thresholds to the highest values glibc's dynamic thresholds
reach by themselves on a 64-bit system (blocks of 32 MiB and more by ``mmap``, the heap
trimmed beyond 64 MiB of free memory), so the arrays of one step are served from memory the
previous step freed, and hands the free memory back (``malloc_trim``) when the block ends.
glibc keeps fixed thresholds once they are set, so the process keeps those (its dynamic
maximums) afterwards. Elsewhere than glibc it does nothing. Results do not depend on it.

:func:`scratch_empty` is for the arrays a synthesis keeps for all its iterations. An array of 32 MiB or more is mapped afresh by glibc's allocator at every allocation (its
largest ``mmap`` threshold), and NumPy asks the kernel to back every array of 4 MiB or more
with huge pages (``madvise(MADV_HUGEPAGE)``). Where the kernel's huge pages are given only
on request and compacted synchronously (``/sys/kernel/mm/transparent_hugepage``: ``enabled``
and ``defrag`` both ``madvise``, the benchmark machine's settings), the first touch of such
an array costs about 1.3 s of system time per GiB, against 0.4 to 0.6 s in ordinary pages
(measured: 2.4 GiB of 100 MB arrays filled once, 3.1-3.3 s against 0.8-1.4 s). A
2048x2048 colour Heeger-Bergen synthesis holds about 2 GiB of arrays that large (issue 20;
``docs/methods/heeger_bergen.md``, "Performance"). Its scratch arrays, the pyramid's
spectra, its coefficients and the sort keys, live in anonymous memory maps made here without
that request: the kernel's default page policy, not NumPy's. Values do not depend on where
an array lives.
"""

from __future__ import annotations

import contextlib
import functools
import math
import mmap
from collections.abc import Iterator

import numpy as np

__all__ = ["LARGE_SCRATCH_BYTES", "controls_allocator", "retained_heap", "scratch_empty"]

#: ``mallopt`` parameters (glibc's ``malloc.h``)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: glibc's largest dynamic mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``),
#: and the trim threshold it sets with it (twice as much)
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 2 * MMAP_THRESHOLD


@functools.cache
def _glibc():
    """The C library when it is glibc (it has ``mallopt`` and ``malloc_trim``), else None."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        return libc
    except (OSError, AttributeError, TypeError):  # not glibc (musl, macOS, Windows)
        return None


def controls_allocator() -> bool:
    """Whether :func:`retained_heap` can set the allocator's thresholds (the C library is glibc)."""
    return _glibc() is not None


@contextlib.contextmanager
def retained_heap() -> Iterator[None]:
    """Within the block, freed memory stays in the process for the next allocations
    (the module's docstring); at its end the free memory goes back to the system."""
    libc = _glibc()
    if libc is not None:
        libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
        libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    try:
        yield
    finally:
        if libc is not None:
            libc.malloc_trim(0)


#: from this size an array is mapped on its own by glibc anyway (its largest ``mmap``
#: threshold); smaller ones are recycled inside the heap and made with ``numpy.empty``
LARGE_SCRATCH_BYTES = MMAP_THRESHOLD


def scratch_empty(shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """An uninitialised C-contiguous array, like ``numpy.empty(shape, dtype)``.

    From :data:`LARGE_SCRATCH_BYTES` the array lives in an anonymous memory map of its own,
    without NumPy's request for huge pages (see the module's docstring); the map is released
    with the last view of the array. Smaller arrays are ``numpy.empty``'s.

    Examples
    --------
    >>> a = scratch_empty((5000, 1000))
    >>> a.shape, a.dtype, a.flags.c_contiguous, a.flags.writeable
    ((5000, 1000), dtype('float64'), True, True)
    """
    dtype = np.dtype(dtype)
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes < LARGE_SCRATCH_BYTES or not hasattr(mmap, "MAP_PRIVATE"):  # (Windows: no flags)
        return np.empty(shape, dtype=dtype)
    pages = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE)  # anonymous, private (not shared memory)
    return np.frombuffer(pages, dtype=dtype).reshape(shape)
