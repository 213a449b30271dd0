"""The header of each format, completed where Pillow does not tell what texsyn needs.

Each ``probe_*`` function returns a :class:`Probe`: the :class:`~texsyn.io.budget.ImageHeader`
plus how to decode the file and what the decoder's guards need. A few bytes read at fixed
offsets complete Pillow's lazy open (see :mod:`texsyn.io.headers` for why each is needed):
PNG's IHDR fields, WebP's canvas size, PNM's header tokens, and the first page of a TIFF
that Pillow has no mode for (through tifffile).
"""

from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass, field, replace
from typing import BinaryIO

from ..errors import ImageReadError
from .budget import ImageHeader
from .files import read_error

__all__ = [
    "PNM_MAGIC",
    "Probe",
    "png_raw_size",
    "probe_png",
    "probe_pnm",
    "probe_tiff",
    "probe_tifffile",
    "probe_webp",
]

#: A PNM header (magic, comments, sizes) longer than this is refused.
_MAX_PNM_HEADER = 64 * 1024


@dataclass(frozen=True)
class Probe:
    """A header, plus how to decode the file and what the decoder must check.

    ``decoder`` is ``"pillow"``, ``"pypng"``, ``"tifffile"``, ``"numpy"`` (raw PNM), ``"npy"``
    or ``"exr"`` (:mod:`texsyn.io.float_formats`);
    ``mode`` and ``target`` are Pillow's mode at open and the mode to decode to (``None``
    where Pillow did not open the file); ``details`` holds what the guards need.
    """

    header: ImageHeader
    decoder: str = "pillow"
    mode: str | None = None
    target: str | None = None
    details: dict = field(default_factory=dict)


# PNG ---------------------------------------------------------------------------------------

_PNG_SAMPLES = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # colour type -> samples a pixel in the file
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


def png_raw_size(width: int, height: int, bits_per_pixel: int, interlaced: bool) -> int:
    """Bytes of filtered scanlines (one filter byte a row) a PNG's pixel data inflates to."""

    def rows(w: int, h: int) -> int:
        return 0 if w <= 0 or h <= 0 else h * (1 + (w * bits_per_pixel + 7) // 8)

    if not interlaced:
        return rows(width, height)
    return sum(rows((width - x0 + dx - 1) // dx, (height - y0 + dy - 1) // dy) for x0, y0, dx, dy in _ADAM7)


def probe_png(im, fh: BinaryIO, probe: Probe, path) -> Probe:
    """Add what Pillow does not expose, from the IHDR chunk at bytes 12-28: the bit depth
    (a 16-bit colour PNG goes to pypng, which keeps 16 bits) and the exact size of the
    inflated pixel data, with the offset of the first IDAT chunk (for the decoder's guard)."""
    fh.seek(12)
    ihdr = fh.read(17)
    if len(ihdr) != 17 or ihdr[:4] != b"IHDR":
        raise read_error(path, "corrupt PNG file (the first chunk is not IHDR)")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", ihdr[4:])
    if (width, height) != im.size or colour not in _PNG_SAMPLES or not im.tile:
        raise read_error(path, "corrupt PNG file (inconsistent IHDR chunk)")
    details = {
        "first_idat": im.tile[0][2],
        "raw_size": png_raw_size(width, height, depth * _PNG_SAMPLES[colour], interlace == 1),
    }
    decoder = "pypng" if depth == 16 and colour in (2, 4, 6) else "pillow"
    header = replace(probe.header, bit_depth=depth)
    return replace(probe, header=header, decoder=decoder, details=details)


# TIFF --------------------------------------------------------------------------------------


def probe_tiff(im, probe: Probe, path) -> Probe:
    """The bit depth from the BitsPerSample tag; a 16-bit colour TIFF, which Pillow would
    cut to 8 bits (mode RGB or RGBA), goes to tifffile."""
    bits = max(im.tag_v2.get(258) or (1,))
    decoder = "tifffile" if bits > 8 and not im.mode.startswith(("I", "F")) else "pillow"
    if decoder == "pillow" and im.tile and im.tile[0][0] == "raw":
        # Pillow's raw decoder leaves the rows of missing strips blank, so a small file
        # that declares a tall image would be read, slowly, as a black one
        covered = sum((x1 - x0) * (y1 - y0) for _, (x0, y0, x1, y1), *_ in im.tile)
        if covered < probe.header.pixels:
            raise read_error(
                path,
                f"truncated TIFF file (its strips hold {covered:,} of the "
                f"{probe.header.pixels:,} pixels its header declares)",
            )
    return replace(probe, header=replace(probe.header, bit_depth=bits), decoder=decoder)


def probe_tifffile(path: str | os.PathLike, pillow_error: ImageReadError) -> Probe:
    """The first page's header as tifffile reads it, for a TIFF Pillow has no mode for
    (16-bit grey + alpha, float RGB, 64-bit float); ``pillow_error`` if tifffile fails too."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages.first
            width, height = int(page.imagewidth), int(page.imagelength)
            samples, bits, kind = int(page.samplesperpixel), int(page.bitspersample), int(page.sampleformat)
    except Exception:  # tifffile cannot read it either: Pillow's complaint is the one to show
        raise pillow_error from None
    if samples > 4 or (kind, bits) not in ((1, 8), (1, 16), (3, 32), (3, 64)):
        raise read_error(
            path, f"unsupported TIFF file ({samples} samples of {bits} bits, sample format {kind})"
        )
    return Probe(ImageHeader(width, height, samples, bits, "TIFF"), "tifffile")


# WebP --------------------------------------------------------------------------------------


def probe_webp(fh: BinaryIO, path) -> Probe:
    """The canvas size from the first 30 bytes (as Pillow's own ``_get_size`` reads it):
    Pillow's WebP open reads the whole file and creates libwebp's decoder, which allocates
    the canvas, so it must wait for the budget check."""
    fh.seek(0)
    s = fh.read(30)
    chunk = s[12:16]
    if chunk == b"VP8 " and len(s) >= 30 and s[23:26] == b"\x9d\x01\x2a":
        width, height = (int.from_bytes(s[i : i + 2], "little") & 0x3FFF for i in (26, 28))
        channels = 3
    elif chunk == b"VP8L" and len(s) >= 25 and s[20] == 0x2F:
        bits = int.from_bytes(s[21:25], "little")
        width, height = (bits & 0x3FFF) + 1, (bits >> 14 & 0x3FFF) + 1
        channels = 4 if bits >> 28 & 1 else 3
    elif chunk == b"VP8X" and len(s) >= 30:
        width, height = (int.from_bytes(s[i : i + 3], "little") + 1 for i in (24, 27))
        channels = 4 if s[20] & 0x10 else 3
    else:
        raise read_error(path, "truncated or corrupt WebP file (no VP8, VP8L or VP8X header)")
    return Probe(ImageHeader(width, height, channels, 8, "WEBP"))


# PNM (PBM, PGM, PPM) -----------------------------------------------------------------------

PNM_MAGIC = re.compile(rb"P[1-6](?:[ \t\n\r\v\f#]|\Z)")
#: A header field: whitespace and comments (``#`` to the end of the line), then digits.
_PNM_FIELD = re.compile(rb"(?:[ \t\n\r\v\f]|#[^\n\r]*(?:[\n\r]|\Z))*(\d*)")


def probe_pnm(fh: BinaryIO, size: int, path) -> Probe:
    """The PNM header's tokens, read here rather than by Pillow so that a message names the
    field that is missing or out of range, and so that a file too short for the size it
    declares is called truncated (before the budget, which it may also exceed)."""
    fh.seek(0)
    head = fh.read(_MAX_PNM_HEADER)
    kind = head[1] - 0x30
    names = ("width", "height") if kind in (1, 4) else ("width", "height", "maxval")
    values, pos = [], 2
    for name in names:
        match = _PNM_FIELD.match(head, pos)
        assert match is not None  # every part of the pattern is optional
        pos = match.end()
        if not match[1]:
            if pos < len(head):
                raise read_error(
                    path,
                    f"corrupt PNM header (expected the {name} at byte {pos}, found {head[pos : pos + 1]!r})",
                )
            if len(head) < size:
                raise read_error(path, f"PNM header longer than {_MAX_PNM_HEADER // 1024} KiB")
            raise read_error(path, f"truncated PNM file (it ends before the {name} in its header)")
        if len(match[1]) > 12:
            raise read_error(path, f"corrupt PNM header (the {name} has too many digits)")
        values.append(int(match[1]))
    if pos >= size:
        raise read_error(path, "truncated PNM file (it ends after its header, without pixel data)")
    if head[pos] not in b" \t\n\r\v\f":
        raise read_error(path, f"corrupt PNM header (byte {pos} should be whitespace after the {names[-1]})")
    width, height, maxval = values[0], values[1], values[2] if kind not in (1, 4) else 1
    if width < 1 or height < 1:
        raise read_error(path, f"the PNM header declares an impossible size {width}x{height}")
    if not 1 <= maxval <= 65535:
        raise read_error(path, f"the PNM header declares maxval {maxval}; it must be between 1 and 65535")
    channels = 3 if kind in (3, 6) else 1
    offset, samples = pos + 1, width * height * channels
    # the least pixel data the header implies: raw samples, raw bits, or one character a
    # plain PBM pixel and a digit plus a separator a plain PGM/PPM sample
    need = {1: samples, 2: 2 * samples - 1, 3: 2 * samples - 1, 4: (width + 7) // 8 * height}.get(
        kind, samples * (1 if maxval < 256 else 2)
    )
    if need > size - offset:
        raise read_error(
            path,
            f"truncated PNM file (its header declares {width}x{height}, which needs "
            f"{need:,} bytes of pixel data; the file holds {max(size - offset, 0):,})",
        )
    # Pillow's raw PGM/PPM decoder for a maxval other than 255 converts a sample at a time
    # in Python and rescales it: those are read by numpy instead
    decoder = "numpy" if kind in (5, 6) and maxval != 255 else "pillow"
    header = ImageHeader(width, height, channels, maxval.bit_length(), "PNM")
    return Probe(header, decoder, details={"kind": kind, "maxval": maxval, "offset": offset})
