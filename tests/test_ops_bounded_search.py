"""The proven nearest-row search (texsyn.ops.search.BoundedNearestIndex) against brute force."""

import numpy as np
import pytest

from texsyn.ops.linalg import fixed_order
from texsyn.ops.search import (
    BoundedNearestIndex,
    nearest_rows,
    nearest_rows_bounded,
    nearest_rows_by_column_blocks,
)


def _bank(rng, k, d, duplicates=0):
    # smooth, correlated rows (like image neighbourhoods) so that the projection matters
    base = rng.random((k, 4)) @ rng.random((4, d)) + 0.05 * rng.random((k, d))
    if duplicates:
        base[-duplicates:] = base[:duplicates]
    return base


@pytest.mark.parametrize("dims,extra", [(8, 8), (16, 0), (4, 60)])
def test_nearest_equals_brute_force_with_exact_distances(dims, extra):
    rng = np.random.default_rng(0)
    bank = _bank(rng, 3000, 60)
    queries = bank[rng.integers(0, 3000, 200)] + 0.02 * rng.standard_normal((200, 60))
    index = BoundedNearestIndex(bank, dims=dims, extra=extra, chunk=512)
    with fixed_order():
        best, dist, counts = index.query(queries, np.zeros((200, 1)))
    exact = ((queries[:, None, :] - bank[None]) ** 2).sum(-1)
    assert np.array_equal(best, exact.argmin(axis=1))
    np.testing.assert_allclose(dist, exact.min(axis=1), rtol=1e-12)
    assert np.all(counts[:, 0] >= 1)


def test_counts_find_every_row_within_the_band_and_seeds_change_nothing():
    rng = np.random.default_rng(1)
    bank = _bank(rng, 2048, 30, duplicates=100)
    queries = bank[rng.integers(0, 2048, 300)] + 0.01 * rng.standard_normal((300, 30))
    queries[:50] = bank[1948:1998]  # exact copies of duplicated rows: two rows at distance 0
    exact = ((queries[:, None, :] - bank[None]) ** 2).sum(-1)
    band = 0.05 * np.ones(300)
    index = BoundedNearestIndex(bank, dims=6, extra=6, chunk=256)
    seeds = np.stack([rng.integers(-1, 2048, 300), exact.argmin(axis=1)], axis=1)
    with fixed_order():
        best, _, counts = index.query(queries, np.stack([np.zeros(300), band], axis=1))
        best_seeded, _, counts_seeded = index.query(queries, np.stack([np.zeros(300), band], axis=1), seeds)
    within = (exact <= exact.min(axis=1, keepdims=True) + band[:, None]).sum(axis=1)
    assert np.all(counts[:, 1] >= within) and np.all(counts_seeded[:, 1] >= within)
    assert np.all(counts[:50, 0] >= 2)  # the exact duplicates are counted
    assert np.array_equal(best, exact.argmin(axis=1)) and np.array_equal(best_seeded, best)


def test_nearest_rows_bounded_is_nearest_rows():
    rng = np.random.default_rng(2)
    bank = _bank(rng, 4096, 45, duplicates=50)
    norms = np.sum(bank * bank, axis=1)
    index = BoundedNearestIndex(bank, dims=12, extra=12)
    with fixed_order():
        for rows in (1, 7, 64):
            queries = bank[rng.integers(0, 4096, rows)] + 0.03 * rng.standard_normal((rows, 45))
            assert np.array_equal(
                nearest_rows_bounded(queries, bank, norms, index), nearest_rows(queries, bank, norms)
            )
        ties = bank[4046:4056]  # rows with an identical twin: answered by nearest_rows itself
        assert np.array_equal(nearest_rows_bounded(ties, bank, norms, index), nearest_rows(ties, bank, norms))


def test_fallback_in_column_blocks_is_nearest_rows():
    # 100 copies of row 10 in the last block of columns: more tied rows than the index keeps,
    # so nearest_rows_bounded falls back to the exact search, one block of bank rows at a time
    rng = np.random.default_rng(3)
    bank = _bank(rng, 5000, 20)
    bank[4900:] = bank[10]
    norms = np.sum(bank * bank, axis=1)
    noisy = bank[rng.integers(0, 5000, 300)] + 0.01 * rng.standard_normal((300, 20))
    queries = np.concatenate([bank[[10, 4950]], noisy])  # two tiles of query rows
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    with fixed_order():
        expected = nearest_rows(queries, bank, norms)
        assert np.array_equal(nearest_rows_by_column_blocks(queries, bank, norms), expected)
        assert np.array_equal(nearest_rows_bounded(queries[:2], bank, norms, index), expected[:2])
    assert expected[:2].tolist() == [10, 10]  # the lowest of the tied rows


def _exemplar(size=64):
    import texsyn

    return np.stack([texsyn.data.exemplar(n, size=size) for n in ("grass", "gravel", "brick")], -1)


@pytest.mark.parametrize("workers", [1, 3])
def test_wei_levoy_proven_search_gives_the_plain_search_bytes(monkeypatch, workers):
    import texsyn
    import texsyn.methods.wei_levoy as wl
    import texsyn.ops.search as search

    ex = _exemplar()
    params = {"levels": 2, "window": 5, "parent_window": 3}
    fast = texsyn.make_method("wei_levoy", **params).fit(ex)
    assert fast.indexes_[0] is not None  # 64 x 64 = 4096 rows: the proven search is used
    monkeypatch.setattr(search, "worker_count", lambda: workers)  # parts of the bank per query
    monkeypatch.setattr(search, "PARALLEL_PAIRS", 0)  # however few the queries of a wavefront
    got = fast.sample_with_map((72, 80), rng=3)
    monkeypatch.setattr(wl, "BOUNDED_SEARCH_ROWS", 10**9)
    plain = texsyn.make_method("wei_levoy", **params).fit(ex)
    assert plain.indexes_[0] is None
    want = plain.sample_with_map((72, 80), rng=3)
    assert np.array_equal(got.image, want.image) and np.array_equal(got.source_map, want.source_map)


def test_patch_wavelet_fast_search_gives_the_index_bytes(monkeypatch):
    import texsyn
    import texsyn.models.patch_search as pws

    ex = _exemplar()
    fast = texsyn.make_method("patch_wavelet").fit(ex)
    assert 8 in fast.transform_.fast
    got = fast.sample_with_map((128, 128), rng=5)
    monkeypatch.setattr(pws, "FAST_SEARCH_POSITIONS", 10**9)
    plain = texsyn.make_method("patch_wavelet").fit(ex)
    assert not plain.transform_.fast
    want = plain.sample_with_map((128, 128), rng=5)
    assert np.array_equal(got.image, want.image) and np.array_equal(got.source_map, want.source_map)
    # the pairs the fast search cannot prove go to the index, and give its answers
    t = fast.transform_
    rng = np.random.default_rng(0)
    first = np.stack([rng.integers(0, 64, 300), rng.integers(0, 64, 300)], axis=1)
    second = (first + rng.integers(-3, 4, (300, 2))) % 64
    rows = np.arange(300)
    answers = pws.index_answers(
        t, lambda k: t.windows.mean_descriptors(first[k], second[k], 1, 2, 8), rows, 300, 8
    )
    assert np.array_equal(answers, plain.transform_.mean_features(first, second, 1, 2, 8))
    assert np.array_equal(t.mean_features(first, second, 1, 2, 8), answers)


def test_query_terms_in_one_pass_equal_the_side_terms():
    """The compiled query side of the bounds (``_bounded_prepare``) against its NumPy formulas."""
    from texsyn.ops.search import _U32, _U64, _bounded_prepare, _bounded_seeds, _gamma

    rng = np.random.default_rng(3)
    bank = _bank(rng, 2048, 40)
    index = BoundedNearestIndex(bank, dims=8, extra=8)
    q = bank[rng.integers(0, 2048, 37)] + 0.02 * rng.standard_normal((37, 40))
    seeds = rng.integers(-1, 2048, (37, 2))
    bands = rng.random((37, 2, 3))
    m, (dim, coords), dims = len(q), index.basis.shape, index.dims
    centred = q - index.mean
    full = centred @ index.basis
    proj32, q_ext, band, terms = (
        np.empty((m, dims + 1), np.float32), np.empty((m, coords - dims)), np.empty((m, 3)), np.empty((7, m))
    )  # fmt: skip
    state = [np.empty((2, m), np.int64), np.empty((2, m)), np.empty((2, m))]
    keep = [np.empty((2, m, 8), np.int64), np.empty((2, m, 8)), np.empty((2, m), np.int64)]
    gamma_x = 1.01 * _gamma(dim + 3, _U64)
    _bounded_prepare(
        centred, full, dims, _gamma(dims + 4, _U32), index._proj_max,
        1.2 * (_U32 + np.sqrt(coords) * _gamma(dim + 3, _U64)) * index._sigma,
        1.1 * (3.0 * np.sqrt(coords) * _gamma(dim + coords, _U64) + 4.0 * index._ortho + 4.0 * _U64),
        bands, proj32, q_ext, terms, band, q, index.bank, seeds, gamma_x, *state, *keep,
    )  # fmt: skip
    p64 = full[:, :dims].astype(np.float32).astype(np.float64)
    q_sq = np.einsum("kd,kd->k", p64, p64)
    l_err = 2.5 * _gamma(dims + 4, _U32) * (np.sqrt(q_sq) + index._proj_max) ** 2 + 1e-300
    reference = np.array([q_sq, l_err, *index._side_terms(centred, full)])
    np.testing.assert_allclose(terms, reference, rtol=1e-9, atol=1e-12)
    assert np.array_equal(proj32[:, :dims], full[:, :dims].astype(np.float32)) and np.all(
        proj32[:, dims] == 1
    )
    assert np.array_equal(q_ext, full[:, dims:].astype(np.float32).astype(np.float64))
    assert np.array_equal(band, bands.max(axis=1))
    best_j, best_x, upper = np.empty(m, np.int64), np.empty(m), np.full(m, np.inf)
    keep_j, keep_x, kept = np.empty((m, 8), np.int64), np.empty((m, 8)), np.empty(m, np.int64)
    _bounded_seeds(q, index.bank, seeds, gamma_x, best_j, best_x, upper, keep_j, keep_x, kept)
    assert np.array_equal(state[0][0], best_j) and np.array_equal(state[1][0], best_x)
    assert np.array_equal(state[2], np.stack([upper, upper])) and np.all(state[0][1] == -1)
    assert np.array_equal(keep[2], np.stack([kept, np.zeros(m, np.int64)]))


def test_isolated_seeds_take_the_first_equal_isolated_seed():
    from texsyn.ops.search import _isolated_seeds

    rng = np.random.default_rng(4)
    bank = rng.random((50, 6))
    isolated = rng.random(50) < 0.7
    seeds = rng.integers(-1, 50, (40, 2))
    pick = rng.integers(0, 2, 40)
    queries = bank[np.maximum(seeds[np.arange(40), pick], 0)].copy()
    queries[::5] += 1e-3  # equal to no row
    best = np.full(40, -1, dtype=np.int64)
    _isolated_seeds(queries, bank, seeds, isolated, best)
    expected = np.full(40, -1, dtype=np.int64)
    for s in range(2):  # the former NumPy loop
        col = seeds[:, s]
        equal = (col >= 0) & (expected < 0)
        equal[equal] = np.all(bank[col[equal]] == queries[equal], axis=1) & isolated[col[equal]]
        expected[equal] = col[equal]
    assert np.array_equal(best, expected) and np.any(best >= 0)


def test_gather_wrapped_equals_the_numpy_gather():
    """Wei-Levoy's wavefront queries: the compiled gather against the NumPy one, both parts."""
    from texsyn.methods.wei_levoy import _gather, causal_offsets, square_offsets
    from texsyn.ops.patches import gather_wrapped

    rng = np.random.default_rng(5)
    image, parent = rng.random((20, 17, 3)), rng.random((10, 9, 3))
    ys, xs = rng.integers(0, 20, 30), rng.integers(0, 17, 30)
    causal, square = causal_offsets(7), square_offsets(3)
    q = np.empty((30, (len(causal) + len(square)) * 3))
    gather_wrapped(image, ys, xs, causal, q)
    gather_wrapped(parent, ys // 2, xs // 2, square, q, len(causal) * 3)
    expected = np.concatenate(
        [_gather(image, ys, xs, causal), _gather(parent, ys // 2, xs // 2, square)], axis=1
    )
    assert np.array_equal(q, expected)
    tiny = rng.random((2, 3, 3))  # offsets reaching past the whole image
    q = np.empty((4, len(causal) * 3))
    gather_wrapped(tiny, np.array([0, 1, 1, 0]), np.array([0, 2, 1, 1]), causal, q)
    assert np.array_equal(q, _gather(tiny, np.array([0, 1, 1, 0]), np.array([0, 2, 1, 1]), causal))


def test_wavefront_queries_equal_the_gathers_and_the_seeds():
    """Wei-Levoy's compiled wavefront pass against the NumPy gathers and seed formulas."""
    from texsyn.methods.wei_levoy import _gather, _wavefront_queries, causal_offsets, square_offsets

    rng = np.random.default_rng(6)
    out, parent = rng.random((20, 17, 3)), rng.random((10, 9, 3))
    src = rng.integers(0, 12 * 11, (20, 17))
    ys = np.array([0, 1, 7, 19])
    xs = np.array([16, 0, 3, 0])  # the wraps on every side
    causal, square = causal_offsets(9), square_offsets(5)  # reaching across the parent's wrap
    for par in (parent, np.empty((0, 0, 3))):
        width = len(causal) * 3 + (len(square) * 3 if par.size else 0)
        q, seeds = np.empty((4, width)), np.empty((4, 2), dtype=np.int64)
        _wavefront_queries(out, par, ys, xs, causal, square, src, 11, 12, q, seeds)
        parts = [_gather(out, ys, xs, causal)] + (
            [_gather(par, ys // 2, xs // 2, square)] if par.size else []
        )
        assert np.array_equal(q, np.concatenate(parts, axis=1))
        left, up = src[ys, xs - 1], src[ys - 1, xs]
        assert np.array_equal(seeds[:, 0], left - left % 11 + (left + 1) % 11)
        assert np.array_equal(seeds[:, 1], (up + 11) % (12 * 11))


def test_searched_bands_are_the_band_of_the_queries_left():
    from texsyn.ops.search import _BAND_FACTOR, _U64, _gamma, _searched_bands, nearest_rows_band

    rng = np.random.default_rng(7)
    queries = rng.random((30, 11))
    best = np.where(rng.random(30) < 0.3, rng.integers(0, 9, 30), -1)
    rest, bands = np.empty(30, dtype=np.int64), np.full((30, 1, 3), np.nan)
    count = _searched_bands(queries, best, _BAND_FACTOR * _gamma(13, _U64), 2.5, rest, bands)
    assert count == np.sum(best < 0) and np.array_equal(rest[:count], np.flatnonzero(best < 0))
    np.testing.assert_allclose(bands[:count, 0, 2], nearest_rows_band(queries[best < 0], 2.5), rtol=1e-13)
    assert np.all(bands[:count, 0, :2] == 0)
