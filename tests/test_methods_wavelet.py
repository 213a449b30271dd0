"""DT-CWT sampling (Gallagher and Kokaram) and its Wei-Levoy comparison."""

import numpy as np
import pytest

import texsyn
from texsyn.methods.wavelet_sampling import block_indices, propagate
from texsyn.metrics import source_map_regions
from texsyn.ops import rgb_to_yuv


def test_coefficient_tree_maps_a_cell_to_its_child_blocks():
    cells = np.array([[[5, 7], [1, 2]]])  # a 1x2 grid of level-3 source cells
    level2 = block_indices(cells, 2)
    level1 = block_indices(cells, 4)
    assert level2.shape == (2, 4, 2) and level1.shape == (4, 8, 2)
    # output cell (0, 0) <- source (5, 7): its children at level 2 are (10..11, 14..15)
    np.testing.assert_array_equal(level2[:2, :2, 0], [[10, 10], [11, 11]])
    np.testing.assert_array_equal(level2[:2, :2, 1], [[14, 15], [14, 15]])
    np.testing.assert_array_equal(level2[:2, 2:, 0], [[2, 2], [3, 3]])
    np.testing.assert_array_equal(level1[:4, :4, 0], np.repeat(np.arange(20, 24)[:, None], 4, axis=1))
    np.testing.assert_array_equal(level1[:4, 4:, 1], np.repeat(np.arange(8, 12)[None, :], 4, axis=0))


@pytest.mark.method("cwt")
def test_same_size_output_with_the_exemplar_seed_is_the_exemplar():
    ex = texsyn.data.exemplar("gravel", size=64)
    out = texsyn.synthesize(ex, "cwt", ex.shape, rng=0)
    np.testing.assert_allclose(out, ex, atol=1e-6)


def test_every_level_copies_the_blocks_named_by_the_source_cells():
    ex = texsyn.data.exemplar("grass", size=64).astype(np.float64)
    method = texsyn.make_method("cwt").fit(ex)
    seen = []
    method.sample((128, 96), rng=1, callback=seen.append)
    info = next(p.info for p in seen if p.info)
    cells = info["cells"]
    pyr = method.pyramids_[0]
    out = propagate(pyr, info["level_maps"], info["lowpass_map"])
    top = pyr.highpasses[-1]
    np.testing.assert_array_equal(out.highpasses[-1], top[cells[..., 0], cells[..., 1]])
    # level 1: the 4x4 block of output cell (i, j) is the 4x4 block of its source cell
    i, j = 3, 5
    a, b = cells[i, j]
    np.testing.assert_array_equal(
        out.highpasses[0][4 * i : 4 * i + 4, 4 * j : 4 * j + 4],
        pyr.highpasses[0][4 * a : 4 * a + 4, 4 * b : 4 * b + 4],
    )
    np.testing.assert_array_equal(
        out.lowpass[2 * i : 2 * i + 2, 2 * j : 2 * j + 2], pyr.lowpass[2 * a : 2 * a + 2, 2 * b : 2 * b + 2]
    )
    assert cells.min() >= 0


@pytest.mark.method("cwt")
def test_colour_u_and_v_follow_the_luminance_source_map():
    layers = [texsyn.data.exemplar(n, size=64) for n in ("grass", "gravel", "brick")]
    ex = 0.35 + 0.3 * np.stack(layers, axis=-1)  # low contrast: no clipping
    method = texsyn.make_method("cwt").fit(ex)
    seen = []
    out = method.sample((96, 96), rng=2, callback=seen.append).astype(np.float64)
    info = next(p.info for p in seen if p.info)
    yuv = rgb_to_yuv(out)
    transform = method._transform()
    for c in (1, 2):  # U and V: their own pyramids gathered along Y's maps
        expected = transform.inverse(propagate(method.pyramids_[c], info["level_maps"], info["lowpass_map"]))
        np.testing.assert_allclose(yuv[..., c], expected, atol=1e-5)


@pytest.mark.method("cwt")
def test_a_periodic_coarse_structure_keeps_its_period():
    yy, xx = np.mgrid[:64, :64]
    ex = 0.5 + 0.3 * np.sin(2 * np.pi * xx / 16) + 0.1 * np.sin(2 * np.pi * yy / 32)
    out = texsyn.synthesize(ex, "cwt", (128, 128), rng=3).astype(np.float64)
    inner = out[16:-16, 16:-16]
    lag = np.mean(np.abs(inner[:, 16:] - inner[:, :-16]))
    half = np.mean(np.abs(inner[:, 8:] - inner[:, :-8]))
    assert lag < 0.05 < half


def text_exemplar():
    from skimage import data

    page = data.page().astype(np.float64) / 255.0  # a scanned page of printed text
    return page[20:116, 0:96]


def mean_region_area_outside(source_map, inside):
    """Mean size (in pixels) of the constant-offset region of a pixel, over pixels outside a mask."""
    labels, _ = source_map_regions(source_map)
    areas = np.bincount(labels.ravel())
    return float(np.mean(areas[labels[~inside]]))


@pytest.mark.method("cwt")
def test_level_3_reproduces_words_where_pixel_sampling_grows_fragments():
    from texsyn.drivers.raster import grow_pixels
    from texsyn.ops.nonparametric import NonParametricSampler

    ex = text_exemplar()  # 96x96 of printed text
    cwt = texsyn.make_method("cwt").fit(ex).sample_with_map((128, 128), rng=0)
    # the paper's pixel-domain baseline with the same seed (the whole exemplar at the centre)
    pixel = NonParametricSampler(np.pad(ex, 2), 5)
    _, source = grow_pixels(
        pixel, (128, 128), max_error=np.inf, seed_block=(2, 2, 96, 96), rng=np.random.default_rng(0)
    )
    seed = np.zeros((128, 128), dtype=bool)
    seed[16:112, 16:112] = True
    words = mean_region_area_outside(cwt.source_map, seed)
    letters = mean_region_area_outside(source - 2, seed)
    assert words > 10 * letters  # measured: about 370 px against 5 px


def test_refinement_keeps_the_coarsest_level_and_changes_the_finer_ones():
    """``refine`` re-chooses positions of the finer levels only (docs/methods/cwt.md): the
    coarsest source map is the growth's, every refined source lies inside the exemplar."""
    ex = texsyn.data.exemplar("gravel", size=64)
    maps = {}
    for refine in (False, True):
        seen = []
        result = (
            texsyn.make_method("cwt", refine=refine)
            .fit(ex)
            .sample_with_map((96, 96), rng=4, callback=seen.append)
        )
        maps[refine] = (result, next(p.info for p in seen if p.info))
    (plain, plain_info), (refined, refined_info) = maps[False], maps[True]
    np.testing.assert_array_equal(plain_info["cells"], refined_info["cells"])
    assert not np.array_equal(plain_info["level_maps"][0], refined_info["level_maps"][0])
    assert not np.array_equal(plain.image, refined.image)
    for level, m in enumerate(refined_info["level_maps"]):
        assert m.min() >= 0 and np.all(m.max(axis=(0, 1)) < np.array(ex.shape) // 2 ** (level + 1))


def test_wei_levoy_tsvq_with_one_leaf_is_the_exact_search():
    ex = texsyn.data.exemplar("gravel", size=32)
    exact = texsyn.make_method("wei_levoy", levels=2, window=5).fit(ex).sample((24, 24), rng=0)
    tree = (
        texsyn.make_method("wei_levoy", levels=2, window=5, search="tsvq", leaf_size=4096)
        .fit(ex)
        .sample((24, 24), rng=0)
    )
    np.testing.assert_array_equal(exact, tree)
    approx = texsyn.make_method("wei_levoy", levels=2, window=5, search="tsvq", leaf_size=8).fit(ex)
    result = approx.sample_with_map((24, 24), rng=0)
    np.testing.assert_array_equal(result.image, ex[result.source_map[..., 0], result.source_map[..., 1]])
    # small leaves: the tree search is approximate, yet it finds almost every exemplar
    # neighbourhood itself (measured: 97.1 % at level 0, 99.6 % at level 1)
    for bank, tree in zip(approx.banks_, approx.trees_):
        found = np.array([tree.query(v) for v in bank])
        assert np.mean(np.all(bank[found] == bank, axis=1)) > 0.9


def test_bad_parameters():
    ex = texsyn.data.exemplar("gravel", size=64)
    with pytest.raises(ValueError, match="odd"):
        texsyn.make_method("cwt", window=4).fit(ex)
    with pytest.raises(ValueError, match="odd"):
        texsyn.make_method("wei_levoy", window=4).fit(ex)
    with pytest.raises(ValueError, match="too small"):
        texsyn.make_method("cwt", levels=4).fit(ex[:20, :20])


@pytest.mark.method("wei_levoy")
def test_wei_levoy_handles_tiny_coarse_levels():
    ex = texsyn.data.exemplar("gravel", size=64)
    result = texsyn.make_method("wei_levoy").fit(ex).sample_with_map((24, 24), rng=0)  # coarsest level 3x3
    assert result.image.shape == (24, 24)
    np.testing.assert_array_equal(result.image, ex[result.source_map[..., 0], result.source_map[..., 1]])
