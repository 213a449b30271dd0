"""DT-CWT: perfect reconstruction, orientation, reference values, filter identities (Kingsbury's DT-CWT; docs/methods/cwt.md)."""

import numpy as np
import pytest

from texsyn.transforms.dtcwt import DTCWT
from texsyn.transforms.dtcwt_filters import FILTERS

SETS = [("near_sym_a", "qshift_a"), ("near_sym_b", "qshift_b")]


@pytest.mark.parametrize("biort, qshift", SETS)
@pytest.mark.parametrize("shape", [(64, 64), (128, 96), (32, 48)])
@pytest.mark.parametrize("levels", [1, 2, 3, 4])
def test_perfect_reconstruction_and_shapes(biort, qshift, shape, levels):
    if shape[0] % 2**levels or shape[1] % 2**levels:
        pytest.skip("size not a multiple of 2^levels")
    x = np.random.default_rng(levels).random(shape)
    t = DTCWT(levels, biort=biort, qshift=qshift)
    pyr = t.forward(x)
    assert pyr.lowpass.shape == (shape[0] // 2 ** (levels - 1), shape[1] // 2 ** (levels - 1))
    for k, hp in enumerate(pyr.highpasses, start=1):
        assert hp.shape == (shape[0] // 2**k, shape[1] // 2**k, 6)
    assert np.abs(t.inverse(pyr) - x).max() < 1e-12


def band_energies(phi_deg, level, transform):
    r, c = np.mgrid[:128, :128]
    rho = 0.42 / 2 ** (level - 1)
    phi = np.deg2rad(phi_deg)
    x = np.cos(2 * np.pi * rho * (c * np.cos(phi) + r * np.sin(phi)))
    hp = transform.forward(x).highpasses[level - 1][2:-2, 2:-2]
    return np.mean(np.abs(hp) ** 2, axis=(0, 1))


@pytest.mark.parametrize("biort, qshift", SETS)
def test_a_45_degree_grating_lands_in_the_45_degree_band(biort, qshift):
    t = DTCWT(3, biort=biort, qshift=qshift)
    for level in (1, 2, 3):
        e45 = band_energies(45, level, t)
        e135 = band_energies(135, level, t)
        share = 0.4 if level == 1 else 0.5
        ratio = 0.1 if level == 1 else 0.02
        assert e45[1] > share * e45.sum() and e45[4] / e45[1] < ratio
        assert e135[4] > share * e135.sum() and e135[1] / e135[4] < ratio


def test_reference_coefficients():
    r, c = np.mgrid[:32, :48]
    x = ((r**2 + 3 * c**2 + 7 * r * c + 2 * r + 5 * c) % 23) / 22
    pyr = DTCWT(3).forward(x)
    np.testing.assert_allclose(
        pyr.lowpass[[0, 3, 7], [0, 5, 11]], [2.0980035436, 1.9454343357, 2.1335256027], atol=1e-9
    )
    np.testing.assert_allclose(
        pyr.highpasses[0][2, 3],
        [
            0.0879177084 + 0.0784532678j,
            0.2175312669 + 0.1231545677j,
            0.0980823684 - 0.0158525075j,
            -0.1976283100 - 0.0319460742j,
            -0.2068951477 - 0.2685148629j,
            -0.1410769861 - 0.0069964543j,
        ],
        atol=1e-9,
    )
    np.testing.assert_allclose(
        pyr.highpasses[2][1, 2],
        [
            -0.1879578410 - 0.1734437971j,
            0.1068474968 + 0.1182769147j,
            0.0923507525 - 0.3829291109j,
            -0.2468910333 - 0.0592017878j,
            -0.1874014245 - 0.0995817474j,
            -0.0962735841 + 0.0452822848j,
        ],
        atol=1e-9,
    )
    np.testing.assert_allclose(
        np.sum(np.abs(pyr.highpasses[2]) ** 2, axis=(0, 1)),
        [0.7004981967, 0.6755435801, 1.7677629356, 1.2813862160, 0.5355509035, 0.4349433243],
        atol=1e-9,
    )
    b = DTCWT(3, biort="near_sym_b", qshift="qshift_b").forward(x)
    np.testing.assert_allclose(
        b.lowpass[[0, 3, 7], [0, 5, 11]], [2.1057593670, 1.9630478973, 2.1485926392], atol=1e-9
    )
    np.testing.assert_allclose(
        np.sum(np.abs(b.highpasses[2]) ** 2, axis=(0, 1)),
        [0.5394075088, 0.6447856144, 1.8596328759, 1.1371402220, 0.6201450485, 0.3843247823],
        atol=1e-9,
    )


@pytest.mark.parametrize("name", ["qshift_a", "qshift_b"])
def test_qshift_filter_identities(name):
    f = FILTERS[name]
    h0a = f["h0a"]
    assert abs(h0a.sum() - np.sqrt(2)) < 1e-12
    assert abs(np.sum(h0a**2) - 1) < 1e-12
    for s in range(1, len(h0a) // 2):
        assert abs(np.sum(h0a[: -2 * s] * h0a[2 * s :])) < 1e-12
    sign = (-1.0) ** np.arange(len(h0a))
    np.testing.assert_allclose(f["h0b"], h0a[::-1], atol=1e-15)
    np.testing.assert_allclose(f["h1a"], sign * f["h0b"], atol=1e-15)
    np.testing.assert_allclose(f["h1b"], f["h1a"][::-1], atol=1e-15)
    for key in ("0a", "0b", "1a", "1b"):
        np.testing.assert_allclose(f["g" + key], f["h" + key][::-1], atol=1e-15)


@pytest.mark.parametrize("name", ["near_sym_a", "near_sym_b"])
def test_near_sym_filter_identities(name):
    f = FILTERS[name]
    for key in ("h0o", "h1o", "g0o", "g1o"):
        np.testing.assert_allclose(f[key], f[key][::-1], atol=1e-15)
    assert abs(f["h0o"].sum() - 1) < 1e-12 and abs(f["g0o"].sum() - 1) < 1e-12
    np.testing.assert_allclose(f["g1o"], (-1.0) ** np.arange(len(f["g1o"])) * f["h0o"], atol=1e-15)
    np.testing.assert_allclose(f["h1o"], (-1.0) ** (np.arange(len(f["h1o"])) + 1) * f["g0o"], atol=1e-15)
    total = np.convolve(f["h0o"], f["g0o"]) + np.pad(np.convolve(f["h1o"], f["g1o"]), 0)
    centre = np.zeros_like(total)
    centre[len(total) // 2] = 1
    np.testing.assert_allclose(total, centre, atol=1e-12)


def test_rejects_sizes_that_are_not_multiples():
    with pytest.raises(ValueError, match="multiples of 8"):
        DTCWT(3).forward(np.zeros((20, 24)))


def test_blocked_filtering_and_tiled_copies_give_the_bytes_of_the_whole_arrays():
    """The column filters work on tiled contiguous copies and on blocks of rows (cache-sized
    temporaries for large images): the same values as one einsum of the whole gather."""
    from texsyn.ops.patches import extend_index
    from texsyn.transforms import dtcwt

    rng = np.random.default_rng(4)
    image = rng.standard_normal((300, 257))
    view = image.T  # what a column filter moves first
    assert np.array_equal(dtcwt._contiguous(view), np.ascontiguousarray(view))
    assert dtcwt._contiguous(view).flags.c_contiguous
    taps = rng.standard_normal(7)
    index = extend_index(np.arange(257)[:, None] + 3 - np.arange(7)[None, :], 257)
    moved = np.ascontiguousarray(view)
    whole = np.einsum("rl...,l->r...", moved[index], taps)
    assert np.array_equal(dtcwt._filter_rows(moved, index, taps), whole)
    old = dtcwt._BLOCK_VALUES
    try:
        dtcwt._BLOCK_VALUES = 7 * 300 * 5  # blocks of 5 rows, a last one of 2
        assert np.array_equal(dtcwt._filter_rows(moved, index, taps), whole)
    finally:
        dtcwt._BLOCK_VALUES = old
