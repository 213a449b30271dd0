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


@pytest.mark.parametrize("compiled", [False, True])
def test_match_sorted_rows_in_place_with_reused_keys_is_the_same_bytes(compiled, monkeypatch):
    """Issue 20: grouplets match their bands in place (``out=values``) with a reused key
    buffer; ties, runs of values equal in their high bits and the NumPy path included."""
    from texsyn.ops import histogram, ranks
    from texsyn.ops.histogram import match_sorted_rows

    if compiled:
        _ot_targets.compiled()
    else:
        monkeypatch.setattr(histogram, "compiled_ranks", lambda size: False)
    rng = np.random.default_rng(4)
    x = rng.standard_normal((6, 2000))
    x[1] = 1.0 + rng.integers(0, 40, 2000) * 2.0**-52  # equal high bits, distinct values
    x[2, :60] = 0.0
    x[3, ::3] = -0.0
    targets = np.sort(rng.standard_normal((8, 2000)), axis=1)
    rows = np.array([7, 0, 3, 3, 1, 2])
    expected = match_sorted_rows(x, targets, rows=rows)
    stable = np.argsort(x, axis=1, kind="stable")
    reference = np.empty_like(x)
    np.put_along_axis(reference, stable, targets[rows], axis=1)
    assert expected.tobytes() == reference.tobytes()
    keys = np.empty(x.shape, dtype=np.uint64)
    for _ in range(2):  # the key buffer holds the last call's keys
        values = x.copy()
        assert match_sorted_rows(values, targets, rows=rows, out=values, keys=keys) is values
        assert values.tobytes() == expected.tobytes()
    assert ranks.PARALLEL_RANK_VALUES > x.size  # one thread here; test_determinism runs the threads
