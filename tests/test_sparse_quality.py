"""Constrained sparse synthesis, issue 19 item 2: what the fixes of the low-pass term, the
K-SVD update and the convergence criterion change (``docs/methods/sparse.md``).

Each test fails on texsyn 0.2's behaviour, which a parameter still restores:
``lowpass_ref='mean'`` (the constant low-pass reference), ``ksvd(update='power')`` (one
power step per atom) and ``tolerance=0`` (no convergence test: every scale runs ``n_outer``
iterations; the old sampler returned no energy curve at all).
"""

import copy

import numpy as np
import pytest

import texsyn
from texsyn.metrics import box_null_energy_share as null_band_share
from texsyn.metrics import local_mean_spread
from texsyn.ops.sparse import SpectrumProjector, batch_omp, box_power, ksvd


# ------------------------------------------------------------------------------- K-SVD
def clustered_patches(rng, dim=12, n_atoms=6, per_atom=40):
    """Patches in ``n_atoms`` well separated cones, each of rank 3 around its own axis."""
    axes = np.linalg.qr(rng.standard_normal((dim, dim)))[0][:, :n_atoms]
    cols = []
    for n in range(n_atoms):
        spread = rng.standard_normal((dim, 2)) @ np.diag([0.35, 0.2])
        coef = rng.standard_normal((2, per_atom))
        cols.append(axes[:, [n]] * rng.uniform(1.0, 2.0, per_atom) + spread @ coef)
    return np.concatenate(cols, axis=1)


@pytest.mark.parametrize("seed", range(3))
def test_ksvd_atom_update_is_the_leading_singular_vector_of_its_users(seed):
    # One iteration with 1-sparse codes: every atom must become the leading left singular
    # vector of the patches that use it (Aharon et al. 2006, IV-B). The one power step of
    # texsyn 0.2 (update='power') is off by max 1 - |cos| = 1.4e-2, 1.7e-2, 3.0e-1 on
    # seeds 0-2; the exact update agrees to 7e-16.
    rng = np.random.default_rng(seed)
    x = clustered_patches(rng)
    n_atoms = 6
    draw = np.random.default_rng(100 + seed)
    start = draw.choice(x.shape[1], n_atoms, replace=False)  # what ksvd draws first
    d0 = x[:, start] / np.linalg.norm(x[:, start], axis=0)
    supports = np.flatnonzero(batch_omp(d0, x, 1).T) % n_atoms  # the atom of each patch
    for update, tolerance in (("svd", 1e-12), ("power", None)):
        d = ksvd(
            x,
            n_atoms,
            1,
            n_iterations=1,
            max_training=x.shape[1],
            rng=np.random.default_rng(100 + seed),
            update=update,
            tol=0.0,
        )
        gaps = []
        for n in range(n_atoms):
            members = x[:, supports == n]
            lead = np.linalg.svd(members, full_matrices=False)[0][:, 0]
            gaps.append(1.0 - abs(float(lead @ d[:, n])))
        if tolerance is not None:
            assert max(gaps) < tolerance, (update, gaps)
        else:
            assert max(gaps) > 1e-3, gaps  # the old update is measurably not the SVD


def test_ksvd_reports_its_errors_and_stops_when_they_stall():
    rng = np.random.default_rng(1)
    truth = np.linalg.qr(rng.standard_normal((20, 20)))[0][:, :15]
    codes = np.zeros((15, 600))
    for k in range(600):
        codes[rng.choice(15, 2, replace=False), k] = rng.standard_normal(2)
    x = truth @ codes + 1e-3 * rng.standard_normal((20, 600))
    d, errors = ksvd(
        x, 15, 2, n_iterations=60, max_training=600, rng=np.random.default_rng(2), return_errors=True
    )
    # measured: the relative error falls from 0.26 to the noise floor 8.6e-6 and the
    # criterion stops it after 24 of the 60 iterations allowed; the curve is the energy of
    # eq. (1) on the training patches (texsyn 0.2 ran all iterations and returned none)
    assert 3 <= errors.size < 60
    assert errors[-1] < 0.01 * errors[0]
    full = ksvd(
        x, 15, 2, n_iterations=30, max_training=600, rng=np.random.default_rng(2), tol=0.0, return_errors=True
    )[1]
    assert full.size == 30  # tol=0: every iteration


# ------------------------------------------------------------------------------- low-pass term
def lowpass_term(u: np.ndarray, reference, tau: int) -> float:
    """``||h * (u - u_ref)||^2`` of eq. (3), ``h`` the normalised ``tau x tau`` box (periodic)."""
    ref = reference(u) if callable(reference) else reference
    spec = np.fft.rfft2(u - ref, axes=(0, 1)) * np.sqrt(box_power(u.shape[:2], tau))[..., None]
    return float(np.sum(np.fft.irfft2(spec, s=u.shape[:2], axes=(0, 1)) ** 2))


def test_spectrum_reference_is_translation_invariant_and_keeps_the_exemplars_low_frequencies():
    # The exemplar (seen periodically) and all its translates are minimisers (term 0) of the
    # 'spectrum' low-pass term; the constant 'mean' reference of texsyn 0.2 penalises them
    # all by the same positive amount, i.e. it pulls the output's large-scale variation to flat.
    ex = texsyn.data.exemplar("gravel", size=32).astype(np.float64)[..., None]
    periodic = ex
    project = SpectrumProjector(ex, ex.shape[:2])
    flat = np.broadcast_to(ex.mean(), ex.shape)
    scale = lowpass_term(periodic, flat, 6)
    assert scale > 1e-3
    for shift in [(0, 0), (5, 0), (3, 11), (17, 29)]:
        moved = np.roll(periodic, shift, axis=(0, 1))
        assert lowpass_term(moved, project, 6) < 1e-20 * scale
        np.testing.assert_allclose(project(moved), moved, atol=1e-12)
        assert lowpass_term(moved, flat, 6) == pytest.approx(scale)  # old: never zero
    # on a larger canvas the reference has the exemplar's Fourier modulus (the spot's)
    big = SpectrumProjector(ex, (48, 40))
    u = big(np.random.default_rng(0).standard_normal((48, 40, 1)))
    np.testing.assert_allclose(np.abs(np.fft.rfft2(u, axes=(0, 1))), np.abs(big.spectrum), atol=1e-9)
    # and the exemplar's local-mean spread (measured 0.977 of it for this crop)
    assert local_mean_spread(u, 6) == pytest.approx(local_mean_spread(ex, 6), rel=0.05)


#: fast settings: 64x64 grey exemplar, 128x128 output (about 1.5 s per sample on 2 cores)
FAST = dict(patch_size=8, step=4, n_scales=2, n_atoms=32, ksvd_iterations=4, n_outer=12, n_inner=5)


@pytest.fixture(scope="module")
def gravel_model():
    ex = texsyn.data.exemplar("gravel", size=64).astype(np.float64)
    return ex, texsyn.make_method("sparse", **FAST).fit(ex)


def tiles(image: np.ndarray, side: int):
    return [image[i : i + side, j : j + side] for i in (0, side) for j in (0, side)]


_OUTPUTS: dict[str, np.ndarray] = {}


def full_output(method, reference: str) -> np.ndarray:
    """The 128x128 output of seed 0 with the given low-pass reference (computed once)."""
    if reference not in _OUTPUTS:
        sampler = copy.deepcopy(method)
        sampler.lowpass_ref = reference
        _OUTPUTS[reference] = sampler.sample((128, 128), rng=0).astype(np.float64)
    return _OUTPUTS[reference]


# Measured with FAST, 64 -> 128, seeds 0-2 ('mean' with tolerance=0, as texsyn 0.2 ran):
#   spread ratio std(h*u)/std(h*u0), h 12x12:  gravel: spectrum 1.079-1.084   mean 0.34-0.37
#                                             grass:  spectrum 1.289-1.292   mean 0.57-0.58
#                                             brick:  spectrum 1.110-1.125   mean 0.76-0.80
#   energy at the zeros of the 8x8 box / exemplar's:  gravel: spectrum 0.67-0.68, mean 1.27-1.42
#                                                     brick: 0.92-1.06 / 2.29-2.59
# At the default parameters, 128 -> 256, the spread ratio is 1.016-1.055 on the five VisTex
# crops of benchmarks/sparse.md (1.202 on t4).
@pytest.mark.method("sparse")
@pytest.mark.parametrize(
    "reference",
    [
        "spectrum",
        pytest.param("mean", marks=pytest.mark.xfail(strict=True, raises=AssertionError), id="old-mean"),
    ],
)
def test_full_mode_keeps_the_local_mean_spread_and_makes_no_ridges(gravel_model, reference):
    ex, method = gravel_model
    out = full_output(method, reference)
    ratio = local_mean_spread(out, 12) / local_mean_spread(ex, 12)
    assert 0.9 < ratio < 1.1, ratio  # issue 19's figure
    ridges = np.mean([null_band_share(t, 8) for t in tiles(out, 64)]) / null_band_share(ex, 8)
    assert ridges < 1.0, ridges  # no more energy at the box's zeros than the exemplar has


@pytest.mark.method("sparse")
@pytest.mark.parametrize(
    "rounds",
    [4, pytest.param(0, marks=pytest.mark.xfail(strict=True, raises=AssertionError), id="no-final-rounds")],
)
def test_full_mode_local_mean_spread_within_ten_percent_on_grass_at_fast_settings(rounds):
    """With the fast settings (8x8 patches, 32 atoms) the coded patches lack fine detail and
    the histogram puts the missing variance in the low frequencies: spread ratio 1.29 after
    the iterations (seeds 0 and 1); the final rounds (low band to the exemplar's modulus,
    then the histogram; docs/methods/sparse.md, "Final rounds") bring it to 1.14, 1.07, 1.02
    after 1, 2, 4 rounds (4 is the default)."""
    ex = texsyn.data.exemplar("grass", size=64).astype(np.float64)
    method = texsyn.make_method("sparse", **FAST, final_rounds=rounds).fit(ex)
    out = method.sample((128, 128), rng=0).astype(np.float64)
    assert abs(local_mean_spread(out, 12) / local_mean_spread(ex, 12) - 1.0) < 0.1


# ------------------------------------------------------------------------------- convergence
@pytest.mark.method("sparse")
def test_sample_returns_the_energy_curve_and_stops_when_it_converges(gravel_model):
    ex, method = gravel_model
    runner = copy.deepcopy(method)
    runner.n_outer = 40
    result = runner.sample_with_map((96, 96), rng=1)
    diag = result.diagnostics
    assert diag is not None  # texsyn 0.2 returned no diagnostics
    energy, where = diag["energy"], diag["energy_scale"]
    assert energy.shape == where.shape and energy.size == diag["iterations"].sum()
    assert np.all(np.isfinite(energy)) and np.all(energy > 0)
    assert list(np.unique(where)[::-1]) == [1, 0]  # coarsest scale first
    for j in (1, 0):
        curve = energy[where == j]
        assert curve[-1] < 0.9 * curve[0]  # measured (seeds 0-3): 0.49-0.81 of the first value
    # measured: iterations [11, 12] (seed 1; 7-12 and 8-12 on seeds 0-3), all converged
    assert diag["converged"].all()
    assert np.all(diag["iterations"] < 40)
    endless = copy.deepcopy(method)
    endless.n_outer, endless.tolerance = 6, 0.0  # texsyn 0.2: every scale ran n_outer
    ran = endless.sample_with_map((96, 96), rng=1).diagnostics
    assert ran["iterations"].tolist() == [6, 6]
    assert not ran["converged"].any()  # no criterion, no convergence


@pytest.mark.method("sparse")
def test_converged_says_whether_the_criterion_was_met_not_whether_n_outer_was_reached():
    ex = texsyn.data.exemplar("gravel", size=64).astype(np.float64)
    method = texsyn.make_method("sparse", **{**FAST, "n_scales": 1, "n_outer": 40}).fit(ex)
    free = method.sample_with_map((48, 48), rng=1).diagnostics
    (k,) = free["iterations"].tolist()  # measured: 14, the criterion met on the 14th iteration
    assert free["converged"].tolist() == [True] and k < 40
    for cap, met in ((k, True), (k - 1, False)):  # the same run, stopped by the cap or not
        capped = copy.deepcopy(method)
        capped.n_outer = cap
        diag = capped.sample_with_map((48, 48), rng=1).diagnostics
        np.testing.assert_array_equal(diag["energy"], free["energy"][:cap])
        assert diag["iterations"].tolist() == [cap]
        # at the cap, converged only when the criterion fired on that very iteration
        assert diag["converged"].tolist() == [met], (cap, k)
