"""Adversarial image files: truncated, flipped, lying headers, decompression bombs.

Every read must either return a valid float32 image in [0, 1] or raise one
``ImageReadError`` with a one-line message naming the file, within a second, without a
large allocation (``docs/reading.md``). Hypothesis runs derandomized so CI is reproducible.
"""

from __future__ import annotations

import functools
import io
import os
import struct
import subprocess
import sys
import textwrap
import time
import tracemalloc
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image, ImageFile

import texsyn.io.reading as reading
from texsyn.errors import ImageReadError, ImageTooLargeError, InputError
from texsyn.io import read_image, read_image_header

FUZZ = settings(
    # TEXSYN_FUZZ_EXAMPLES=5000 for a deeper (still reproducible) run
    max_examples=int(os.environ.get("TEXSYN_FUZZ_EXAMPLES", "100")),
    deadline=None,  # each read is timed below, against a fixed 1 s
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
TIME_LIMIT = 1.0


# --------------------------------------------------------------------------- file builders


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


@functools.cache
def _deflate_zeros(n: int) -> bytes:
    """zlib data that inflates to ``n`` zero bytes (about 1000:1), built in pieces."""
    comp, parts, zeros = zlib.compressobj(9), [], bytes(1 << 20)
    while n > 0:
        parts.append(comp.compress(zeros[: min(n, len(zeros))]))
        n -= len(zeros)
    return b"".join(parts) + comp.flush()


def png_file(width: int, height: int, depth: int, colour: int, idat: bytes, interlace: int = 0) -> bytes:
    """A PNG with the given IHDR fields and IDAT payload, all checksums right."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, interlace)
    plte = _chunk(b"PLTE", bytes(range(48))) if colour == 3 else b""
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + plte + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def tiff_file(entries: dict[int, tuple[int, list[int]]], body: bytes) -> bytes:
    """A little-endian classic TIFF: header, ``body`` at byte 8, then one IFD.

    ``entries`` maps tag -> (type, values); values that do not fit in 4 bytes are stored
    after the IFD.
    """
    codes = {3: "H", 4: "I"}
    ifd_at = 8 + len(body) + (len(body) & 1)
    n = len(entries)
    extra_at = ifd_at + 2 + 12 * n + 4
    table, extra = b"", b""
    for tag in sorted(entries):
        typ, values = entries[tag]
        code = codes[typ]
        data = struct.pack(f"<{len(values)}{code}", *values)
        if len(data) <= 4:
            field = data.ljust(4, b"\0")
        else:
            field = struct.pack("<I", extra_at + len(extra))
            extra += data
        table += struct.pack("<HHI", tag, typ, len(values)) + field
    pad = b"\0" * (ifd_at - 8 - len(body))
    return (
        b"II*\0" + struct.pack("<I", ifd_at) + body + pad + struct.pack("<H", n) + table + b"\0" * 4 + extra
    )


def tiff_image(width, height, samples, bits, compression, strip: bytes, photometric=None) -> bytes:
    photometric = (2 if samples >= 3 else 1) if photometric is None else photometric
    entries = {
        256: (4, [width]),
        257: (4, [height]),
        258: (3, [bits] * samples),
        259: (3, [compression]),
        262: (3, [photometric]),
        273: (4, [8]),
        277: (3, [samples]),
        278: (4, [height]),
        279: (4, [len(strip)]),
    }
    return tiff_file(entries, strip)


def bmp_file(width, height, bpp, compression=0, offset=None, dib=40, body=b"") -> bytes:
    palette = 4 * (1 << bpp) if bpp <= 8 else 0
    offset = 14 + dib + palette if offset is None else offset
    info = struct.pack("<IiiHHIIiiII", dib, width, height, 1, bpp, compression, len(body), 2835, 2835, 0, 0)
    info = info.ljust(dib, b"\0")[:dib]
    head = b"BM" + struct.pack("<IHHI", 14 + len(info) + palette + len(body), 0, 0, offset)
    return head + info + b"\0" * palette + body


def _encode(image: Image.Image, fmt: str, **kwargs) -> bytes:
    buf = io.BytesIO()
    image.save(buf, fmt, **kwargs)
    return buf.getvalue()


def _samples() -> dict[str, bytes]:
    """Small valid files of every format and flavour texsyn reads (a few hundred bytes each)."""
    import png
    import tifffile

    rng = np.random.default_rng(7)
    rgb = (rng.random((5, 6, 3)) * 255).astype(np.uint8)
    rgba = np.dstack([rgb, (rng.random((5, 6)) * 255).astype(np.uint8)])
    u16 = (rng.random((5, 6, 4)) * 65535).astype(np.uint16)
    im = Image.fromarray(rgb)
    out = {
        "rgb.png": _encode(im, "PNG"),
        "palette.png": _encode(im.convert("P"), "PNG"),
        "la.png": _encode(im.convert("LA"), "PNG"),
        "interlaced.png": _encode(im, "PNG", interlace=1),
        "grey16.png": _encode(Image.fromarray(u16[..., 0]), "PNG"),
        "rgb.jpg": _encode(im, "JPEG"),
        "grey.jpg": _encode(im.convert("L"), "JPEG"),
        "cmyk.jpg": _encode(im.convert("CMYK"), "JPEG"),
        "rgb.tif": _encode(im, "TIFF"),
        "lzw.tif": _encode(im, "TIFF", compression="tiff_lzw"),
        "grey16.tif": _encode(Image.fromarray(u16[..., 0]), "TIFF"),
        "rgb.bmp": _encode(im, "BMP"),
        "palette.bmp": _encode(im.convert("P"), "BMP"),
        "rgb.gif": _encode(im.convert("P"), "GIF"),
        "lossless.webp": _encode(Image.fromarray(rgba), "WEBP", lossless=True),
        "lossy.webp": _encode(im, "WEBP", quality=50),
        "p1.pbm": b"P1\n# plain\n6 5\n"
        + b"\n".join(b" ".join(b"01"[v % 2 : v % 2 + 1] for v in row) for row in rgb[..., 0]),
        "p2.pgm": b"P2 6 5 1000\n" + b" ".join(b"%d" % (v % 1001) for v in u16[..., 0].ravel()) + b"\n",
        "p3.ppm": b"P3\n6 5\n255\n" + b" ".join(b"%d" % v for v in rgb.ravel()) + b"\n",
        "p4.pbm": _encode(im.convert("1"), "PPM"),
        "p5.pgm": _encode(im.convert("L"), "PPM"),
        "p6.ppm": _encode(im, "PPM"),
        "p6_16.ppm": b"P6 6 5 65535\n" + u16[..., :3].astype(">u2").tobytes(),
    }
    buf = io.BytesIO()
    png.Writer(6, 5, greyscale=False, alpha=True, bitdepth=16).write(buf, u16.reshape(5, -1).tolist())
    out["rgba16.png"] = buf.getvalue()
    buf = io.BytesIO()
    tifffile.imwrite(buf, u16[..., :3], compression="zlib")
    out["rgb16_deflate.tif"] = buf.getvalue()
    buf = io.BytesIO()
    tifffile.imwrite(buf, rng.random((5, 6)).astype(np.float32))
    out["float.tif"] = buf.getvalue()
    return out


SAMPLES = _samples()
#: formats whose every strict prefix must be refused (the data is needed to its last byte);
#: not plain PNM (a cut "255" still reads as "25") nor GIF (its last byte is a trailer)
STRICT_TRUNCATION = ("png", "tif", "bmp", "webp", "pgm", "ppm", "pbm", "jpg")


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def put(path: Path, data: bytes) -> Path:
    """Write ``data`` over ``path`` without truncating it first: replacing a file through
    ``O_TRUNC`` makes ext4 flush it on close (``auto_da_alloc``), 100 times slower here."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        os.write(fd, data)
        os.ftruncate(fd, len(data))
    finally:
        os.close(fd)
    return path


def check_read(path: Path, *, must_fail: bool = False) -> np.ndarray | None:
    """Read ``path``; it either gives a valid image or one short ImageReadError, in time."""
    start = time.monotonic()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            image = read_image(path)
    except ImageReadError as exc:
        image = None
        message = str(exc)
        assert "\n" not in message and len(message) <= 220, message
        assert path.name in message, message
    elapsed = time.monotonic() - start
    assert elapsed < TIME_LIMIT, f"{path.name}: {elapsed:.2f} s"
    if image is not None:
        assert not must_fail, f"{path.name} was read although it is broken"
        assert image.dtype == np.float32 and image.ndim in (2, 3) and image.size
        assert np.all(np.isfinite(image)) and image.min() >= 0.0 and image.max() <= 1.0
    return image


def check_header(path: Path) -> None:
    start = time.monotonic()
    try:
        header = read_image_header(path)
    except ImageReadError as exc:
        assert "\n" not in str(exc) and len(str(exc)) <= 220, str(exc)
    else:
        assert header.width >= 1 and header.height >= 1 and header.channels in (1, 2, 3, 4)
    assert time.monotonic() - start < TIME_LIMIT


def _refused_in_bounded_memory(path, error, match=None, *, peak_limit=16 << 20) -> str:
    """Read ``path``: it must raise ``error`` within the time limit and peak traced memory."""
    tracemalloc.start()
    start = time.monotonic()
    try:
        with pytest.raises(error, match=match) as info:
            read_image(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert time.monotonic() - start < TIME_LIMIT
    assert peak < peak_limit
    return str(info.value)


# --------------------------------------------------------------------------- valid samples


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_every_sample_reads(fuzz_dir, name):
    path = fuzz_dir / name
    path.write_bytes(SAMPLES[name])
    image = check_read(path)
    assert image is not None and image.shape[:2] == (5, 6)
    header = read_image_header(path)
    assert (header.width, header.height) == (6, 5)
    assert image.ndim == 2 or image.shape[2] <= header.channels


# --------------------------------------------------------------------------- truncations


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_every_truncation_is_refused_or_valid(fuzz_dir, name):
    """Every prefix of every sample, from 0 bytes to one byte short."""
    data = SAMPLES[name]
    strict = name.rsplit(".", 1)[1] in STRICT_TRUNCATION and name[:2] not in ("p1", "p2", "p3")
    path = fuzz_dir / f"cut-{name}"
    for length in range(len(data)):
        put(path, data[:length])
        check_read(path, must_fail=strict)


# --------------------------------------------------------------------------- flipped bytes


@FUZZ
@given(name=st.sampled_from(sorted(SAMPLES)), data=st.data())
def test_flipped_bytes(fuzz_dir, name, data):
    raw = bytearray(SAMPLES[name])
    flips = data.draw(
        st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(1, 255)), min_size=1, max_size=6)
    )
    for pos, mask in flips:
        raw[pos] ^= mask
    path = put(fuzz_dir / f"flip-{name}", bytes(raw))
    check_read(path)
    check_header(path)


# --------------------------------------------------------------------------- lying headers

SIDES = st.one_of(
    st.integers(0, 70), st.integers(0, 2**32 - 1), st.sampled_from([2**31 - 1, 2**31, 30000, 65535])
)


@FUZZ
@given(
    width=SIDES,
    height=SIDES,
    depth=st.sampled_from([0, 1, 2, 3, 4, 8, 16, 32, 255]),
    colour=st.integers(0, 7),
    interlace=st.integers(0, 2),
    payload=st.one_of(st.binary(max_size=200), st.integers(0, 20000).map(lambda n: zlib.compress(bytes(n)))),
    damage=st.sampled_from(["none", "crc", "length", "cut"]),
)
def test_lying_png(fuzz_dir, width, height, depth, colour, interlace, payload, damage):
    data = bytearray(png_file(width, height, depth, colour, payload, interlace))
    if damage == "crc":
        data[-20] ^= 0xFF  # inside the IDAT chunk or its checksum
    elif damage == "length":
        data[33:37] = struct.pack(">I", 0x7FFFFFF0)  # the first chunk after IHDR lies about its length
    elif damage == "cut":
        data = data[: len(data) // 2]
    path = put(fuzz_dir / "lie.png", bytes(data))
    check_read(path)
    check_header(path)


@FUZZ
@given(
    magic=st.sampled_from([b"P1", b"P2", b"P3", b"P4", b"P5", b"P6"]),
    fields=st.lists(
        st.one_of(st.integers(0, 20), st.integers(0, 10**12), st.sampled_from([255, 256, 65535, 65536, 0])),
        min_size=0,
        max_size=3,
    ),
    separator=st.sampled_from([b" ", b"\n", b"\n# comment\n", b"\t", b"#"]),
    body=st.one_of(st.binary(max_size=400), st.text("0123456789 \n#x-", max_size=300).map(str.encode)),
)
def test_lying_pnm(fuzz_dir, magic, fields, separator, body):
    header = magic + b"".join(separator + str(f).encode() for f in fields)
    path = put(fuzz_dir / "lie.pnm", header + b"\n" + body)
    check_read(path)
    check_header(path)


@FUZZ
@given(
    width=st.integers(-5, 2**31 - 1) | st.integers(-5, 40),
    height=st.integers(-(2**31), 2**31 - 1) | st.integers(-40, 40),
    bpp=st.sampled_from([0, 1, 4, 8, 16, 24, 32, 7, 64]),
    compression=st.sampled_from([0, 1, 2, 3, 4, 6, 99]),
    dib=st.sampled_from([12, 40, 108, 124, 41, 7]),
    offset=st.none() | st.integers(0, 2**32 - 1),
    body=st.binary(max_size=600),
)
def test_lying_bmp(fuzz_dir, width, height, bpp, compression, dib, offset, body):
    try:
        data = bmp_file(width, height, bpp, compression, offset, dib, body)
    except struct.error:  # a field out of its struct range cannot be written
        return
    path = put(fuzz_dir / "lie.bmp", data)
    check_read(path)
    check_header(path)


@FUZZ
@given(
    width=st.integers(0, 40) | st.integers(0, 2**32 - 1),
    height=st.integers(0, 40) | st.integers(0, 2**32 - 1),
    samples=st.integers(0, 6),
    bits=st.sampled_from([0, 1, 4, 8, 12, 16, 32, 64]),
    compression=st.sampled_from([1, 5, 7, 8, 32773, 34925, 2, 999]),
    photometric=st.sampled_from([0, 1, 2, 3, 5, 6, 8]),
    strip=st.one_of(st.binary(max_size=300), st.integers(0, 50000).map(lambda n: zlib.compress(bytes(n)))),
    offset_lie=st.sampled_from([None, 0, 2**31, 7]),
)
def test_lying_tiff(fuzz_dir, width, height, samples, bits, compression, photometric, strip, offset_lie):
    data = bytearray(tiff_image(width, height, max(samples, 1), bits, compression, strip, photometric))
    if samples == 0:
        data = bytearray(tiff_image(width, height, 1, bits, compression, strip, photometric))
        data[data.find(struct.pack("<HHI", 277, 3, 1)) + 8] = 0
    if offset_lie is not None:  # StripOffsets point elsewhere
        at = data.find(struct.pack("<HHI", 273, 4, 1))
        data[at + 8 : at + 12] = struct.pack("<I", offset_lie)
    path = put(fuzz_dir / "lie.tif", bytes(data))
    check_read(path)
    check_header(path)


# --------------------------------------------------------------------------- explicit cases


def test_truncated_ppm_header_is_refused_at_once(tmp_path):
    """``printf 'P6 4 4'`` used to make the PNM token loop spin forever."""
    path = tmp_path / "t.ppm"
    path.write_bytes(b"P6 4 4")
    start = time.monotonic()
    with pytest.raises(ImageReadError, match=r"t\.ppm.*truncated.*maxval"):
        read_image(path)
    assert time.monotonic() - start < TIME_LIMIT


@pytest.mark.parametrize(
    "content, problem",
    [
        (b"", "empty"),
        (b"P5 0 4 255\n", "impossible size"),
        (b"P5 4 4 0\n" + bytes(16), "maxval 0"),
        (b"P6 4 4 65536\n" + bytes(96), "maxval 65536"),
        (b"P5 4 4 255\n" + bytes(15), "truncated"),
        (b"P5 400000 400000 255\n" + bytes(99), "truncated"),
        (b"P2 2 2 9\n1 2 3", "truncated"),
        (b"P2 2 2 9\n1 2 3 10", "exceeds its maxval"),
        (b"P2 2 2 9\n1 2 x 4", "unexpected character"),
        (b"P5 2 2 255\n\x00\x00\x00\x00", None),
    ],
)
def test_pnm_lies(tmp_path, content, problem):
    path = tmp_path / "x.pgm"
    path.write_bytes(content)
    if problem is None:
        assert read_image(path).shape == (2, 2)
        return
    with pytest.raises(ImageReadError, match=problem):
        read_image(path)


def test_png_bomb_refused_before_decoding(tmp_path, monkeypatch):
    """A 16-bit PNG of under 1 MB that declares 30000x30000 pixels (about 5 GB to decode)."""
    path = tmp_path / "bomb.png"
    path.write_bytes(png_file(30000, 30000, 16, 2, _deflate_zeros(200 << 20)))
    assert path.stat().st_size < 1 << 20
    header = read_image_header(path)
    assert (header.width, header.height, header.channels, header.bit_depth) == (30000, 30000, 3, 16)

    def no_decoding(*args, **kwargs):
        raise AssertionError("decoding started")

    monkeypatch.setattr(reading, "_decode", no_decoding)
    message = _refused_in_bounded_memory(path, ImageTooLargeError, peak_limit=4 << 20)
    assert "bomb.png" in message and "30000x30000" in message and "TEXSYN_MAX_PIXELS" in message
    assert "40 million" in message and "\n" not in message


def test_12000_square_png_refused_without_decoding(tmp_path, monkeypatch):
    path = tmp_path / "big.png"
    path.write_bytes(png_file(12000, 12000, 8, 2, _deflate_zeros(12000 * 36001)))
    monkeypatch.setattr(reading, "_decode", lambda *a, **k: pytest.fail("decoding started"))
    start = time.monotonic()
    with pytest.raises(ImageTooLargeError, match="12000x12000"):
        read_image(path)
    assert time.monotonic() - start < TIME_LIMIT


def test_png_whose_data_inflates_past_its_header(tmp_path):
    """Within the budget, but the compressed data holds 200 MB: refused in bounded memory."""
    path = tmp_path / "lie.png"
    path.write_bytes(png_file(1000, 1000, 8, 0, _deflate_zeros(200 << 20)))
    message = _refused_in_bounded_memory(path, ImageReadError, "larger than")
    assert "lie.png" in message  # the one line names the file


def test_tiff_bombs(tmp_path):
    # declares 30000x30000 16-bit RGB with a small Deflate strip: refused on the header
    path = tmp_path / "bomb.tif"
    path.write_bytes(tiff_image(30000, 30000, 3, 16, 8, _deflate_zeros(200 << 20)))
    assert path.stat().st_size < 1 << 20
    start = time.monotonic()
    with pytest.raises(ImageTooLargeError, match="30000x30000"):
        read_image(path)
    assert time.monotonic() - start < TIME_LIMIT
    # within the budget, but its strip inflates to 200 MB (tifffile would inflate it at once)
    path = tmp_path / "lie.tif"
    path.write_bytes(tiff_image(500, 500, 3, 16, 8, _deflate_zeros(200 << 20)))
    _refused_in_bounded_memory(path, ImageReadError, "inflate")
    # an uncompressed TIFF whose strip is shorter than its header declares (small enough
    # not to be refused as a decompression bomb first)
    path = tmp_path / "short.tif"
    path.write_bytes(tiff_image(400, 400, 3, 8, 1, bytes(100)))
    with pytest.raises(ImageReadError, match="truncated"):
        read_image(path)


def test_other_format_bombs_are_refused_on_their_header(tmp_path):
    cases = {
        "bomb.bmp": bmp_file(20000, 20000, 8, compression=1, body=bytes(64)),  # RLE
        "bomb.gif": b"GIF89a" + struct.pack("<HHBBB", 65535, 65535, 0, 0, 0) + b"," + bytes(20),
        "bomb.webp": b"RIFF"
        + struct.pack("<I", 22)
        + b"WEBPVP8X"
        + struct.pack("<I", 10)
        + b"\0" * 4
        + (16383).to_bytes(3, "little") * 2,
        "bomb.pgm": b"P5 100000 100000 255\n" + bytes(100),
        "bomb.jpg": b"\xff\xd8\xff\xc0"
        + struct.pack(">HBHHB", 17, 8, 60000, 60000, 3)
        + bytes(9)
        + b"\xff\xd9",
    }
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        start = time.monotonic()
        with pytest.raises(ImageReadError):
            read_image(path)
        assert time.monotonic() - start < TIME_LIMIT
    for name in ("bomb.bmp", "bomb.gif", "bomb.webp", "bomb.jpg"):
        with pytest.raises(ImageTooLargeError):
            read_image(tmp_path / name)


# --------------------------------------------------------------------------- the pixel budget


def _png(path: Path, shape, dtype=np.uint8) -> Path:
    data = np.zeros(shape, dtype)
    if dtype == np.uint16 and len(shape) == 3:
        import png

        writer = png.Writer(shape[1], shape[0], greyscale=shape[2] < 3, alpha=shape[2] in (2, 4), bitdepth=16)
        with open(path, "wb") as fh:
            writer.write(fh, data.reshape(shape[0], -1).tolist())
    else:
        Image.fromarray(data).save(path)
    return path


def test_max_pixels_is_respected(tmp_path, monkeypatch):
    path = _png(tmp_path / "x.png", (10, 12, 3))
    monkeypatch.setenv("TEXSYN_MAX_PIXELS", "119")
    with pytest.raises(ImageTooLargeError, match=r"x\.png.*12x10.*119 allowed.*TEXSYN_MAX_PIXELS=1K"):
        read_image(path)
    assert read_image_header(path).width == 12  # the header alone is always given
    monkeypatch.setenv("TEXSYN_MAX_PIXELS", "120")
    assert read_image(path).shape == (10, 12, 3)
    for value in ("1K", " 2k ", "1M", "40m", "1000000"):
        monkeypatch.setenv("TEXSYN_MAX_PIXELS", value)
        assert read_image(path).shape == (10, 12, 3)


@pytest.mark.parametrize("value", ["0", "-5", "abc", "1.5M", "10G", "1e6", "12 34", "0K"])
def test_max_pixels_is_validated(tmp_path, monkeypatch, value):
    path = _png(tmp_path / "x.png", (4, 4))
    monkeypatch.setenv("TEXSYN_MAX_PIXELS", value)
    with pytest.raises(InputError, match=r"TEXSYN_MAX_PIXELS must be a positive whole number.*K.*M") as info:
        read_image(path)
    assert not isinstance(info.value, ImageReadError)


def test_memory_equivalent_of_the_budget(tmp_path, monkeypatch):
    """16-bit RGBA takes 24 bytes a pixel decoded; the budget allows 20 per pixel."""
    monkeypatch.setenv("TEXSYN_MAX_PIXELS", "1000")
    wide = _png(tmp_path / "w.png", (30, 30, 4), np.uint16)  # 900 pixels, 21,600 bytes
    with pytest.raises(ImageTooLargeError, match=r"to decode.*TEXSYN_MAX_PIXELS"):
        read_image(wide)
    assert read_image(_png(tmp_path / "n.png", (30, 30, 4)), keep_alpha=True).shape == (
        30,
        30,
        4,
    )  # 8-bit: 18,000


def test_pillow_guard_does_not_answer(tmp_path, monkeypatch):
    """Pillow's own limit, however low, neither refuses nor warns below our budget."""
    path = tmp_path / "x.jpg"
    Image.fromarray(np.zeros((40, 50, 3), np.uint8)).save(path, "JPEG")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_image(path).shape == (40, 50, 3)
    assert Image.MAX_IMAGE_PIXELS == 100
    assert ImageFile.LOAD_TRUNCATED_IMAGES is False


def test_folders_devices_and_empty_files(tmp_path):
    with pytest.raises(ImageReadError, match="folder"):
        read_image(tmp_path)
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ImageReadError, match="empty"):
        read_image(tmp_path / "empty.png")
    if os.path.exists("/dev/zero"):
        with pytest.raises(ImageReadError, match="not a regular file"):
            read_image("/dev/zero")
    fifo = tmp_path / "pipe.png"
    if hasattr(os, "mkfifo"):
        os.mkfifo(fifo)
        start = time.monotonic()
        with pytest.raises(ImageReadError, match="not a regular file"):
            read_image(fifo)  # opening a pipe would block
        assert time.monotonic() - start < TIME_LIMIT


# --------------------------------------------------------------------------- the command line

_CHILD = textwrap.dedent(
    """
    import resource, subprocess, sys
    cmd = [sys.executable, "-c",
           "import sys; from texsyn.cli import main; sys.exit(main(sys.argv[1:]))", *sys.argv[1:]]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # KiB on Linux
    sys.stdout.write(f"{done.returncode}\\n{peak}\\n")
    sys.stdout.write(done.stderr)
    """
)


def _run_cli(*args: str, env: dict | None = None) -> tuple[int, int, str]:
    """Run ``texsyn ARGS`` in a child, returning its exit status, peak RSS (MiB) and stderr."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, *args],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
        env=None if env is None else {**os.environ, **env},
    )
    assert done.returncode == 0, done.stderr
    code, peak, stderr = done.stdout.split("\n", 2)
    scale = 1 if sys.platform.startswith("linux") else 1024  # macOS reports bytes
    return int(code), int(peak) // 1024 // scale, stderr


@pytest.mark.skipif(sys.platform == "win32", reason="peak memory needs the resource module")
def test_cli_refuses_a_bomb_in_little_memory(tmp_path):
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(png_file(30000, 30000, 16, 2, _deflate_zeros(200 << 20)))
    out = tmp_path / "out.png"
    code, peak_mib, stderr = _run_cli("synth", str(bomb), "-o", str(out))
    assert code == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("texsyn: error:") and "bomb.png" in lines[0], stderr
    assert "TEXSYN_MAX_PIXELS" in lines[0]
    assert not out.exists()
    assert peak_mib < 300, f"peak RSS {peak_mib} MiB"


@pytest.mark.skipif(sys.platform == "win32", reason="uses the resource module")
def test_cli_refuses_a_truncated_ppm_at_once(tmp_path):
    bad = tmp_path / "t.ppm"
    bad.write_bytes(b"P6 4 4")
    out = tmp_path / "o.png"
    start = time.monotonic()
    code, _, stderr = _run_cli("synth", str(bad), "-o", str(out))
    assert time.monotonic() - start < 60
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "t.ppm" in stderr, stderr
    assert not out.exists()


# ------------------------------------------------------------ bombs under the pixel budget


def _jpeg_with_declared_size(path, width, height):
    """A real 64x64 JPEG whose frame header is patched to declare ``width`` x ``height``."""
    from io import BytesIO

    from PIL import Image

    buffer = BytesIO()
    rng = np.random.default_rng(5)
    Image.fromarray((rng.random((64, 64, 3)) * 255).astype(np.uint8)).save(buffer, "JPEG", quality=90)
    data = bytearray(buffer.getvalue())
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("side", [2000, 6000])
def test_jpeg_whose_header_lies_about_its_size_is_refused_before_decoding(tmp_path, side):
    path = _jpeg_with_declared_size(tmp_path / "lie.jpg", side, side)
    start = time.monotonic()
    with pytest.raises(ImageTooLargeError, match="decompression bomb"):
        read_image(path)
    assert time.monotonic() - start < 1.0


@pytest.mark.parametrize("fmt", ["PNG", "GIF", "TIFF"])
def test_small_file_declaring_millions_of_pixels_is_refused_as_a_bomb(tmp_path, fmt):
    from PIL import Image

    path = tmp_path / f"zeros.{fmt.lower()}"
    kwargs = {"compression": "tiff_deflate"} if fmt == "TIFF" else {}
    Image.new("RGB", (3000, 3000)).save(path, fmt, **kwargs)  # 27 MB of zeros in a few KB
    assert path.stat().st_size * 250 < 3000 * 3000 * 3
    start = time.monotonic()
    with pytest.raises(ImageTooLargeError, match="decompression bomb"):
        read_image(path)
    assert time.monotonic() - start < 1.0


def test_flat_images_below_the_floor_are_read_whatever_their_compression(tmp_path):
    from PIL import Image

    Image.new("RGB", (500, 500), (10, 200, 30)).save(tmp_path / "flat.png")  # 750 kB in ~1 kB
    assert read_image(tmp_path / "flat.png").shape == (500, 500, 3)


@pytest.mark.skipif(sys.platform == "win32", reason="uses the resource module")
@pytest.mark.parametrize("kind", ["zeros PNG", "lying JPEG"])
def test_cli_refuses_bombs_under_the_pixel_budget_in_little_memory(tmp_path, kind):
    if kind == "zeros PNG":
        bomb = tmp_path / "bomb.png"
        Image.new("RGB", (6000, 6000)).save(bomb)  # 108 MB of zeros in ~100 kB, 36 of 40 million pixels
    else:
        bomb = _jpeg_with_declared_size(tmp_path / "bomb.jpg", 6000, 6000)
    out = tmp_path / "out.png"
    code, peak_mib, stderr = _run_cli("synth", str(bomb), "-o", str(out), "--size", "32x32")
    assert code == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "decompression bomb" in lines[0], stderr
    assert not out.exists()
    assert peak_mib < 300, f"peak RSS {peak_mib} MiB"


@pytest.mark.skipif(sys.platform == "win32", reason="uses the resource module")
def test_cli_checks_the_memory_limit_from_the_header_before_decoding(tmp_path):
    # 3500x3500 RGB, uncompressed: decoding it (37 MB) and its float32 copy (147 MB) on top of
    # the ~130 MB start-up would pass 300 MB, so a refusal under 300 MB came before decoding
    noise = np.random.default_rng(0).integers(0, 256, (3500, 3500, 3), dtype=np.uint8)
    big = tmp_path / "big.bmp"
    Image.fromarray(noise).save(big)
    out = tmp_path / "out.png"
    code, peak_mib, stderr = _run_cli(
        "synth", str(big), "-o", str(out), "-m", "patch_wavelet", env={"TEXSYN_MEMORY_LIMIT": "64M"}
    )
    assert code == 2 and "TEXSYN_MEMORY_LIMIT" in stderr, stderr
    assert not out.exists()
    assert peak_mib < 300, f"peak RSS {peak_mib} MiB"
