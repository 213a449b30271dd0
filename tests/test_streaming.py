"""Outputs of any size in bounded memory: bands of rows from the method to the file (issue 20).

``TextureSynthesizer.sample_rows`` yields an output top to bottom; quilting, and LG, CLG and
RCLG with ``histogram='none'``, hold one row of blocks, and the command line streams the rows
to PNG, TIFF and ``.npy`` files (``docs/performance.md``, "Any size in bounded memory").
"""

from __future__ import annotations

import subprocess
import sys
import tracemalloc

import imageio.v3 as iio
import numpy as np
import pytest

import texsyn
from texsyn.errors import OutputWriteError
from texsyn.io import OutputSet, read_image, write_image
from texsyn.io.streaming import PngRows, filter_rows


@pytest.fixture(scope="module")
def exemplar():
    return texsyn.data.exemplar("brick", size=48)


@pytest.fixture(scope="module")
def colour():
    return np.stack([texsyn.data.exemplar(name, size=48) for name in ("grass", "gravel", "brick")], axis=-1)


@pytest.mark.parametrize(
    "params,shape",
    [
        ({"patch_size": 12}, (64, 80)),
        ({"patch_size": 10, "overlap": 4}, (37, 101)),
        ({"patch_size": 16, "boundary_cut": False}, (16, 40)),
    ],
)
def test_quilting_bands_put_together_are_the_sample(exemplar, params, shape):
    model = texsyn.make_method("quilting", **params).fit(exemplar)
    bands = list(model.sample_rows(shape, rng=5))
    whole = model.sample_with_map(shape, rng=5)
    assert [b.top for b in bands] == list(np.cumsum([0] + [b.image.shape[0] for b in bands[:-1]]))
    assert max(b.image.shape[0] for b in bands) <= model.patch_size
    assert np.array_equal(np.concatenate([b.image for b in bands]), whole.image)
    assert np.array_equal(np.concatenate([b.source_map for b in bands]), whole.source_map)


@pytest.mark.parametrize(
    "name,params,shape,grey",
    [
        ("lg", {"patch_size": 12}, (64, 80), False),
        ("lg", {"patch_size": 12, "seam": "average", "mode": "mean"}, (70, 33), True),
        ("clg", {"patch_size": 10, "overlap": 4}, (37, 101), False),
        ("clg", {"patch_size": 9, "seed_patch": "copy", "looseness": 0.0}, (41, 30), True),
        ("rclg", {"patch_size": 16, "seed_patch": "copy", "seam": "quilt"}, (16, 40), False),
        ("rclg", {"patch_size": 9, "overlap": 3}, (50, 50), True),
    ],
)
def test_local_gaussian_bands_put_together_are_the_sample(exemplar, colour, name, params, shape, grey):
    """LG, CLG and RCLG stream Algorithm 2 one row of blocks at a time, with ``histogram='none'``."""
    model = texsyn.make_method(name, histogram="none", **params).fit(exemplar if grey else colour)
    assert model.streams_rows
    stages, streamed = [], []
    bands = list(model.sample_rows(shape, rng=5, callback=lambda p: streamed.append((p.done, p.total))))
    whole = model.sample(shape, rng=5, callback=lambda p: stages.append((p.done, p.total)))
    assert [b.top for b in bands] == list(np.cumsum([0] + [b.image.shape[0] for b in bands[:-1]]))
    assert max(b.image.shape[0] for b in bands) <= model.patch_size
    assert all(b.source_map is None for b in bands) and streamed == stages
    assert np.array_equal(np.concatenate([b.image for b in bands]), whole)


def test_local_gaussian_with_histogram_matching_does_not_stream(colour):
    """``histogram='match'`` ranks every value among all the others: one band, the sample's memory."""
    model = texsyn.make_method("clg", patch_size=12).fit(colour)
    assert not model.streams_rows and not type(model).streams_rows
    (band,) = model.sample_rows((40, 30), rng=2)
    assert band.top == 0 and np.array_equal(band.image, model.sample((40, 30), rng=2))
    assert model.estimate_memory(colour.shape, (900, 900), streaming=True) == model.estimate_memory(
        colour.shape, (900, 900)
    )


def test_local_gaussian_streams_in_a_window_whatever_the_height(colour):
    """Traced peak of a tall output: a small fraction of its float canvas, close to a short one's.

    (The peaks differ by the cyclic garbage the collector has not freed yet, not by rows.)
    """
    model = texsyn.make_method("clg", patch_size=24, overlap=4, n_neighbors=8, histogram="none").fit(colour)
    peaks = []
    for shape in ((600, 64), (6000, 64)):
        tracemalloc.start()
        rows = sum(band.image.shape[0] for band in model.sample_rows(shape, rng=0))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert rows == shape[0]
    canvas = 6000 * 64 * 3 * 8.0
    assert peaks[1] < canvas / 8
    assert peaks[1] < peaks[0] + canvas / 16
    streamed = model.estimate_memory(colour.shape, (6000, 64), streaming=True)
    assert streamed == model.estimate_memory(colour.shape, (24, 64), streaming=True)
    assert streamed < model.estimate_memory(colour.shape, (6000, 64)) / 3
    big = texsyn.make_method("lg", histogram="none")
    assert big.estimate_memory((128, 128, 3), (8192, 8192), streaming=True) < 100 * 2**20


def test_a_method_that_does_not_stream_yields_its_sample_as_one_band(exemplar):
    model = texsyn.make_method("random_phase").fit(exemplar)
    (band,) = model.sample_rows((40, 30), rng=2)
    assert band.top == 0 and np.array_equal(band.image, model.sample((40, 30), rng=2))


def test_quilting_streams_in_a_window_whatever_the_height(exemplar):
    """Traced peak of a tall output stays a small fraction of its float canvas."""
    model = texsyn.make_method("quilting", patch_size=16).fit(exemplar)
    shape = (3000, 96)
    tracemalloc.start()
    rows = sum(band.image.shape[0] for band in model.sample_rows(shape, rng=0))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    canvas = shape[0] * shape[1] * (3 + 2) * 8.0
    assert rows == shape[0]
    assert peak < canvas / 8
    assert model.estimate_memory(exemplar.shape, shape, streaming=True) == model.estimate_memory(
        exemplar.shape, (16, 96), streaming=True
    )
    assert model.estimate_memory(exemplar.shape, (8192, 8192), streaming=True) < 100 * 2**20


@pytest.mark.parametrize("suffix,depth", [(".png", 8), (".png", 16), (".tif", 8), (".tif", 16), (".jpg", 8)])
def test_synth_streams_the_same_pixels_as_the_api(tmp_path, exemplar, suffix, depth):
    source = tmp_path / "ex.png"
    write_image(source, exemplar)
    out, npy, pic = tmp_path / f"out{suffix}", tmp_path / "map.npy", tmp_path / "map.png"
    args = [
        "synth",
        str(source),
        "-m",
        "quilting",
        "-p",
        "patch_size=12",
        "--size",
        "50x70",
        "--seed",
        "9",
        "-q",
    ]
    for target, extra in (
        (out, ["--source-map", str(npy)]),
        (tmp_path / "again.png", ["--source-map", str(pic)]),
    ):
        run = [*args, "-o", str(target), "--bit-depth", str(depth if target == out else 8), *extra]
        done = subprocess.run([sys.executable, "-m", "texsyn.cli", *run], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    expected = (
        texsyn.make_method("quilting", patch_size=12).fit(read_image(source)).sample_with_map((70, 50), rng=9)
    )
    got = read_image(out)
    if suffix == ".jpg":
        assert np.abs(got - expected.image).mean() < 0.05
    else:
        assert np.abs(got - expected.image).max() <= 0.5 / (2**depth - 1) + 1e-6
    assert np.array_equal(np.load(npy), expected.source_map)
    colours = iio.imread(pic)
    assert colours.shape == (70, 50, 3) and colours[..., 2].min() == colours[..., 2].max() == 128


def test_png_rows_use_every_filter_and_decode_to_the_input(tmp_path):
    rng = np.random.default_rng(1)
    image = np.zeros((40, 33, 3))
    image[:10] = rng.random((10, 33, 3))  # noise: no filter helps much
    image[10:20] = np.linspace(0, 1, 33)[None, :, None]  # ramps along rows (Sub)
    image[20:30] = image[19]  # repeated rows (Up)
    image[30:] = np.add.outer(np.arange(10), np.arange(33))[..., None] / 50.0  # planes (Paeth, Average)
    path = tmp_path / "f.png"
    writer = PngRows(path, image.shape, 8)
    for start in range(0, 40, 7):
        writer.write(image[start : start + 7])
    writer.close()
    assert np.array_equal(iio.imread(path), np.rint(image * 255).astype(np.uint8))
    raw = np.rint(image * 255).astype(np.uint8).reshape(40, -1)
    kinds = set(filter_rows(raw, np.zeros(raw.shape[1], np.uint8), 3)[:, 0])
    assert {1, 2} <= kinds and len(kinds) >= 3


def test_a_failure_while_streaming_leaves_no_file(tmp_path):
    target, other = tmp_path / "a.png", tmp_path / "b.npy"
    outputs = OutputSet()
    outputs.claim(target)
    outputs.claim(other, formats={".npy": (8,)})
    with pytest.raises(KeyboardInterrupt):
        with outputs:
            rows = outputs.open_rows(target, (20, 10, 3))
            rows.write(np.zeros((5, 10, 3)))
            outputs.open_rows(other, (20, 10, 2), dtype=np.int32).write(np.zeros((5, 10, 2)))
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    outputs = OutputSet()
    outputs.claim(target)
    with pytest.raises(RuntimeError, match="not closed"):
        with outputs:
            outputs.open_rows(target, (20, 10)).write(np.zeros((5, 10)))
    assert list(tmp_path.iterdir()) == []


def test_a_write_error_while_streaming_names_the_output(tmp_path, monkeypatch):
    target = tmp_path / "a.png"
    outputs = OutputSet()
    outputs.claim(target)

    def full(self, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(PngRows, "_write", full)
    with pytest.raises(OutputWriteError, match="a.png"):
        with outputs:
            outputs.open_rows(target, (20, 10)).write(np.zeros((5, 10)))
    assert list(tmp_path.iterdir()) == []


def test_prepare_exemplar_crops_the_centre_then_shrinks():
    from texsyn.ops.canvas import prepare_exemplar, prepared_exemplar_shape

    image = np.zeros((300, 400, 3))
    image[100:200, 100:300] = 1.0
    centre = prepare_exemplar(image, crop=(100, 200))
    assert centre.shape == (100, 200, 3) and centre.min() == 1.0
    small = prepare_exemplar(image, max_side=100)
    assert small.shape == (75, 100, 3) == prepared_exemplar_shape(image.shape, max_side=100)
    assert abs(small.mean() - image.mean()) < 0.01  # area averaging keeps the mean
    assert prepare_exemplar(image, max_side=400) is image


def test_synth_shrinks_a_photo_sized_exemplar_before_the_memory_check(tmp_path):
    source = tmp_path / "photo.png"
    write_image(source, np.tile(texsyn.data.exemplar("gravel", size=64), (16, 20))[:1000, :1200])
    out = tmp_path / "o.png"
    args = [
        sys.executable,
        "-m",
        "texsyn.cli",
        "synth",
        str(source),
        "-m",
        "heeger_bergen",
        "--size",
        "64x64",
    ]
    env = {**__import__("os").environ, "TEXSYN_MEMORY_LIMIT": "60M"}
    refused = subprocess.run([*args, "-o", str(out)], capture_output=True, text=True, env=env)
    assert refused.returncode == 2 and "memory" in refused.stderr and not out.exists()
    shrunk = [*args, "--exemplar-crop", "800x600", "--exemplar-max-side", "128", "-q", "-o", str(out)]
    done = subprocess.run(shrunk, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    options = __import__("json").loads((tmp_path / "o.png.json").read_text())["options"]
    assert options["exemplar_crop"] == [800, 600] and options["exemplar_max_side"] == 128


@pytest.mark.parametrize("histogram,streams", [("none", True), ("match", False)])
def test_synth_streams_the_local_gaussian_family_only_without_histogram_matching(
    tmp_path, monkeypatch, exemplar, histogram, streams
):
    """The command asks the configured synthesizer, not its class, whether it streams."""
    from texsyn.cli import main, synthesis

    calls = []
    original = synthesis.stream_bands
    monkeypatch.setattr(synthesis, "stream_bands", lambda *a, **k: calls.append(1) or original(*a, **k))
    source, out = tmp_path / "ex.png", tmp_path / "out.png"
    write_image(source, exemplar)
    args = ["synth", str(source), "-m", "lg", "-p", f"histogram={histogram}", "-p", "patch_size=8"]
    code = main([*args, "--size", "40x30", "--seed", "4", "-q", "-o", str(out), "--bit-depth", "16"])
    assert code == 0
    assert bool(calls) is streams
    model = texsyn.make_method("lg", histogram=histogram, patch_size=8)
    expected = model.fit(read_image(source)).sample((30, 40), rng=4)
    assert np.abs(read_image(out) - expected).max() <= 0.5 / 65535 + 1e-6
