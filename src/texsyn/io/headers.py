"""Image headers read without decoding pixels, and the pixel budget checked against them.

A header comes from Pillow's lazy open: a format plugin reads the file's header (size,
mode, for TIFF its tags) and decodes nothing until ``load()``. texsyn takes the two steps
``Image.open`` takes (the plugin's ``accept`` on the first bytes, then its factory) without
the third, Pillow's own pixel-count check, so that texsyn's budget answers first. Where
Pillow hides what texsyn needs, a tiny read at fixed offsets completes it:

- PNG: the IHDR fields at bytes 16-28 (Pillow's mode does not say that a colour PNG is
  16-bit, and the decoder's guard needs the exact size of the pixel data);
- WebP: the canvas size in the first 30 bytes, read *instead of* Pillow's open, which reads
  the whole file and creates libwebp's decoder (that allocates the canvas);
- PNM: the header's tokens (at most 64 KiB), so that a message names the missing or
  impossible field and a file too short for its declared size is called truncated;
- TIFF that Pillow has no mode for (16-bit grey + alpha, float RGB, 64-bit float): the
  first page's header, from tifffile.

Two checks are added where Pillow's decoders are lenient, from Pillow's own tiles (where
it will read the pixel data): the rows of an uncompressed BMP, padding included, must lie
within the file, and the strips of an uncompressed TIFF must cover the whole image.

The header is then compared with the pixel budget (``TEXSYN_MAX_PIXELS``) before a single
pixel is decoded, so that a small file that declares a huge image (a "decompression bomb")
is refused at once and cheaply. See ``docs/reading.md`` for the policy.
"""

from __future__ import annotations

import functools
import os
import re
import stat
import struct
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO

from .._validation import human_bytes
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

#: Largest ratio of decoded bytes (samples as stored) to file bytes accepted for an image
#: that decodes to more than :data:`COMPRESSION_FLOOR_BYTES`. Photographed and scanned
#: textures compress 1:1 to about 20:1 (the 32 development exemplars: 1.0 to 98, the 98 a
#: synthetic checkerboard); a small file that declares a large image is a decompression bomb
#: (or a lying header that a decoder would pad with grey), refused before decoding.
MAX_COMPRESSION_RATIO = 250

#: Images that decode to at most this many bytes are accepted whatever their compression.
COMPRESSION_FLOOR_BYTES = 1 << 20

#: A PNM header (magic, comments, sizes) longer than this is refused.
_MAX_PNM_HEADER = 64 * 1024

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
        For WebP this is what the header's alpha flag says.
    bit_depth : int
        Bits per sample: as stored for PNG (1-16) and TIFF (1-16; 32 or 64 for float),
        the maxval's bit length for PNM (e.g. 12 for maxval 4095); otherwise that of
        Pillow's mode: 8, or 1 for a bilevel BMP.
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


def check_image_size(
    header: ImageHeader,
    path: str | os.PathLike | None = None,
    *,
    max_pixels: int | None = None,
    file_size: int | None = None,
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
    file_size : int, optional
        The file's length in bytes; when given, an image that decodes to more than
        :data:`COMPRESSION_FLOOR_BYTES` and more than :data:`MAX_COMPRESSION_RATIO` times the
        file's length is refused as a decompression bomb.

    Raises
    ------
    ImageTooLargeError
        ``width * height`` exceeds the budget, or the decoded samples plus their float32
        copy would need more than ``20 * budget`` bytes (what an 8-bit RGBA image at the
        budget needs), e.g. a 16-bit RGBA image above 5/6 of the budget; or, with
        ``file_size``, the file is a decompression bomb (see ``file_size``).
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
    stored = header.pixels * header.channels * header.bytes_per_sample
    if file_size is not None and stored > max(COMPRESSION_FLOOR_BYTES, MAX_COMPRESSION_RATIO * file_size):
        raise ImageTooLargeError(
            f"'{name}' declares {size} pixels in {file_size} bytes, over {MAX_COMPRESSION_RATIO}:1: "
            "refused as a decompression bomb (a real image may be saved uncompressed, e.g. BMP)"
        )
    memory = REFERENCE_BYTES_PER_PIXEL * budget
    if header.decoded_bytes > memory:
        need = -(-header.decoded_bytes // REFERENCE_BYTES_PER_PIXEL)
        raise ImageTooLargeError(
            f"'{name}' declares {size} pixels of {header.channels}x{header.bit_depth} bits: "
            f"{human_bytes(header.decoded_bytes)} to decode, more than the {human_bytes(memory)} "
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


def _said(exc: BaseException, path: str | os.PathLike) -> str:
    """A library's complaint, in one short line, without the path (the message names it once)."""
    text = str(exc)
    for name in {os.fspath(path), str(Path(path)), Path(path).name} - {""}:
        text = text.replace(repr(name), "it").replace(name, "it")
    return (" ".join(text.split()) or type(exc).__name__)[:90]


def _open_checked(path: str | os.PathLike) -> tuple[BinaryIO, int]:
    """Open a regular file for reading; refuse missing files, folders and special files
    (a pipe is never opened, so that a read cannot block)."""
    if not os.fspath(path):  # Path("") is the current folder
        raise InputFileNotFoundError("no such file: '' (an empty file name)")
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
    return fh, os.fstat(fh.fileno()).st_size


# --------------------------------------------------------------------------- libraries


@functools.cache
def _quiet_library_logs() -> None:
    """Keep Pillow's and tifffile's log records about odd files off stderr.

    Both log complaints about a broken file (e.g. Pillow's TIFF plugin: "More samples per
    pixel than can be decoded") before raising; with no handler configured, Python's
    last-resort handler would print them beside texsyn's one-line error. A ``NullHandler``
    on their loggers stops that; an application that configures logging still gets them.
    """
    import logging

    for name in ("PIL", "tifffile"):
        logging.getLogger(name).addHandler(logging.NullHandler())


# --------------------------------------------------------------------------- Pillow

#: The Pillow formats texsyn reads (PNM is recognised by texsyn, see _probe_pnm).
_PILLOW_FORMATS = ("PNG", "JPEG", "TIFF", "GIF", "WEBP", "BMP")

#: Pillow mode -> the mode texsyn decodes it to (``P``: RGB, or RGBA with transparency).
_PIL_TARGETS = {
    "1": "1", "L": "L", "LA": "LA", "RGB": "RGB", "RGBA": "RGBA", "I": "I", "F": "F",
    "I;16": "I;16", "I;16L": "I;16L", "I;16B": "I;16B", "I;16N": "I;16N",
    "PA": "RGBA", "La": "LA", "RGBa": "RGBA", "RGBX": "RGB",
    "CMYK": "RGB", "YCbCr": "RGB", "LAB": "RGB", "HSV": "RGB",
}


@functools.cache
def _pillow():
    """PIL.Image with the plugins of the formats texsyn reads registered."""
    _quiet_library_logs()
    from PIL import (  # noqa: F401 - importing a plugin registers its format
        BmpImagePlugin,
        GifImagePlugin,
        Image,
        JpegImagePlugin,
        PngImagePlugin,
        PpmImagePlugin,
        TiffImagePlugin,
        WebPImagePlugin,
    )

    return Image


def _pillow_open(fh: BinaryIO, fmt: str, path: str | os.PathLike):
    """Pillow's lazy open of ``fh`` as format ``fmt``: the header is read, nothing is decoded.

    This is ``Image.open(fh, formats=[fmt])`` without its last step, Pillow's pixel-count
    check (``Image.MAX_IMAGE_PIXELS``), which would refuse or warn about an image before
    texsyn can check its own budget, and whose error does not say the image's size.
    Where a plugin still runs that check itself (a WebP, GIF frame or TIFF tile beyond
    Pillow's limit), its error becomes an :class:`ImageTooLargeError`.

    Raises
    ------
    ImageReadError
        Pillow cannot read the header; the message is Pillow's, in one line.
    """
    Image = _pillow()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # EXIF and metadata complaints are not the user's concern
            return Image.OPEN[fmt][0](fh, os.fspath(path))
    except Image.DecompressionBombError:
        raise ImageTooLargeError(
            f"'{_show(path)}' declares more than {_amount(2 * (Image.MAX_IMAGE_PIXELS or 0))} pixels, "
            f"which Pillow refuses to decode (PIL.Image.MAX_IMAGE_PIXELS)"
        ) from None
    except MemoryError:
        raise
    except Exception as exc:  # SyntaxError, OSError, ValueError, struct.error...
        raise _error(path, f"corrupt or unsupported {fmt} file ({_said(exc, path)})") from None


def _pillow_target(im) -> str:
    """The Pillow mode texsyn decodes an image of mode ``im.mode`` to."""
    if im.mode == "P":
        return "RGBA" if "transparency" in im.info else "RGB"
    return _PIL_TARGETS.get(im.mode, "")


def _mode_bits(mode: str) -> int:
    return 1 if mode == "1" else 16 if mode.startswith("I;16") else 32 if mode in ("I", "F") else 8


# --------------------------------------------------------------------------- probing


@dataclass(frozen=True)
class _Probe:
    """A header, plus how to decode the file and what the decoder must check.

    ``decoder`` is ``"pillow"``, ``"pypng"``, ``"tifffile"`` or ``"numpy"`` (raw PNM);
    ``mode`` and ``target`` are Pillow's mode at open and the mode to decode to (``None``
    where Pillow did not open the file); ``details`` holds what the guards need.
    """

    header: ImageHeader
    decoder: str = "pillow"
    mode: str | None = None
    target: str | None = None
    details: dict = field(default_factory=dict)


def read_image_header(path: str | os.PathLike) -> ImageHeader:
    """Read an image file's header (size, channels, bit depth, format) without decoding pixels.

    The header is what Pillow's lazy open reads, completed by a few bytes read at fixed
    offsets where Pillow does not tell (see the module's docstring); a header that Pillow
    cannot read, a zero or impossible size, a PNM maxval out of range or a PNM file too
    short for its declared size are reported here. The pixel budget is *not* applied: see
    :func:`check_image_size`.

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
            probe = _probe_open(fh, size, path)
    except InputError:
        raise
    except MemoryError:
        raise _error(path, "not enough memory to read its header") from None
    except Exception as exc:  # a read error, or a case nobody foresaw
        raise _error(path, f"unreadable image header ({_said(exc, path)})") from None
    h = probe.header
    if h.width < 1 or h.height < 1 or not 1 <= h.channels <= 4:
        raise _error(path, f"the {h.format} header declares an impossible image "
                           f"({h.width}x{h.height}, {h.channels} channels)")
    return probe


def _probe_open(fh: BinaryIO, size: int, path: str | os.PathLike) -> _Probe:
    if size == 0:
        raise _error(path, "the file is empty (0 bytes)")
    head = fh.read(16)
    if _PNM_MAGIC.match(head):
        return _probe_pnm(fh, size, path)
    Image = _pillow()
    for fmt in _PILLOW_FORMATS:
        accepted = Image.OPEN[fmt][1](head)
        if isinstance(accepted, str):  # e.g. "WEBP support not installed"
            raise _error(path, accepted)
        if accepted:
            break
    else:
        raise _error(path, f"not an image file texsyn knows; it reads {_FORMAT_NAMES}")
    if fmt == "WEBP":
        return _probe_webp(fh, path)
    fh.seek(0)
    try:
        im = _pillow_open(fh, fmt, path)
    except ImageTooLargeError:
        raise
    except ImageReadError as exc:
        if fmt == "TIFF":  # Pillow has no mode for it: perhaps tifffile reads it
            return _probe_tifffile(path, exc)
        raise
    with im:
        target = _pillow_target(im)
        if not target:
            raise _error(path, f"unsupported {fmt} pixel mode {im.mode}")
        bits = getattr(im, "bits", 8) if fmt == "JPEG" else _mode_bits(im.mode)
        header = ImageHeader(im.size[0], im.size[1], Image.getmodebands(target), bits, fmt)
        probe = _Probe(header, "pillow", im.mode, target)
        if fmt == "PNG":
            return _probe_png(im, fh, probe, path)
        if fmt == "TIFF":
            return _probe_tiff(im, probe, path)
        if fmt == "BMP" and im.tile and im.tile[0][0] == "raw":
            # Pillow's raw decoder does not need the last row's padding, so a file cut
            # there would be read: the rows, padding included, must all be in the file
            end = im.tile[0][2] + im.tile[0][3][1] * im.size[1]
            if end > size:
                raise _error(path, f"truncated BMP file (its pixel data would end at byte {end:,}, "
                                   f"the file has {size:,} bytes)")
        return probe


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


def _probe_png(im, fh: BinaryIO, probe: _Probe, path) -> _Probe:
    """Add what Pillow does not expose, from the IHDR chunk at bytes 12-28: the bit depth
    (a 16-bit colour PNG goes to pypng, which keeps 16 bits) and the exact size of the
    inflated pixel data, with the offset of the first IDAT chunk (for the decoder's guard)."""
    fh.seek(12)
    ihdr = fh.read(17)
    if len(ihdr) != 17 or ihdr[:4] != b"IHDR":
        raise _error(path, "corrupt PNG file (the first chunk is not IHDR)")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", ihdr[4:])
    if (width, height) != im.size or colour not in _PNG_SAMPLES or not im.tile:
        raise _error(path, "corrupt PNG file (inconsistent IHDR chunk)")
    details = {
        "first_idat": im.tile[0][2],
        "raw_size": png_raw_size(width, height, depth * _PNG_SAMPLES[colour], interlace == 1),
    }
    decoder = "pypng" if depth == 16 and colour in (2, 4, 6) else "pillow"
    header = replace(probe.header, bit_depth=depth)
    return replace(probe, header=header, decoder=decoder, details=details)


# TIFF --------------------------------------------------------------------------------------


def _probe_tiff(im, probe: _Probe, path) -> _Probe:
    """The bit depth from the BitsPerSample tag; a 16-bit colour TIFF, which Pillow would
    cut to 8 bits (mode RGB or RGBA), goes to tifffile."""
    bits = max(im.tag_v2.get(258) or (1,))
    decoder = "tifffile" if bits > 8 and not im.mode.startswith(("I", "F")) else "pillow"
    if decoder == "pillow" and im.tile and im.tile[0][0] == "raw":
        # Pillow's raw decoder leaves the rows of missing strips blank, so a small file
        # that declares a tall image would be read, slowly, as a black one
        covered = sum((x1 - x0) * (y1 - y0) for _, (x0, y0, x1, y1), *_ in im.tile)
        if covered < probe.header.pixels:
            raise _error(path, f"truncated TIFF file (its strips hold {covered:,} of the "
                               f"{probe.header.pixels:,} pixels its header declares)")
    return replace(probe, header=replace(probe.header, bit_depth=bits), decoder=decoder)


def _probe_tifffile(path: str | os.PathLike, pillow_error: ImageReadError) -> _Probe:
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
        raise _error(path, f"unsupported TIFF file ({samples} samples of {bits} bits, sample format {kind})")
    return _Probe(ImageHeader(width, height, samples, bits, "TIFF"), "tifffile")


# WebP --------------------------------------------------------------------------------------


def _probe_webp(fh: BinaryIO, path) -> _Probe:
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
        raise _error(path, "truncated or corrupt WebP file (no VP8, VP8L or VP8X header)")
    return _Probe(ImageHeader(width, height, channels, 8, "WEBP"))


# PNM (PBM, PGM, PPM) -----------------------------------------------------------------------

_PNM_MAGIC = re.compile(rb"P[1-6](?:[ \t\n\r\v\f#]|\Z)")
#: A header field: whitespace and comments (``#`` to the end of the line), then digits.
_PNM_FIELD = re.compile(rb"(?:[ \t\n\r\v\f]|#[^\n\r]*(?:[\n\r]|\Z))*(\d*)")


def _probe_pnm(fh: BinaryIO, size: int, path) -> _Probe:
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
        pos = match.end()
        if not match[1]:
            if pos < len(head):
                raise _error(path, f"corrupt PNM header (expected the {name} at byte {pos}, found {head[pos:pos + 1]!r})")
            if len(head) < size:
                raise _error(path, f"PNM header longer than {_MAX_PNM_HEADER // 1024} KiB")
            raise _error(path, f"truncated PNM file (it ends before the {name} in its header)")
        if len(match[1]) > 12:
            raise _error(path, f"corrupt PNM header (the {name} has too many digits)")
        values.append(int(match[1]))
    if pos >= size:
        raise _error(path, "truncated PNM file (it ends after its header, without pixel data)")
    if head[pos] not in b" \t\n\r\v\f":
        raise _error(path, f"corrupt PNM header (byte {pos} should be whitespace after the {names[-1]})")
    width, height, maxval = values[0], values[1], values[2] if kind not in (1, 4) else 1
    if width < 1 or height < 1:
        raise _error(path, f"the PNM header declares an impossible size {width}x{height}")
    if not 1 <= maxval <= 65535:
        raise _error(path, f"the PNM header declares maxval {maxval}; it must be between 1 and 65535")
    channels = 3 if kind in (3, 6) else 1
    offset, samples = pos + 1, width * height * channels
    # the least pixel data the header implies: raw samples, raw bits, or one character a
    # plain PBM pixel and a digit plus a separator a plain PGM/PPM sample
    need = {1: samples, 2: 2 * samples - 1, 3: 2 * samples - 1, 4: (width + 7) // 8 * height}.get(
        kind, samples * (1 if maxval < 256 else 2)
    )
    if need > size - offset:
        raise _error(path, f"truncated PNM file (its header declares {width}x{height}, which needs "
                           f"{need:,} bytes of pixel data; the file holds {max(size - offset, 0):,})")
    # Pillow's raw PGM/PPM decoder for a maxval other than 255 converts a sample at a time
    # in Python and rescales it: those are read by numpy instead
    decoder = "numpy" if kind in (5, 6) and maxval != 255 else "pillow"
    header = ImageHeader(width, height, channels, maxval.bit_length(), "PNM")
    return _Probe(header, decoder, details={"kind": kind, "maxval": maxval, "offset": offset})
