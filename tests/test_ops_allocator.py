"""``texsyn.ops.allocator.retained_heap``: freed memory serves the next allocations."""

from __future__ import annotations

import resource

import numpy as np
import pytest

from texsyn.ops import allocator


def _faults_of_cycles(cycles: int) -> int:
    """Minor page faults of ``cycles`` rounds of allocating, touching and freeing 20 + 3x4 MiB."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(cycles):
        arrays = [np.ones(20 << 17), *(np.ones(4 << 17) for _ in range(3))]  # float64: 20 MiB, 4 MiB
        del arrays
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


@pytest.mark.skipif(not allocator.controls_allocator(), reason="glibc's mallopt only")
def test_retained_heap_reuses_freed_memory_without_page_faults():
    with allocator.retained_heap():
        _faults_of_cycles(1)  # the heap grows once
        # a 20 MiB block is below the block's mmap threshold and the freed memory below its
        # trim threshold: the rounds reuse the same pages (mmap'd blocks would fault 8 000 times)
        assert _faults_of_cycles(5) < 500


def test_retained_heap_lets_exceptions_through():
    with pytest.raises(KeyError):
        with allocator.retained_heap():
            raise KeyError("x")
