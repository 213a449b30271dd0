"""Issue 20: :func:`texsyn.ops.histogram.hist_target_rows` (compiled rows) gives the bytes of
:func:`texsyn.ops.histogram.hist_target` row by row."""

import numpy as np
import pytest

from texsyn.ops.histogram import _ot_targets, hist_target, hist_target_rows


@pytest.mark.parametrize(("ny", "n"), [(300, 1200), (300, 1201), (257, 100), (7, 5000), (1, 9), (50, 50)])
def test_rows_are_the_bytes_of_hist_target(ny, n):
    _ot_targets.compiled()  # numba loaded: the compiled rows
    rng = np.random.default_rng(ny + n)
    ys = np.sort(rng.standard_normal((4, ny)) ** 3, axis=1)
    ys[1, : ny // 2] = 0.25  # ties
    expected = np.stack([hist_target(n, row, presorted=True) for row in ys])
    assert hist_target_rows(n, ys).tobytes() == expected.tobytes()


def test_large_rows_on_the_worker_threads_are_the_same_bytes():
    _ot_targets.compiled()
    ys = np.sort(np.random.default_rng(3).standard_normal((5, 1000)), axis=1)
    n = (1 << 20) // 5 + 17
    expected = np.stack([hist_target(n, row, presorted=True) for row in ys])
    assert hist_target_rows(n, ys).tobytes() == expected.tobytes()


def test_rejects_an_empty_reference():
    with pytest.raises(ValueError):
        hist_target_rows(4, np.empty((2, 0)))
