import os
import warnings

import numpy as np
import pytest
from PIL import Image

from texsyn.io import ImageReadError, read_image, write_array, write_image


@pytest.fixture
def rgb8():
    return (np.random.default_rng(0).random((12, 10, 3)) * 255).astype(np.uint8)


@pytest.mark.parametrize("ext", ["png", "bmp", "ppm", "tif", "webp"])
def test_lossless_colour_formats_round_trip(tmp_path, rgb8, ext):
    path = tmp_path / f"x.{ext}"
    kwargs = {"lossless": True} if ext == "webp" else {}
    Image.fromarray(rgb8).save(path, **kwargs)
    img = read_image(path)
    assert img.dtype == np.float32 and img.shape == (12, 10, 3)
    np.testing.assert_array_equal(np.rint(img * 255).astype(np.uint8), rgb8)


def test_jpeg_and_gif_palette(tmp_path, rgb8):
    Image.fromarray(rgb8).save(tmp_path / "x.jpg")
    assert read_image(tmp_path / "x.jpg").shape == (12, 10, 3)
    Image.fromarray(rgb8).convert("P").save(tmp_path / "x.gif")
    Image.fromarray(rgb8).convert("P").save(tmp_path / "p.png")
    for name in ("x.gif", "p.png"):
        img = read_image(tmp_path / name)
        assert img.shape == (12, 10, 3) and 0 <= img.min() and img.max() <= 1


@pytest.mark.parametrize("ext", ["png", "pgm", "tif"])
def test_sixteen_bit_grey(tmp_path, ext):
    data = (np.random.default_rng(1).random((9, 11)) * 65535).astype(np.uint16)
    data[0, 0] = 3  # a dark pixel: the scale must come from the bit depth, not the maximum
    Image.fromarray(data).save(tmp_path / f"g.{ext}")
    img = read_image(tmp_path / f"g.{ext}")
    assert img.shape == (9, 11)
    np.testing.assert_allclose(img, data / 65535.0, atol=1e-7)


def test_sixteen_bit_colour_ppm_and_png(tmp_path):
    data = (np.random.default_rng(4).random((5, 6, 3)) * 65535).astype(np.uint16)
    (tmp_path / "c.ppm").write_bytes(b"P6\n# comment\n6 5\n65535\n" + data.astype(">u2").tobytes())
    np.testing.assert_allclose(read_image(tmp_path / "c.ppm"), data / 65535.0, atol=1e-7)
    write_image(tmp_path / "c.png", data / 65535.0, bit_depth=16)
    np.testing.assert_allclose(read_image(tmp_path / "c.png"), data / 65535.0, atol=1e-7)
    twelve = (data[..., 0] // 16).astype(">u2")
    (tmp_path / "g.pgm").write_bytes(b"P5 6 5 4095\n" + twelve.tobytes())
    np.testing.assert_allclose(read_image(tmp_path / "g.pgm"), twelve / 4095.0, atol=1e-6)


def test_eight_bit_grey_pgm(tmp_path):
    data = (np.random.default_rng(2).random((9, 11)) * 255).astype(np.uint8)
    Image.fromarray(data).save(tmp_path / "g.pgm")
    np.testing.assert_allclose(read_image(tmp_path / "g.pgm"), data / 255.0, atol=1e-7)


def test_alpha_is_dropped_with_a_warning_only_when_transparent(tmp_path, rgb8):
    rgba = np.dstack([rgb8, np.full(rgb8.shape[:2], 255, np.uint8)])
    Image.fromarray(rgba).save(tmp_path / "opaque.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_image(tmp_path / "opaque.png").shape == (12, 10, 3)
    rgba[0, 0, 3] = 10
    Image.fromarray(rgba).save(tmp_path / "t.png")
    with pytest.warns(UserWarning, match="alpha"):
        assert read_image(tmp_path / "t.png").shape == (12, 10, 3)
    assert read_image(tmp_path / "t.png", keep_alpha=True).shape == (12, 10, 4)


def test_unreadable_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_image(tmp_path / "missing.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ImageReadError, match="cannot read"):
        read_image(tmp_path / "text.png")
    good = tmp_path / "good.png"
    Image.fromarray(np.zeros((64, 64, 3), np.uint8) + 7).save(good)
    (tmp_path / "trunc.png").write_bytes(good.read_bytes()[:60])
    with pytest.raises(ImageReadError):
        read_image(tmp_path / "trunc.png")
    with pytest.raises(ImageReadError, match="folder"):
        read_image(tmp_path)


@pytest.mark.parametrize("ext, depth", [("png", 8), ("png", 16), ("tif", 8), ("tif", 16), ("jpg", 8)])
def test_write_then_read(tmp_path, ext, depth):
    yy, xx = np.mgrid[:10, :14]
    img = np.random.default_rng(3).random((10, 14, 3)).astype(np.float32)
    if ext == "jpg":  # lossy: a smooth image
        img = np.dstack([0.5 + 0.3 * np.sin(xx / 4 + c) * np.cos(yy / 5) for c in range(3)]).astype(np.float32)
    path = write_image(tmp_path / f"o.{ext}", img, bit_depth=depth)
    back = read_image(path)
    tol = 0.08 if ext == "jpg" else (0.5 / 255 if depth == 8 else 0.5 / 65535) + 1e-7
    np.testing.assert_allclose(back, img, atol=tol)
    assert [p.name for p in tmp_path.iterdir()] == [f"o.{ext}"]  # no temporary file left
    assert oct(os.stat(path).st_mode & 0o777) != "0o600"


def test_write_refuses_bad_requests_and_leaves_existing_files(tmp_path):
    target = tmp_path / "keep.png"
    target.write_bytes(b"old")
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        write_image(target, np.full((4, 4), 2.0))
    assert target.read_bytes() == b"old"
    with pytest.raises(ValueError, match="16-bit"):
        write_image(tmp_path / "x.jpg", np.zeros((4, 4)), bit_depth=16)
    with pytest.raises(ValueError, match="unsupported file type"):
        write_image(tmp_path / "x.xyz", np.zeros((4, 4)))
    with pytest.raises(FileNotFoundError, match="does not exist"):
        write_image(tmp_path / "no" / "x.png", np.zeros((4, 4)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_write_array(tmp_path):
    arr = np.arange(12).reshape(2, 3, 2)
    np.testing.assert_array_equal(np.load(write_array(tmp_path / "a.npy", arr)), arr)
