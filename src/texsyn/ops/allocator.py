"""Keep freed memory in the process while a loop allocates and frees the same large arrays.

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
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator

__all__ = ["controls_allocator", "retained_heap"]

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
