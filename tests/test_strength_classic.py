"""What makes the copy-based methods (quilting, Efros-Leung, Wei-Levoy, DT-CWT sampling) and
constrained sparse synthesis what they are (issue 16): tests that fail on a broken output.

Every bound was set from measurements on the exemplar below (a 40x40 crop of gravel), output
48x48, seeds 0-5, for the real output, a shuffled-pixel version and a blurred version
(sigma 1.5) as ``tests/sabotage.py`` makes them; the measured ranges are in the comments.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import texsyn
from conftest import FAST_PARAMS
from strength_utils import GRAVEL as EXEMPLAR
from strength_utils import SEEDS, SHAPE, coherent_fraction
from texsyn.methods.wavelet_sampling import block_indices, propagate
from texsyn.metrics import sharpness_ratio, spectrum_distance
from texsyn.ops import as_channels, extract_patches
from texsyn.ops.sparse import batch_omp
from texsyn.transforms.dtcwt import DTCWT

COPY_METHODS = ("quilting", "efros_leung", "wei_levoy", "cwt")


@functools.cache
def fitted(name: str):
    return texsyn.make_method(name, **FAST_PARAMS[name]).fit(EXEMPLAR)


@functools.cache
def result(name: str, seed: int, shape: tuple[int, int] = SHAPE):
    return fitted(name).sample_with_map(shape, rng=seed)


def each(names, **bounds):
    """Parameters ``(name, *bounds[name])`` of a test, each carrying its method's marker."""
    return [pytest.param(n, *bounds.get(n, ()), marks=pytest.mark.method(n), id=n) for n in names]


# ------------------------------------------------------------------ copy-based methods
@pytest.mark.parametrize("name", each(("quilting", "efros_leung", "wei_levoy")))
def test_every_pixel_is_the_exemplar_pixel_its_source_map_names(name):
    assert type(fitted(name)).has_source_map and type(fitted(name)).source_map_exact
    for seed in SEEDS:
        res = result(name, seed)
        src = res.source_map
        assert src.shape == SHAPE + (2,)
        np.testing.assert_array_equal(res.image, EXEMPLAR[src[..., 0], src[..., 1]])


def cwt_reconstruction(source_map: np.ndarray, levels: int) -> np.ndarray:
    """The DT-CWT image the pixel source map of ``cwt`` stands for: every level's coefficients
    and the low-pass image gathered from the exemplar's along the coefficient tree that the map
    encodes (pixel map = level-1 map expanded to 2x2 blocks; level-1 map = the top-level source
    cells expanded to 2^(L-1) blocks), then inverted."""
    level1 = source_map[::2, ::2] // 2
    block = 2 ** (levels - 1)
    cells = level1[::block, ::block] // block
    # the map has the tree's block structure (a permuted map has not)
    np.testing.assert_array_equal(block_indices(level1, 2), source_map)
    np.testing.assert_array_equal(block_indices(cells, block), level1)
    maps = [block_indices(cells, 2 ** (levels - k)) for k in range(1, levels + 1)]
    transform = DTCWT(levels, biort="near_sym_a", qshift="qshift_a")
    pyramid = transform.forward(EXEMPLAR.astype(np.float64))
    return transform.inverse(propagate(pyramid, maps, block_indices(cells, 2)))


@pytest.mark.method("cwt")
def test_cwt_output_is_the_coefficient_tree_its_source_map_names():
    method = fitted("cwt")
    assert not type(method).source_map_exact  # pixels mix the filters' overlapping supports
    for seed in SEEDS:
        res = result("cwt", seed)
        expected = cwt_reconstruction(res.source_map.astype(np.int64), method.levels)
        assert 0 < expected.min() and expected.max() < 1  # nothing clipped
        np.testing.assert_allclose(res.image, expected, atol=1e-5)


# coherent fraction (right neighbour's source = source + (0, 1), bottom's = source + (1, 0)),
# measured real / shuffled map (blur keeps the map):
#   quilting     0.897-0.921 / 0.0009-0.0018  -> bound 0.6
#   efros_leung  0.391-0.690 / 0.0002-0.0024  -> bound 0.15
#   wei_levoy    0.296-0.358 / 0.0011-0.0024  -> bound 0.1
#   cwt          0.948-0.971 / 0.0004-0.0009  -> bound 0.6
@pytest.mark.parametrize(
    "name, bound",
    each(COPY_METHODS, quilting=(0.6,), efros_leung=(0.15,), wei_levoy=(0.1,), cwt=(0.6,)),
)
def test_neighbours_are_copied_together(name, bound):
    for seed in SEEDS:
        assert coherent_fraction(result(name, seed).source_map) > bound, seed


# sharpness_ratio (mean gradient over the exemplar's), real / shuffled / blurred:
#   quilting 0.94-1.02 / 3.21-3.52 / 0.42-0.47     efros_leung 0.82-0.98 / 2.50-3.64 / 0.32-0.45
#   wei_levoy 1.10-1.22 / 3.10-3.60 / 0.40-0.49    cwt 1.02-1.08 / 2.92-3.44 / 0.41-0.48
#   -> 0.65 < ratio < 1.8
# spectrum_distance (RMS of the radial log10 power spectra), real / shuffled / blurred:
#   quilting 0.07-0.10 / 0.99-1.08 / 1.36-1.69     efros_leung 0.04-0.20 / 1.00-1.04 / 1.49-1.59
#   wei_levoy 0.19-0.28 / 0.96-1.05 / 1.53-1.78    cwt 0.08-0.13 / 0.96-1.02 / 1.44-1.84
#   -> distance < 0.5
@pytest.mark.parametrize("name", each(COPY_METHODS))
def test_gradients_and_power_spectrum_are_the_exemplars(name):
    for seed in SEEDS:
        image = result(name, seed).image
        assert 0.65 < sharpness_ratio(image, EXEMPLAR) < 1.8, seed
        assert spectrum_distance(image, EXEMPLAR) < 0.5, seed


# ------------------------------------------------------------------ constrained sparse synthesis
# sharpness_ratio real 1.44-1.50 / shuffled 3.42-3.48 / blurred 0.53-0.56 -> 0.9 < ratio < 2.25
# spectrum_distance real 0.36-0.45 / shuffled 0.98-1.03 / blurred 1.56-1.75 -> distance < 0.65
@pytest.mark.method("sparse")
def test_sparse_gradients_and_power_spectrum_are_the_exemplars():
    for seed in SEEDS:
        image = result("sparse", seed).image
        assert 0.9 < sharpness_ratio(image, EXEMPLAR) < 2.25, seed
        assert spectrum_distance(image, EXEMPLAR) < 0.65, seed


def coding_error(method, image) -> float:
    """Relative error of the image's patches coded with ``sparsity`` atoms of the finest
    learned dictionary (batch OMP)."""
    dictionary = method.scales_[0]["dictionary"]
    patches = extract_patches(as_channels(np.asarray(image, dtype=np.float64)), method.patch_size)[0].T
    codes = batch_omp(dictionary, patches, method.sparsity)
    return float(np.linalg.norm(patches - dictionary @ codes) / np.linalg.norm(patches))


# relative coding error: exemplar 0.065; output real 0.095-0.100 / shuffled 0.205-0.211 /
# blurred 0.030-0.033 (a blur is sparser: the histogram test below catches it) -> error < 0.145
@pytest.mark.method("sparse")
def test_sparse_output_patches_are_sparse_in_the_learned_dictionary():
    method = fitted("sparse")
    assert coding_error(method, EXEMPLAR) < 0.145
    for seed in SEEDS:
        assert coding_error(method, result("sparse", seed).image) < 0.145, seed


@pytest.mark.method("sparse")
def test_sparse_output_of_the_exemplars_size_has_its_histogram():
    for seed in SEEDS:
        image = result("sparse", seed, EXEMPLAR.shape).image
        np.testing.assert_allclose(np.sort(image, axis=None), np.sort(EXEMPLAR, axis=None), atol=1e-7)
