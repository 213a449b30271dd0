"""Properties the methods' papers promise, measured on small real images."""

import numpy as np
import pytest

import texsyn
from texsyn.methods.random_phase import random_phase_noise
from texsyn.ops import periodic_smooth_decomposition


@pytest.mark.method("random_phase")
def test_random_phase_keeps_the_fourier_modulus(colour_exemplar):
    ex = 0.4 + 0.2 * colour_exemplar  # low contrast: the output needs no clipping
    method = texsyn.make_method("random_phase").fit(ex)
    out = method.sample(ex.shape[:2], rng=0).astype(np.float64)
    periodic = periodic_smooth_decomposition(ex)[0]
    assert out.min() > 0 and out.max() < 1
    modulus_out = np.abs(np.fft.fft2(out, axes=(0, 1)))
    modulus_ex = np.abs(np.fft.fft2(periodic, axes=(0, 1)))
    np.testing.assert_allclose(modulus_out, modulus_ex, atol=1e-4 * modulus_ex.max())
    # and the phase really changed
    assert np.abs(out - periodic).mean() > 0.01


def test_random_phase_uses_one_phase_for_all_channels(colour_exemplar):
    spot = colour_exemplar - colour_exemplar.mean(axis=(0, 1))
    out = random_phase_noise(spot, spot.shape[:2], np.random.default_rng(1))
    s_in = np.fft.fft2(spot, axes=(0, 1))
    s_out = np.fft.fft2(out, axes=(0, 1))
    # the cross-spectrum between channels is unchanged: same added phase everywhere
    cross_in = s_in[..., 0] * np.conj(s_in[..., 1])
    cross_out = s_out[..., 0] * np.conj(s_out[..., 1])
    np.testing.assert_allclose(cross_out, cross_in, atol=1e-9 * np.abs(cross_in).max())


@pytest.mark.method("random_phase")
def test_random_phase_larger_output_keeps_mean_and_variance(grey_exemplar):
    out = texsyn.synthesize(0.3 + 0.4 * grey_exemplar, "random_phase", (160, 160), rng=2)
    ex = 0.3 + 0.4 * grey_exemplar
    assert abs(out.mean() - ex.mean()) < 1e-3
    assert abs(out.std() / ex.std() - 1) < 0.15


@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_output_histogram_equals_the_exemplars(grey_exemplar):
    out = texsyn.synthesize(
        grey_exemplar, "heeger_bergen", grey_exemplar.shape, rng=0, n_iterations=2, n_scales=3
    )
    np.testing.assert_allclose(np.sort(out, axis=None), np.sort(grey_exemplar, axis=None), atol=1e-7)


@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_larger_output_matches_the_histogram_quantiles(grey_exemplar):
    out = texsyn.synthesize(grey_exemplar, "heeger_bergen", (80, 80), rng=0, n_iterations=2, n_scales=3)
    np.testing.assert_allclose(np.sort(out, axis=None)[::4], np.sort(grey_exemplar, axis=None), atol=1e-6)


@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_matches_colour_statistics(colour_exemplar):
    out = texsyn.synthesize(colour_exemplar, "heeger_bergen", (40, 40), rng=0, n_scales=3, n_iterations=3)
    c_out = np.cov(out.reshape(-1, 3).T)
    c_ex = np.cov(colour_exemplar.reshape(-1, 3).T)
    assert np.abs(c_out - c_ex).max() < 0.1 * np.abs(c_ex).max()


@pytest.mark.method("heeger_bergen")
def test_heeger_bergen_iterations_bring_subband_statistics_closer(grey_exemplar):
    from texsyn.ops import transport_energy
    from texsyn.transforms.steerable import SteerablePyramid

    def band_distance(img):
        pyr = SteerablePyramid(img.shape, 3, 4)
        a, b = pyr.forward(img), pyr.forward(periodic_smooth_decomposition(grey_exemplar)[0])
        return sum(transport_energy(a[k], b[k]) for k in a.keys() if k not in ("lowpass",))

    noise = texsyn.synthesize(grey_exemplar, "heeger_bergen", (40, 40), rng=0, n_iterations=1, n_scales=3)
    more = texsyn.synthesize(grey_exemplar, "heeger_bergen", (40, 40), rng=0, n_iterations=6, n_scales=3)
    assert band_distance(more.astype(float)) < band_distance(noise.astype(float))


@pytest.mark.parametrize(
    "name, params",
    [
        pytest.param("quilting", {"patch_size": 16}, marks=pytest.mark.method("quilting")),
        pytest.param("efros_leung", {"window_size": 7}, marks=pytest.mark.method("efros_leung")),
    ],
)
def test_copy_methods_copy_exemplar_pixels_along_their_source_map(name, params, grey_exemplar):
    result = texsyn.make_method(name, **params).fit(grey_exemplar).sample_with_map((50, 45), rng=4)
    src = result.source_map
    np.testing.assert_array_equal(result.image, grey_exemplar[src[..., 0], src[..., 1]])


@pytest.mark.method("quilting")
def test_quilting_copies_whole_blocks_with_cut_seams(grey_exemplar):
    method = texsyn.make_method("quilting", patch_size=20).fit(grey_exemplar)
    result = method.sample_with_map((60, 60), rng=0)
    src = result.source_map.astype(int)
    offset = src - np.stack(np.mgrid[:60, :60], axis=-1)
    # the first block is copied verbatim outside its overlaps: constant offset
    block = offset[:17, :17].reshape(-1, 2)
    assert np.all(block == block[0])
    # seams are cuts, not straight lines: some row of the second block's overlap mixes sources
    second = offset[:20, 17:20].reshape(20, 3, 2)
    assert len({tuple(v) for v in second.reshape(-1, 2)}) >= 2


def block_cells_with_one_source(result, step):
    """Whether each ``step x step`` cell of the block grid was copied from one block (one offset)."""
    offset = result.source_map.astype(int) - np.stack(
        np.mgrid[: result.image.shape[0], : result.image.shape[1]], axis=-1
    )
    return [
        len({tuple(v) for v in offset[y : y + step, x : x + step].reshape(-1, 2)}) == 1
        for y in range(0, offset.shape[0], step)
        for x in range(0, offset.shape[1], step)
    ]


@pytest.mark.method("quilting")
def test_quilting_without_cut_overwrites_overlaps(grey_exemplar):
    with_cut = (
        texsyn.make_method("quilting", patch_size=16).fit(grey_exemplar).sample_with_map((40, 40), rng=5)
    )
    without = (
        texsyn.make_method("quilting", patch_size=16, boundary_cut=False)
        .fit(grey_exemplar)
        .sample_with_map((40, 40), rng=5)
    )
    step = 16 - 16 // 6  # blocks every 14 pixels; the next blocks overwrite the last 2 rows/columns
    # without the cut, each block is pasted whole over the overlap: straight seams on the grid
    assert all(block_cells_with_one_source(without, step))
    # with it, seams wander inside the overlaps: some grid cell mixes two blocks
    assert not all(block_cells_with_one_source(with_cut, step))
    assert not np.array_equal(with_cut.image, without.image)


@pytest.mark.method("efros_leung")
def test_efros_leung_continues_the_exemplar_on_a_periodic_texture():
    yy, xx = np.mgrid[:24, :24]
    stripes = (0.5 + 0.4 * np.sin(2 * np.pi * xx / 6)).astype(np.float64)
    out = texsyn.synthesize(stripes, "efros_leung", (30, 30), rng=0, window_size=5, epsilon=0.0)
    # every row keeps the period 6 of the exemplar
    np.testing.assert_allclose(out[:, 6:], out[:, :-6], atol=1e-6)
