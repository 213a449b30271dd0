"""Tileable outputs for every method (issue 23, ``docs/tiling.md``): the seams of a 2x2 tiling
are no stronger than the interior's strong lines, the output keeps the exemplar's sharpness,
and the generic join (texsyn.ops.tiling) is what it says."""

from __future__ import annotations

import json

import numpy as np
import pytest

import texsyn
from texsyn.cli import main
from texsyn.drivers import raster
from texsyn.io import read_image
from texsyn.methods._tiling import BAND_PATCH, quilted_seam_band, seam_band_width
from texsyn.metrics import gradient_energy_ratio, mean_gradient, rms_gradient, sharpness_ratio
from texsyn.ops.kcoherence import CoherentWindows
from texsyn.ops.nonparametric import NonParametricSampler

#: settings that keep the slow methods quick; the tiling does not depend on them
FAST = {
    "sparse": {"n_outer": 2, "ksvd_iterations": 2},
    "portilla_simoncelli": {"n_iterations": 10},
    "efros_leung": {"search": "approximate"},
}
#: the seams of a 2x2 tiling may be at most this much stronger than the interior lines'
#: 90th percentile of mean absolute gradient (docs/tiling.md, "How it is tested")
SEAM_LIMIT = 1.1
#: the methods whose model is Gaussian: random phase noise keeps the exemplar's power spectrum,
#: hence its gradient energy, but its gradients are Gaussian, so their mean magnitude is
#: sqrt(pi)/2 = 0.89 of their RMS where a structured exemplar's is much less (0.59 on brick): its
#: mean-|gradient| sharpness ratio is 1.5 on brick at any size, tileable or not, by its model.
#: Its sharpness is checked as gradient energy (docs/tiling.md, "How it is tested").
GAUSSIAN_GRADIENTS = {"random_phase"}
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


#: on a torus, no line of quilting's source map (the wrap included) may change source along more
#: than this share of its length (the pixel methods copy short runs: a plain Wei-Levoy output
#: has lines broken along 0.78-0.90): a block joined to its neighbour along a straight edge breaks
#: the whole line (1.0, the last block pasted into the first without the every-side cut),
#: quilting's minimum-error cuts break at most 0.47 of any line on brick at 128 and 256
STRAIGHT_JOIN_LIMIT = 0.75


def straight_join(source_map: np.ndarray) -> float:
    """The largest share of a line of the torus (between two neighbouring columns or rows,
    the wrap included) along which the source map is not the exemplar's next pixel."""
    source = np.asarray(source_map, dtype=np.int64)
    across_columns = np.any(np.roll(source, -1, axis=1) != source + [0, 1], axis=-1)
    across_rows = np.any(np.roll(source, -1, axis=0) != source + [1, 0], axis=-1)
    return float(max(across_columns.mean(axis=0).max(), across_rows.mean(axis=1).max()))


def wrapped_join_offsets(model, size: int) -> list[int]:
    """Offsets (as :func:`line_spikes` counts them) of the line where the last block of a row
    (column) of the LG family's torus layout ends inside the first block (``docs/tiling.md``,
    "On a torus"); none for the other methods, whose layouts differ per scale or which have
    an exact source map (:func:`straight_join`)."""
    if model.name not in ("lg", "clg", "rclg"):
        return []
    from texsyn.drivers.raster import torus_positions
    from texsyn.methods.single_scale_gaussian import overlap_pixels, torus_free

    n = model.patch_size
    step = n - overlap_pixels(model.overlap, n, "overlap", warn=False)
    corners = torus_positions(size, n, step, free=torus_free(n))
    return [int(corners[-1] + n - size)]  # the line between that column (row) and the one before


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
        if model.tiling_for((size, size)) == "torus":
            # no band; the lines at the wrap, and the line where the last block of each row
            # (column) ends inside the first, are no spikier than every line away from them (a
            # draw squeezed between two given sides measured 3-4x its neighbours at the wrap, a
            # straight join of the last block into the first 3.2-6.8x; the lines' own spikes
            # reach 1.5-1.9, block joins up to 2.0)
            offsets, spikes = line_spikes(result.image)
            at_wrap = [-1, 0, *wrapped_join_offsets(model, size)]
            apart = np.abs(offsets[:, None] - np.array(at_wrap)[None, :]) % size  # lines repeat every size
            distance = np.minimum(apart, size - apart).min(axis=1)
            farthest = spikes[distance > 8].max()
            for offset in at_wrap:
                spike = spikes[offsets == offset][0]
                assert spike <= farthest, (
                    f"{name} seed {seed}: the line {offset:+d} from the wrap is {spike:.2f}x its neighbours"
                )
            if result.source_map is not None and name != "quilting":  # pixel methods
                across, inside = wrap_coherence(result.source_map)
                assert across >= 0.5 * inside, (
                    f"{name} seed {seed}: sources continue across the wraps {across:.2f}, inside {inside:.2f}"
                )
            if name == "quilting":  # blocks: long runs, broken only along cuts
                broken = straight_join(result.source_map)
                assert broken <= STRAIGHT_JOIN_LIMIT, (
                    f"{name} seed {seed}: a line of the torus is broken along {broken:.0%} of its length"
                )
        elif model.tiling_for((size, size)) == "seam band":  # a periodic output has no band
            for offset in (-half_band, half_band):  # where the band meets the method's pixels
                spike = edge_spike(result.image, offset, 2 * half_band)
                assert spike <= EDGE_SPIKE_LIMIT, (
                    f"{name} seed {seed}: the line {offset:+d} from the seam is {spike:.2f}x its neighbours"
                )
        if result.source_map is not None and model.source_map_exact:
            rows, cols = result.source_map[..., 0], result.source_map[..., 1]
            np.testing.assert_array_equal(result.image, model.source_image[rows, cols].astype(np.float32))
        if sharpness_too:
            check_sharpness(name, result.image, exemplar, f"{name} seed {seed}")


def check_sharpness(name: str, image: np.ndarray, exemplar: np.ndarray, label: str) -> None:
    """The output's sharpness is the exemplar's within 20 %: as gradient energy for every
    method, and as mean gradient magnitude for every method whose gradients are not Gaussian."""
    energy = gradient_energy_ratio(image, exemplar)
    assert 0.8 <= energy <= 1.2, f"{label}: gradient energy ratio {energy:.2f}"
    if name not in GAUSSIAN_GRADIENTS:
        sharpness = sharpness_ratio(image, exemplar)
        assert 0.8 <= sharpness <= 1.2, f"{label}: sharpness ratio {sharpness:.2f}"


@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_every_method_tiles_without_a_seam_and_keeps_its_sharpness(name, brick):
    check_method_tiles(name, brick, 128, seeds=(0,))


def test_random_phase_keeps_the_gradient_energy_with_gaussian_gradients(brick):
    """Why random phase noise is held to gradient energy only: its output has the exemplar's
    gradient energy, and the mean |gradient| of a Gaussian field, sqrt(pi)/2 of its RMS (a
    Rayleigh law), where the brick's gradients are sparse (mean/RMS 0.59)."""
    model = texsyn.make_method("random_phase").fit(brick)
    image = model.sample((128, 128), rng=0, tileable=True)
    assert 0.95 <= gradient_energy_ratio(image, brick) <= 1.1
    assert mean_gradient(image) / rms_gradient(image) == pytest.approx(np.sqrt(np.pi) / 2, abs=0.04)
    assert mean_gradient(brick) / rms_gradient(brick) < 0.7


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_every_method_tiles_at_256_on_two_seeds(name, brick):
    """The issue's figure: 256x256 outputs tiled 2x2, two seeds."""
    check_method_tiles(name, brick, 256, seeds=(0, 1), sharpness_too=False)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(texsyn.METHODS))
def test_sharpness_of_a_tileable_256_output_is_the_exemplars(name, brick):
    model = texsyn.make_method(name, **FAST.get(name, {})).fit(brick)
    for seed in (0, 1):
        check_sharpness(name, model.sample((256, 256), rng=seed, tileable=True), brick, f"{name} seed {seed}")


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


def test_grouplets_and_sparse_are_periodic_where_their_canvas_is(brick):
    """Grouplets: periodic at every shape with a flow that wraps; sparse: where its working
    canvas (whole patch grids) is the output itself. There the plain output tiles, and
    ``tileable`` changes nothing."""
    grouplets = texsyn.make_method("grouplets", n_iterations=2).fit(brick)
    assert grouplets.tiling_for((97, 130)) == "periodic"
    assert texsyn.make_method("grouplets", flow="vortex").fit(brick).tiling_for((97, 130)) == "seam band"
    plain = grouplets.sample((97, 130), rng=2)
    np.testing.assert_array_equal(grouplets.sample((97, 130), rng=2, tileable=True), plain)
    assert seam_strength(plain) <= SEAM_LIMIT
    sparse = texsyn.make_method("sparse", **FAST["sparse"]).fit(brick)
    assert sparse.tiling_for((144, 168)) == "periodic" and sparse.tiling_for((128, 128)) == "seam band"
    plain = sparse.sample((144, 168), rng=0)
    np.testing.assert_array_equal(sparse.sample((144, 168), rng=0, tileable=True), plain)
    assert seam_strength(plain) <= SEAM_LIMIT


# ------------------------------------------------------------------ on a torus
#: the methods that search and stitch on the output's torus themselves (docs/tiling.md), and
#: the module whose fill_blocks lays their blocks
TORUS_METHODS = {
    "quilting": ["texsyn.methods.quilting"],
    "lg": ["texsyn.methods.single_scale_gaussian"],
    "clg": ["texsyn.methods.single_scale_gaussian"],
    "rclg": ["texsyn.methods.single_scale_gaussian"],
    "mslg": ["texsyn.methods.single_scale_gaussian", "texsyn.methods.multiscale_gaussian"],
}


def test_quilting_on_a_torus_cuts_across_the_wraps(brick):
    """No band: the last block column and row overlap the first ones across the wraps and are
    joined to them along cuts, so across each wrap most neighbours are exemplar neighbours
    (inside a block) and the places where they are not are not one straight line."""
    model = texsyn.make_method("quilting").fit(brick)
    assert model.tiling_for((100, 90)) == "torus" and model.tiling_for((30, 128)) == "seam band"
    tiled = model.sample_with_map((100, 90), rng=3, tileable=True)
    source = tiled.source_map
    np.testing.assert_array_equal(tiled.image, brick[source[..., 0], source[..., 1]])
    across_columns = np.all(source[:, 0] == source[:, -1] + [0, 1], axis=-1)
    across_rows = np.all(source[0] == source[-1] + [1, 0], axis=-1)
    assert 0.5 < across_columns.mean() < 1 and 0.5 < across_rows.mean() < 1


def test_quilting_fits_a_torus_at_the_sides_its_docs_say():
    """docs/tiling.md: every side at least patch_size + 2, patch_size + 1 for an odd patch_size,
    which must be 5 or at least 7."""
    for patch_size in [5, *range(7, 49)]:
        model = texsyn.make_method("quilting", patch_size=patch_size)
        least = patch_size + 1 + (patch_size % 2 == 0)
        for side in range(patch_size - 1, 3 * patch_size):
            assert model.torus_for((side, 3 * patch_size)) == (side >= least), (patch_size, side)
    assert not texsyn.make_method("quilting", patch_size=6).torus_for((11, 18))


@pytest.mark.parametrize("name", sorted(TORUS_METHODS))
def test_the_block_methods_tile_on_a_torus_not_with_a_band(name, brick):
    model = texsyn.make_method(name).fit(brick)
    assert model.tiling_for((128, 128)) == model.tiling_for((256, 256)) == "torus"
    if name != "quilting":  # the pixels across the wraps are the model's draws, not copied blocks
        raw = texsyn.make_method(name, histogram="none").fit(brick)  # matched values are the brick's
        image = raw.sample((96, 80), rng=4, tileable=True)
        across = np.concatenate([image[:4], image[-4:], image[:, :4].T, image[:, -4:].T], axis=None)
        assert np.isin(across, brick).mean() < 0.5


def _blocks_without_wrap(canvas, rows, cols, size, choose, paste, *, torus=False, **options):
    """The sabotage: the same blocks laid on a plane (nothing wraps), cropped to the output."""
    from texsyn.drivers.raster import fill_blocks

    plane = np.zeros((int(rows[-1]) + size, int(cols[-1]) + size, canvas.shape[2]))
    done = fill_blocks(plane, rows, cols, size, choose, paste, **options)
    canvas[...] = plane[: canvas.shape[0], : canvas.shape[1]]
    return done[: canvas.shape[0], : canvas.shape[1]]


@pytest.mark.parametrize("name", ["quilting", "clg", "mslg"])
def test_the_seam_check_fails_a_torus_method_whose_blocks_do_not_wrap(name, brick, monkeypatch):
    for module in TORUS_METHODS[name]:
        monkeypatch.setattr(f"{module}.fill_blocks", _blocks_without_wrap)
    model = texsyn.make_method(name).fit(brick)
    assert seam_strength(model.sample((128, 128), rng=0, tileable=True)) > SEAM_LIMIT  # the check fails


def _leading_known_only(block):
    """The block as a plane's raster loop would see it: only its known strips on the left and
    at the top, the wrapped ones on the right and at the bottom forgotten."""
    from texsyn.drivers.raster import Block
    from texsyn.ops.seams import leading_known

    left, top = leading_known(block.known)
    known = np.zeros_like(block.known)
    known[:, :left], known[:top] = block.known[:, :left], block.known[:top]
    return Block(block.row, block.col, block.values, known)


@pytest.mark.parametrize("name", ["quilting", "lg"])
def test_the_torus_check_fails_blocks_pasted_into_the_first_without_the_every_side_cut(
    name, brick, monkeypatch
):
    """The last block of a row overwrites the first block's strip along a straight edge: the
    source map breaks along a whole line (quilting), the line there spikes 1.9-5.5x (LG)."""
    import texsyn.methods.quilting as quilting
    import texsyn.methods.single_scale_gaussian as single_scale_gaussian
    from texsyn.ops.seams import cut_mask

    monkeypatch.setattr(quilting, "cut_mask", lambda old, new, known, every_side: cut_mask(old, new, known))
    monkeypatch.setitem(single_scale_gaussian.PASTE_TORUS, "quilt", single_scale_gaussian.PASTE["quilt"])
    with pytest.raises(AssertionError, match="broken along|from the wrap"):
        check_method_tiles(name, brick, 128, seeds=(0,), sharpness_too=False)


@pytest.mark.parametrize("name", ["clg", "rclg"])
def test_the_torus_check_fails_a_draw_blind_to_the_wrapped_pixels(name, brick, monkeypatch):
    """Conditioned on the left and top strips only, the last block's draw meets the first
    block along a straight line that spikes 5-7x its neighbours."""
    import texsyn.methods.single_scale_gaussian as single_scale_gaussian

    drawn = single_scale_gaussian.conditional_patch
    monkeypatch.setattr(
        single_scale_gaussian,
        "conditional_patch",
        lambda block, *args, **options: drawn(_leading_known_only(block), *args, **options),
    )
    with pytest.raises(AssertionError, match="from the wrap"):
        check_method_tiles(name, brick, 128, seeds=(0,), sharpness_too=False)


# ------------------------------------------------------------------ the quilted seam band
def test_the_seam_band_keeps_the_methods_pixels_and_copies_exemplar_blocks_across_the_wraps(brick):
    model = texsyn.make_method("quilting", patch_size=24).fit(brick)
    plain = model.sample_with_map((100, 90), rng=5)  # quilting tiles on a torus: its band directly
    image, source = quilted_seam_band(plain.image, plain.source_map, brick, np.random.default_rng(5))
    tiled = texsyn.SynthesisResult(image=image, source_map=source)
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


@pytest.mark.parametrize("name", ["sparse", "grouplets", "cwt"])
def test_the_seam_band_of_a_method_that_does_not_copy_is_copied_not_blended(name, brick):
    """No cross-fade, no blur: outside the band the method's pixels, inside it exemplar values
    (the 8-bit brick's levels, which the LG and sparse outputs' floats almost never hit).
    The seam and sharpness statistics alone pass a 16-pixel cross-fade of these methods' wraps."""
    settings = {"grouplets": {"flow": "vortex"}}.get(name, FAST.get(name, {}))  # a flow that does not wrap
    model = texsyn.make_method(name, **settings).fit(brick)
    assert model.tiling_for((96, 80)) == "seam band"
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
    out = texsyn.synthesize(tiny, "lg", (24, 30), rng=1, tileable=True, patch_size=10)
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


# ------------------------------------------------------------------ on a torus: efros_leung
def wrap_coherence(source_map: np.ndarray) -> tuple[float, float]:
    """How often a pixel's right (lower) neighbour across the wrap, and inside the output,
    comes from the exemplar pixel right of (below) its own: the growth's copied runs."""
    across = np.mean(
        [
            np.all(source_map[:, 0] == source_map[:, -1] + [0, 1], axis=-1).mean(),
            np.all(source_map[0] == source_map[-1] + [1, 0], axis=-1).mean(),
        ]
    )
    inside = np.mean(
        [
            np.all(source_map[:, 1:] == source_map[:, :-1] + [0, 1], axis=-1).mean(),
            np.all(source_map[1:] == source_map[:-1] + [1, 0], axis=-1).mean(),
        ]
    )
    return float(across), float(inside)


def middle_line_spikes(image: np.ndarray) -> tuple[float, float]:
    """The spikiest of the three lines around the middle row and column, where the growing
    fronts of a torus growth meet (half a tile from the seed at the corner), and the spikiest
    line farther than 8 pixels from them: :func:`line_spikes` of the output rolled by half."""
    h, w = image.shape[:2]
    offsets, spikes = line_spikes(np.roll(image, (h // 2, w // 2), axis=(0, 1)))
    return float(spikes[np.abs(offsets) <= 1].max()), float(spikes[np.abs(offsets) > 8].max())


def check_torus_tiles(model, exemplar: np.ndarray, size: int, seeds, sharpness_too: bool = True) -> None:
    """A torus output: seams, where the fronts meet, the exact source map, its copied runs
    across the wraps, sharpness."""
    assert model.tiling_for((size, size)) == "torus"
    for seed in seeds:
        result = model.sample_with_map((size, size), rng=seed, tileable=True)
        strength = seam_strength(result.image)
        assert strength <= SEAM_LIMIT, f"seed {seed}: seams {strength:.2f} x the interior's 90th percentile"
        # the fronts' join, before it was sampled again: 1.3-4.7x its neighbours on brick,
        # above the output's spikiest other line on 8 of 16 outputs (exact and approximate
        # search, 128 and 256, seeds 0-3); sampled again, 0.99-1.66x, below it on all 16
        # (docs/tiling.md, "On a torus (efros_leung)")
        middle, farthest = middle_line_spikes(result.image)
        assert middle <= farthest, (
            f"seed {seed}: where the fronts meet {middle:.2f}x, elsewhere {farthest:.2f}x"
        )
        rows, cols = result.source_map[..., 0], result.source_map[..., 1]
        np.testing.assert_array_equal(result.image, exemplar[rows, cols])
        across, inside = wrap_coherence(result.source_map)
        assert across >= 0.5 * inside, f"seed {seed}: runs across the wraps {across:.2f}, inside {inside:.2f}"
        if sharpness_too:
            sharpness = sharpness_ratio(result.image, exemplar)
            assert 0.8 <= sharpness <= 1.2, f"seed {seed}: sharpness ratio {sharpness:.2f}"


@pytest.mark.parametrize("search", ["exact", "approximate"])
def test_efros_leung_grows_on_a_torus(search, brick):
    model = texsyn.make_method("efros_leung", search=search).fit(brick)
    assert model.tiling_for((128, 128)) == model.tiling_for((256, 256)) == "torus"
    assert model.tiling_for((128, 10)) == "seam band"  # narrower than a window
    assert texsyn.make_method("cwt").fit(brick).tiling_for((128, 128)) == "seam band"
    check_torus_tiles(model, brick, 128, seeds=(0,))
    if search == "approximate":  # what a plain output has across its edges
        assert wrap_coherence(model.sample_with_map((128, 128), rng=0).source_map)[0] < 0.05


def test_efros_leung_on_a_torus_is_the_same_bytes_twice_and_not_the_plain_output(brick):
    model = texsyn.make_method("efros_leung", window_size=7).fit(brick)
    first = model.sample_with_map((40, 48), rng=5, tileable=True)
    again = model.sample_with_map((40, 48), rng=5, tileable=True)
    np.testing.assert_array_equal(first.image, again.image)
    np.testing.assert_array_equal(first.source_map, again.source_map)
    assert not np.array_equal(first.image, model.sample((40, 48), rng=5))


@pytest.mark.parametrize("search", [pytest.param("exact", marks=pytest.mark.slow), "approximate"])
def test_efros_leung_with_the_wrap_ignored_fails_the_seam_check(search, brick, monkeypatch):
    """Sabotage: the growth on the torus, but every pixel written only in place (no copy
    across the wraps) and the compiled loops told nothing wraps: the windows and the
    neighbours stop at the output's edges. The seam check must then fail."""

    def write_in_place(self, rows, cols, values):
        self.values[rows + self.r, cols + self.r] = values
        self.filled[rows + self.r, cols + self.r] = True

    def no_wrap(method):
        def call(*args, **kwargs):
            return method(*args, **{**kwargs, "wrap": False})

        return call

    monkeypatch.setattr(raster._Canvas, "write", write_in_place)
    monkeypatch.setattr(NonParametricSampler, "fill_screened", no_wrap(NonParametricSampler.fill_screened))
    monkeypatch.setattr(CoherentWindows, "grow_pass", no_wrap(CoherentWindows.grow_pass))
    model = texsyn.make_method("efros_leung", search=search).fit(brick)
    with pytest.raises(AssertionError, match="seams"):
        check_torus_tiles(model, brick, 128, seeds=(0,))


@pytest.mark.slow
@pytest.mark.parametrize("search", ["exact", "approximate"])
def test_efros_leung_tiles_on_a_torus_at_256_on_two_seeds(search, brick):
    """The issue's figures on two seeds, where the fronts meet too; the join once added
    gradient (exact search, seed 1: sharpness 1.21, its middle lines 1.56x where the
    output's spikiest other line is 1.46x)."""
    model = texsyn.make_method("efros_leung", search=search).fit(brick)
    check_torus_tiles(model, brick, 256, seeds=(0, 1))


# ------------------------------------------------------------------ Wei-Levoy on a torus
def wei_levoy_wraps(model, seed: int) -> bool:
    """The 2x2 seam check of a tileable 128x128 Wei-Levoy output, and its sources across the
    wraps continuing exemplar neighbours at least half as often as inside (0.40-0.58 against
    0.42-0.63 on seeds 0-3; 0.00-0.10 with the wrap ignored, where the gradient statistic
    alone still passes some seeds: 0.82 on seed 0 with clamped neighbourhoods)."""
    result = model.sample_with_map((128, 128), rng=seed, tileable=True)
    seams, inner = wrap_coherence(result.source_map)
    return seam_strength(result.image) <= SEAM_LIMIT and seams >= 0.5 * inner


def test_wei_levoy_synthesises_on_a_torus(brick):
    model = texsyn.make_method("wei_levoy").fit(brick)
    assert model.tiling_for((128, 128)) == model.tiling_for((256, 256)) == "torus"
    assert model.tiling_for((100, 128)) == "seam band"  # a level that does not halve exactly
    assert texsyn.make_method("wei_levoy", window=21).fit(brick).tiling_for((128, 128)) == "seam band"
    # the output's seams and its sources across the wraps: check_method_tiles, above


def test_wei_levoy_with_the_wrap_ignored_fails_the_check(brick, monkeypatch):
    """Sabotage: neighbourhoods clamped at the output's edges instead of wrapped."""
    import texsyn.methods.wei_levoy as wl

    def clamped(image, rows, cols, offsets, out, start=0):
        h, w = image.shape[:2]
        rr = np.clip(rows[:, None] + offsets[None, :, 0], 0, h - 1)
        cc = np.clip(cols[:, None] + offsets[None, :, 1], 0, w - 1)
        values = image[rr, cc].reshape(len(rows), -1)
        out[:, start : start + values.shape[1]] = values

    monkeypatch.setattr(wl, "gather_wrapped", clamped)
    assert not wei_levoy_wraps(texsyn.make_method("wei_levoy").fit(brick), seed=0)


@pytest.mark.slow
def test_wei_levoy_without_the_wrap_pass_fails_the_check(brick, monkeypatch):
    """Sabotage: the raster pass on the torus only, no second pass across the wraps (the first
    rows and columns keep what they drew against the initial noise): seams 1.20 on seed 0,
    sources continuing each other across the wraps 0.10 against 0.50 inside."""
    import texsyn.methods.wei_levoy as wl

    monkeypatch.setattr(wl.WeiLevoy, "_wrap_pass", lambda self, *args: None)
    model = texsyn.make_method("wei_levoy").fit(brick)
    assert not wei_levoy_wraps(model, seed=0)
    with pytest.raises(AssertionError, match="seams"):
        check_method_tiles("wei_levoy", brick, 128, seeds=(0,), sharpness_too=False)
