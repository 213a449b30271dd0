import numpy as np
import pytest

from texsyn.ops import (
    FFTPatchSearch,
    WeightedPatchBank,
    average_patches,
    extract_patches,
    knn_patches,
    knn_select,
    overlap_add,
)


def brute_distances(ex, query, weights, mode):
    ex = ex if ex.ndim == 3 else ex[..., None]
    q = query if query.ndim == 3 else query[..., None]
    h, w = q.shape[:2]
    H, W = ex.shape[:2]
    rows = range(H) if mode == "periodic" else range(H - h + 1)
    cols = range(W) if mode == "periodic" else range(W - w + 1)
    out = np.empty((len(rows), len(cols)))
    for i in rows:
        for j in cols:
            win = ex[np.arange(i, i + h)[:, None] % H, np.arange(j, j + w)[None, :] % W]
            out[i, j] = np.sum(weights[..., None] * (win - q) ** 2)
    return out


@pytest.mark.parametrize("mode", ["valid", "periodic"])
@pytest.mark.parametrize("channels", [1, 3])
def test_extract_patches_matches_slicing(mode, channels):
    rng = np.random.default_rng(1)
    img = rng.random((9, 11, channels))
    patches, anchors = extract_patches(img, 4, stride=2, mode=mode)
    for (i, j), p in zip(anchors, patches):
        win = img[np.arange(i, i + 4)[:, None] % 9, np.arange(j, j + 4)[None, :] % 11]
        np.testing.assert_array_equal(p, win.ravel())


@pytest.mark.parametrize("mode", ["valid", "periodic"])
def test_overlap_add_is_the_adjoint_of_extraction(mode):
    rng = np.random.default_rng(2)
    img = rng.random((10, 12, 3))
    patches, anchors = extract_patches(img, 5, stride=1, mode=mode)
    other = rng.random(patches.shape)
    back, coverage = overlap_add(other, anchors, img.shape, 5, mode=mode)
    assert np.isclose(np.sum(patches * other), np.sum(img * back))
    if mode == "periodic":
        assert np.all(coverage == 25)
    np.testing.assert_allclose(average_patches(patches, anchors, img.shape, 5, mode=mode), img, atol=1e-12)


@pytest.mark.parametrize("mode", ["valid", "periodic"])
@pytest.mark.parametrize("channels", [1, 3])
def test_fft_search_equals_brute_force(mode, channels):
    rng = np.random.default_rng(3)
    ex = rng.random((17, 15, channels))
    query = rng.random((5, 4, channels))
    weights = rng.random((5, 4)) * (rng.random((5, 4)) > 0.3)
    search = FFTPatchSearch(ex, (5, 4), mode=mode)
    d = search.distances(query, weights)
    ref = brute_distances(ex, query, weights, mode)
    assert d.shape == ref.shape
    np.testing.assert_allclose(d, ref, atol=1e-10)
    anchors, dist = search.knn(query, weights, k=6)
    np.testing.assert_allclose(dist, np.sort(ref.ravel())[:6], atol=1e-10)
    for (i, j), v in zip(anchors, dist):
        assert np.isclose(ref[i, j], v, atol=1e-10)


def test_fft_search_with_per_channel_weights():
    rng = np.random.default_rng(6)
    ex = rng.random((14, 16, 4))
    query = rng.random((5, 5, 4))
    weights = rng.random((5, 5, 4)) * (rng.random((5, 5, 4)) > 0.4)
    d = FFTPatchSearch(ex, (5, 5)).distances(query, weights)
    ref = np.empty_like(d)
    for i in range(d.shape[0]):
        for j in range(d.shape[1]):
            ref[i, j] = np.sum(weights * (ex[i : i + 5, j : j + 5] - query) ** 2)
    np.testing.assert_allclose(d, ref, atol=1e-10)


def test_fft_search_rejects_window_larger_than_exemplar():
    with pytest.raises(ValueError, match="larger than the exemplar"):
        FFTPatchSearch(np.zeros((8, 8)), (9, 3))


def test_knn_select_breaks_ties_by_index_and_clamps_k():
    d = np.array([3.0, 1.0, 2.0, 1.0, 0.5, 1.0])
    np.testing.assert_array_equal(knn_select(d, 3), [4, 1, 3])
    np.testing.assert_array_equal(knn_select(d, 6), np.argsort(d, kind="stable"))
    np.testing.assert_array_equal(knn_select(d, 60), np.argsort(d, kind="stable"))


def test_knn_patches_equals_brute_force():
    rng = np.random.default_rng(4)
    bank = rng.random((200, 12))
    queries = rng.random((37, 12))
    idx, dist = knn_patches(queries, bank, k=5, block=16)
    full = ((queries[:, None, :] - bank[None]) ** 2).sum(-1)
    np.testing.assert_allclose(dist, np.sort(full, axis=1)[:, :5], atol=1e-12)
    np.testing.assert_allclose(np.take_along_axis(full, idx, axis=1), dist, atol=1e-12)


def test_weighted_bank_equals_brute_force():
    rng = np.random.default_rng(5)
    bank = rng.random((50, 20))
    queries = rng.random((7, 20))
    weights = rng.random((7, 20)) * (rng.random((7, 20)) > 0.5)
    d = WeightedPatchBank(bank).distances(queries, weights)
    ref = (weights[:, None, :] * (bank[None] - queries[:, None, :]) ** 2).sum(-1)
    np.testing.assert_allclose(d, ref, atol=1e-12)
