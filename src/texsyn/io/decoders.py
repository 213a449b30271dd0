"""The decoders behind :func:`texsyn.io.read_image`, each kept to the size the header declared.

Pillow decodes most files; pypng decodes 16-bit colour PNG and tifffile 16-bit colour and
float TIFF (Pillow would cut them to 8 bits, or has no mode for them); numpy reads raw
PGM/PPM whose maxval is not 255. Two guards cover what those decoders do not
(``docs/reading.md``): a PNG's compressed data must inflate to exactly the size its header
declares, and a TIFF strip given to tifffile must not inflate past it, both checked in
bounded pieces (:func:`check_png`, :func:`decode_tifffile`).

Every function returns the samples as stored (integers, bool or float); the caller divides
them by the value that means 1.0.
"""

from __future__ import annotations

import contextlib
import lzma
import os
import sys
import threading
import zlib
from collections.abc import Iterable, Iterator
from typing import Any, BinaryIO

import numpy as np

from .budget import ImageHeader
from .files import open_checked, read_error
from .libraries import pillow_open, pillow_target, quiet_library_logs
from .probes import Probe

__all__ = [
    "check_png",
    "decode_pillow",
    "decode_png16",
    "decode_raw_pnm",
    "decode_tifffile",
    "undo_pnm_rescale",
]

#: Compressed data is inflated, counted and dropped in pieces of this size.
_PIECE = 1 << 20

_STDERR_LOCK = threading.RLock()


# --------------------------------------------------------------------------- Pillow


def decode_pillow(path: str | os.PathLike, probe: Probe) -> np.ndarray:
    """Pillow's decode (``load()``), converted to the mode the probe chose, as an array."""
    header = probe.header
    fh, _ = open_checked(path)
    with fh, pillow_open(fh, "PPM" if header.format == "PNM" else header.format, path) as im:
        if im.size != (header.width, header.height) or probe.mode not in (None, im.mode):
            raise read_error(path, "the file changed while it was read")
        target = probe.target or pillow_target(im)
        if not target:
            raise read_error(path, f"unsupported {header.format} pixel mode {im.mode}")
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
            raise read_error(path, f"truncated {fmt} file (its pixel data ends early)")
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


def check_png(path: str | os.PathLike, probe: Probe) -> None:
    """Check a PNG's chunks (Pillow's ``verify``: every chunk up to IEND present, checksums
    right) and that its pixel data inflates to exactly the size its header declares.

    Pillow stops inflating when the image is full and ignores what is left, and pypng
    inflates each IDAT chunk in one piece (a 1 MB chunk can give 1 GB), so the data is
    first inflated here a MiB at a time, counted and dropped: a compressed bomb costs at
    most the declared size in work and 1 MiB in memory.
    """
    expected = probe.details["raw_size"]
    fh, _ = open_checked(path)
    with fh:
        pillow_open(fh, "PNG", path).verify()
        # verify() stops at IEND's type, before its checksum: a file cut in its last four
        # bytes would pass, so look for the whole IEND chunk where verify() stopped
        fh.seek(max(fh.tell() - 12, 0))
        if _IEND not in fh.read(16):
            raise read_error(path, "truncated PNG file (its IEND chunk is incomplete)")

        def idat_pieces() -> Iterator[bytes]:
            fh.seek(probe.details["first_idat"] - 8)
            while (head := fh.read(8))[4:] == b"IDAT":
                yield from _pieces(fh, fh.tell(), int.from_bytes(head[:4], "big"), path, "PNG")
                fh.seek(4, os.SEEK_CUR)  # the checksum, verified above

        inflater = zlib.decompressobj()
        total = _inflated_size(idat_pieces(), inflater, expected)
    if total > expected:
        raise read_error(
            path,
            f"corrupt PNG file (its pixel data is larger than the {expected:,} bytes its header declares)",
        )
    if not inflater.eof or total != expected:
        raise read_error(
            path,
            f"truncated PNG file (its pixel data holds {total:,} bytes, its header declares {expected:,})",
        )


def decode_png16(path: str | os.PathLike, header: ImageHeader) -> np.ndarray:
    """16-bit colour PNG (grey + alpha, RGB, RGBA), which Pillow would cut to 8 bits."""
    import png

    fh, _ = open_checked(path)
    with fh:
        width, height, rows, meta = png.Reader(file=fh).read()
        if (width, height, meta["bitdepth"]) != (header.width, header.height, 16):
            raise read_error(path, "the file changed while it was read")
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


def decode_tifffile(path: str | os.PathLike, header: ImageHeader) -> tuple[np.ndarray, float]:
    """16-bit colour and floating-point TIFF, through tifffile (first page only).

    tifffile inflates each strip in one piece, so the strips are first inflated here a MiB
    at a time, counted and dropped: together they must hold at least the declared pixel
    data (tifffile would pad what is missing, slowly) and at most twice that.
    """
    import tifffile

    quiet_library_logs()
    fh, size = open_checked(path)
    with fh, tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        if (page.imagewidth, page.imagelength) != (header.width, header.height):
            raise read_error(path, "the file changed while it was read")
        compression, photometric = int(page.compression), int(page.photometric)
        if compression not in _TIFFFILE_CODECS or photometric not in (0, 1, 2):
            raise read_error(
                path,
                f"unsupported {header.bit_depth}-bit TIFF (compression {compression}, "
                f"photometric {photometric}); save it uncompressed or with Deflate",
            )
        codec, limit, total = _TIFFFILE_CODECS[compression], 2 * page.nbytes + _PIECE, 0
        for offset, count in zip(page.dataoffsets, page.databytecounts):
            if offset + count > size:
                raise read_error(
                    path,
                    f"truncated TIFF file (a strip would end at byte {offset + count:,}, "
                    f"the file has {size:,} bytes)",
                )
            if codec is None:
                total += count
                continue
            total += _inflated_size(_pieces(fh, offset, count, path, "TIFF"), codec(), limit - total)
            if total > limit:
                raise read_error(
                    path, "corrupt TIFF file (its strips inflate to more than its header declares)"
                )
        if total < page.nbytes:  # tifffile would pad the missing data, a strip at a time
            raise read_error(
                path,
                f"truncated TIFF file (its strips hold {total:,} of the {page.nbytes:,} "
                f"bytes of pixel data its header declares)",
            )
        arr = page.asarray(maxworkers=1)
        if page.axes.startswith("S") and arr.ndim == 3:  # planar configuration: samples first
            arr = np.moveaxis(arr, 0, -1)
    if arr.shape[:2] != (header.height, header.width):
        raise ValueError(f"tifffile decodes shape {arr.shape}")
    if arr.dtype.kind == "u" and arr.dtype.itemsize <= 2:
        return arr, float(np.iinfo(arr.dtype).max)
    if arr.dtype.kind == "f":
        return arr, 1.0
    raise read_error(path, f"unsupported TIFF sample type {arr.dtype}")


# --------------------------------------------------------------------------- PNM


def decode_raw_pnm(path: str | os.PathLike, probe: Probe) -> tuple[np.ndarray, float]:
    """Raw PGM and PPM whose maxval is not 255 (e.g. 16-bit, or 12-bit as 4095): numpy reads
    the samples as stored, to be divided by the maxval; Pillow would convert them a sample
    at a time in Python and rescale them to 8 bits (colour) or 16 bits (grey)."""
    h, maxval = probe.header, probe.details["maxval"]
    dtype = np.dtype(np.uint8 if maxval < 256 else ">u2")
    count = h.pixels * h.channels * dtype.itemsize
    fh, _ = open_checked(path)
    with fh:
        fh.seek(probe.details["offset"])
        raw = fh.read(count)
    if len(raw) != count:
        raise read_error(path, "truncated PNM file (pixel data missing)")
    arr = np.frombuffer(raw, dtype).reshape(
        (h.height, h.width, 3) if h.channels == 3 else (h.height, h.width)
    )
    if arr.size and int(arr.max()) > maxval:
        raise read_error(path, f"corrupt PNM file (a sample of {int(arr.max())} exceeds its maxval {maxval})")
    return arr, float(maxval)


def undo_pnm_rescale(arr: np.ndarray, maxval: int) -> tuple[np.ndarray, float]:
    """Pillow's plain PGM/PPM decoder turns a sample ``v`` into ``round(v * top / maxval)``,
    ``top`` being 255 (or 65535 for grey above maxval 255). Below ``top`` that is one to
    one: undo it exactly, in integers, so that samples are divided by the maxval. (A plain
    PPM above maxval 255 comes out of Pillow with 8 bits.)"""
    top = 255 if arr.dtype == np.uint8 else 65535
    if maxval >= top:
        return arr, float(top)
    wide = np.uint16 if top == 255 else np.uint32  # v * maxval + top // 2 fits
    samples: Any = arr.astype(wide)  # numpy's stubs do not type integer array arithmetic
    return (samples * wide(maxval) + wide(top // 2)) // wide(top), float(maxval)
