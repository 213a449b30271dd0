"""Reading image files: float32 [0, 1] arrays out, header first, never a hang or a bomb.

Read: PNG (1-16 bit, grey, grey + alpha, RGB, RGBA, palette), JPEG (grey, RGB, CMYK),
TIFF (1-16 bit integer, 32/64 bit float), BMP, GIF (first frame), WebP and PNM (PBM, PGM,
PPM, plain and raw, maxval up to 65535).

Every read follows the same steps (``docs/reading.md``):

1. the header is parsed by :mod:`texsyn.io.headers` without decoding pixels;
2. the declared size is checked against the pixel budget (``TEXSYN_MAX_PIXELS``) and its
   memory equivalent, so that a decompression bomb is refused before any allocation;
3. the pixels are decoded by a decoder whose work is bounded by the declared size (Pillow,
   pypng for 16-bit colour PNG, tifffile for 16-bit colour and float TIFF, texsyn's own
   PNM decoder); compressed data is first checked to decompress to exactly the declared
   size, in bounded pieces;
4. any failure of a decoder becomes one :class:`~texsyn.errors.ImageReadError` that names
   the file and the problem.
"""

from __future__ import annotations

import contextlib
import lzma
import os
import sys
import threading
import warnings
import zlib
from pathlib import Path

import numpy as np

from ..errors import ImageTooLargeError, InputError
from .headers import (
    ImageHeader,
    _error,
    _open_checked,
    _Probe,
    _probe,
    _show,
    check_image_size,
    max_image_pixels,
)

__all__ = ["READ_FORMATS", "read_image"]

READ_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".gif", ".webp", ".pgm", ".ppm", ".pnm", ".pbm")
_READ_NAMES = "PNG, JPEG, TIFF, BMP, GIF, WebP, PBM/PGM/PPM"

#: Compressed data is read and checked in pieces of this size.
_PIECE = 1 << 20
#: A plain (ASCII) PNM raster is parsed in blocks of this many characters.
_PLAIN_BLOCK = 4 << 20

_PIL_LOCK = threading.Lock()
_STDERR_LOCK = threading.RLock()


def read_image(path: str | os.PathLike, *, keep_alpha: bool = False) -> np.ndarray:
    """Read an image file as float32 in [0, 1], shape ``(H, W)`` or ``(H, W, 3)``.

    The header is read and checked against the pixel budget before any pixel is decoded
    (see :func:`texsyn.io.read_image_header` and ``docs/reading.md``).

    Parameters
    ----------
    path : str or path-like
        A PNG, JPEG, TIFF, BMP, GIF (first frame), WebP or PNM (PBM/PGM/PPM) file; the
        format is recognised from the file's first bytes, not from its name.
    keep_alpha : bool
        Return ``(H, W, 4)`` (or ``(H, W, 2)`` for grey) when the file has an alpha channel.
        By default the alpha channel is dropped, with a warning when it is not fully opaque.

    Returns
    -------
    numpy.ndarray
        float32, C-contiguous, values in [0, 1]: samples divided by the largest value of
        their bit depth (by the maxval for PNM). CMYK and palette images come out RGB.

    Raises
    ------
    FileNotFoundError
        The file does not exist (an :class:`~texsyn.errors.InputFileNotFoundError`).
    ImageTooLargeError
        The file declares more pixels than ``TEXSYN_MAX_PIXELS`` allows (or more memory
        than its equivalent); nothing was decoded.
    ImageReadError
        The file exists but is not a readable image: a folder, empty, an unknown format,
        truncated, or a header that does not match the data. The message is one line.
    InputError
        ``TEXSYN_MAX_PIXELS`` holds a value that is not a positive number of pixels.
    """
    probe = _probe(path)
    budget = max_image_pixels()
    check_image_size(probe.header, path, max_pixels=budget)
    try:
        data, scale = _decode(path, probe, budget)
    except InputError:
        raise
    except MemoryError:
        raise _error(path, "not enough memory to decode it (lower TEXSYN_MAX_PIXELS)") from None
    except Exception as exc:  # every decoder failure, whatever its type, is an ImageReadError
        raise _error(path, _reason(exc, probe.header.format, path)) from None
    return _to_float(data, scale, path, keep_alpha)


def _reason(exc: BaseException, fmt: str, path: str | os.PathLike) -> str:
    """A decoder's complaint, short and without the path (the message names it once)."""
    text = str(exc)
    for name in {os.fspath(path), str(Path(path)), Path(path).name} - {""}:
        text = text.replace(repr(name), "it").replace(name, "it")
    text = " ".join(text.split()) or type(exc).__name__
    return f"corrupt or unsupported {fmt} file ({text[:90]})"


def _decode(path: str | os.PathLike, probe: _Probe, budget: int) -> tuple[np.ndarray, float]:
    """Decode the pixels: an integer, bool or float array and the value that means 1.0."""
    header, info = probe.header, probe.info
    if header.format == "PNM":
        return _decode_pnm(path, probe)
    if header.format == "PNG":
        _check_png_data(path, info)
        if header.bit_depth == 16 and info["colour_type"] != 0:
            return _decode_png16(path, header), 65535.0
    if header.format == "TIFF" and not _pillow_reads_tiff(header, info):
        return _decode_tifffile(path, probe)
    return _decode_pillow(path, header, budget)


# --------------------------------------------------------------------------- Pillow

_PIL_TARGETS = {
    "1": "1", "L": "L", "LA": "LA", "RGB": "RGB", "RGBA": "RGBA", "I": "I", "F": "F",
    "I;16": "I;16", "I;16L": "I;16L", "I;16B": "I;16B", "I;16N": "I;16N",
    "PA": "RGBA", "La": "LA", "RGBa": "RGBA", "RGBX": "RGB",
    "CMYK": "RGB", "YCbCr": "RGB", "LAB": "RGB", "HSV": "RGB",
}


def _decode_pillow(path: str | os.PathLike, header: ImageHeader, budget: int) -> tuple[np.ndarray, float]:
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Pillow's warnings (EXIF, palettes) are not the user's concern
        quiet = _silent_stderr if header.format == "TIFF" else contextlib.nullcontext
        with quiet():
            im = _pillow_open(path, header.format, budget)
        with im, quiet():
            if im.size != (header.width, header.height):
                raise _error(path, f"the {header.format} decoder sees size {im.size[0]}x{im.size[1]}, "
                                   f"the header declares {header.width}x{header.height}")
            mode = im.mode
            target = _PIL_TARGETS.get(mode)
            if mode == "P":
                target = "RGBA" if "transparency" in im.info else "RGB"
            if target is None:
                raise _error(path, f"unsupported {header.format} pixel mode {mode}")
            bits = 16 if target.startswith("I;16") else 32 if target in ("I", "F") else 8
            decoded = ImageHeader(header.width, header.height, Image.getmodebands(target), bits, header.format)
            check_image_size(decoded, path, max_pixels=budget)
            im.load()
            if target != mode:
                converted = im.convert(target)
                im.close()
                im = converted
            arr = np.asarray(im)
    if arr.dtype == np.uint8 or arr.dtype == bool:
        return arr, 255.0 if arr.dtype == np.uint8 else 1.0
    if arr.dtype.kind == "u" and arr.dtype.itemsize == 2:
        return arr, 65535.0
    if arr.dtype.kind == "i":  # 32-bit integer images: read as 16-bit data
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise _error(path, "it holds integers outside the 16-bit range; texsyn reads 8 and 16 bit images")
        return arr, 65535.0
    return arr, 1.0


@contextlib.contextmanager
def _silent_stderr():
    """Send file descriptor 2 to the null device: libtiff, under Pillow, prints its warnings
    about a broken file straight to stderr, which would add lines to the one-line error.
    Output of other threads during the decode is lost too; the lock keeps our own nested
    or concurrent uses from restoring the wrong descriptor."""
    with _STDERR_LOCK:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):  # no real stderr: nothing to silence
            yield
            return
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 2)
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            os.close(null)


def _pillow_open(path: str | os.PathLike, fmt: str, budget: int):
    """``Image.open`` restricted to the format the header showed, with Pillow's bomb guard
    consistent with ours: our budget was checked first, so Pillow must not refuse below it."""
    from PIL import Image

    limit = Image.MAX_IMAGE_PIXELS
    try:
        if limit is None or budget <= 2 * limit:
            return Image.open(path, formats=[fmt])
        with _PIL_LOCK:  # only when TEXSYN_MAX_PIXELS is set above Pillow's own limit
            saved, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, budget
            try:
                return Image.open(path, formats=[fmt])
            finally:
                Image.MAX_IMAGE_PIXELS = saved
    except Image.DecompressionBombError:
        raise ImageTooLargeError(
            f"'{_show(path)}' is larger than Pillow's Image.MAX_IMAGE_PIXELS allows; "
            "set TEXSYN_MAX_PIXELS to change texsyn's budget"
        ) from None


# --------------------------------------------------------------------------- PNG


def _check_png_data(path: str | os.PathLike, info: dict) -> None:
    """Check that the IDAT chunks decompress to exactly the size the header declares.

    The data is inflated in pieces of at most 1 MiB that are counted and dropped, so that a
    compressed bomb costs at most the declared size in work and 1 MiB in memory. Each IDAT
    chunk's checksum is verified on the way.
    """
    expected = info["raw_size"]
    inflater = zlib.decompressobj()
    total = 0
    fh, _ = _open_checked(path)
    with fh:
        for offset, length in info["idat"]:
            fh.seek(offset - 4)
            crc = zlib.crc32(fh.read(4))
            left = length
            while left:
                piece = fh.read(min(left, _PIECE))
                if not piece:
                    raise _error(path, "truncated PNG file (IDAT data missing)")
                left -= len(piece)
                crc = zlib.crc32(piece, crc)
                while piece and not inflater.eof:
                    try:
                        out = inflater.decompress(piece, _PIECE)
                    except zlib.error as exc:
                        raise _error(path, f"corrupt PNG file (compressed data: {exc})") from None
                    total += len(out)
                    if total > expected:
                        raise _error(path, f"corrupt PNG file (its pixel data is larger than "
                                           f"the {expected:,} bytes its header declares)")
                    piece = inflater.unconsumed_tail
            if not inflater.eof:
                try:
                    total += len(inflater.flush())  # no input left: at most a window of output
                except zlib.error as exc:
                    raise _error(path, f"corrupt PNG file (compressed data: {exc})") from None
            stored = fh.read(4)
            if len(stored) != 4 or int.from_bytes(stored, "big") != crc:
                raise _error(path, f"corrupt PNG file (IDAT checksum mismatch at byte {offset - 8})")
    if not inflater.eof or total != expected:
        raise _error(path, f"truncated PNG file (its pixel data holds {total:,} bytes, "
                           f"its header declares {expected:,})")


def _decode_png16(path: str | os.PathLike, header: ImageHeader) -> np.ndarray:
    """16-bit colour PNG (grey + alpha, RGB, RGBA), which Pillow would cut to 8 bits."""
    import png

    fh, _ = _open_checked(path)
    with fh:
        width, height, rows, meta = png.Reader(file=fh).read()
        planes = int(meta["planes"])
        if (width, height) != (header.width, header.height) or meta["bitdepth"] != 16:
            raise ValueError("pypng disagrees with the header")
        out = np.empty((height, width * planes), np.uint16)
        filled = 0
        for row in rows:
            if filled == height:
                raise ValueError("more rows than declared")
            out[filled] = np.frombuffer(row, dtype=np.uint16) if not isinstance(row, list) else row
            filled += 1
        if filled != height:
            raise ValueError(f"{filled} rows of {height}")
    return out.reshape(height, width, planes)


# --------------------------------------------------------------------------- TIFF


def _pillow_reads_tiff(header: ImageHeader, info: dict) -> bool:
    """Pillow reads 8-bit (and smaller) TIFF with every compression, and 16-bit grey;
    16-bit colour would be cut to 8 bits and float images go to tifffile."""
    if info["sample_format"] != 1:
        return False
    return header.bit_depth <= 8 or (header.bit_depth == 16 and info["samples"] == 1)


#: Compressions the tifffile path decodes without the optional imagecodecs package
_TIFFFILE_CODECS = {1: None, 8: "zlib", 32946: "zlib", 34925: "lzma"}


def _decode_tifffile(path: str | os.PathLike, probe: _Probe) -> tuple[np.ndarray, float]:
    """16-bit colour and floating-point TIFF, through tifffile (first page only)."""
    header, info = probe.header, probe.info
    codec = _TIFFFILE_CODECS.get(info["compression"], "unsupported")
    if codec == "unsupported" or info["photometric"] not in (0, 1, 2):
        raise _error(path, f"unsupported {header.bit_depth}-bit TIFF (compression {info['compression']}, "
                           f"photometric {info['photometric']}); save it uncompressed or with Deflate")
    if codec is not None:
        _check_tiff_segments(path, info, codec)
    import tifffile

    _quiet_tifffile()
    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        arr = page.asarray(maxworkers=1)
        axes = page.axes
    if axes.startswith("S") and arr.ndim == 3:  # planar configuration: samples first
        arr = np.moveaxis(arr, 0, -1)
    if arr.shape[:2] != (header.height, header.width):
        raise ValueError(f"tifffile decodes shape {arr.shape}")
    if arr.dtype.kind == "u" and arr.dtype.itemsize <= 2:
        return arr, float(np.iinfo(arr.dtype).max)
    if arr.dtype.kind == "f":
        return arr, 1.0
    raise _error(path, f"unsupported TIFF sample type {arr.dtype}")


def _check_tiff_segments(path: str | os.PathLike, info: dict, codec: str) -> None:
    """Check, in bounded pieces, that compressed strips or tiles do not inflate past the
    declared size (tifffile would otherwise inflate each strip in one piece)."""
    limit = 2 * info["least"] + _PIECE
    total = 0
    fh, _ = _open_checked(path)
    with fh:
        for offset, count in info["segments"]:
            inflater = zlib.decompressobj() if codec == "zlib" else lzma.LZMADecompressor()
            fh.seek(offset)
            left = count
            while left and not inflater.eof:
                piece = fh.read(min(left, _PIECE))
                if not piece:
                    raise _error(path, "truncated TIFF file (strip data missing)")
                left -= len(piece)
                while piece:
                    out = inflater.decompress(piece, _PIECE)
                    total += len(out)
                    if total > limit:
                        raise _error(path, "corrupt TIFF file (its strips inflate to more than its header declares)")
                    if codec == "zlib":
                        piece = inflater.unconsumed_tail
                    else:
                        piece = b""
                        while not inflater.needs_input and not inflater.eof:
                            out = inflater.decompress(b"", _PIECE)
                            total += len(out)
                            if total > limit:
                                raise _error(path, "corrupt TIFF file (its strips inflate to more than its header declares)")
                    if inflater.eof:
                        break


def _quiet_tifffile() -> None:
    """tifffile logs warnings about odd files; keep them off stderr (the error says enough)."""
    import logging

    logger = logging.getLogger("tifffile")
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())


# --------------------------------------------------------------------------- PNM


def _decode_pnm(path: str | os.PathLike, probe: _Probe) -> tuple[np.ndarray, float]:
    """PBM, PGM and PPM, plain (P1-P3) and raw (P4-P6), maxval up to 65535."""
    header, info = probe.header, probe.info
    kind, maxval, offset = info["kind"], info["maxval"], info["offset"]
    w, h, c = header.width, header.height, header.channels
    shape = (h, w, c) if c > 1 else (h, w)
    count = w * h * c
    fh, _ = _open_checked(path)
    with fh:
        fh.seek(offset)
        if kind in (5, 6):
            dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
            raw = fh.read(count * dtype.itemsize)
            if len(raw) != count * dtype.itemsize:
                raise _error(path, "truncated PNM file (pixel data missing)")
            arr = np.frombuffer(raw, dtype=dtype).reshape(shape)
        elif kind == 4:
            row = (w + 7) // 8
            raw = fh.read(row * h)
            if len(raw) != row * h:
                raise _error(path, "truncated PBM file (pixel data missing)")
            bits = np.unpackbits(np.frombuffer(raw, np.uint8).reshape(h, row), axis=1)[:, :w]
            return bits == 0, 1.0  # 1 is black
        elif kind == 1:
            return (_plain_bits(fh, count, path) == 0).reshape(shape), 1.0
        else:
            arr = _plain_numbers(fh, count, path).reshape(shape)
    if maxval < (255 if arr.dtype == np.uint8 else 65535) and arr.size and int(arr.max()) > maxval:
        raise _error(path, f"corrupt PNM file (a sample of {int(arr.max())} exceeds its maxval {maxval})")
    return arr, float(maxval)


def _plain_bits(fh, count: int, path) -> np.ndarray:
    """Plain PBM pixels: '0' and '1' characters, whitespace optional."""
    out = np.empty(count, np.uint8)
    filled = 0
    while filled < count:
        block = fh.read(_PLAIN_BLOCK)
        if not block:
            raise _error(path, f"truncated PBM file (it holds {filled:,} of its {count:,} pixels)")
        a = np.frombuffer(block, np.uint8)
        _check_characters(a, (a == 0x30) | (a == 0x31), path)
        bits = a[(a == 0x30) | (a == 0x31)][: count - filled]
        out[filled : filled + bits.size] = bits - 0x30
        filled += bits.size
    return out


def _plain_numbers(fh, count: int, path) -> np.ndarray:
    """Plain PGM/PPM samples: decimal numbers separated by whitespace, parsed by block."""
    out = np.empty(count, np.uint16)
    filled, carry = 0, b""
    while filled < count:
        block = fh.read(_PLAIN_BLOCK)
        data = carry + block
        if block:  # keep a number cut by the block's end for the next block
            body = data.rstrip(b"0123456789")
            data, carry = body, data[len(body):]
            if len(carry) > 5:
                raise _error(path, "corrupt PNM file (a sample has more than 5 digits)")
        else:
            carry = b""
        values = _numbers(np.frombuffer(data, np.uint8), path)
        take = min(values.size, count - filled)
        out[filled : filled + take] = values[:take]
        filled += take
        if not block:
            break
    if filled < count:
        raise _error(path, f"truncated PNM file (it holds {filled:,} of its {count:,} samples)")
    return out


def _check_characters(a: np.ndarray, allowed: np.ndarray, path) -> None:
    space = (a == 0x20) | ((a >= 0x09) & (a <= 0x0D))
    bad = ~(allowed | space)
    if bad.any():
        char = bytes(a[int(np.argmax(bad)) : int(np.argmax(bad)) + 1])
        raise _error(path, f"corrupt PNM file (unexpected character {char!r} in the pixel data)")


def _numbers(a: np.ndarray, path) -> np.ndarray:
    digit = (a >= 0x30) & (a <= 0x39)
    _check_characters(a, digit, path)
    pad = np.zeros(1, np.int8)
    edges = np.diff(np.concatenate((pad, digit.view(np.int8), pad)))
    starts = np.flatnonzero(edges == 1)
    lengths = np.flatnonzero(edges == -1) - starts
    if lengths.size and lengths.max() > 5:
        raise _error(path, "corrupt PNM file (a sample has more than 5 digits)")
    values = np.zeros(starts.size, np.int64)
    for k in range(int(lengths.max()) if lengths.size else 0):
        more = lengths > k
        values[more] = values[more] * 10 + (a[starts[more] + k] - 0x30)
    if values.size and values.max() > 65535:
        raise _error(path, f"corrupt PNM file (a sample of {int(values.max())} exceeds 65535)")
    return values


# --------------------------------------------------------------------------- to float


def _to_float(arr: np.ndarray, scale: float, path: str | os.PathLike, keep_alpha: bool) -> np.ndarray:
    """Integer (or float) samples to float32 in [0, 1], alpha handled on the integer data."""
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3, 4)):
        raise _error(path, f"unsupported layout {arr.shape}; expected a grey or colour image")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise _error(path, "it is an empty image")
    if arr.dtype.kind == "f":
        if arr.size and (not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1):
            raise _error(path, "it holds floating-point values outside [0, 1]")
        scale = 1.0
    if arr.ndim == 3 and arr.shape[2] in (2, 4) and not keep_alpha:
        opaque = True if arr.dtype == bool else scale
        if np.any(arr[..., -1] < opaque):
            warnings.warn(
                f"'{Path(path).name}' has transparency; the alpha channel is dropped", UserWarning, stacklevel=3
            )
        arr = arr[..., :-1]
        if arr.shape[2] == 1:
            arr = arr[..., 0]
    out = np.empty(arr.shape, np.float32)
    if arr.dtype == bool or scale == 1.0:
        out[...] = arr
    else:
        np.divide(arr, np.float32(scale), out=out, casting="unsafe")
    return out
