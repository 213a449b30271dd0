import dataclasses
import os
import warnings

import numpy as np
import pytest
from PIL import Image

from texsyn.io import (
    ImageHeader,
    ImageReadError,
    read_image,
    read_image_header,
    write_array,
    write_image,
)


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
        img = np.dstack([0.5 + 0.3 * np.sin(xx / 4 + c) * np.cos(yy / 5) for c in range(3)]).astype(
            np.float32
        )
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


def test_cmyk_and_grey_jpeg(tmp_path, rgb8):
    Image.fromarray(rgb8).convert("CMYK").save(tmp_path / "c.jpg")
    Image.fromarray(rgb8).convert("L").save(tmp_path / "g.jpg")
    cmyk = read_image(tmp_path / "c.jpg")
    assert cmyk.shape == (12, 10, 3) and cmyk.dtype == np.float32
    np.testing.assert_allclose(cmyk, rgb8 / 255.0, atol=0.2)  # lossy, but the colours survive
    assert read_image(tmp_path / "g.jpg").shape == (12, 10)
    header = read_image_header(tmp_path / "c.jpg")
    assert (header.width, header.height, header.channels, header.format) == (10, 12, 3, "JPEG")


def test_netpbm_family(tmp_path):
    bits = np.random.default_rng(5).random((5, 7)) > 0.5  # True = white
    plain_bits = b"\n".join(b"".join(b"0" if v else b"1" for v in row) for row in bits)
    (tmp_path / "p1.pbm").write_bytes(b"P1\n# a comment\n7 5\n" + plain_bits)
    Image.fromarray(bits).save(tmp_path / "p4.pbm")
    for name in ("p1.pbm", "p4.pbm"):
        np.testing.assert_array_equal(read_image(tmp_path / name), bits.astype(np.float32))
    grey = np.random.default_rng(6).integers(0, 1001, (5, 7))
    (tmp_path / "p2.pgm").write_bytes(
        b"P2 7 5 1000\n" + b"\n".join(b" ".join(b"%d" % v for v in row) for row in grey)
    )
    np.testing.assert_allclose(read_image(tmp_path / "p2.pgm"), grey / 1000.0, atol=1e-7)
    colour = np.random.default_rng(7).integers(0, 256, (5, 7, 3))
    (tmp_path / "p3.ppm").write_bytes(b"P3\n7 5\n255\n" + b" ".join(b"%d" % v for v in colour.ravel()))
    np.testing.assert_allclose(read_image(tmp_path / "p3.ppm"), colour / 255.0, atol=1e-7)
    header = read_image_header(tmp_path / "p2.pgm")
    assert (header.width, header.height, header.channels, header.bit_depth, header.format) == (
        7,
        5,
        1,
        10,
        "PNM",
    )


def test_sixteen_bit_grey_alpha_png_and_colour_tiff(tmp_path):
    import png
    import tifffile

    data = (np.random.default_rng(8).random((6, 5, 2)) * 65535).astype(np.uint16)
    with open(tmp_path / "la.png", "wb") as fh:
        png.Writer(5, 6, greyscale=True, alpha=True, bitdepth=16).write(fh, data.reshape(6, -1).tolist())
    np.testing.assert_allclose(read_image(tmp_path / "la.png", keep_alpha=True), data / 65535.0, atol=1e-7)
    rgb = (np.random.default_rng(9).random((6, 5, 3)) * 65535).astype(np.uint16)
    tifffile.imwrite(tmp_path / "c.tif", rgb, compression="zlib")
    np.testing.assert_allclose(read_image(tmp_path / "c.tif"), rgb / 65535.0, atol=1e-7)
    assert read_image_header(tmp_path / "c.tif").bit_depth == 16


def test_compressed_tiff_and_transparent_palette(tmp_path, rgb8):
    Image.fromarray(rgb8).save(tmp_path / "lzw.tif", compression="tiff_lzw")
    np.testing.assert_array_equal(np.rint(read_image(tmp_path / "lzw.tif") * 255), rgb8)
    palette = Image.fromarray(rgb8).convert("P")
    palette.save(tmp_path / "t.png", transparency=int(np.asarray(palette)[0, 0]))
    assert read_image_header(tmp_path / "t.png").channels == 4
    assert read_image(tmp_path / "t.png", keep_alpha=True).shape == (12, 10, 4)


def test_header_is_read_without_decoding(tmp_path, rgb8, monkeypatch):
    import texsyn.io.reading as reading

    Image.fromarray(rgb8).save(tmp_path / "x.png")
    monkeypatch.setattr(reading, "_decode", lambda *a, **k: pytest.fail("decoded"))
    header = read_image_header(tmp_path / "x.png")
    assert header == ImageHeader(width=10, height=12, channels=3, bit_depth=8, format="PNG")
    assert header.pixels == 120 and header.decoded_bytes == 120 * 3 * 5
    with pytest.raises(dataclasses.FrozenInstanceError):
        header.width = 3
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_image_header(tmp_path / "missing.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ImageReadError, match="text.png"):
        read_image_header(tmp_path / "text.png")
