"""Constrained sparse synthesis (Tartavel, Gousseau, Peyre 2013): building blocks and method."""

import itertools

import numpy as np
import pytest

import texsyn
from texsyn.io import load_fitted, save_fitted
from texsyn.ops import HistogramMatcher, average_patches, extract_patches
from texsyn.ops.graphcut import cut_value, graphcut_reassemble, kwatra_costs, seam_take_old
from texsyn.ops.sparse import (
    SpectrumProjector,
    batch_omp,
    constrained_matching_pursuit,
    image_energy,
    image_update,
    ksvd,
    upsample_bicubic,
)
from texsyn.ops.sparse import box_power as _box_power


def unit_dictionary(rng, dim, n):
    d = rng.standard_normal((dim, n))
    return d / np.linalg.norm(d, axis=0)


def test_batch_omp_equals_scikit_learn():
    sklearn = pytest.importorskip("sklearn.linear_model")
    rng = np.random.default_rng(0)
    d = unit_dictionary(rng, 30, 50)
    x = rng.standard_normal((30, 200))
    w = batch_omp(d, x, 4)
    ref = sklearn.orthogonal_mp_gram(d.T @ d, d.T @ x, n_nonzero_coefs=4)
    np.testing.assert_allclose(w, ref, atol=1e-10)
    assert np.count_nonzero(w, axis=0).max() <= 4


def test_ksvd_learns_unit_atoms_that_code_better_than_its_start():
    rng = np.random.default_rng(1)
    truth = unit_dictionary(rng, 20, 15)
    codes = np.zeros((15, 600))
    for k in range(600):
        codes[rng.choice(15, 2, replace=False), k] = rng.standard_normal(2)
    x = truth @ codes
    d = ksvd(x, 15, 2, n_iterations=15, max_training=600, rng=np.random.default_rng(2))
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-12)
    err = np.linalg.norm(x - d @ batch_omp(d, x, 2)) / np.linalg.norm(x)
    start = x[:, np.random.default_rng(2).choice(600, 15, replace=False)]
    start /= np.linalg.norm(start, axis=0)
    err0 = np.linalg.norm(x - start @ batch_omp(start, x, 2)) / np.linalg.norm(x)
    assert err < 0.5 * err0


def naive_cmp(p, d, s, f):
    """Constrained MP by exhaustive argmax over the available pairs (reference)."""
    corr = d.T @ p
    n, k = corr.shape
    w = np.zeros((n, k))
    g = d.T @ d
    for _ in range(s * k):
        used = w != 0
        per_patch = used.sum(0)
        per_atom = used.sum(1)
        avail = used | ((per_patch[None, :] < s) & (per_atom[:, None] < f[:, None]))
        if not avail.any():
            break
        score = np.where(avail, np.abs(corr), -1)
        # ties between patches: the heap pops the lowest patch index first
        best = score.max()
        cols = np.flatnonzero((score == best).any(axis=0))
        col = cols[0]
        row = int(np.argmax(score[:, col]))
        c = corr[row, col]
        w[row, col] += c
        corr[:, col] -= c * g[:, row]
    return w


def test_constrained_matching_pursuit_respects_both_constraints_and_matches_naive():
    rng = np.random.default_rng(3)
    d = unit_dictionary(rng, 12, 10)
    p = rng.standard_normal((12, 15))
    budget = rng.integers(1, 6, 10)
    w = constrained_matching_pursuit(p, d, 3, budget)
    assert np.count_nonzero(w, axis=0).max() <= 3
    assert np.all(np.count_nonzero(w, axis=1) <= budget)
    np.testing.assert_allclose(w, naive_cmp(p, d, 3, budget), atol=1e-12)


def test_matching_pursuit_without_budget_on_one_patch_is_plain_mp():
    rng = np.random.default_rng(4)
    d = unit_dictionary(rng, 10, 8)
    x = rng.standard_normal(10)
    w = constrained_matching_pursuit(x[:, None], d, 3, None)[:, 0]
    r, ref, energies = x.copy(), np.zeros(8), [x @ x]
    for _ in range(3):
        n = int(np.argmax(np.abs(d.T @ r)))
        c = d[:, n] @ r
        ref[n] += c
        r = r - c * d[:, n]
        energies.append(r @ r)
        assert np.isclose(energies[-2] - energies[-1], c * c)  # energy drops by exactly c^2
    np.testing.assert_allclose(w, ref, atol=1e-12)


def test_linear_and_graphcut_reconstruction_of_true_patches_is_the_identity():
    rng = np.random.default_rng(5)
    u = rng.random((24, 36, 3))
    patches, anchors = extract_patches(u, 6, stride=3, mode="periodic")
    np.testing.assert_allclose(average_patches(patches, anchors, u.shape, 6, mode="periodic"), u, atol=1e-12)
    grid = patches.reshape(8, 12, 6, 6, 3)
    np.testing.assert_array_equal(graphcut_reassemble(grid, 3, (24, 36)), u)


@pytest.mark.parametrize("seed", range(12))
def test_graph_cut_seam_is_the_brute_force_minimum_cut(seed):
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(2, 5)), int(rng.integers(3, 6))
    a, b = rng.random((h, w, 3)), rng.random((h, w, 3))
    cost_h, cost_v = kwatra_costs(a, b)
    keep = seam_take_old(a, b)
    assert keep[:, 0].all() and not keep[:, -1].any()
    free = [(r, c) for r in range(h) for c in range(1, w - 1)]
    best = np.inf
    for bits in itertools.product([False, True], repeat=len(free)):
        lab = np.zeros((h, w), dtype=bool)
        lab[:, 0] = True
        for (r, c), bit in zip(free, bits):
            lab[r, c] = bit
        best = min(best, cut_value(lab, cost_h, cost_v))
    assert np.isclose(cut_value(keep, cost_h, cost_v), best, rtol=1e-9, atol=1e-12)


def test_graphcut_reconstruction_of_two_patches_is_the_minimum_cut_composite():
    rng = np.random.default_rng(7)
    a, b = rng.random((4, 5)), rng.random((4, 5))
    keep = seam_take_old(a, b)
    composite = np.where(keep, a, b)
    cost_h, cost_v = kwatra_costs(a, b)
    free = [(r, c) for r in range(4) for c in range(1, 4)]
    values = []
    for bits in itertools.product([False, True], repeat=len(free)):
        lab = np.zeros((4, 5), dtype=bool)
        lab[:, 0] = True
        for (r, c), bit in zip(free, bits):
            lab[r, c] = bit
        values.append((cut_value(lab, cost_h, cost_v), lab))
    best_value, best_lab = min(values, key=lambda v: v[0])
    assert sum(np.isclose(v, best_value) for v, _ in values) == 1  # a unique minimum for this seed
    np.testing.assert_array_equal(composite, np.where(best_lab, a, b))


def test_image_update_decreases_the_energy_with_linear_reconstruction():
    rng = np.random.default_rng(8)
    ex = texsyn.data.exemplar("gravel", size=36).astype(np.float64)[..., None]
    tau, step = 6, 3
    d = ksvd(extract_patches(ex, tau)[0].T, 20, 3, n_iterations=2, rng=np.random.default_rng(0))
    u = rng.random((24, 24, 1))
    patches, anchors = extract_patches(u, tau, stride=step, mode="periodic")
    coded = (d @ constrained_matching_pursuit(patches.T, d, 3, None)).T
    recon = average_patches(coded, anchors, u.shape, tau, mode="periodic")
    projector = HistogramMatcher([np.sort(ex, axis=None)], u.shape[0] * u.shape[1])
    box = _box_power(u.shape[:2], tau)
    mean = np.full(u.shape, ex.mean())
    # the histogram set and the spectrum set are not convex: the step still descends because
    # both projections are exact nearest points (ops.sparse.image_update's docstring)
    spectrum = SpectrumProjector(ex, u.shape[:2])
    for beta, ref, power in ((0.0, mean, box), (1.0, mean, box), (1.0, spectrum, np.maximum(box, 0.3))):
        energies = []
        v = u.copy()
        for _ in range(8):
            energies.append(
                image_energy(
                    v, coded, tau, step, projector, alpha=1.0, beta=beta, box_power=power, reference=ref
                )
            )
            v = image_update(
                v, recon, projector, alpha=1.0, beta=beta, box_power=power, reference=ref, n_steps=1, rng=None
            )
        assert np.all(np.diff(energies) <= 1e-10 * energies[0])
        assert energies[-1] < energies[0]


def test_histogram_projection_gives_the_exemplar_values():
    rng = np.random.default_rng(9)
    ex = rng.random((10, 12))
    proj = HistogramMatcher([np.sort(ex, axis=None)], 120)
    out = proj(rng.random((10, 12, 1)), rng)
    np.testing.assert_array_equal(np.sort(out, axis=None), np.sort(ex, axis=None))


def test_bicubic_upsampling_interpolates_the_samples():
    u = np.random.default_rng(10).random((8, 6, 2))
    np.testing.assert_allclose(upsample_bicubic(u)[::2, ::2], u, atol=1e-12)


SMALL = dict(patch_size=6, step=3, n_atoms=24, ksvd_iterations=3, n_outer=4, n_inner=4)


@pytest.mark.method("sparse")
def test_final_histogram_equals_the_exemplars_for_an_equal_size():
    ex = texsyn.data.exemplar("brick", size=36)
    out = texsyn.synthesize(ex, "sparse", ex.shape, rng=0, n_scales=2, **SMALL)
    np.testing.assert_allclose(np.sort(out, axis=None), np.sort(ex, axis=None), atol=1e-7)


def test_save_load_sample_is_identical(tmp_path):
    ex = texsyn.data.exemplar("grass", size=32)
    colour = np.stack([ex, ex[::-1], ex.T], axis=-1)
    method = texsyn.make_method("sparse", n_scales=2, **SMALL).fit(colour)
    path = save_fitted(tmp_path / "dict.npz", method)
    loaded = load_fitted(path)
    np.testing.assert_array_equal(loaded.sample((30, 30), rng=3), method.sample((30, 30), rng=3))
    faster = load_fitted(path, n_outer=2)
    assert faster.n_outer == 2
    with pytest.raises(ValueError, match="patch_size"):
        load_fitted(path, patch_size=8)


def test_frequency_budget_follows_the_output_size_and_bounds_the_usage():
    ex = texsyn.data.exemplar("brick", size=36)
    method = texsyn.make_method("sparse", mode="frequency", **SMALL).fit(ex)
    scale = method.scales_[0]
    assert scale["usage"].sum() <= method.sparsity * scale["n_patches"]
    budgets = {}
    for shape in [(30, 30), (90, 60)]:
        seen = []
        method.sample(shape, rng=0, callback=seen.append)
        info = seen[-1].info
        expected = np.ceil(info["n_patches"] / scale["n_patches"] * scale["usage"]).astype(int)
        np.testing.assert_array_equal(info["budget"], expected)
        assert np.all(info["usage"] <= info["budget"])
        assert info["usage"].sum() >= 0.9 * min(info["budget"].sum(), method.sparsity * info["n_patches"])
        budgets[shape] = info["budget"]
    assert budgets[(90, 60)].sum() > budgets[(30, 30)].sum()


def test_too_small_exemplar_and_bad_steps_are_rejected():
    with pytest.raises(ValueError, match="need at least"):
        texsyn.make_method("sparse", patch_size=12, n_scales=3).fit(np.random.default_rng(0).random((52, 52)))
    with pytest.raises(ValueError, match="divide"):
        texsyn.make_method("sparse", patch_size=12, step=5).fit(np.zeros((64, 64)))
    with pytest.raises(ValueError, match="at least patch_size/2"):
        texsyn.make_method("sparse", patch_size=12, step=4).fit(np.zeros((64, 64)))


@pytest.mark.parametrize("shape", [(264, 264, 3), (66, 66, 1), (37, 50, 3), (9, 7, 1)])
def test_scipy_ffts_give_numpys_bytes(shape):
    """Issue 20: the image step's FFTs run on scipy.fft (faster, lines on threads) and must
    give the bytes of the numpy.fft calls they replace (the inverse one axis at a time)."""
    from texsyn.ops.sparse import _irfft2, _rfft2

    u = np.random.default_rng(13).standard_normal(shape)
    spectrum = np.fft.rfft2(u, axes=(0, 1))
    assert _rfft2(u).tobytes() == spectrum.tobytes()
    assert (
        _irfft2(spectrum, shape[:2]).tobytes() == np.fft.irfft2(spectrum, s=shape[:2], axes=(0, 1)).tobytes()
    )


# ---------------------------------------------------------------- issue 20: fast paths, same bytes
def heap_pursuit(patches, d, s, budget):
    """texsyn 0.3's constrained matching pursuit in Python (one heap entry per patch): the
    reference the compiled kernel must reproduce byte for byte."""
    import heapq

    g = d.T @ d
    corr = d.T @ patches
    n_atoms, n_patches = corr.shape
    limit = np.full(n_atoms, np.iinfo(np.int64).max) if budget is None else np.asarray(budget, dtype=np.int64)
    w = np.zeros((n_atoms, n_patches))
    used = np.zeros((n_atoms, n_patches), dtype=bool)
    per_patch = np.zeros(n_patches, dtype=np.int64)
    per_atom = np.zeros(n_atoms, dtype=np.int64)

    def best_atom(k):
        avail = used[:, k] | (per_atom < limit) if per_patch[k] < s else used[:, k]
        return int(np.argmax(np.where(avail, np.abs(corr[:, k]), -1.0))) if avail.any() else -1

    best = np.array([best_atom(k) for k in range(n_patches)])
    heap = [(-abs(corr[best[k], k]), k) for k in range(n_patches) if best[k] >= 0]
    heapq.heapify(heap)
    steps = 0
    while steps < s * n_patches and heap:
        _, k = heapq.heappop(heap)
        n = int(best[k])
        if not used[n, k] and (per_patch[k] >= s or per_atom[n] >= limit[n]):
            best[k] = best_atom(k)
            if best[k] >= 0:
                heapq.heappush(heap, (-abs(corr[best[k], k]), k))
            continue
        c = corr[n, k]
        if abs(c) < 1e-12:
            break
        if not used[n, k]:
            used[n, k], per_patch[k], per_atom[n] = True, per_patch[k] + 1, per_atom[n] + 1
        w[n, k] += c
        corr[:, k] -= c * g[:, n]
        best[k] = best_atom(k)
        if best[k] >= 0:
            heapq.heappush(heap, (-abs(corr[best[k], k]), k))
        steps += 1
    return w


@pytest.mark.parametrize("seed", range(6))
def test_compiled_pursuit_is_the_python_heap_pursuit_byte_for_byte(seed):
    rng = np.random.default_rng(seed)
    dim, n_atoms, n_patches = int(rng.integers(4, 30)), int(rng.integers(3, 40)), int(rng.integers(1, 200))
    d = unit_dictionary(rng, dim, n_atoms)
    p = rng.standard_normal((dim, n_patches))
    p[:, : n_patches // 4] = 0.0  # patches with nothing to code
    s = int(rng.integers(1, 5))
    budget = None if seed % 2 else rng.integers(0, 3 * n_patches // n_atoms + 2, n_atoms)
    ref = heap_pursuit(p, d, s, budget)
    assert constrained_matching_pursuit(p, d, s, budget).tobytes() == ref.tobytes()


def reference_batch_omp(d, x, s):
    """texsyn 0.3's batch OMP in NumPy and SciPy (the Gram update as a CSR product)."""
    from scipy.sparse import csr_matrix

    g = d.T @ d
    n_atoms, n_signals = d.shape[1], x.shape[1]
    xtd = x.T @ d
    corr = xtd.copy()
    codes = np.zeros((n_signals, n_atoms))
    support = np.zeros((n_signals, 0), dtype=np.int64)
    rows = np.arange(n_signals)
    active = np.ones(n_signals, dtype=bool)
    floor = 1e-12 * np.sqrt(np.maximum(np.einsum("ij,ij->j", x, x), 1e-300))
    for _ in range(min(s, n_atoms)):
        score = np.abs(corr)
        if support.shape[1]:
            score[rows[:, None], support] = -1.0
        pick = np.argmax(score, axis=1)
        active &= score[rows, pick] > floor
        if not active.any():
            break
        support = np.concatenate([support, pick[:, None]], axis=1)
        idx = np.flatnonzero(active)
        sup = support[idx]
        coef = np.linalg.solve(
            g[sup[:, :, None], sup[:, None, :]], np.take_along_axis(xtd[idx], sup, axis=1)[..., None]
        )[..., 0]
        codes[idx] = 0.0
        codes[idx[:, None], sup] = coef
        sparse = csr_matrix(
            (coef.ravel(), (np.repeat(np.arange(idx.size), sup.shape[1]), sup.ravel())),
            shape=(idx.size, n_atoms),
        )
        corr[idx] = xtd[idx] - sparse @ g
    return np.ascontiguousarray(codes.T)


@pytest.mark.parametrize("threads", [False, True])
def test_compiled_batch_omp_is_the_numpy_batch_omp_byte_for_byte(threads, monkeypatch):
    """Selection and Gram update in compiled row kernels, on numba's threads or not."""
    import texsyn.ops.sparse as sparse_ops

    monkeypatch.setattr(sparse_ops, "_PARALLEL_ROWS_WORK", 0 if threads else 1 << 62)
    rng = np.random.default_rng(21)
    for trial in range(8):
        d = unit_dictionary(rng, int(rng.integers(4, 40)), int(rng.integers(3, 60)))
        if trial % 3 == 1:
            d[:, 1] = d[:, 0]  # tied correlations
        x = rng.standard_normal((d.shape[0], int(rng.integers(1, 300))))
        x[:, ::5] = 2.0 * d[:, :1]  # represented exactly after one atom
        x[:, 1::7] = 0.0
        s = int(rng.integers(1, 6))
        assert batch_omp(d, x, s).tobytes() == reference_batch_omp(d, x, s).tobytes()


def test_ksvd_kernels_are_the_numpy_column_updates():
    """K-SVD keeps the residual as rows; gathering an atom's error and writing it back must
    give the bytes of the column expressions, and the eigenvector that of scipy's eigh."""
    from scipy import linalg

    from texsyn.ops.sparse import _gather_error, _scatter_error, _top_eigenvector

    rng = np.random.default_rng(22)
    residual = rng.standard_normal((30, 500))
    codes, atom = rng.standard_normal(500), rng.standard_normal(30)
    users = np.sort(rng.choice(500, 37, replace=False))
    rows = np.ascontiguousarray(residual.T)
    err = _gather_error(rows, users, codes, atom)
    expected = residual[:, users] + np.outer(atom, codes[users])
    assert err.tobytes() == expected.tobytes()
    coeffs, new_atom = rng.standard_normal(37), rng.standard_normal(30)
    _scatter_error(rows, users, err, coeffs, new_atom)
    residual[:, users] = expected - np.outer(new_atom, coeffs)
    assert rows.tobytes() == np.ascontiguousarray(residual.T).tobytes()
    gram = err.T @ err
    _, vec = linalg.eigh(gram, subset_by_index=[36, 36])
    assert _top_eigenvector(gram).tobytes() == vec[:, 0].tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_batched_graph_cuts_are_the_item_by_item_line(seed):
    """With single overlaps every seam of a closed line is cut at once: the same costs and
    cuts, so the same bytes, as item by item."""
    from texsyn.ops.graphcut import _assemble_line, _assemble_line_sequential

    rng = np.random.default_rng(seed)
    tau, step = [(6, 3), (12, 6), (8, 8), (9, 6)][seed]
    items = rng.random((int(rng.integers(2, 9)), int(rng.integers(3, 20)), tau, 3))
    if seed == 1:
        items = np.round(items, 1)  # tied costs
    length = items.shape[0] * step
    fast = _assemble_line(items, step, length, tau - step)
    assert fast.tobytes() == _assemble_line_sequential(items, step, length, tau - step).tobytes()


def test_seams_cut_on_threads_are_the_serial_cuts():
    """The seams of a stack cut in chunks on numba's threads are those cut one after the other."""
    from texsyn.ops.graphcut import _kwatra_costs_stack, _seams_take_old_parallel, _seams_take_old_rows

    rng = np.random.default_rng(5)
    tails, heads = rng.random((2, 37, 12, 6, 3))
    tails[::3] = np.round(tails[::3], 1)  # tied costs
    cost_h, cost_v = _kwatra_costs_stack(tails, heads)
    serial = np.empty((37, 12, 6), dtype=bool)
    _seams_take_old_rows(cost_h, cost_v, serial, 0, 37)
    for chunks in (1, 2, 3, 8):
        parallel = np.empty_like(serial)
        _seams_take_old_parallel(cost_h, cost_v, parallel, chunks)
        assert np.array_equal(parallel, serial)


@pytest.mark.parametrize("beta", [0.0, 1.0])
def test_compiled_gradient_step_is_numpys_expression_byte_for_byte(beta):
    """The fused step of image_update gives the bytes of eq. (7) written with NumPy arrays."""
    from texsyn.ops.sparse import _gradient_step

    rng = np.random.default_rng(3)
    u, recon, projected, lowpass = rng.standard_normal((4, 24, 18, 3))
    recon_t = np.ascontiguousarray(recon.transpose(1, 0, 2)).transpose(1, 0, 2)  # not contiguous
    alpha, eta = 0.7, 1.0 / (2.0 * (1.0 + 0.7 + beta))
    grad = 2.0 * (u - recon) + 2.0 * alpha * (u - projected)
    if beta > 0:
        grad += 2.0 * beta * lowpass
    expected = u - eta * grad
    fast = _gradient_step(u, recon_t, projected, lowpass if beta > 0 else None, 2.0 * alpha, 2.0 * beta, eta)
    assert fast.tobytes() == expected.tobytes()


def test_compiled_kwatra_costs_are_numpys_byte_for_byte():
    """The compiled costs of a stack of overlaps (NumPy's channel sums and pairwise mean,
    replayed value by value) are the bytes of the NumPy expressions, on numba's threads too."""
    from texsyn.ops.graphcut import _kwatra_costs_stack
    from texsyn.ops.seam_costs import _kwatra_costs_parallel, kwatra_costs_stack, numpy_sum

    rng = np.random.default_rng(11)
    for n in [*range(0, 140), 257, 1000, 2898, 9000]:
        values = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 3, n)
        assert numpy_sum(values) == np.add.reduce(values)
    for shape in [(37, 12, 6, 3), (5, 264, 6, 3), (9, 7, 3, 1), (4, 2, 2, 3)]:
        a, b = rng.random((2, *shape))
        a[::2] = np.round(a[::2], 1)  # tied and zero differences
        expected = _kwatra_costs_stack(a, b)
        fast = kwatra_costs_stack(a, b)
        threaded = (np.empty_like(expected[0]), np.empty_like(expected[1]))
        _kwatra_costs_parallel(a, b, *threaded, 3)
        for got in (fast, threaded):
            assert got[0].tobytes() == expected[0].tobytes()
            assert got[1].tobytes() == expected[1].tobytes()
