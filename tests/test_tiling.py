"""Tileable outputs for every method (issue 23, ``docs/tiling.md``): the seams of a 2x2 tiling
are no stronger than the interior's strong lines, the output keeps the exemplar's sharpness,
and the generic join (texsyn.ops.tiling) is what it says."""

from __future__ import annotations

import json

import numpy as np
import pytest

import texsyn
from texsyn.cli import main
from texsyn.io import read_image
from texsyn.methods._tiling import BAND_PATCH, seam_band_width
from texsyn.metrics import sharpness_ratio

#: settings that keep the slow methods quick; the tiling does not depend on them
FAST = {
    "sparse": {"n_outer": 2, "ksvd_iterations": 2},
    "portilla_simoncelli": {"n_iterations": 10},
    "efros_leung": {"search": "approximate"},
}
#: the seams of a 2x2 tiling may be at most this much stronger than the interior lines'
#: 90th percentile of mean absolute gradient (docs/tiling.md, "How it is tested")
SEAM_LIMIT = 1.1
#: methods whose outputs are sharper or blurrier than a structured exemplar whether they tile
#: or not: random phase noise spreads the spectrum's energy over Gaussian-like gradients
#: (sharpness 1.5 on brick at any size); strict xfails below
SHARPNESS_XFAIL_256 = {
    "random_phase": "random phase noise has Gaussian gradients: 1.5x the brick's mean |gradient| (issue 23)",
}
SHARPNESS_XFAIL = {"random_phase": SHARPNESS_XFAIL_256["random_phase"]}
#: a line across the band's edge may be at most 10 % spikier (its mean |gradient| over its
#: six neighbours') than the 90th percentile of the output's other lines: a straight join of
#: the band to the method's pixels measured 1.6-5.2x its neighbours on brick, where an
#: output's own lines (quilting's block seams, mortar joints) reach 1.3-1.7
EDGE_SPIKE_LIMIT = 1.1


@pytest.fixture(scope="module")
def brick() -> np.ndarray:
    """A structured exemplar: scikit-image's brick wall, 64x64."""
    return texsyn.data.exemplar("brick", size=64)


def seam_strength(image: np.ndarray) -> float:
    """Mean |gradient| across the seams of a 2x2 tiling over the interior lines' 90th percentile.

    Each line between two neighbouring columns (rows) has its mean absolute difference; the two
    seams' mean is compared with the 90th percentile of all the others, so that a line that
    happens to run along a mortar joint does not count as a seam.
    """
    grey = image if image.ndim == 2 else image.mean(axis=2)
    tiled = np.tile(grey.astype(np.float64), (2, 2))
    columns = np.abs(np.diff(tiled, axis=1)).mean(axis=0)
    rows = np.abs(np.diff(tiled, axis=0)).mean(axis=1)
    h, w = grey.shape
    seams = (columns[w - 1] + rows[h - 1]) / 2
    inner = np.concatenate([np.delete(columns, w - 1), np.delete(rows, h - 1)])
    return float(seams / np.percentile(inner, 90))


def line_spikes(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets from the 2x2 tiling's seams and, at each, the mean |gradient| of the line there
    over the median of its six neighbouring lines (columns and rows averaged)."""
    grey = image if image.ndim == 2 else image.mean(axis=2)
    tiled = np.tile(grey.astype(np.float64), (2, 2))
    n = min(grey.shape)
    offsets = np.arange(-(n - 8), n - 8)
    ratios = []
    for lines, size in (
        (np.abs(np.diff(tiled, axis=1)).mean(axis=0), grey.shape[1]),
        (np.abs(np.diff(tiled, axis=0)).mean(axis=1), grey.shape[0]),
    ):
        k = size - 1 + offsets
        around = np.stack([lines[k + d] for d in (-3, -2, -1, 1, 2, 3)])
        ratios.append(lines[k] / np.median(around, axis=0))
    return offsets, np.mean(ratios, axis=0)


def edge_spike(image: np.ndarray, offset: int, reach: int) -> float:
    """The spike of the lines ``offset`` pixels from the seams over the 90th percentile of the
    spikes of the lines farther than ``reach`` from them (the output's own structure)."""
    offsets, spikes = line_spikes(image)
    interior = spikes[np.abs(offsets) > reach + 3]
    return float(spikes[offsets == offset][0] / np.percentile(interior, 90))


def check_method_tiles(name: str, exemplar: np.ndarray, size: int, seeds, sharpness_too: bool = True) -> None:
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(exemplar)
    half_band = seam_band_width(min(BAND_PATCH, size, *exemplar.shape[:2])) // 2
    for seed in seeds:
        result = model.sample_with_map((size, size), rng=seed, tileable=True)
        assert result.image.shape == (size, size)
        strength = seam_strength(result.image)
        assert strength <= SEAM_LIMIT, (
            f"{name} seed {seed}: seams {strength:.2f} x the interior's 90th percentile"
        )
        for offset in (-half_band, half_band):  # where the band meets the method's pixels
            spike = edge_spike(result.image, offset, 2 * half_band)
            assert spike <= EDGE_SPIKE_LIMIT, (
                f"{name} seed {seed}: the line {offset:+d} from the seam is {spike:.2f}x its neighbours"
            )
        if result.source_map is not None and model.source_map_exact:
            rows, cols = result.source_map[..., 0], result.source_map[..., 1]
            np.testing.assert_array_equal(result.image, exemplar[rows, cols])
        if not sharpness_too or name in SHARPNESS_XFAIL:
            continue
        sharpness = sharpness_ratio(result.image, exemplar)
        assert 0.8 <= sharpness <= 1.2, f"{name} seed {seed}: sharpness ratio {sharpness:.2f}"


@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_every_method_tiles_without_a_seam_and_keeps_its_sharpness(name, brick):
    check_method_tiles(name, brick, 128, seeds=(0,))


def with_xfails(reasons: dict[str, str]) -> list:
    return [
        pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=reasons[n])) if n in reasons else n
        for n in sorted(texsyn.METHODS)
    ]


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=r)) for n, r in SHARPNESS_XFAIL.items()],
)
def test_sharpness_of_a_tileable_output_is_the_exemplars(name, brick):
    """The methods the test above does not hold to the sharpness bounds, as strict xfails."""
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(brick)
    sharpness = sharpness_ratio(model.sample((128, 128), rng=0, tileable=True), brick)
    assert 0.8 <= sharpness <= 1.2, f"{name}: {sharpness:.2f}"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_every_method_tiles_at_256_on_two_seeds(name, brick):
    """The issue's figure: 256x256 outputs tiled 2x2, two seeds."""
    check_method_tiles(name, brick, 256, seeds=(0, 1), sharpness_too=False)


@pytest.mark.slow
@pytest.mark.parametrize("name", with_xfails(SHARPNESS_XFAIL_256))
def test_sharpness_of_a_tileable_256_output_is_the_exemplars(name, brick):
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(brick)
    sharpness = sharpness_ratio(model.sample((256, 256), rng=0, tileable=True), brick)
    assert 0.8 <= sharpness <= 1.2, f"{name}: {sharpness:.2f}"


@pytest.mark.slow
def test_patch_wavelet_keeps_the_exemplars_sharpness_at_256_on_two_seeds(brick):
    """Its synthesis got blurrier with the output's size while the exemplar was mirrored
    (0.79 and 0.75 at 256, docs/methods/patch_wavelet.md); on the paper's cyclic patches
    it holds at any size."""
    model = texsyn.make_method("patch_wavelet").fit(brick)
    for seed in (0, 1):
        sharpness = sharpness_ratio(model.sample((256, 256), rng=seed, tileable=True), brick)
        assert 0.8 <= sharpness <= 1.2, f"patch_wavelet seed {seed}: {sharpness:.2f}"


@pytest.mark.parametrize("name", ["quilting", "efros_leung", "lg", "cwt", "sparse"])
def test_the_seam_statistic_sees_the_seam_of_an_output_that_does_not_tile(name, brick):
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(brick)
    assert seam_strength(model.sample((128, 128), rng=0)) > 1.5


def test_a_method_periodic_by_construction_samples_as_usual(brick):
    model = texsyn.make_method("random_phase").fit(brick)
    assert model.periodic_for((96, 80)) and not model.periodic_for((32, 32))  # smaller than the exemplar
    np.testing.assert_array_equal(model.sample((96, 80), rng=3, tileable=True), model.sample((96, 80), rng=3))
    assert texsyn.make_method("patch_wavelet").fit(brick).periodic_for((128, 128))
    assert not texsyn.make_method("patch_wavelet").fit(brick).periodic_for((96, 128))


# ------------------------------------------------------------------ the quilted seam band
def test_the_seam_band_keeps_the_methods_pixels_and_copies_exemplar_blocks_across_the_wraps(brick):
    model = texsyn.make_method("quilting", patch_size=24).fit(brick)
    plain = model.sample_with_map((100, 90), rng=5)
    tiled = model.sample_with_map((100, 90), rng=5, tileable=True)
    reach = seam_band_width(BAND_PATCH)  # half the band and the zone of its cut, each side
    kept = np.ones((100, 90), dtype=bool)
    kept[:reach, :] = kept[-reach:, :] = False  # the band across each wrap and its edges' cuts
    kept[:, :reach] = kept[:, -reach:] = False
    np.testing.assert_array_equal(tiled.image[kept], plain.image[kept])
    np.testing.assert_array_equal(tiled.source_map[kept], plain.source_map[kept])
    assert not np.array_equal(tiled.image[~kept], plain.image[~kept])
    np.testing.assert_array_equal(tiled.image, brick[tiled.source_map[..., 0], tiled.source_map[..., 1]])
    # across the wraps, most neighbours are exemplar neighbours (inside quilted blocks)
    across = np.all(tiled.source_map[:, 0] == tiled.source_map[:, -1] + [0, 1], axis=-1)
    assert across.mean() > 0.6


@pytest.mark.parametrize("name", ["lg", "clg", "rclg", "mslg", "sparse", "grouplets", "cwt"])
def test_the_seam_band_of_a_method_that_does_not_copy_is_copied_not_blended(name, brick):
    """No cross-fade, no blur: outside the band the method's pixels, inside it exemplar values
    (the 8-bit brick's levels, which the LG and sparse outputs' floats almost never hit).
    The seam and sharpness statistics alone pass a 16-pixel cross-fade of these methods' wraps."""
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(brick)
    plain, tiled = model.sample((96, 80), rng=4), model.sample((96, 80), rng=4, tileable=True)
    half, reach = seam_band_width(BAND_PATCH) // 2, seam_band_width(BAND_PATCH)
    band = np.zeros((96, 80), dtype=bool)
    band[:half] = band[-half:] = True
    band[:, :half] = band[:, -half:] = True
    edges = np.zeros((96, 80), dtype=bool)  # the band and the zones its edges are cut in
    edges[:reach] = edges[-reach:] = True
    edges[:, :reach] = edges[:, -reach:] = True
    np.testing.assert_array_equal(tiled[~edges], plain[~edges])
    assert np.isin(tiled[band], brick).all()
    changed = tiled != plain
    assert np.isin(tiled[changed], brick).all()  # every pixel changed is an exemplar value
    assert not np.isin(plain[band], brick).all()


def test_the_seam_band_fits_small_outputs_and_small_exemplars():
    tiny = texsyn.data.exemplar("gravel", size=20)
    out = texsyn.synthesize(tiny, "efros_leung", (24, 30), rng=1, tileable=True, window_size=5)
    assert out.shape == (24, 30) and seam_strength(out) <= 1.6
    assert seam_band_width(32) == 10 and seam_band_width(4) == 2


def test_same_seed_same_tileable_bytes(brick):
    model = texsyn.make_method("lg").fit(brick)
    np.testing.assert_array_equal(
        model.sample((80, 80), rng=9, tileable=True), model.sample((80, 80), rng=9, tileable=True)
    )


# ------------------------------------------------------------------ command line
def test_synth_tileable_writes_an_output_that_wraps_and_says_so(tmp_path):
    out = tmp_path / "t.png"
    args = ["synth", "-m", "quilting", "--size", "160x120", "--seed", "2", "--tileable", "-q", "-o", str(out)]
    assert main(args) == 0
    image = read_image(out)
    assert image.shape == (120, 160) and seam_strength(image) <= SEAM_LIMIT
    assert json.loads((tmp_path / "t.png.json").read_text())["options"]["tileable"] is True
    plain = tmp_path / "p.png"
    assert main([*args[:-4], "-q", "-o", str(plain)]) == 0
    assert seam_strength(read_image(plain)) > 1.5


def test_tileable_with_a_flow_is_a_usage_error(tmp_path, capsys):
    flow = tmp_path / "flow.npy"
    np.save(flow, np.zeros((32, 32, 2), dtype=np.float32))
    code = main(
        ["synth", "-m", "grouplets", "--flow", str(flow), "--tileable", "-o", str(tmp_path / "o.png")]
    )
    assert code == 2 and "--tileable" in capsys.readouterr().err
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("name", ["quilting", "mslg"])
def test_a_tileable_material_stays_in_register(name, brick):
    """The guide's source map (replay) or the joint image carries the band to every image."""
    from texsyn.materials import synthesize_stack

    albedo = np.stack([brick, 0.8 * brick, 0.5 * brick], axis=-1)
    height = 2.0 * brick  # in metres, outside [0, 1]: mapped to [0, 1] and back
    result = synthesize_stack(albedo, [height], name, (96, 96), rng=0, tileable=True)
    out_albedo, out_height = result.images
    assert np.abs(out_height - 2.0 * out_albedo[..., 0]).max() < 1e-4
    assert seam_strength(out_albedo) <= SEAM_LIMIT and seam_strength(out_height) <= SEAM_LIMIT
