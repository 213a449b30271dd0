"""What makes the locally Gaussian models of Raad, Desolneux and Morel (2016) what they are
(issue 16): LG, CLG, RCLG and MSLG tests that fail on a broken output.

Bounds come from measurements on a 48x48 crop of gravel, output 48x48, seeds 0-5, with the
suite's fast parameters, for the real output, a shuffled-pixel version and a blurred version
(sigma 1.5) as ``tests/sabotage.py`` makes them (``band_log2_ratios`` with 3 scales:
[high-pass, scale 0, ...]); the paper-parameter sharpness test uses 128x128 crops of gravel,
grass and brick. The measured ranges are in the comments.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import texsyn
from conftest import FAST_PARAMS
from strength_utils import autocorrelation_gap, band_log2_ratios
from texsyn.metrics import sharpness_ratio

GRAVEL = texsyn.data.exemplar("gravel", size=48)
SHAPE = (48, 48)
SEEDS = (0, 1, 2)
NAMES = ("lg", "clg", "rclg", "mslg")


def each(names):
    return [pytest.param(n, marks=pytest.mark.method(n), id=n) for n in names]


@functools.cache
def fitted(name: str):
    return texsyn.make_method(name, **FAST_PARAMS[name]).fit(GRAVEL)


@functools.cache
def output(name: str, seed: int) -> np.ndarray:
    return fitted(name).sample(SHAPE, rng=seed)


@pytest.mark.parametrize("name", each(NAMES))
def test_local_gaussian_synthesis_has_the_exemplars_band_energies(name):
    # log2 energy ratios, seeds 0-5, all four models (real / shuffled / blurred):
    #   high-pass  -0.71 .. 0.94 / 4.12 .. 4.90 / -7.04 .. -5.06
    #   scale 0    -1.18 .. 0.00 / 1.10 .. 1.82 / -6.07 .. -5.03
    for seed in SEEDS:
        ratios = band_log2_ratios(output(name, seed), GRAVEL, 3)
        assert abs(ratios[0]) <= 2.5, ratios
        assert abs(ratios[1]) <= 2.0, ratios


@pytest.mark.parametrize("name", each(NAMES))
def test_local_gaussian_synthesis_is_as_sharp_and_as_correlated_as_the_exemplar(name):
    for seed in SEEDS:
        out = output(name, seed)
        # mean gradient over the exemplar's, seeds 0-5: real 0.79 (clg) .. 1.10 (lg, rclg);
        # shuffled 2.79 .. 3.70; blurred 0.37 .. 0.49
        assert 0.65 <= sharpness_ratio(out, GRAVEL) <= 1.6
        # autocorrelation gap at lags up to 2 px: real 0.04 .. 0.14; shuffled 0.85 .. 0.93
        # (blurred 0.20 .. 0.30: caught by the two statistics above)
        assert autocorrelation_gap(out, GRAVEL) <= 0.5


#: mean sharpness ratio over two seeds at the paper's parameters (128x128 exemplars)
#: measured: lg 0.99 (brick) .. 1.10 (grass); mslg 0.82 (gravel) .. 0.90 (brick);
#: clg 0.97 (gravel) .. 1.11 (brick); rclg 1.03 (gravel) .. 1.39 (brick); blurred 0.35 .. 0.45
#: (before issue 19's looseness: clg 0.52 on grass, a blur along the raster order; rclg 2.25
#: on brick, the theta noise of 5/255)
PAPER_SHARPNESS = [
    pytest.param("lg", marks=pytest.mark.method("lg"), id="lg"),
    pytest.param("mslg", marks=pytest.mark.method("mslg"), id="mslg"),
    pytest.param("clg", marks=pytest.mark.method("clg"), id="clg"),
    pytest.param("rclg", marks=pytest.mark.method("rclg"), id="rclg"),
]


@pytest.mark.parametrize("name", PAPER_SHARPNESS)
def test_paper_parameters_keep_the_exemplars_sharpness(name):
    """Raad et al. 2016, Figs. 4, 6, 7: the models are at most slightly blurrier than the input."""
    for texture in ("gravel", "grass", "brick"):
        exemplar = texsyn.data.exemplar(texture, size=128)
        method = texsyn.make_method(name).fit(exemplar)
        ratio = np.mean([sharpness_ratio(method.sample((128, 128), rng=seed), exemplar) for seed in (0, 1)])
        assert 0.7 <= ratio <= 1.4, (texture, ratio)


def seed_patch_of(exemplar, seed, n=10):
    """The exemplar patch at the seed anchor t0, the first draw of the rng (the first patch of the raster loop)."""
    t0 = int(np.random.default_rng(seed).integers((exemplar.shape[0] - n + 1) * (exemplar.shape[1] - n + 1)))
    i, j = np.unravel_index(t0, (exemplar.shape[0] - n + 1, exemplar.shape[1] - n + 1))
    return exemplar[i : i + n, j : j + n]


@pytest.mark.method("clg")
@pytest.mark.parametrize("seed", [0, 5])
def test_clg_keeps_every_overlap_exactly(seed):
    """Raad et al. 2016, section 3.1: each patch is drawn conditioned on the values already
    synthesised in its overlap and keeps them, so a copied seed patch survives whole even
    though three later patches overlap it (LG's boundary cut, in contrast, rewrites part of it)."""
    exemplar = (0.15 + 0.7 * GRAVEL).astype(np.float32)  # no clipping
    params = dict(patch_size=10, n_neighbors=8, seed_patch="copy", histogram="none")  # the model's own draws
    seed_patch = seed_patch_of(exemplar, seed)
    clg = texsyn.make_method("clg", **params).fit(exemplar).sample((30, 30), rng=seed)
    np.testing.assert_allclose(clg[:10, :10], seed_patch, atol=1e-6)
    lg = texsyn.make_method("lg", **params).fit(exemplar).sample((30, 30), rng=seed)
    np.testing.assert_allclose(lg[:5, :5], seed_patch[:5, :5], atol=1e-6)  # kept by both
    assert np.abs(lg[:10, :10] - seed_patch).max() > 1e-3  # the cut rewrote part of LG's


@pytest.mark.method("mslg")
def test_mslg_coarsest_scale_gets_the_coarse_exemplars_histogram(monkeypatch):
    """``histogram='match'`` (docs/methods/local_gaussian.md, "Marginals"): the coarsest scale
    is given the coarsest exemplar scale's histogram before it is zoomed in as the low
    frequencies of the next scale. Matching only the final output left the coarse scale's lost
    contrast to be made up by stretching every frequency (measured before: coarse contrast
    0.62-0.93 of the coarse exemplar's on six shared exemplars, high-pass variance 1.24-2.37
    times the exemplar's after the final matching)."""
    import texsyn.methods.multiscale_gaussian as module

    zoomed = []
    real_zoom_in = module.zoom_in
    monkeypatch.setattr(
        module, "zoom_in", lambda image, **kw: zoomed.append(image) or real_zoom_in(image, **kw)
    )
    exemplar = texsyn.data.exemplar("grass", size=64)
    method = texsyn.make_method("mslg", patch_size=10, n_neighbors=10).fit(exemplar)
    method.sample((64, 64), rng=0)
    coarse, coarse_exemplar = zoomed[0][..., 0], method.scales_[-1][..., 0]
    assert coarse.min() == pytest.approx(coarse_exemplar.min(), abs=1e-6)
    assert coarse.max() == pytest.approx(coarse_exemplar.max(), abs=1e-6)
    assert coarse.std() == pytest.approx(coarse_exemplar.std(), rel=0.01)
    zoomed.clear()
    texsyn.make_method("mslg", patch_size=10, n_neighbors=10, histogram="none").fit(exemplar).sample(
        (64, 64), rng=0
    )
    assert zoomed[0].std() < 0.97 * coarse_exemplar.std()  # the model's own draws: contrast lost


@pytest.mark.parametrize("name", each(NAMES))
def test_outputs_smaller_than_a_patch_are_not_stretched_to_the_whole_histogram(name):
    """An output of fewer pixels than a patch is not a sample of the exemplar's histogram:
    matching stretched a 13x9 output to the exemplar's whole range (sharpness ratio 2.4); it is
    only clipped to the range (``match_exemplar_marginals``)."""
    exemplar = texsyn.data.exemplar("gravel", size=64)
    method = texsyn.make_method(name, patch_size=20, n_neighbors=10).fit(exemplar)
    spans = []
    for seed in range(6):
        small = method.sample((13, 9), rng=seed)
        assert exemplar.min() <= small.min() and small.max() <= exemplar.max()
        spans.append(float(small.max() - small.min()))
    # as wide as a 13x9 crop of the exemplar, not as its whole histogram: the crops' ranges
    # span 0.58 (median) .. 0.67 (90th percentile) .. 0.77, the whole exemplar 0.83; the
    # median over six seeds here is at most the crops' median plus a tenth; matched to the
    # whole histogram every seed gave 0.76
    crops = np.lib.stride_tricks.sliding_window_view(exemplar, (13, 9))
    ranges = crops.max(axis=(-2, -1)) - crops.min(axis=(-2, -1))
    assert float(np.median(spans)) <= float(np.median(ranges)) + 0.1
