import numpy as np
import pytest
from scipy import ndimage

from texsyn.transforms.pyramids import gaussian_blur, gaussian_pyramid, zoom_in, zoom_out
from texsyn.transforms.steerable import SteerablePyramid


def smooth_image(shape, seed=0):
    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random(shape), sigma=(2, 2) + (0,) * (len(shape) - 2), mode="wrap")


@pytest.mark.parametrize("shape", [(15, 21), (16, 20), (12, 14, 3)])
def test_mirror_zoom_in_interpolates_every_image(shape):
    u = np.random.default_rng(1).random(shape)
    v = zoom_in(u)
    assert v.shape[:2] == (2 * shape[0], 2 * shape[1])
    np.testing.assert_allclose(v[::2, ::2], u, atol=1e-12)


def test_periodic_zoom_in_interpolates_odd_sizes_and_band_limited_images():
    u = np.random.default_rng(2).random((15, 13))
    np.testing.assert_allclose(zoom_in(u, boundary="periodic")[::2, ::2], u, atol=1e-12)
    even = np.random.default_rng(3).random((16, 12))
    spec = np.fft.fft2(even)
    spec[8, :] = 0
    spec[:, 6] = 0
    band_limited = np.real(np.fft.ifft2(spec))
    np.testing.assert_allclose(zoom_in(band_limited, boundary="periodic")[::2, ::2], band_limited, atol=1e-12)


def test_zoom_in_after_zoom_out_restores_a_smooth_image():
    u = smooth_image((64, 64))
    restored = zoom_in(zoom_out(u, 1.4, mode="periodic"), boundary="periodic")
    target = gaussian_blur(u, 1.4, mode="periodic")
    rel = np.linalg.norm(restored - target) / np.linalg.norm(target - target.mean())
    assert rel < 5e-3


def test_gaussian_blur_periodic_matches_spatial_wrap_and_keeps_channels_apart():
    u = np.random.default_rng(4).random((32, 30, 3))
    spatial = ndimage.gaussian_filter(u, sigma=(1.5, 1.5, 0), mode="wrap", truncate=8)
    np.testing.assert_allclose(gaussian_blur(u, 1.5, mode="periodic"), spatial, atol=1e-5)
    grey = gaussian_blur(u[..., 1], 1.5)
    np.testing.assert_allclose(gaussian_blur(u, 1.5)[..., 1], grey, atol=1e-14)


@pytest.mark.parametrize(("shape", "sigma"), [((33, 20, 3), 1.0), ((16, 9), 1.4), ((3, 7, 2), 2.3)])
def test_gaussian_blur_is_scipys_mirrored_filter_byte_for_byte(shape, sigma):
    """The NumPy blur (no ``scipy.ndimage`` at start-up) gives SciPy's bytes, in C order,
    also where the kernel is longer than a side (the mirror of the mirror)."""
    u = np.random.default_rng(6).random(shape) * 255
    want = ndimage.gaussian_filter(
        u, sigma=(sigma, sigma) + (0,) * (u.ndim - 2), mode="reflect", truncate=4.0
    )
    got = gaussian_blur(u, sigma)
    assert got.tobytes() == want.tobytes() and got.flags.c_contiguous


def test_gaussian_pyramid_sizes():
    levels = gaussian_pyramid(np.zeros((40, 24)), 3)
    assert [lv.shape for lv in levels] == [(40, 24), (20, 12), (10, 6)]


@pytest.mark.parametrize("shape", [(64, 64), (67, 53), (33, 40, 3)])
def test_steerable_pyramid_perfect_reconstruction(shape):
    x = np.random.default_rng(5).random(shape)
    pyr = SteerablePyramid(shape[:2], n_scales=4, n_orientations=4)
    coeffs = pyr.forward(x)
    assert len(coeffs.keys()) == 1 + 16 + 1
    assert coeffs[0, 0].shape[:2] == shape[:2]
    np.testing.assert_allclose(pyr.inverse(coeffs), x, atol=1e-10)


def test_steerable_pyramid_channels_are_the_bytes_of_each_channel_alone():
    """Issue 20: the channels are transformed as (C, H, W) planes; each channel's coefficients
    and reconstruction are those of its own 2-D pyramid, byte for byte, and the channels'
    (H, W, C) coefficients are accepted in any memory layout."""
    x = np.random.default_rng(6).random((33, 40, 3))
    pyr = SteerablePyramid((33, 40), n_scales=3, n_orientations=4)
    coeffs = pyr.forward(x)
    alone = [pyr.forward(x[..., c]) for c in range(3)]
    for key in coeffs.keys():
        assert coeffs[key].shape == alone[0][key].shape + (3,)
        for c in range(3):
            assert coeffs[key][..., c].tobytes() == alone[c][key].tobytes()
    image = pyr.inverse(coeffs)
    for c in range(3):
        assert image[..., c].tobytes() == pyr.inverse(alone[c]).tobytes()
    for key in coeffs.keys():  # channels-last copies: the same reconstruction
        coeffs[key] = np.ascontiguousarray(coeffs[key])
    assert pyr.inverse(coeffs).tobytes() == image.tobytes()
    previous = pyr.forward(x[::-1].copy())  # its arrays receive the next analysis
    again = pyr.forward(x, out=previous)
    for key in coeffs.keys():
        assert again[key].tobytes() == coeffs[key].tobytes()
    assert np.shares_memory(again[0, 1], previous[0, 1]) and np.shares_memory(
        again.highpass, previous.highpass
    )


@pytest.mark.parametrize("shape", [(33, 40, 3), (30, 21)])
def test_steerable_pyramid_workspace_gives_the_same_bytes(shape):
    """Issue 20: with one workspace and the last step's arrays reused (Heeger-Bergen's loop),
    analysis and synthesis give the bytes of fresh calls, whatever the workspace held."""
    rng = np.random.default_rng(7)
    pyr = SteerablePyramid(shape[:2], n_scales=3, n_orientations=4)
    workspace = pyr.workspace(shape[2] if len(shape) == 3 else None)
    coeffs = None
    for _ in range(2):
        x = rng.random(shape)
        expected = pyr.forward(x)
        coeffs = pyr.forward(x, out=coeffs, workspace=workspace)
        for key in expected.keys():
            assert coeffs[key].tobytes() == expected[key].tobytes()
        image = pyr.inverse(coeffs, workspace=workspace, out=x)
        assert image.tobytes() == pyr.inverse(expected).tobytes()
        assert len(shape) == 3 or np.shares_memory(image, x)
    with pytest.raises(ValueError, match="workspace"):
        pyr.forward(np.zeros(shape[:2] + (2,)), workspace=workspace)


def test_steerable_pyramid_bands_are_oriented():
    n = 64
    yy, xx = np.mgrid[:n, :n]
    grating = np.cos(2 * np.pi * 8 * xx / n)  # varies along x: vertical stripes
    coeffs = SteerablePyramid((n, n), 3, 4).forward(grating)
    energies = [np.sum(coeffs[1, b] ** 2) for b in range(4)]
    assert np.argmax(energies) == 0
    assert energies[0] > 100 * energies[2]


def test_steerable_pyramid_rejects_tiny_images():
    with pytest.raises(ValueError, match="too small"):
        SteerablePyramid((10, 40), n_scales=4)


@pytest.mark.parametrize("per_call", [1, 2, 64])
@pytest.mark.parametrize(("shape", "threads"), [((24, 20), "1"), ((24, 20), "3"), ((23, 17), "2")])
def test_laplacian_planes_a_few_at_a_time_are_the_bytes_of_one_call(monkeypatch, per_call, shape, threads):
    """Issue 20: the tight frame transforms large stacks a few images per FFT call (bounded
    temporaries) and into a reused ``out``; the bytes are those of one call on the stack, and
    those of ``scipy.fft`` (its NumPy FFTs split in runs of lines over any number of threads)."""
    import scipy.fft as sfft

    from texsyn.transforms import pyramids
    from texsyn.transforms.pyramids import LaplacianTightFrame

    monkeypatch.setenv("TEXSYN_NUM_THREADS", threads)
    frame = LaplacianTightFrame(shape, 3)
    planes = np.random.default_rng(5).standard_normal((5,) + shape)
    spectrum = sfft.rfft2(planes, axes=(1, 2))
    bands = sfft.irfft2(frame.filters[:, None] * spectrum[None], s=shape, axes=(2, 3))
    spectra = sfft.rfft2(bands, axes=(2, 3))
    images = sfft.irfft2(np.sum(frame.filters[:, None] * spectra, axis=0), s=shape, axes=(1, 2))
    monkeypatch.setattr(pyramids, "SPECTRUM_VALUES", per_call * frame.filters.size)
    out = np.empty_like(bands)
    assert frame.forward_planes(planes, out=out) is out
    assert out.tobytes() == bands.tobytes()
    assert frame.forward_planes(planes).tobytes() == bands.tobytes()
    assert frame.inverse_planes(bands).tobytes() == images.tobytes()
    np.testing.assert_allclose(images, planes, atol=1e-12)
