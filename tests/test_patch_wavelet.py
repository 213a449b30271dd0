"""Peyré 2007 patch-valued wavelet transform: building blocks, transform, synthesis, modification."""

import numpy as np
import pytest
from scipy import ndimage

import texsyn
from strength_utils import coherent_fraction
from texsyn.cli import main
from texsyn.io import read_image
from texsyn.models.patch_wavelet import (
    ExemplarWindows,
    PatchWaveletTransform,
    lle_embedding,
)
from texsyn.ops import NearestPatchIndex, extend_index, knn_patches, wrap_seam_ratio


@pytest.fixture(scope="module")
def brick():
    return texsyn.data.exemplar("brick", size=40)


@pytest.fixture(scope="module")
def transform(brick):
    return PatchWaveletTransform(brick, exemplar_boundary="symmetric").prepare()


def brute_window(image, centre, width, boundary):
    """The ``width x width`` window centred on ``centre`` of the extended image, explicitly."""
    h, w = image.shape[:2]
    offsets = np.arange(-width // 2, width // 2)
    rows = extend_index(centre[0] + offsets, h, boundary)
    cols = extend_index(centre[1] + offsets, w, boundary)
    return image[np.ix_(rows, cols)]


def block_average(window, m):
    b = window.shape[0] // m
    return window.reshape(m, b, m, b, -1).mean(axis=(1, 3))


# ---------------------------------------------------------------------- building blocks
@pytest.mark.parametrize("mode", ["symmetric", "periodic"])
def test_extend_index_matches_numpy_padding(mode):
    x = np.arange(7)
    padded = np.pad(x, 20, mode="symmetric" if mode == "symmetric" else "wrap")
    np.testing.assert_array_equal(x[extend_index(np.arange(-20, 27), 7, mode)], padded)


def test_wrap_seam_ratio_tells_periodic_from_cropped_textures(brick):
    periodic = texsyn.synthesize(brick, "random_phase", (64, 64), rng=0)
    assert wrap_seam_ratio(periodic) < 1.2
    assert wrap_seam_ratio(np.tile(np.linspace(0, 1, 32), (32, 1))) > 10


def test_nearest_patch_index_is_the_exact_nearest_row():
    rng = np.random.default_rng(0)
    bank = rng.random((3000, 48))
    queries = bank[rng.integers(0, 3000, 500)] + 0.05 * rng.standard_normal((500, 48))
    index, distance = NearestPatchIndex(bank, block=128).query(queries)
    _, exact = knn_patches(queries, bank, 1)
    np.testing.assert_allclose(distance, exact[:, 0], atol=1e-9)
    np.testing.assert_allclose(np.sum((bank[index] - queries) ** 2, axis=1), distance, atol=1e-9)


def test_nearest_patch_index_breaks_ties_by_lowest_row():
    bank = np.zeros((10, 4))
    bank[3:] = 1.0
    index, _ = NearestPatchIndex(bank).query(np.full((2, 4), 0.9))
    np.testing.assert_array_equal(index, [3, 3])


@pytest.mark.parametrize("boundary", ["symmetric", "periodic"])
@pytest.mark.parametrize("width", [4, 8, 32])
def test_window_descriptors_are_block_means_of_the_extended_window(boundary, width):
    rng = np.random.default_rng(1)
    image = rng.random((24, 20, 3))
    windows = ExemplarWindows(image, boundary, max_resolution=8)
    centres = np.array([[0, 0], [23, 19], [5, 11], [-3, 40]])
    got = windows.descriptors(centres[:, 0], centres[:, 1], width)
    m = min(width, 8)
    for centre, row in zip(centres, got):
        expected = block_average(brute_window(image, centre, width, boundary), m)
        np.testing.assert_allclose(row, expected.ravel(), atol=1e-12)


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("width, s", [(8, 4), (16, 2), (32, 32)])
def test_mean_descriptor_glues_the_two_continuations(axis, width, s):
    """mu(x) = E(ta + s e_a + x) for x_a < 0, E(tb - s e_a + x) otherwise (Peyré 2007, section 4; docs/methods/patch_wavelet.md)."""
    rng = np.random.default_rng(2)
    image = rng.random((30, 26, 1))
    windows = ExemplarWindows(image, "symmetric", max_resolution=8)
    ta, tb = np.array([[3, 25]]), np.array([[17, 2]])
    got = windows.mean_descriptors(ta, tb, axis, s, width)[0]
    e = np.zeros(2, dtype=int)
    e[axis] = s
    first = brute_window(image, ta[0] + e, width, "symmetric")
    second = brute_window(image, tb[0] - e, width, "symmetric")
    glued = np.where(
        (np.arange(width) < width // 2)[:, None, None]
        if axis == 0
        else (np.arange(width) < width // 2)[None, :, None],
        first,
        second,
    )
    np.testing.assert_allclose(got, block_average(glued, min(width, 8)).ravel(), atol=1e-12)


def test_lle_embedding_is_normalised_and_mostly_injective(transform):
    rows, cols = transform.all_positions()
    X = transform.windows.descriptors(rows, cols, 8)
    Y = lle_embedding(X, transform.exemplar_shape, max_points=400)  # landmarks + barycentric placement
    assert Y.shape == (X.shape[0], 5)
    np.testing.assert_allclose(Y.mean(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(Y.std(axis=0), 1, atol=1e-9)
    from scipy.spatial import cKDTree

    nearest = cKDTree(Y).query(Y)[1]
    assert np.mean(nearest == np.arange(len(Y))) > 0.99


# ---------------------------------------------------------------------- the transform
@pytest.fixture(scope="module")
def gravel_features(transform):
    return transform.estimate_features(texsyn.data.exemplar("gravel", size=32))


@pytest.mark.parametrize("boundary", ["symmetric", "periodic"])
def test_inverse_of_forward_gives_back_the_coordinate_map(transform, gravel_features, boundary):
    coefficients = transform.forward(gravel_features, grid_boundary=boundary)
    assert coefficients.coarse.shape == (1, 1, 2)
    np.testing.assert_array_equal(coefficients.coarse[0, 0], gravel_features[0, 0])
    assert sum(d.shape[0] * d.shape[1] for d in coefficients.details.values()) == 32 * 32 - 1
    assert coefficients.max_norm() > 0  # the input is not a pure synthesis: the test can fail
    rebuilt = transform.inverse(coefficients)
    assert np.mean(np.all(rebuilt == gravel_features, axis=-1)) >= 0.99
    a, b = transform.image(gravel_features), transform.image(rebuilt)
    mse = np.mean((a - b) ** 2)
    assert mse == 0 or 10 * np.log10(1.0 / mse) > 40


def test_feature_estimation_of_the_exemplar_itself_is_the_identity(brick):
    transform = PatchWaveletTransform(brick[:32, :32], exemplar_boundary="symmetric")
    features = transform.estimate_features(brick[:32, :32])
    rows, cols = np.mgrid[:32, :32]
    assert np.mean((features[..., 0] == rows) & (features[..., 1] == cols)) > 0.95


def test_magnitudes_pack_every_detail_once(transform, gravel_features):
    coefficients = transform.forward(gravel_features)
    packed = coefficients.magnitudes()
    assert packed.shape == (32, 32)
    total = sum(n.sum() for n in coefficients.norms().values())
    np.testing.assert_allclose(packed.sum(), total)
    assert packed[0, 0] == 0


def test_thresholding_removes_small_details_only(transform, gravel_features):
    coefficients = transform.forward(gravel_features)
    top = coefficients.max_norm()
    for ratio in (0.0, 0.3, 1.0):
        kept = coefficients.thresholded(ratio)
        for key, norms in coefficients.norms().items():
            new = np.linalg.norm(kept[key], axis=-1)
            np.testing.assert_array_equal(new > 0, norms > ratio * top)
            np.testing.assert_array_equal(new[new > 0], norms[new > 0])
    assert coefficients.thresholded(1.0).max_norm() == 0
    with pytest.raises(ValueError, match="ratio"):
        coefficients.thresholded(1.5)


def test_detail_positions_name_the_odd_samples(transform, gravel_features):
    """Table 1: the details of (level, axis) are measured at the odd samples of that split."""
    coefficients = transform.forward(gravel_features)
    for (level, axis), odd in coefficients.features.items():
        rows, cols = coefficients.detail_positions(level, axis)
        np.testing.assert_array_equal(odd, gravel_features[np.ix_(rows, cols)])
    every = np.zeros((32, 32), dtype=int)
    every[0, 0] = 1  # the coarse feature
    for level, axis in coefficients.details:
        every[np.ix_(*coefficients.detail_positions(level, axis))] += 1
    assert np.all(every == 1)  # each sample of the map is measured once


def test_detail_energy_adds_every_squared_magnitude_over_its_cell(transform, gravel_features):
    coefficients = transform.forward(gravel_features)
    energy = coefficients.detail_energy()
    assert energy.shape == (32, 32)
    np.testing.assert_allclose(
        energy.sum(),
        sum(
            (n**2).sum() * (2 ** (2 * j - 1) if a == 0 else 4**j)
            for (j, a), n in coefficients.norms().items()
        ),
    )
    normalised = coefficients.detail_energy(per_level=True)
    assert normalised.max() <= 2 * coefficients.top_level + 1e-9  # each level and axis adds at most 1


def test_kept_regions_are_nested_and_as_large_as_asked(transform, gravel_features):
    coefficients = transform.forward(gravel_features)
    ratios = np.linspace(0, 1, 9)
    regions = [coefficients.kept_region(r) for r in ratios]
    assert regions[0].all() and not regions[-1].any()
    np.testing.assert_allclose([1 - r.mean() for r in regions], ratios)
    for a, b in zip(regions, regions[1:]):
        assert np.all(b <= a)
    # the region follows the smoothed local energy: it keeps where the input deviates most
    smooth = ndimage.gaussian_filter(coefficients.detail_energy(), 4.0, mode="reflect")
    half = regions[4]
    assert smooth[half].min() >= smooth[~half].max()
    with pytest.raises(ValueError, match="ratio"):
        coefficients.kept_region(1.2)


def test_modify_removes_the_asked_share_of_an_input_whose_sides_are_not_powers_of_two():
    """The share is counted on the input, not on its extension to powers of two: ranking the
    whole extended grid removed 0.49 / 0.685 / 0.902 of a 33x40 input for ratios 0.25 / 0.5 /
    0.75, and 0.16 / 0.48 / 0.80 of a 20x64 one."""
    gravel = texsyn.data.exemplar("gravel", size=48)
    brick = texsyn.data.exemplar("brick", size=64)
    method = texsyn.make_method("patch_wavelet", sigma=(0.0, 0.2)).fit(gravel)
    for shape in [(33, 40), (20, 64)]:
        results = method.modify(brick[: shape[0], : shape[1]], [0.25, 0.5, 0.75])
        removed = [1.0 - r.kept.mean() for r in results]
        np.testing.assert_allclose(removed, [0.25, 0.5, 0.75], atol=1.0 / (shape[0] * shape[1]))
        for a, b in zip(results, results[1:]):
            assert np.all(b.kept <= a.kept)


def test_restoring_inverse_rebuilds_the_kept_region_and_synthesises_the_rest(transform, gravel_features):
    coefficients = transform.forward(gravel_features)
    # everything kept: the analysed map exactly (the literal inverse only up to gamma's injectivity)
    np.testing.assert_array_equal(transform.inverse(coefficients, restore=True), gravel_features)
    region = coefficients.kept_region(0.5)
    kept = coefficients.restricted(region)
    same = coefficients.locally_thresholded(0.5)
    for key in kept.details:
        np.testing.assert_array_equal(same.details[key], kept.details[key])
        np.testing.assert_array_equal(same.features[key], kept.features[key])
    rebuilt = transform.inverse(kept, restore=True)
    np.testing.assert_array_equal(rebuilt[region], gravel_features[region])
    assert np.mean(np.all(rebuilt[~region] == gravel_features[~region], axis=-1)) < 0.5
    # details outside the region are gone, inside they are untouched
    for key, d in coefficients.details.items():
        inside = region[np.ix_(*coefficients.detail_positions(*key))]
        np.testing.assert_array_equal(kept.details[key][inside], d[inside])
        assert not kept.details[key][~inside].any() and np.all(kept.features[key][~inside] == -1)
    # nothing kept: the pure synthesis of the paper's rule at ratio 1
    nothing = coefficients.restricted(np.zeros((32, 32), dtype=bool))
    np.testing.assert_array_equal(
        transform.inverse(nothing, restore=True), transform.inverse(coefficients.thresholded(1.0))
    )
    with pytest.raises(ValueError, match="shape"):
        coefficients.restricted(region[:16])


# ---------------------------------------------------------------------- synthesis
@pytest.mark.method("patch_wavelet")
def test_pure_synthesis_copies_coherent_regions_and_reports_every_level(brick):
    method = texsyn.make_method("patch_wavelet").fit(brick)
    levels = []
    result = method.sample_with_map((64, 64), rng=3, callback=lambda p: levels.append(p.image.shape[:2]))
    assert levels == [(2, 2), (4, 4), (8, 8), (16, 16), (32, 32), (64, 64)]
    # (output pixels are the exemplar pixels the source map names by construction: E(T))
    # the coordinate map is locally a translation: neighbour pairs copied together, seeds 0-5:
    # 0.64 .. 0.70 (0.58 .. 0.63 with the exemplar mirrored); shuffled 0.001; random predictions 0.001
    assert coherent_fraction(result.source_map) >= 0.4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_synthesis_tiles_the_plane(brick, seed):
    image = texsyn.synthesize(brick, "patch_wavelet", (64, 64), rng=seed)
    tiled = np.tile(image, (2, 2))
    across = np.abs(tiled[63] - tiled[64]).mean() + np.abs(tiled[:, 63] - tiled[:, 64]).mean()
    inside = np.abs(np.diff(image, axis=0)).mean() + np.abs(np.diff(image, axis=1)).mean()
    assert across <= 1.5 * inside
    assert wrap_seam_ratio(image) <= 1.5


def test_sizes_other_than_powers_of_two_are_crops_of_the_next_one(brick):
    method = texsyn.make_method("patch_wavelet").fit(brick)
    big = method.sample_with_map((64, 64), rng=5)
    small = method.sample_with_map((40, 57), rng=5)
    np.testing.assert_array_equal(small.source_map, big.source_map[:40, :57])


def test_synthesis_wraps_the_exemplar_and_modification_mirrors_one_that_does_not_tile(brick):
    """'auto': the paper's cyclic patches for a synthesis (docs/methods/patch_wavelet.md,
    "Deviations"), the mirror for a modification with an exemplar that does not tile."""
    assert wrap_seam_ratio(brick) > 1.5
    method = texsyn.make_method("patch_wavelet").fit(brick)
    assert method.transform_.exemplar_boundary == "periodic"
    mirrored = texsyn.make_method("patch_wavelet", exemplar_boundary="symmetric").fit(brick)
    assert not np.array_equal(method.sample((64, 64), rng=0), mirrored.sample((64, 64), rng=0))
    texture = texsyn.data.exemplar("gravel", size=32)
    np.testing.assert_array_equal(
        method.modify(texture, 0.5, equalize=False).source_map,
        mirrored.modify(texture, 0.5, equalize=False).source_map,
    )


def test_sigma_profile_adds_details_at_the_chosen_levels(brick):
    pure = texsyn.make_method("patch_wavelet").fit(brick).sample((32, 32), rng=4)
    fine = texsyn.make_method("patch_wavelet", sigma=(0.3,)).fit(brick).sample((32, 32), rng=4)
    coarse_only = texsyn.make_method("patch_wavelet", sigma=(0, 0, 0, 0.4)).fit(brick)
    assert np.mean(fine != pure) > 0.2
    assert not np.array_equal(coarse_only.sample((32, 32), rng=4), pure)
    np.testing.assert_array_equal(coarse_only.sigma_profile(5), [0, 0, 0, 0.4, 0])
    np.testing.assert_array_equal(texsyn.make_method("patch_wavelet", sigma=0.2).sigma_profile(3), [0.2] * 3)


def test_sigma_accepts_lists_and_rejects_bad_values():
    spec = texsyn.METHODS["patch_wavelet"].param_specs()["sigma"]
    assert spec.parse("0,0.2, 0.1", "patch_wavelet") == (0.0, 0.2, 0.1)
    assert spec.check([0, 1], "patch_wavelet") == (0.0, 1.0)
    assert spec.check(0.5, "patch_wavelet") == (0.5,)
    for bad in ("a,b", "-1", "0,nan", ""):
        with pytest.raises(ValueError, match="sigma"):
            spec.parse(bad, "patch_wavelet")
    with pytest.raises(TypeError, match="sigma"):
        spec.check(["x"], "patch_wavelet")


# ---------------------------------------------------------------------- modification
@pytest.fixture(scope="module")
def fitted(brick):
    return texsyn.make_method("patch_wavelet").fit(brick)


def test_ratio_zero_rebuilds_the_input_and_ratio_one_keeps_fewer_coordinates(fitted):
    fractions = []
    for name in ("gravel", "grass"):
        texture = texsyn.data.exemplar(name, size=32)
        results = fitted.modify(texture, [0.0, 0.1, 0.5, 1.0])
        base = results[0].source_map
        np.testing.assert_array_equal(results[0].source_map, results[0].feature_map)
        frac = [np.mean(np.all(r.source_map == base, axis=-1)) for r in results]
        assert frac[3] < frac[1]
        fractions.append(frac)
        assert results[3].magnitudes.max() == 0
        assert results[0].magnitudes.max() > 0
    mean = np.mean(fractions, axis=0)
    assert mean[3] <= mean[2] <= mean[0]


def test_modify_thresholding_local_and_coefficient(fitted):
    """Local thresholding (default) reports its kept region; the paper's per-coefficient rule
    is still there and keeps its old results (``docs/methods/patch_wavelet.md``)."""
    texture = texsyn.data.exemplar("gravel", size=32)
    local = fitted.modify(texture, [0.0, 0.5, 1.0], equalize=False)
    paper = fitted.modify(texture, [0.0, 0.5, 1.0], equalize=False, thresholding="coefficient")
    assert [m.kept.mean() for m in local] == [1.0, 0.5, 0.0]
    assert all(m.kept is None for m in paper)
    np.testing.assert_array_equal(local[0].source_map, local[0].feature_map)
    np.testing.assert_array_equal(local[2].source_map, paper[2].source_map)  # both: pure synthesis
    # the kept half is the input's own features
    np.testing.assert_array_equal(local[1].source_map[local[1].kept], local[1].feature_map[local[1].kept])
    with pytest.raises(ValueError, match="thresholding"):
        fitted.modify(texture, 0.5, thresholding="soft")


def test_ratio_one_depends_on_the_input_only_through_the_coarse_feature(fitted, brick):
    texture = texsyn.data.exemplar("gravel", size=32).copy()
    other = texture.copy()
    other[8:, :] = texsyn.data.exemplar("grass", size=32)[8:, :]
    other[:, 8:] = texsyn.data.exemplar("grass", size=32)[:, 8:]
    a = fitted.modify(texture, [0.0, 1.0], equalize=False)
    b = fitted.modify(other, [0.0, 1.0], equalize=False)
    np.testing.assert_array_equal(a[0].feature_map[0, 0], b[0].feature_map[0, 0])
    assert not np.array_equal(a[0].image, b[0].image)  # the inputs do differ
    np.testing.assert_array_equal(a[1].source_map, b[1].source_map)
    np.testing.assert_array_equal(a[1].image, b[1].image)


def test_modify_handles_any_size_and_channel_count(brick, colour_exemplar):
    texture = texsyn.data.exemplar("gravel", size=40)[:30, :37]
    out = texsyn.modify(texture, brick, 0.2)
    assert out.shape == (30, 37) and out.dtype == np.float32
    coloured = texsyn.modify(texture, colour_exemplar, 0.0, equalize=False)
    assert coloured.shape == (30, 37, 3)
    # without equalisation every pixel is an exemplar pixel
    pixels = {tuple(p) for p in colour_exemplar.reshape(-1, 3).tolist()}
    assert all(tuple(p) in pixels for p in coloured.reshape(-1, 3).tolist())
    with pytest.raises(ValueError, match="ratio"):
        texsyn.modify(texture, brick, -0.1)
    with pytest.raises(ValueError, match="grid_boundary"):
        texsyn.modify(texture, brick, 0.5, grid_boundary="zero")


def test_equalisation_matches_the_inputs_colours(brick):
    dark = 0.3 * texsyn.data.exemplar("gravel", size=32)
    plain = texsyn.modify(dark, brick, 0.0, equalize=False)
    equalised = texsyn.modify(dark, brick, 0.0)
    assert abs(equalised.mean() - dark.mean()) < 0.02
    assert abs(plain.mean() - dark.mean()) > 0.1


def test_cli_modify_writes_the_texture_and_the_magnitudes(tmp_path, capsys):
    out, mags = tmp_path / "m.png", tmp_path / "mag.npy"
    where = tmp_path / "where.npy"
    code = main(
        [
            "modify",
            "builtin:gravel",
            "-e",
            "builtin:brick",
            "-r",
            "0.2",
            "-o",
            str(out),
            "--magnitudes",
            str(mags),
            "--source-map",
            str(where),
            "-q",
            "-p",
            "lle_points=256",
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert read_image(out).shape == (128, 128)
    assert np.load(mags).shape == (128, 128)
    positions = np.load(where)
    assert positions.shape == (128, 128, 2) and positions.min() >= 0 and positions.max() < 128


@pytest.mark.parametrize(
    "args, message",
    [
        (["-r", "1.5"], "ratio"),
        (["-e", "missing.png"], "missing.png"),
        (["-p", "sigma=x"], "sigma"),
        (["--boundary", "zero"], "boundary"),
    ],
)
def test_cli_modify_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "m.png"
    base = ["modify", "builtin:gravel", "-e", "builtin:brick", "-o", str(out)]
    for i in range(0, len(args), 2):
        flag = args[i]
        if flag in base:
            base[base.index(flag) + 1] = args[i + 1]
        else:
            base += args[i : i + 2]
    code = main(base)
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and message in err
    assert not out.exists()


def test_exemplars_too_large_for_the_indexes_are_refused(monkeypatch, brick):
    monkeypatch.setenv("TEXSYN_MEMORY_LIMIT", "1M")
    with pytest.raises(MemoryError, match="patch indexes"):
        texsyn.make_method("patch_wavelet").fit(brick)
