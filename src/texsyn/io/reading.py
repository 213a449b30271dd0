"""Reading image files: float32 [0, 1] arrays out, header first, never a hang or a bomb.

Read: PNG (1-16 bit, grey, grey + alpha, RGB, RGBA, palette), JPEG (grey, RGB, CMYK),
TIFF (1-16 bit integer, 32/64 bit float), BMP, GIF (first frame), WebP and PNM (PBM, PGM,
PPM, plain and raw, maxval up to 65535).

Every read follows the same steps (``docs/reading.md``):

1. the header is read by :mod:`texsyn.io.headers` (Pillow's lazy open) without decoding;
2. the declared size is checked against the pixel budget (``TEXSYN_MAX_PIXELS``) and its
   memory equivalent, so that a decompression bomb is refused before any allocation;
3. the pixels are decoded into at most the declared size: by Pillow; by pypng for 16-bit
   colour PNG and by tifffile for 16-bit colour and float TIFF (Pillow would cut them to
   8 bits, or has no mode for them); by numpy for raw PGM/PPM whose maxval is not 255.
   Two guards cover what those decoders do not: a PNG's compressed data must inflate to
   exactly the size its header declares, and a TIFF strip given to tifffile must not
   inflate past it, both checked in bounded pieces;
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
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..errors import InputError
from .headers import (
    ImageHeader,
    _error,
    _open_checked,
    _pillow_open,
    _pillow_target,
    _Probe,
    _probe,
    _quiet_library_logs,
    _said,
    check_image_size,
    max_image_pixels,
)

__all__ = ["READ_FORMATS", "read_image"]

READ_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".gif", ".webp", ".pgm", ".ppm", ".pnm", ".pbm")

#: Compressed data is inflated, counted and dropped in pieces of this size.
_PIECE = 1 << 20

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
    check_image_size(probe.header, path, max_pixels=max_image_pixels(), file_size=os.path.getsize(path))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # decoders' warnings (EXIF, palettes) are not the user's concern
            data, scale = _decode(path, probe)
    except InputError:
        raise
    except MemoryError:
        raise _error(path, "not enough memory to decode it (lower TEXSYN_MAX_PIXELS)") from None
    except Exception as exc:  # every decoder failure, whatever its type, is an ImageReadError
        raise _error(path, _complaint(exc, probe, path)) from None
    return _to_float(data, scale, path, keep_alpha)


#: What Pillow's plain PNM decoder says -> the same problem in texsyn's PNM messages.
_PNM_COMPLAINTS = {
    "too large for this mode": "corrupt PNM file (a sample exceeds its maxval {maxval}: {said})",
    "invalid literal for int": "corrupt PNM file (unexpected character in the pixel data: {said})",
    "Invalid token": "corrupt PNM file (unexpected character in the pixel data: {said})",
    "not enough image data": "truncated PNM file (it holds fewer samples than its header declares)",
}


def _complaint(exc: BaseException, probe: _Probe, path: str | os.PathLike) -> str:
    said, fmt = _said(exc, path), probe.header.format
    for words, ours in _PNM_COMPLAINTS.items() if fmt == "PNM" else ():
        if words in said:
            return ours.format(maxval=probe.details["maxval"], said=said)
    return f"corrupt or unsupported {fmt} file ({said})"


def _decode(path: str | os.PathLike, probe: _Probe) -> tuple[np.ndarray, float]:
    """Decode the pixels: an integer, bool or float array and the value that means 1.0."""
    if probe.header.format == "PNG":
        _check_png(path, probe)
    if probe.decoder == "pypng":
        return _decode_png16(path, probe.header), 65535.0
    if probe.decoder == "tifffile":
        return _decode_tifffile(path, probe.header)
    if probe.decoder == "numpy":
        return _decode_raw_pnm(path, probe)
    arr = _decode_pillow(path, probe)
    if probe.header.format == "PNM" and arr.dtype != bool:
        return _undo_pnm_rescale(arr, probe.details["maxval"])
    if arr.dtype == bool:
        return arr, 1.0
    if arr.dtype == np.uint8:
        return arr, 255.0
    if arr.dtype.kind == "u" and arr.dtype.itemsize == 2:
        return arr, 65535.0
    if arr.dtype.kind == "i":  # 32-bit integer images: read as 16-bit data
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise _error(path, "it holds integers outside the 16-bit range; texsyn reads 8 and 16 bit images")
        return arr, 65535.0
    return arr, 1.0


# --------------------------------------------------------------------------- Pillow


def _decode_pillow(path: str | os.PathLike, probe: _Probe) -> np.ndarray:
    """Pillow's decode (``load()``), converted to the mode the probe chose, as an array."""
    header = probe.header
    fh, _ = _open_checked(path)
    with fh, _pillow_open(fh, "PPM" if header.format == "PNM" else header.format, path) as im:
        if im.size != (header.width, header.height) or probe.mode not in (None, im.mode):
            raise _error(path, "the file changed while it was read")
        target = probe.target or _pillow_target(im)
        if not target:
            raise _error(path, f"unsupported {header.format} pixel mode {im.mode}")
        libtiff = header.format == "TIFF" and im.tile and im.tile[0][0] == "libtiff"
        with _libtiff_muted() if libtiff else contextlib.nullcontext():
            im.load()
        return np.asarray(im.convert(target) if target != im.mode else im)


@contextlib.contextmanager
def _libtiff_muted():
    """Point file descriptor 2 at the null device while Pillow's libtiff decoder runs.

    libtiff prints its complaints about a broken TIFF ("Using code not yet in table",
    "Incorrect count for RowsPerStrip"...) straight to the process's stderr, where they
    would add lines to texsyn's one-line error. Pillow mutes libtiff's warnings but not its
    errors and offers no way to redirect them; tifffile cannot take these files over, since
    without the optional imagecodecs package it decodes neither LZW nor JPEG. Only this
    decode is muted, but output of other threads during it is lost too; the lock keeps
    concurrent reads from restoring the wrong descriptor.
    """
    with _STDERR_LOCK:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):  # no real stderr: nothing to mute
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


# --------------------------------------------------------------------------- bounded inflation


def _pieces(fh: BinaryIO, offset: int, length: int, path, fmt: str) -> Iterator[bytes]:
    """``length`` bytes of ``fh`` from ``offset``, in pieces of at most 1 MiB."""
    fh.seek(offset)
    while length > 0:
        piece = fh.read(min(length, _PIECE))
        if not piece:
            raise _error(path, f"truncated {fmt} file (its pixel data ends early)")
        length -= len(piece)
        yield piece


def _inflated_size(pieces: Iterable[bytes], inflater, limit: int) -> int:
    """Bytes ``pieces`` inflate to through ``inflater`` (zlib or lzma), counted and dropped a
    MiB at a time; stops as soon as the count passes ``limit``."""
    total = 0
    for piece in pieces:
        while not inflater.eof:
            out = inflater.decompress(piece, _PIECE)
            total += len(out)
            if total > limit:
                return total
            piece = getattr(inflater, "unconsumed_tail", b"")
            if not piece and len(out) < _PIECE and getattr(inflater, "needs_input", True):
                break
    return total


# --------------------------------------------------------------------------- PNG

_IEND = b"\0\0\0\0IEND\xaeB`\x82"  # the last chunk of every PNG, checksum included


def _check_png(path: str | os.PathLike, probe: _Probe) -> None:
    """Check a PNG's chunks (Pillow's ``verify``: every chunk up to IEND present, checksums
    right) and that its pixel data inflates to exactly the size its header declares.

    Pillow stops inflating when the image is full and ignores what is left, and pypng
    inflates each IDAT chunk in one piece (a 1 MB chunk can give 1 GB), so the data is
    first inflated here a MiB at a time, counted and dropped: a compressed bomb costs at
    most the declared size in work and 1 MiB in memory.
    """
    expected = probe.details["raw_size"]
    fh, _ = _open_checked(path)
    with fh:
        _pillow_open(fh, "PNG", path).verify()
        # verify() stops at IEND's type, before its checksum: a file cut in its last four
        # bytes would pass, so look for the whole IEND chunk where verify() stopped
        fh.seek(max(fh.tell() - 12, 0))
        if _IEND not in fh.read(16):
            raise _error(path, "truncated PNG file (its IEND chunk is incomplete)")

        def idat_pieces() -> Iterator[bytes]:
            fh.seek(probe.details["first_idat"] - 8)
            while (head := fh.read(8))[4:] == b"IDAT":
                yield from _pieces(fh, fh.tell(), int.from_bytes(head[:4], "big"), path, "PNG")
                fh.seek(4, os.SEEK_CUR)  # the checksum, verified above

        inflater = zlib.decompressobj()
        total = _inflated_size(idat_pieces(), inflater, expected)
    if total > expected:
        raise _error(path, f"corrupt PNG file (its pixel data is larger than the {expected:,} bytes its header declares)")
    if not inflater.eof or total != expected:
        raise _error(path, f"truncated PNG file (its pixel data holds {total:,} bytes, its header declares {expected:,})")


def _decode_png16(path: str | os.PathLike, header: ImageHeader) -> np.ndarray:
    """16-bit colour PNG (grey + alpha, RGB, RGBA), which Pillow would cut to 8 bits."""
    import png

    fh, _ = _open_checked(path)
    with fh:
        width, height, rows, meta = png.Reader(file=fh).read()
        if (width, height, meta["bitdepth"]) != (header.width, header.height, 16):
            raise _error(path, "the file changed while it was read")
        out = np.empty((height, width * meta["planes"]), np.uint16)
        count = 0
        for count, row in enumerate(rows, 1):
            out[count - 1] = row
    if count != height:
        raise ValueError(f"pypng gave {count} rows of {height}")
    return out.reshape(height, width, meta["planes"])


# --------------------------------------------------------------------------- TIFF

#: Compressions tifffile decodes without the optional imagecodecs package
_TIFFFILE_CODECS = {1: None, 8: zlib.decompressobj, 32946: zlib.decompressobj, 34925: lzma.LZMADecompressor}


def _decode_tifffile(path: str | os.PathLike, header: ImageHeader) -> tuple[np.ndarray, float]:
    """16-bit colour and floating-point TIFF, through tifffile (first page only).

    tifffile inflates each strip in one piece, so the strips are first inflated here a MiB
    at a time, counted and dropped: together they must hold at least the declared pixel
    data (tifffile would pad what is missing, slowly) and at most twice that.
    """
    import tifffile

    _quiet_library_logs()
    fh, size = _open_checked(path)
    with fh, tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        if (page.imagewidth, page.imagelength) != (header.width, header.height):
            raise _error(path, "the file changed while it was read")
        compression, photometric = int(page.compression), int(page.photometric)
        if compression not in _TIFFFILE_CODECS or photometric not in (0, 1, 2):
            raise _error(path, f"unsupported {header.bit_depth}-bit TIFF (compression {compression}, "
                               f"photometric {photometric}); save it uncompressed or with Deflate")
        codec, limit, total = _TIFFFILE_CODECS[compression], 2 * page.nbytes + _PIECE, 0
        for offset, count in zip(page.dataoffsets, page.databytecounts):
            if offset + count > size:
                raise _error(path, f"truncated TIFF file (a strip would end at byte {offset + count:,}, "
                                   f"the file has {size:,} bytes)")
            if codec is None:
                total += count
                continue
            total += _inflated_size(_pieces(fh, offset, count, path, "TIFF"), codec(), limit - total)
            if total > limit:
                raise _error(path, "corrupt TIFF file (its strips inflate to more than its header declares)")
        if total < page.nbytes:  # tifffile would pad the missing data, a strip at a time
            raise _error(path, f"truncated TIFF file (its strips hold {total:,} of the {page.nbytes:,} "
                               f"bytes of pixel data its header declares)")
        arr = page.asarray(maxworkers=1)
        if page.axes.startswith("S") and arr.ndim == 3:  # planar configuration: samples first
            arr = np.moveaxis(arr, 0, -1)
    if arr.shape[:2] != (header.height, header.width):
        raise ValueError(f"tifffile decodes shape {arr.shape}")
    if arr.dtype.kind == "u" and arr.dtype.itemsize <= 2:
        return arr, float(np.iinfo(arr.dtype).max)
    if arr.dtype.kind == "f":
        return arr, 1.0
    raise _error(path, f"unsupported TIFF sample type {arr.dtype}")


# --------------------------------------------------------------------------- PNM


def _decode_raw_pnm(path: str | os.PathLike, probe: _Probe) -> tuple[np.ndarray, float]:
    """Raw PGM and PPM whose maxval is not 255 (e.g. 16-bit, or 12-bit as 4095): numpy reads
    the samples as stored, to be divided by the maxval; Pillow would convert them a sample
    at a time in Python and rescale them to 8 bits (colour) or 16 bits (grey)."""
    h, maxval = probe.header, probe.details["maxval"]
    dtype = np.dtype(np.uint8 if maxval < 256 else ">u2")
    count = h.pixels * h.channels * dtype.itemsize
    fh, _ = _open_checked(path)
    with fh:
        fh.seek(probe.details["offset"])
        raw = fh.read(count)
    if len(raw) != count:
        raise _error(path, "truncated PNM file (pixel data missing)")
    arr = np.frombuffer(raw, dtype).reshape((h.height, h.width, 3) if h.channels == 3 else (h.height, h.width))
    if arr.size and int(arr.max()) > maxval:
        raise _error(path, f"corrupt PNM file (a sample of {int(arr.max())} exceeds its maxval {maxval})")
    return arr, float(maxval)


def _undo_pnm_rescale(arr: np.ndarray, maxval: int) -> tuple[np.ndarray, float]:
    """Pillow's plain PGM/PPM decoder turns a sample ``v`` into ``round(v * top / maxval)``,
    ``top`` being 255 (or 65535 for grey above maxval 255). Below ``top`` that is one to
    one: undo it exactly, in integers, so that samples are divided by the maxval. (A plain
    PPM above maxval 255 comes out of Pillow with 8 bits.)"""
    top = 255 if arr.dtype == np.uint8 else 65535
    if maxval >= top:
        return arr, float(top)
    wide = np.uint16 if top == 255 else np.uint32  # v * maxval + top // 2 fits
    return (arr.astype(wide) * wide(maxval) + wide(top // 2)) // wide(top), float(maxval)


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
