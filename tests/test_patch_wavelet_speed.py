"""The patch-valued wavelet transform's faster paths give the reference paths' bytes.

Issue 20 (``docs/methods/patch_wavelet.md``, "Performance"): the indexes are built a few
image rows at a time from strided window copies, the block means without SciPy, the
queries are made in smaller parts and the output pixels are gathered in float32. Each is
compared here with the computation it replaces.
"""

import numpy as np
import pytest
from scipy.ndimage import uniform_filter

import texsyn
from texsyn.models import patch_search
from texsyn.models.patch_wavelet import ExemplarWindows, PatchWaveletTransform, periodic_block_means
from texsyn.ops.search import NearestPatchIndex


def _same_index(got: NearestPatchIndex, want: NearestPatchIndex) -> None:
    np.testing.assert_array_equal(got.mean, want.mean)
    np.testing.assert_array_equal(got._bank32, want._bank32)
    np.testing.assert_array_equal(got._half_norm, want._half_norm)
    assert got.candidates == want.candidates


@pytest.mark.parametrize("shape, part", [((1000, 7), 64), ((777, 48), 100), ((300, 1), 1), ((50, 20), 500)])
def test_an_index_built_part_by_part_is_the_index_of_the_whole_bank(shape, part):
    rng = np.random.default_rng(shape[0])
    bank = rng.random(shape) * rng.random(shape[1]) * 10.0 - 3.0

    def fill(start, stop, out, offset):
        out[...] = bank[start:stop] if offset is None else bank[start:stop] - offset

    got = NearestPatchIndex.from_parts(fill, shape[0], shape[1], part_rows=part, rows=bank.__getitem__)
    _same_index(got, NearestPatchIndex(bank))
    queries = rng.random((40, shape[1])) * 10.0 - 3.0
    for a, b in zip(got.query(queries), NearestPatchIndex(bank).query(queries)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("boundary", ["periodic", "symmetric"])
@pytest.mark.parametrize("channels", [1, 3])
def test_row_descriptors_are_the_gathered_descriptors(boundary, channels):
    rng = np.random.default_rng(channels)
    windows = ExemplarWindows(rng.random((24, 40, channels)), boundary, max_resolution=4, widths=(2, 4, 8))
    h, w = windows.shape
    rows, cols = np.divmod(np.arange(h * w), w)
    for width in (2, 4, 8, 16):  # 8 and 16: block means of 2x2 and 4x4 pixels
        want = windows.descriptors(rows, cols, width)
        np.testing.assert_array_equal(windows.all_descriptors(width), want)
        out = np.empty((3 * w, windows.dimension(width)))
        offset = rng.random(windows.dimension(width))
        got = windows.fill_row_descriptors(width, 5, 8, out, offset)
        np.testing.assert_array_equal(got, want[5 * w : 8 * w] - offset)


@pytest.mark.parametrize("b", [1, 2, 3, 4, 7, 16, 50])
def test_periodic_block_means_are_scipys_uniform_filter(b):
    rng = np.random.default_rng(b)
    for image in (
        rng.random((40, 30, 3)),
        rng.random((9, 33, 1)) * 1e3,
        np.round(rng.random((16, 16, 2)) * 255) / 255,
    ):
        want = uniform_filter(image, size=(b, b, 1), mode="wrap", origin=(-(b // 2), -(b // 2), 0))
        np.testing.assert_array_equal(periodic_block_means(image, b), want)


@pytest.mark.parametrize("boundary", ["periodic", "symmetric"])
def test_the_transforms_indexes_and_fast_searches_are_those_of_the_whole_banks(colour_exemplar, boundary):
    transform = PatchWaveletTransform(colour_exemplar[:48, :40], exemplar_boundary=boundary, min_width=4)
    h, w = transform.exemplar_shape
    rows, cols = np.divmod(np.arange(h * w), w)
    for width, index in transform.indexes.items():
        bank = transform.windows.descriptors(rows, cols, width)
        _same_index(index, NearestPatchIndex(bank, candidates=transform.candidates))
        fast = transform.fast.get(width)
        if fast is not None:
            want = patch_search.FastSearch.build(transform.windows, NearestPatchIndex(bank), width)
            np.testing.assert_array_equal(fast.isolated, want.isolated)
            assert fast.centred_max == want.centred_max


def test_queries_asked_in_parts_get_the_answers_of_whole_chunks(colour_exemplar):
    transform = PatchWaveletTransform(colour_exemplar[:64, :64])
    width = 16  # 768 values: chunks of 5461 queries, parts of 1280
    index = transform.index(width)
    rng = np.random.default_rng(0)
    n = 6000
    queries = transform.windows.descriptors(rng.integers(0, 64, n), rng.integers(0, 64, n), width)
    queries += rng.normal(0.0, 0.05, queries.shape)
    got = transform._nearest(lambda a, b: queries[a:b], n, width)
    chunk = 2**22 // queries.shape[1]
    want = np.concatenate([index.query(queries[a : a + chunk])[0] for a in range(0, n, chunk)])
    np.testing.assert_array_equal(got, want)


def test_the_fast_search_in_small_parts_is_the_plain_search(monkeypatch, colour_exemplar):
    transform = PatchWaveletTransform(colour_exemplar[:64, :64])
    width = 8
    assert width in transform.fast
    rng = np.random.default_rng(1)
    n = 3000
    first = np.stack([rng.integers(0, 64, n), rng.integers(0, 64, n)], axis=1)
    second = first.copy()
    second[: n // 2, 1] += 8  # half coherent pairs (the direct answers), half random ones
    second[n // 2 :] = rng.integers(0, 64, (n - n // 2, 2))
    monkeypatch.setattr(patch_search, "PROVEN_PAIRS", 700)
    monkeypatch.setattr(patch_search, "PROVEN_CHUNK_VALUES", 300 * 192)
    got = transform.mean_features(first, second, 1, 4, width)
    plain = transform._nearest(
        lambda a, b: transform.windows.mean_descriptors(first[a:b], second[a:b], 1, 4, width), n, width
    )
    np.testing.assert_array_equal(got, plain)


@pytest.mark.parametrize("exemplar", ["grey_exemplar", "colour_exemplar"])
def test_the_output_is_the_clipped_float32_copy_of_the_float64_pixels(request, exemplar):
    ex = request.getfixturevalue(exemplar)
    model = texsyn.make_method("patch_wavelet").fit(ex)
    result = model.sample_with_map((40, 56), rng=2)
    pixels = model.transform_.image(result.source_map.astype(np.int64))
    want = np.clip(pixels[..., 0] if ex.ndim == 2 else pixels, 0.0, 1.0).astype(np.float32)
    assert result.image.dtype == np.float32
    np.testing.assert_array_equal(result.image, want)


def test_a_synthesis_does_not_import_scipy_ndimage():
    import subprocess
    import sys

    code = (
        "import sys, numpy as np, texsyn\n"
        "texsyn.make_method('patch_wavelet').fit(np.random.default_rng(0).random((64, 64, 3)))"
        ".sample((64, 64), rng=0)\n"
        "print('scipy.ndimage' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
