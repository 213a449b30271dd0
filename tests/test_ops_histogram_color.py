import numpy as np
import pytest

from texsyn.ops import (
    ColorPCA,
    HistogramMatcher,
    hist_target,
    match_histogram,
    match_histogram_pca,
    match_sorted,
    periodic_smooth_decomposition,
    rgb_to_yuv,
    transport_energy,
    yuv_to_rgb,
)


def test_match_histogram_gives_exactly_the_target_values_in_rank_order():
    rng = np.random.default_rng(0)
    x = rng.random((13, 9))
    y = rng.standard_normal(117) ** 3
    out = match_histogram(x, y)
    np.testing.assert_array_equal(np.sort(out, axis=None), np.sort(y))
    np.testing.assert_array_equal(np.argsort(out, axis=None), np.argsort(x, axis=None))


def test_match_histogram_is_the_closest_permutation():
    rng = np.random.default_rng(1)
    x, y = rng.random(8), rng.random(8)
    out = match_histogram(x, y)
    best = min(np.sum((x - y[list(p)]) ** 2) for p in __import__("itertools").permutations(range(8)))
    assert np.isclose(np.sum((x - out) ** 2), best)


def test_ot_target_for_unequal_sizes():
    rng = np.random.default_rng(2)
    y = rng.random(50)
    np.testing.assert_allclose(hist_target(150, y), np.repeat(np.sort(y), 3), atol=1e-14)
    t = hist_target(37, y)
    assert t.size == 37 and np.all(np.diff(t) >= -1e-15)
    assert np.isclose(t.mean(), y.mean())  # the barycentric projection keeps the mean
    # the OT target minimises the transport energy among monotone rearrangements
    x = rng.random(37)
    matched = match_sorted(x, t)
    assert (
        transport_energy(matched, y)
        <= transport_energy(match_sorted(x, hist_target(37, y, method="interp")), y) + 1e-12
    )


def test_transport_energy_equal_sizes_is_sorted_ssd():
    rng = np.random.default_rng(3)
    x, y = rng.random(20), rng.random(20)
    assert np.isclose(transport_energy(x, y), np.sum((np.sort(x) - np.sort(y)) ** 2))


def test_random_tie_breaking_spreads_equal_values():
    x = np.zeros(1000)
    y = np.arange(1000.0)
    stable = match_sorted(x, y)
    np.testing.assert_array_equal(stable, y)
    shuffled = match_sorted(x, y, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(np.sort(shuffled), y)
    assert not np.array_equal(shuffled, y)


def test_pca_matching_matches_each_principal_axis():
    rng = np.random.default_rng(5)
    mix = np.array([[1.0, 0.5, 0.2], [0.0, 1.0, 0.3], [0.1, 0.0, 1.0]])
    ref = rng.random((20, 20, 3)) @ mix
    img = rng.random((20, 20, 3))
    pca = ColorPCA(ref)
    np.testing.assert_allclose(pca.axes.T @ pca.axes, np.eye(3), atol=1e-12)
    out = match_histogram_pca(img, ref, pca=pca)
    a, a0 = pca.forward(out).reshape(-1, 3), pca.forward(ref).reshape(-1, 3)
    for c in range(3):
        np.testing.assert_allclose(np.sort(a[:, c]), np.sort(a0[:, c]), atol=1e-12)
    np.testing.assert_allclose(np.cov(out.reshape(-1, 3).T), np.cov(ref.reshape(-1, 3).T), atol=0.02)


def test_yuv_round_trip_is_exact():
    rgb = np.random.default_rng(6).random((8, 9, 3))
    np.testing.assert_allclose(yuv_to_rgb(rgb_to_yuv(rgb)), rgb, atol=1e-14)
    grey = np.full((2, 2, 3), 0.4)
    np.testing.assert_allclose(rgb_to_yuv(grey)[..., 1:], 0.0, atol=1e-4)  # BT.601 rows sum to ~1e-5


def periodic_laplacian(u):
    return sum(np.roll(u, s, axis=a) for a in (0, 1) for s in (1, -1)) - 4 * u


def interior_laplacian(u):
    out = np.zeros_like(u)
    for axis in (0, 1):
        fwd = np.diff(u, axis=axis)
        pad_lo = [(0, 0)] * u.ndim
        pad_hi = [(0, 0)] * u.ndim
        pad_lo[axis] = (1, 0)
        pad_hi[axis] = (0, 1)
        out += np.pad(fwd, pad_hi) - np.pad(fwd, pad_lo)
    return out


@pytest.mark.parametrize("shape", [(16, 20), (15, 11, 3)])
def test_periodic_component_solves_moisans_equation(shape):
    u = np.random.default_rng(7).random(shape)
    p, s = periodic_smooth_decomposition(u)
    np.testing.assert_allclose(periodic_laplacian(p), interior_laplacian(u), atol=1e-10)
    # the smooth component (u - p by construction) is harmonic away from the border, zero mean
    np.testing.assert_allclose(periodic_laplacian(s)[1:-1, 1:-1], 0.0, atol=1e-10)
    np.testing.assert_allclose(s.mean(axis=(0, 1)), 0.0, atol=1e-12)
    np.testing.assert_allclose(p.mean(axis=(0, 1)), u.mean(axis=(0, 1)), atol=1e-12)


def test_periodic_component_of_a_periodic_smooth_image_is_close_to_itself():
    yy, xx = np.mgrid[:32, :32]
    u = 0.5 + 0.2 * np.sin(2 * np.pi * xx / 32) * np.cos(2 * np.pi * 2 * yy / 32)
    p, s = periodic_smooth_decomposition(u)
    assert np.abs(s).max() < 0.05


@pytest.mark.parametrize("threaded", [False, True])
@pytest.mark.parametrize("quantum", [None, 0.5, 0.1, "ulp", "sparse"])
def test_numpy_and_compiled_rank_scatters_give_the_same_bytes(monkeypatch, quantum, threaded):
    """``match_sorted_rows`` uses NumPy until numba is loaded (start-up, issue 20) and the
    compiled packed-key ranks after: both put equal values in position order, and values
    that differ only in their last bits (a run of equal high key bits) in value order.
    'sparse': a few short runs among distinct values, some across the blocks of keys the
    compiled kernel passes over at once when they hold no run. ``threaded``: the rows on
    numba's threads (the kernels used from ``PARALLEL_RANK_VALUES`` values, or once loaded)."""
    from texsyn.ops import ranks
    from texsyn.ops.histogram import _argsort_rows, _scatter_by_rank_numpy
    from texsyn.ops.ranks import scatter_by_key, sorted_keys

    if threaded:
        monkeypatch.setattr(ranks, "PARALLEL_RANK_VALUES", 1)
    rng = np.random.default_rng(3)
    x = rng.standard_normal((5, 3000))
    if quantum == "ulp":
        x = 1.0 + rng.integers(0, 50, x.shape) * 2.0**-52  # equal high bits, distinct values
        x[4, ::4] = -0.0
        x[4, 1::4] = 0.0
    elif quantum == "sparse":
        for row in x:
            at = np.sort(rng.choice(row.size, (60, 2), replace=False), axis=1)
            row[at[:, 1]] = row[at[:, 0]]  # pairs of equal values, and (below) pairs with
            row[at[:50, 0]] = np.nextafter(row[at[:50, 0]], np.inf)  # equal high bits out of position order
    elif quantum is not None:
        x = np.round(x / quantum) * quantum
    x[2, :50] = 0.0  # a long run, and runs that reach the row's ends
    targets = np.sort(rng.standard_normal((7, 3000)), axis=1)
    rows = np.array([6, 0, 3, 3, 1])
    order = _argsort_rows(x)
    keys, shift = sorted_keys(x)
    compiled = scatter_by_key(x, keys, shift, targets, rows)
    assert np.array_equal(_scatter_by_rank_numpy(x, order.copy(), targets, rows), compiled)
    stable = np.argsort(x, axis=1, kind="stable")
    expected = np.empty_like(x)
    np.put_along_axis(expected, stable, targets[rows], axis=1)
    assert np.array_equal(compiled, expected)


@pytest.mark.parametrize("pca", [False, True])
def test_histogram_matcher_ranks_the_channels_together_with_the_bytes_of_one_at_a_time(pca):
    """``HistogramMatcher`` ranks every channel in one ``match_sorted_rows`` call (rows over
    the worker threads): the bytes of ``match_sorted`` channel by channel, ties included."""
    from texsyn.ops import ColorPCA, HistogramMatcher
    from texsyn.ops.histogram import hist_target, match_sorted

    rng = np.random.default_rng(5)
    reference = rng.random((40, 30, 3))
    image = np.round(rng.standard_normal((23, 17, 3)) * 4) / 4  # many ties
    axes = ColorPCA(reference) if pca else None
    ref = axes.forward(reference) if pca else reference
    sorted_values = [np.sort(ref[..., c], axis=None) for c in range(3)]
    matcher = HistogramMatcher(sorted_values, 23 * 17, pca=axes)
    coords = axes.forward(image) if pca else image
    expected = np.stack(
        [
            match_sorted(coords[..., c], hist_target(23 * 17, v, presorted=True))
            for c, v in enumerate(sorted_values)
        ],
        axis=-1,
    )
    expected = axes.inverse(expected) if pca else expected
    assert np.array_equal(matcher(image), expected)
    with pytest.raises(ValueError, match="target values"):
        matcher(image[:5])


def test_random_tie_break_is_lexsort():
    """``match_sorted(..., rng)`` orders equal values by a random key: the ranks of
    ``lexsort((random, values))``, computed from one sort and the ties only."""
    from texsyn.ops.histogram import _rank_with_random_ties

    rng = np.random.default_rng(5)
    for quantum in (None, 0.5, 0.05):
        v = rng.standard_normal(4000)
        if quantum is not None:
            v = np.round(v / quantum) * quantum
        v[::9] = -0.0
        v[5::11] = np.nan
        keys = np.round(rng.random(v.size), 2)  # equal keys too: then by position
        assert np.array_equal(_rank_with_random_ties(v, keys), np.lexsort((keys, v)))


def test_expect_ranks_loads_the_compiled_ranks_for_a_large_total_only():
    """An iterative method announces its total (Heeger-Bergen): below the threshold the
    choice stays call by call, from it the compiled kernels are loaded."""
    from texsyn.ops.ranks import COMPILED_SCATTER_VALUES, compiled_ranks, expect_ranks

    assert expect_ranks(10) == compiled_ranks(10)
    assert expect_ranks(COMPILED_SCATTER_VALUES)
    assert compiled_ranks(10)


def test_histogram_matcher_in_place_with_scratch_keys_gives_the_same_bytes():
    """Issue 20: Heeger-Bergen matches its subbands in place with reused key scratch; the
    result is the copy's, byte for byte, written into the (C, H, W) planes it came from."""
    rng = np.random.default_rng(3)
    references = [np.sort(rng.standard_normal(150)) for _ in range(2)]
    matcher = HistogramMatcher(references, 12 * 10)
    planes = rng.standard_normal((2, 12, 10))
    planes[0, :3] = 0.25  # ties, ranked by position
    image = np.moveaxis(planes, 0, -1)  # (H, W, C) view of the planes
    expected = matcher(image.copy())
    keys = np.full((2, 120), 7, dtype=np.uint64)
    out = matcher(image, overwrite=True, keys=keys)
    assert out.tobytes() == expected.tobytes()
    assert np.shares_memory(out, planes) and planes.tobytes() == np.moveaxis(expected, -1, 0).tobytes()
    channels_last = rng.standard_normal((12, 10, 2))  # rows not contiguous: a new array
    before = channels_last.copy()
    out = matcher(channels_last, overwrite=True, keys=keys)
    assert not np.shares_memory(out, channels_last) and channels_last.tobytes() == before.tobytes()
    assert out.tobytes() == matcher(before).tobytes()
