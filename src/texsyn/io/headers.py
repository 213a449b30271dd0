"""Image headers read without decoding pixels, and the pixel budget checked against them.

Every format texsyn reads has its header parsed here by a small, bounded parser: each read
is checked against the file's length, every loop advances through the file, and nothing is
allocated in proportion to what a header *declares*. The header is then compared with the
pixel budget (``TEXSYN_MAX_PIXELS``) before a single pixel is decoded, so that a small file
that declares a huge image (a "decompression bomb") is refused at once and cheaply.

See ``docs/reading.md`` for the policy.
"""

from __future__ import annotations

import os
import re
import stat
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from ..errors import (
    ImageReadError,
    ImageTooLargeError,
    InputError,
    InputFileNotFoundError,
)

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "MAX_PIXELS_ENV",
    "ImageHeader",
    "read_image_header",
    "max_image_pixels",
    "check_image_size",
]

#: The variable that sets the pixel budget.
MAX_PIXELS_ENV = "TEXSYN_MAX_PIXELS"

#: Default pixel budget: 40 megapixels. A texture exemplar is rarely above 4 megapixels and
#: most methods become impractically slow long before 40; the default still admits a full
#: photograph from nearly every camera (24-36 MP is typical) while keeping the decoded
#: float32 copy of an 8-bit RGBA image under 800 MB.
DEFAULT_MAX_PIXELS = 40_000_000

#: Bytes per pixel of the image the memory budget is sized for: an 8-bit RGBA image (4 bytes)
#: plus its float32 copy (16 bytes). The memory budget is this times the pixel budget.
REFERENCE_BYTES_PER_PIXEL = 20

#: Largest width or height any format texsyn reads may declare (PNG's own limit, 2**31 - 1).
_MAX_SIDE = 2**31 - 1
#: A PNM header (magic, comments, sizes) longer than this is refused.
_MAX_PNM_HEADER = 64 * 1024
#: A TIFF directory with more entries than this is refused (real files hold a few dozen).
_MAX_TIFF_ENTRIES = 4096

#: Headers are read through a cache of this many bytes (many small reads, few system calls).
_WINDOW = 64 * 1024

_FORMAT_NAMES = "PNG, JPEG, TIFF, BMP, GIF, WebP, PNM (PBM/PGM/PPM)"


@dataclass(frozen=True)
class ImageHeader:
    """What an image file declares, read without decoding its pixels.

    Attributes
    ----------
    width, height : int
        Size in pixels as declared by the file (both at least 1).
    channels : int
        Channels texsyn decodes the image to, alpha included: 1 (grey), 2 (grey + alpha),
        3 (RGB) or 4 (RGBA). Palette images count as RGB (RGBA with a transparent entry);
        CMYK and YCbCr images count as RGB, since that is what they are converted to.
        For a palette BMP this is an upper bound (a grey palette decodes to 1 channel).
    bit_depth : int
        Bits per sample stored in the file: 1, 2, 4, 8 or 16 for most formats, the PNM
        maxval's bit length (e.g. 12 for maxval 4095), 32 or 64 for float TIFF.
    format : str
        ``"PNG"``, ``"JPEG"``, ``"TIFF"``, ``"BMP"``, ``"GIF"``, ``"WEBP"`` or ``"PNM"``.
    """

    width: int
    height: int
    channels: int
    bit_depth: int
    format: str

    @property
    def pixels(self) -> int:
        """``width * height``."""
        return self.width * self.height

    @property
    def bytes_per_sample(self) -> int:
        """Bytes one decoded sample takes before conversion to float32 (1, 2, 4 or 8)."""
        for size in (1, 2, 4):
            if self.bit_depth <= 8 * size:
                return size
        return 8

    @property
    def decoded_bytes(self) -> int:
        """Memory the decoded image needs: the samples as stored plus their float32 copy."""
        return self.pixels * self.channels * (self.bytes_per_sample + 4)


# --------------------------------------------------------------------------- the budget


def max_image_pixels() -> int:
    """The pixel budget: the most pixels (``width * height``) an image file may declare.

    Read from the environment variable ``TEXSYN_MAX_PIXELS`` on every call: a positive whole
    number, optionally followed by ``K`` (thousand) or ``M`` (million), e.g. ``40M`` or
    ``250000``. Without the variable the budget is :data:`DEFAULT_MAX_PIXELS` (40 million).

    Returns
    -------
    int

    Raises
    ------
    InputError
        The variable is set to something else than a positive whole number of pixels.
    """
    text = os.environ.get(MAX_PIXELS_ENV)
    if text is None or not text.strip():
        return DEFAULT_MAX_PIXELS
    match = re.fullmatch(r"\s*([0-9]{1,15})\s*([kKmM]?)\s*", text)
    value = 0
    if match:
        value = int(match.group(1)) * {"": 1, "K": 10**3, "M": 10**6}[match.group(2).upper()]
    if value < 1:
        raise InputError(
            f"{MAX_PIXELS_ENV} must be a positive whole number of pixels, optionally with a "
            f"K (thousand) or M (million) suffix such as 40M, got {text[:40]!r}"
        )
    return value


def _human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def check_image_size(
    header: ImageHeader, path: str | os.PathLike | None = None, *, max_pixels: int | None = None
) -> None:
    """Refuse an image whose declared size exceeds the pixel budget or its memory equivalent.

    Parameters
    ----------
    header : ImageHeader
        What the file declares (from :func:`read_image_header`).
    path : str or path-like, optional
        The file, named in the message.
    max_pixels : int, optional
        The budget; by default :func:`max_image_pixels` (``TEXSYN_MAX_PIXELS``).

    Raises
    ------
    ImageTooLargeError
        ``width * height`` exceeds the budget, or the decoded samples plus their float32
        copy would need more than ``20 * budget`` bytes (what an 8-bit RGBA image at the
        budget needs), e.g. a 16-bit RGBA image above 5/6 of the budget.
    InputError
        ``TEXSYN_MAX_PIXELS`` is not a valid value.
    """
    budget = max_image_pixels() if max_pixels is None else int(max_pixels)
    name = _show(path) if path is not None else "the image"
    size = f"{header.width}x{header.height}"
    if header.pixels > budget:
        raise ImageTooLargeError(
            f"'{name}' declares {size} pixels ({_amount(header.pixels)}), more than the "
            f"{_amount(budget)} allowed; set {MAX_PIXELS_ENV}={_suggest(header.pixels)} to allow it"
        )
    memory = REFERENCE_BYTES_PER_PIXEL * budget
    if header.decoded_bytes > memory:
        need = -(-header.decoded_bytes // REFERENCE_BYTES_PER_PIXEL)
        raise ImageTooLargeError(
            f"'{name}' declares {size} pixels of {header.channels}x{header.bit_depth} bits: "
            f"{_human_bytes(header.decoded_bytes)} to decode, more than the {_human_bytes(memory)} "
            f"{MAX_PIXELS_ENV}={budget} allows; set it to {_suggest(need)} to allow it"
        )


def _amount(n: int) -> str:
    """A pixel count for messages: '40 million', '1.5 million', '250,000'."""
    if n >= 10**6:
        return f"{n / 10**6:.1f}".removesuffix(".0") + " million"
    return f"{n:,}"


def _suggest(n: int) -> str:
    """A value of TEXSYN_MAX_PIXELS at least ``n``, rounded up to a whole unit."""
    return f"{-(-n // 10**6)}M" if n >= 10**6 else f"{-(-n // 10**3)}K"


# --------------------------------------------------------------------------- file access


def _show(path: str | os.PathLike) -> str:
    """The path as the user gave it, shortened in the middle so that messages stay one short line."""
    text = os.fspath(path)
    if isinstance(text, bytes):  # pragma: no cover - bytes paths
        text = text.decode(errors="replace")
    text = text.replace("\n", "?").replace("\r", "?")
    return text if len(text) <= 70 else text[:20] + "..." + text[-47:]


def _error(path: str | os.PathLike, problem: str) -> ImageReadError:
    problem = " ".join(problem.split())
    if len(problem) > 125:
        problem = problem[:122] + "..."
    return ImageReadError(f"cannot read '{_show(path)}': {problem}")


class _Source:
    """A binary file with reads checked against its length (every read names what it wanted)."""

    def __init__(self, fh: BinaryIO, size: int, path: str | os.PathLike, fmt: str):
        self.fh = fh
        self.size = size
        self.path = path
        self.fmt = fmt
        self._window: tuple[int, bytes] = (0, b"")

    def fail(self, problem: str) -> ImageReadError:
        return _error(self.path, problem)

    def truncated(self, what: str, end: int) -> ImageReadError:
        return self.fail(
            f"truncated {self.fmt} file ({what} would end at byte {end}, the file has {self.size} bytes)"
        )

    def read(self, offset: int, n: int, what: str) -> bytes:
        if offset < 0 or n < 0 or offset + n > self.size:
            raise self.truncated(what, offset + n)
        start, window = self._window
        if start <= offset and offset + n <= start + len(window):
            return window[offset - start : offset - start + n]
        self.fh.seek(offset)
        data = self.fh.read(max(n, _WINDOW) if n <= _WINDOW else n)
        if len(data) < n:
            raise self.truncated(what, offset + n)
        if n <= _WINDOW:
            self._window = (offset, data)
        return data[:n]

    def unpack(self, fmt: str, offset: int, what: str) -> tuple:
        return struct.unpack(fmt, self.read(offset, struct.calcsize(fmt), what))


def _open_checked(path: str | os.PathLike) -> tuple[BinaryIO, int]:
    """Open a regular file for reading; refuse missing files, folders and special files."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise InputFileNotFoundError(f"no such file: '{_show(path)}'") from None
    except OSError as exc:
        raise _error(path, f"cannot access it ({exc.strerror or type(exc).__name__})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ImageReadError(f"'{_show(path)}' is a folder, not an image file")
    if not stat.S_ISREG(st.st_mode):
        raise _error(path, "not a regular file (a device, pipe or socket)")
    try:
        fh = open(p, "rb")
    except OSError as exc:
        raise _error(path, f"cannot open it ({exc.strerror or type(exc).__name__})") from None
    size = os.fstat(fh.fileno()).st_size
    return fh, size


# --------------------------------------------------------------------------- probing


@dataclass(frozen=True)
class _Probe:
    """A header plus what the decoder needs to know about the file's layout."""

    header: ImageHeader
    info: dict


def read_image_header(path: str | os.PathLike) -> ImageHeader:
    """Read an image file's header (size, channels, bit depth, format) without decoding pixels.

    The header is parsed by a small bounded parser for each format, every read checked
    against the file's length; structural lies that can be seen without decoding (a
    declared size larger than the data, zero sizes, impossible bit depths, PNM maxval out
    of range, chunks or tags running past the end of the file) are reported here.
    The pixel budget is *not* applied: see :func:`check_image_size`.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    ImageHeader

    Raises
    ------
    InputFileNotFoundError
        The file does not exist.
    ImageReadError
        The file is a folder, is empty, is not an image texsyn reads, or its header is
        truncated or inconsistent.

    Examples
    --------
    >>> header = read_image_header("brick.png")  # doctest: +SKIP
    >>> header.width, header.height, header.channels, header.bit_depth, header.format
    (512, 512, 3, 8, 'PNG')
    """
    return _probe(path).header


def _probe(path: str | os.PathLike) -> _Probe:
    fh, size = _open_checked(path)
    try:
        with fh:
            return _probe_open(fh, size, path)
    except InputError:
        raise
    except MemoryError:
        raise _error(path, "not enough memory to read its header") from None
    except Exception as exc:  # a read error, or a case the parsers did not foresee
        text = " ".join(str(exc).split())[:80] or type(exc).__name__
        raise _error(path, f"unreadable image header ({text})") from None


def _probe_open(fh: BinaryIO, size: int, path: str | os.PathLike) -> _Probe:
    if size == 0:
        raise _error(path, "the file is empty (0 bytes)")
    head = fh.read(16)
    for magic, fmt, parser in _SIGNATURES:
        if head.startswith(magic) and (fmt != "WEBP" or head[8:12] == b"WEBP"):
            return parser(_Source(fh, size, path, fmt))
    if len(head) >= 2 and head[0] == 0x50 and 0x31 <= head[1] <= 0x36 and (
        len(head) == 2 or head[2] in _WHITESPACE or head[2] == 0x23
    ):
        return _probe_pnm(_Source(fh, size, path, "PNM"))
    if len(head) < 16 and any(m.startswith(head) for m, _, _ in _SIGNATURES):
        raise _error(path, f"truncated image file ({size} bytes)")
    raise _error(path, f"not an image file texsyn knows; it reads {_FORMAT_NAMES}")


def _check_side(src: _Source, width: int, height: int) -> None:
    if width < 1 or height < 1 or width > _MAX_SIDE or height > _MAX_SIDE:
        raise src.fail(f"the {src.fmt} header declares an impossible size {width}x{height}")


# PNG ---------------------------------------------------------------------------------------

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}
_PNG_FILE_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_PNG_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


def png_raw_size(width: int, height: int, bits_per_pixel: int, interlaced: bool) -> int:
    """Bytes of filtered scanlines (one filter byte per row) a PNG image must decompress to."""

    def rows(w: int, h: int) -> int:
        return 0 if w <= 0 or h <= 0 else h * (1 + (w * bits_per_pixel + 7) // 8)

    if not interlaced:
        return rows(width, height)
    return sum(
        rows((width - x0 + dx - 1) // dx, (height - y0 + dy - 1) // dy) for x0, y0, dx, dy in _PNG_ADAM7
    )


def _probe_png(src: _Source) -> _Probe:
    length, ctype = src.unpack(">I4s", 8, "the IHDR chunk")
    if ctype != b"IHDR" or length != 13:
        raise src.fail("corrupt PNG file (the first chunk is not a 13-byte IHDR)")
    body = src.read(16, 13, "the IHDR chunk")
    (crc,) = src.unpack(">I", 29, "the IHDR chunk")
    if zlib.crc32(b"IHDR" + body) != crc:
        raise src.fail("corrupt PNG file (IHDR checksum mismatch)")
    width, height, depth, colour, compression, filtering, interlace = struct.unpack(">IIBBBBB", body)
    _check_side(src, width, height)
    if colour not in _PNG_DEPTHS:
        raise src.fail(f"corrupt PNG file (unknown colour type {colour})")
    if depth not in _PNG_DEPTHS[colour]:
        raise src.fail(f"corrupt PNG file (bit depth {depth} is not allowed for colour type {colour})")
    if compression != 0 or filtering != 0 or interlace not in (0, 1):
        raise src.fail("corrupt PNG file (unknown compression, filter or interlace method)")
    # walk the chunks up to IEND: every length checked against the file's length
    pos, idat, has_plte, has_trns = 33, [], False, False
    while True:
        length, ctype = src.unpack(">I4s", pos, "a chunk header (the file has no IEND chunk)")
        if length > 2**31 - 1 or not all(65 <= c <= 90 or 97 <= c <= 122 for c in ctype):
            raise src.fail(f"corrupt PNG file (bad chunk at byte {pos})")
        end = pos + 12 + length
        if end > src.size:
            raise src.truncated(f"chunk {ctype.decode()} at byte {pos}", end)
        if ctype == b"IDAT":
            idat.append((pos + 8, length))
        elif ctype == b"PLTE":
            has_plte = True
        elif ctype == b"tRNS":
            has_trns = True
        elif ctype == b"IEND":
            break
        pos = end
    if not idat:
        raise src.fail("corrupt PNG file (no IDAT chunk: no pixel data)")
    if colour == 3 and not has_plte:
        raise src.fail("corrupt PNG file (a palette image without a PLTE chunk)")
    channels = {0: 1, 2: 3, 3: 4 if has_trns else 3, 4: 2, 6: 4}[colour]
    header = ImageHeader(width, height, channels, depth, "PNG")
    info = {
        "colour_type": colour,
        "idat": tuple(idat),
        "raw_size": png_raw_size(width, height, depth * _PNG_FILE_CHANNELS[colour], bool(interlace)),
    }
    return _Probe(header, info)


# PNM ---------------------------------------------------------------------------------------

_WHITESPACE = frozenset(b" \t\n\r\v\f")


def _probe_pnm(src: _Source) -> _Probe:
    kind = int(chr(src.read(1, 1, "the magic number")[0]))
    head = src.read(0, min(src.size, _MAX_PNM_HEADER), "the header")
    names = ("width", "height") if kind in (1, 4) else ("width", "height", "maxval")
    values: list[int] = []
    pos = 2
    for name in names:
        while pos < len(head):  # whitespace and comments
            if head[pos] in _WHITESPACE:
                pos += 1
            elif head[pos] == 0x23:  # '#': a comment up to the end of the line
                ends = [i for i in (head.find(b"\n", pos), head.find(b"\r", pos)) if i >= 0]
                pos = min(ends) + 1 if ends else len(head)
            else:
                break
        if pos >= len(head):
            if len(head) < src.size:
                raise src.fail(f"PNM header longer than {_MAX_PNM_HEADER // 1024} KiB")
            raise src.fail(f"truncated PNM file (it ends before the {name} in its header)")
        start = pos
        while pos < len(head) and 0x30 <= head[pos] <= 0x39 and pos - start <= 12:
            pos += 1
        if pos == start:
            raise src.fail(f"corrupt PNM header (expected the {name} at byte {pos}, found {head[pos:pos + 1]!r})")
        if pos - start > 12:
            raise src.fail(f"corrupt PNM header (the {name} has too many digits)")
        values.append(int(head[start:pos]))
    if pos >= src.size:
        raise src.fail("truncated PNM file (it ends after its header, without pixel data)")
    if pos >= len(head) or head[pos] not in _WHITESPACE:
        raise src.fail(f"corrupt PNM header (byte {pos} should be whitespace after the {names[-1]})")
    width, height = values[0], values[1]
    _check_side(src, width, height)
    maxval = values[2] if len(values) == 3 else 1
    if not 1 <= maxval <= 65535:
        raise src.fail(f"the PNM header declares maxval {maxval}; it must be between 1 and 65535")
    channels = 3 if kind in (3, 6) else 1
    offset = pos + 1
    samples = width * height * channels
    left = src.size - offset
    if kind in (5, 6):
        need = samples * (1 if maxval < 256 else 2)
    elif kind == 4:
        need = (width + 7) // 8 * height
    elif kind == 1:
        need = samples  # one character a pixel at least
    else:
        need = 2 * samples - 1  # a digit and a separator a sample at least
    if need > left:
        raise src.fail(
            f"truncated PNM file (its header declares {width}x{height}, which needs "
            f"{need:,} bytes of pixel data; the file holds {max(left, 0):,})"
        )
    header = ImageHeader(width, height, channels, maxval.bit_length(), "PNM")
    return _Probe(header, {"kind": kind, "maxval": maxval, "offset": offset})


# BMP ---------------------------------------------------------------------------------------


def _probe_bmp(src: _Source) -> _Probe:
    (offset,) = src.unpack("<I", 10, "the file header")
    (dib,) = src.unpack("<I", 14, "the file header")
    if dib == 12:
        width, height, _, bpp = src.unpack("<HHHH", 18, "the BMP header")
        compression = 0
    elif dib in (16, 40, 52, 56, 64, 108, 124):
        if dib == 16:
            width, height, _, bpp = src.unpack("<iiHH", 18, "the BMP header")
            compression = 0
        else:
            width, height, _, bpp, compression = src.unpack("<iiHHI", 18, "the BMP header")
    else:
        raise src.fail(f"corrupt or unsupported BMP file (header size {dib})")
    height = abs(height)  # negative: stored top-down
    _check_side(src, width, height)
    if bpp not in (1, 2, 4, 8, 16, 24, 32):
        raise src.fail(f"corrupt BMP file ({bpp} bits per pixel)")
    if compression not in (0, 1, 2, 3, 6):
        raise src.fail(f"unsupported BMP compression {compression} (texsyn reads raw, RLE and bit-field BMP)")
    if compression in (0, 3, 6):
        end = offset + (bpp * width + 31) // 32 * 4 * height
        if end > src.size:
            raise src.truncated(f"the {width}x{height} pixel data", end)
    elif offset >= src.size:
        raise src.truncated("the pixel data", offset + 1)
    channels = 4 if bpp == 32 and compression in (3, 6) else 3
    return _Probe(ImageHeader(width, height, channels, min(bpp, 8), "BMP"), {})


# GIF ---------------------------------------------------------------------------------------


def _skip_sub_blocks(src: _Source, pos: int, what: str) -> int:
    while True:
        (n,) = src.unpack("B", pos, what)
        pos += 1 + n
        if n == 0:
            return pos


def _probe_gif(src: _Source) -> _Probe:
    width, height, packed = src.unpack("<HHB", 6, "the screen descriptor")
    _check_side(src, width, height)
    pos = 13 + (3 * 2 ** ((packed & 7) + 1) if packed & 0x80 else 0)
    transparent = False
    while True:
        (block,) = src.unpack("B", pos, "the first image")
        if block == 0x21:  # extension: label, then sub-blocks
            (label,) = src.unpack("B", pos + 1, "an extension block")
            if label == 0xF9:
                size, flags = src.unpack("BB", pos + 2, "a graphic control extension")
                transparent = size >= 1 and bool(flags & 1)
            pos = _skip_sub_blocks(src, pos + 2, "an extension block")
        elif block == 0x2C:  # the first image: descriptor, colour table, LZW data
            (local,) = src.unpack("B", pos + 9, "the image descriptor")
            pos += 10 + (3 * 2 ** ((local & 7) + 1) if local & 0x80 else 0)
            src.read(pos, 1, "the image data")
            _skip_sub_blocks(src, pos + 1, "the image data")
            break
        elif block == 0x3B:
            raise src.fail("corrupt GIF file (it holds no image)")
        else:
            raise src.fail(f"corrupt GIF file (unknown block 0x{block:02x} at byte {pos})")
    return _Probe(ImageHeader(width, height, 4 if transparent else 3, 8, "GIF"), {})


# WebP --------------------------------------------------------------------------------------


def _probe_webp(src: _Source) -> _Probe:
    (riff_size,) = src.unpack("<I", 4, "the RIFF header")
    if riff_size + 8 > src.size:
        raise src.truncated("the RIFF container", riff_size + 8)
    fourcc = src.read(12, 4, "the first chunk")
    if fourcc == b"VP8 ":
        start, width, height = src.unpack("<3sHH", 23, "the VP8 frame header")
        if start != b"\x9d\x01\x2a":
            raise src.fail("corrupt WebP file (bad VP8 start code)")
        width, height, channels = width & 0x3FFF, height & 0x3FFF, 3
    elif fourcc == b"VP8L":
        signature, bits = src.unpack("<BI", 20, "the VP8L header")
        if signature != 0x2F:
            raise src.fail("corrupt WebP file (bad VP8L signature)")
        width, height = (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
        channels = 4 if bits >> 28 & 1 else 3
    elif fourcc == b"VP8X":
        (flags,) = src.unpack("B", 20, "the VP8X header")
        raw = src.read(24, 6, "the VP8X header")
        width = int.from_bytes(raw[:3], "little") + 1
        height = int.from_bytes(raw[3:], "little") + 1
        channels = 4 if flags & 0x10 else 3
    else:
        raise src.fail(f"corrupt WebP file (unknown first chunk {fourcc!r})")
    _check_side(src, width, height)
    return _Probe(ImageHeader(width, height, channels, 8, "WEBP"), {})


# JPEG --------------------------------------------------------------------------------------

_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _probe_jpeg(src: _Source) -> _Probe:
    pos = 2
    while True:
        (byte,) = src.unpack("B", pos, "a marker (no frame header found)")
        if byte != 0xFF:
            raise src.fail(f"corrupt JPEG file (expected a marker at byte {pos})")
        while byte == 0xFF:  # fill bytes
            pos += 1
            (byte,) = src.unpack("B", pos, "a marker (no frame header found)")
        marker, pos = byte, pos + 1
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:
            continue  # markers without a length
        if marker in (0xD9, 0xDA):
            raise src.fail("corrupt JPEG file (image data before a frame header)")
        (length,) = src.unpack(">H", pos, "a segment length")
        if length < 2:
            raise src.fail(f"corrupt JPEG file (segment length {length} at byte {pos})")
        if marker in _JPEG_SOF:
            precision, height, width, components = src.unpack(">BHHB", pos + 2, "the frame header")
            if length < 8 + 3 * components:
                raise src.fail("corrupt JPEG file (short frame header)")
            if components not in (1, 3, 4):
                raise src.fail(f"unsupported JPEG file ({components} colour components)")
            if height == 0:
                raise src.fail("unsupported JPEG file (height defined after the scan, DNL)")
            _check_side(src, width, height)
            if pos + length > src.size:
                raise src.truncated("the frame header", pos + length)
            channels = 1 if components == 1 else 3  # CMYK/YCCK become RGB
            return _Probe(ImageHeader(width, height, channels, precision, "JPEG"), {})
        pos += length
        if pos > src.size:
            raise src.truncated(f"segment 0x{marker:02x}", pos)


# TIFF --------------------------------------------------------------------------------------

_TIFF_TYPE_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4, 16: 8, 17: 8, 18: 8}
_TIFF_INT_TYPES = {1: "B", 3: "H", 4: "I", 6: "b", 8: "h", 9: "i", 13: "I", 16: "Q", 17: "q", 18: "Q"}
_TIFF_WANTED = {256, 257, 258, 259, 262, 273, 277, 278, 279, 284, 322, 323, 324, 325, 338, 339}
_TIFF_PHOTOMETRIC = {0: "min-is-white", 1: "min-is-black", 2: "RGB", 3: "palette", 5: "CMYK", 6: "YCbCr"}


def _probe_tiff(src: _Source) -> _Probe:
    order = "<" if src.read(0, 2, "the byte order") == b"II" else ">"
    (version,) = src.unpack(order + "H", 2, "the TIFF header")
    if version == 42:
        (ifd,) = src.unpack(order + "I", 4, "the TIFF header")
        count_fmt, entry_fmt, entry_size, inline = "H", "HHI4s", 12, 4
    elif version == 43:
        offset_size, _, ifd = src.unpack(order + "HHQ", 4, "the BigTIFF header")
        if offset_size != 8:
            raise src.fail("corrupt BigTIFF file (offset size is not 8)")
        count_fmt, entry_fmt, entry_size, inline = "Q", "HHQ8s", 20, 8
    else:
        raise src.fail(f"corrupt TIFF file (version {version})")
    if ifd < 8 or ifd >= src.size:
        raise src.truncated("the first image directory", ifd + 2)
    (n,) = src.unpack(order + count_fmt, ifd, "the first image directory")
    if n == 0 or n > _MAX_TIFF_ENTRIES:
        raise src.fail(f"corrupt TIFF file (image directory with {n} entries)")
    start = ifd + struct.calcsize(count_fmt)
    table = src.read(start, n * entry_size, "the first image directory")
    tags: dict[int, tuple[int, ...]] = {}
    for i in range(n):
        tag, typ, count, field = struct.unpack(order + entry_fmt, table[i * entry_size : (i + 1) * entry_size])
        size = _TIFF_TYPE_SIZES.get(typ)
        if size is None:
            continue  # unknown type: readers skip it
        nbytes = size * count
        if nbytes > inline:
            (where,) = struct.unpack(order + ("I" if inline == 4 else "Q"), field)
            if where + nbytes > src.size:
                raise src.truncated(f"the data of TIFF tag {tag}", where + nbytes)
        if tag not in _TIFF_WANTED:
            continue
        if typ not in _TIFF_INT_TYPES:
            raise src.fail(f"corrupt TIFF file (tag {tag} has type {typ})")
        data = field[:nbytes] if nbytes <= inline else src.read(where, nbytes, f"TIFF tag {tag}")
        tags[tag] = struct.unpack(f"{order}{count}{_TIFF_INT_TYPES[typ]}", data)

    def one(tag: int, default: int | None = None) -> int:
        values = tags.get(tag)
        if not values:
            if default is None:
                raise src.fail(f"corrupt TIFF file (required tag {tag} is missing)")
            return default
        return int(values[0])

    width, height = one(256), one(257)
    _check_side(src, width, height)
    spp = one(277, 1)
    depths = set(tags.get(258) or (1,))
    if len(depths) != 1:
        raise src.fail(f"unsupported TIFF file (different bit depths per sample: {sorted(depths)[:4]})")
    bps = depths.pop()
    if spp < 1 or spp > 16 or bps not in (1, 2, 4, 8, 16, 32, 64):
        raise src.fail(f"unsupported TIFF file ({spp} samples of {bps} bits per pixel)")
    compression = one(259, 1)
    photometric = one(262, 2 if spp >= 3 else 1)
    sample_format = one(339, 1)
    planar = one(284, 1)
    if photometric not in _TIFF_PHOTOMETRIC:
        raise src.fail(f"unsupported TIFF colour model (photometric {photometric})")
    base = {0: 1, 1: 1, 2: 3, 3: 1, 5: 4, 6: 3}[photometric]
    if spp < base or spp > base + 1 or (spp == base + 1 and photometric in (3, 5, 6)):
        raise src.fail(f"unsupported TIFF layout ({spp} samples in a {_TIFF_PHOTOMETRIC[photometric]} image)")
    if sample_format not in (1, 3) or (sample_format == 3 and bps not in (32, 64)):
        raise src.fail(f"unsupported TIFF sample format {sample_format} with {bps} bits")
    tiled = 324 in tags or 322 in tags
    offsets = tags.get(324 if tiled else 273)
    counts = tags.get(325 if tiled else 279)
    if not offsets:
        raise src.fail("corrupt TIFF file (no strip or tile offsets)")
    row_bytes = (width * (spp if planar == 1 else 1) * bps + 7) // 8
    least = row_bytes * height * (1 if planar == 1 else spp)  # uncompressed pixel data, at least
    if counts is None:
        if compression != 1 or len(offsets) != 1:
            raise src.fail("corrupt TIFF file (no strip byte counts)")
        counts = (least,)
    if len(counts) != len(offsets):
        raise src.fail("corrupt TIFF file (strip offsets and byte counts differ in number)")
    for offset, count in zip(offsets, counts):
        if count and offset + count > src.size:
            raise src.truncated("the pixel data", offset + count)
    if compression == 1 and photometric != 6 and sum(counts) < least:
        raise src.fail(
            f"truncated TIFF file (its header declares {width}x{height}, which needs "
            f"{least:,} bytes of pixel data; the strips hold {sum(counts):,})"
        )
    channels = 3 if photometric in (3, 5, 6) else spp
    header = ImageHeader(width, height, channels, bps, "TIFF")
    info = {
        "photometric": photometric,
        "compression": compression,
        "samples": spp,
        "sample_format": sample_format,
        "planar": planar,
        "segments": tuple(zip(offsets, counts)),
        "least": least,
    }
    return _Probe(header, info)


_SIGNATURES = (
    (_PNG_SIGNATURE, "PNG", _probe_png),
    (b"\xff\xd8\xff", "JPEG", _probe_jpeg),
    (b"II*\x00", "TIFF", _probe_tiff),
    (b"MM\x00*", "TIFF", _probe_tiff),
    (b"II+\x00", "TIFF", _probe_tiff),
    (b"MM\x00+", "TIFF", _probe_tiff),
    (b"GIF87a", "GIF", _probe_gif),
    (b"GIF89a", "GIF", _probe_gif),
    (b"RIFF", "WEBP", _probe_webp),
    (b"BM", "BMP", _probe_bmp),
)
