"""Metrics on constructed cases (issue: crop, tiled copy, random phase, blur, other texture)."""

import numpy as np
import pytest
from scipy import ndimage

import texsyn
from texsyn import metrics
from texsyn.errors import InputError
from texsyn.ops import nearest_both_ways


@pytest.fixture(scope="module")
def exemplar():
    return texsyn.data.exemplar("gravel", size=48).astype(np.float64)


@pytest.fixture(scope="module")
def cases(exemplar):
    return {
        "self": exemplar,
        "crop": exemplar[6:42, 3:45],
        "tiled": np.tile(exemplar, (2, 2)),
        "random_phase": texsyn.synthesize(exemplar, "random_phase", exemplar.shape, rng=0).astype(np.float64),
        "blurred": ndimage.gaussian_filter(exemplar, 1.5),
        "other": texsyn.data.exemplar("brick", size=48).astype(np.float64),
    }


@pytest.fixture(scope="module")
def scores(cases, exemplar):
    return {name: metrics.evaluate(img, exemplar) for name, img in cases.items()}


def test_identity_scores(scores):
    s = scores["self"]
    assert s["histogram_distance"] == 0
    assert s["spectrum_distance"] < 1e-9
    assert s["patch_coherence"] < 1e-12 and s["reverse_distance"] < 1e-12
    assert s["completeness"] == 1.0
    assert s["largest_copy"] == 1.0 and s["copied_share"] == 1.0
    assert s["sharpness_ratio"] == pytest.approx(1.0)


def test_a_crop_is_one_verbatim_copy(scores):
    s = scores["crop"]
    assert s["patch_coherence"] < 1e-12
    assert s["largest_copy"] == pytest.approx(1.0)
    assert s["copied_share"] == pytest.approx(1.0)
    assert s["completeness"] < 0.9  # the crop uses only part of the exemplar


def test_a_tiled_copy_scores_near_one_on_copy_metrics(scores):
    s = scores["tiled"]
    assert s["copied_share"] > 0.95
    assert s["largest_copy"] >= 0.2  # one tile is a quarter of the output
    assert s["completeness"] == 1.0
    assert s["histogram_distance"] < 1e-12


def test_random_phase_noise_copies_nothing_but_keeps_the_spectrum(scores):
    s = scores["random_phase"]
    assert s["largest_copy"] == 0.0 and s["copied_share"] == 0.0
    assert s["spectrum_distance"] < 0.05
    assert s["patch_coherence"] > 10 * scores["crop"]["patch_coherence"] + 1e-4


def test_blur_drops_sharpness_and_high_frequencies(scores):
    s = scores["blurred"]
    assert s["sharpness_ratio"] < 0.6
    assert s["spectrum_distance"] > 10 * scores["random_phase"]["spectrum_distance"]
    assert s["largest_copy"] == 0.0


def test_gradient_energy_sees_blur_and_noise_but_not_gaussian_gradients(cases, exemplar):
    assert metrics.gradient_energy_ratio(exemplar, exemplar) == pytest.approx(1.0)
    assert metrics.gradient_energy_ratio(cases["blurred"], exemplar) < 0.6
    rng = np.random.default_rng(0)
    shuffled = rng.permutation(exemplar.reshape(-1, *exemplar.shape[2:])).reshape(exemplar.shape)
    assert metrics.gradient_energy_ratio(shuffled, exemplar) > 1.5
    # random phase noise keeps the power spectrum, hence the gradient energy
    assert metrics.gradient_energy_ratio(cases["random_phase"], exemplar) == pytest.approx(1.0, abs=0.1)


def test_a_different_texture_is_farther_on_every_distance(scores):
    near, far = scores["crop"], scores["other"]
    for key in ("histogram_distance", "spectrum_distance", "patch_coherence", "reverse_distance"):
        assert far[key] > near[key], key
    assert far["copied_share"] == 0.0


def test_histogram_distance_matches_known_shift(exemplar):
    shifted = np.clip(exemplar * 0.5 + 0.25, 0, 1)
    base = np.clip(exemplar * 0.5 + 0.2, 0, 1)
    assert metrics.histogram_distance(shifted, base) == pytest.approx(0.05, abs=1e-9)
    # exact for unequal sizes: a tiled image has the same histogram
    assert metrics.histogram_distance(np.tile(base, (3, 2)), base) < 1e-12


def test_nearest_field_is_exact_in_both_directions():
    rng = np.random.default_rng(0)
    q, b = rng.random((70, 9)), rng.random((45, 9))
    qi, qd, bi, bd = nearest_both_ways(q, b, block=16)
    full = ((q[:, None] - b[None]) ** 2).sum(-1)
    np.testing.assert_array_equal(qi, full.argmin(1))
    np.testing.assert_array_equal(bi, full.argmin(0))
    np.testing.assert_allclose(qd, full.min(1), atol=1e-12)
    np.testing.assert_allclose(bd, full.min(0), atol=1e-12)


def test_copy_map_regions_follow_pasted_blocks(exemplar):
    out = np.zeros((40, 40))
    out[:20] = exemplar[5:25, 2:42]
    out[20:] = exemplar[25:45, 6:46]
    cm = metrics.copy_map(out, exemplar, patch_size=5)
    assert cm.labels.max() >= 1
    assert cm.largest == pytest.approx(0.5, abs=0.01)
    assert cm.copied_share == pytest.approx(1.0, abs=0.01)
    assert set(np.unique(cm.offsets[0, :, 0])) == {5}


def test_synthesis_map_uses_the_source_map_or_nearest_patches(exemplar):
    crop = exemplar[10:30, 5:35]
    ex_colours, out_colours = metrics.synthesis_map(crop, exemplar)
    np.testing.assert_allclose(out_colours, ex_colours[10:30, 5:35], atol=1e-6)
    source = np.stack(np.mgrid[:20, :30], axis=-1) + (10, 5)
    _, from_map = metrics.synthesis_map(crop, exemplar, source_map=source)
    np.testing.assert_array_equal(from_map, out_colours)


def test_metrics_reject_mismatched_channels(exemplar):
    with pytest.raises(ValueError, match="channel"):
        metrics.histogram_distance(np.dstack([exemplar] * 3), exemplar)
    with pytest.raises(ValueError, match="flat"):
        metrics.sharpness_ratio(exemplar, np.zeros((10, 10)))


def test_contrast_ratio_refuses_an_exemplar_without_luma_contrast(exemplar):
    g = exemplar
    # red against green at equal BT.601 luma: 0.299 R + 0.587 G = 0.4 everywhere
    red = 0.3 + 0.5 * g
    iso = np.stack([red, (0.4 - 0.299 * red) / 0.587, np.full_like(g, 0.4)], axis=-1)
    assert np.std(texsyn.ops.luma(iso)) < 1e-12
    other = np.stack([g, g, g], axis=-1)
    with pytest.raises(InputError, match="no luma contrast.*luma only"):
        metrics.contrast_ratio(other, iso)  # texsyn 0.2: about 1e15
    with pytest.raises(InputError, match="no luma contrast"):
        metrics.evaluate(other, iso)  # as sharpness_ratio on a flat exemplar: passed on
    with pytest.raises(InputError, match="no luma contrast"):
        metrics.contrast_ratio(g, np.full_like(g, 0.5))
    faint = iso.copy()
    faint[..., 2] += 0.2 * (g - g.mean())  # blue moves luma by 0.114 * that: above 1 % of the channels'
    assert np.isfinite(metrics.contrast_ratio(other, faint))
    assert metrics.contrast_ratio(iso, other) == pytest.approx(0.0, abs=1e-9)  # the image may be flat
