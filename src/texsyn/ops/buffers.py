"""Large scratch arrays that an iterative method makes once and reuses: :func:`scratch_empty`.

An array of 32 MiB or more is mapped afresh by glibc's allocator at every allocation (its
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

import math
import mmap

import numpy as np

__all__ = ["LARGE_SCRATCH_BYTES", "scratch_empty"]

#: from this size an array is mapped on its own by glibc anyway (its largest ``mmap``
#: threshold); smaller ones are recycled inside the heap and made with ``numpy.empty``
LARGE_SCRATCH_BYTES = 32 << 20


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
