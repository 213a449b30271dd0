"""What an image file declares, and the pixel budget it is checked against.

An :class:`ImageHeader` is what a file declares (read by :func:`texsyn.io.read_image_header`
without decoding a pixel); :func:`check_image_size` compares it with the pixel budget
(``TEXSYN_MAX_PIXELS``) and its memory equivalent, and refuses a small file that declares a
huge image (a "decompression bomb") before anything is allocated. See ``docs/reading.md``
for the policy.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from .._validation import human_bytes
from ..errors import ImageTooLargeError, InputError
from .files import pixel_amount, show_path

__all__ = [
    "COMPRESSION_FLOOR_BYTES",
    "DEFAULT_MAX_PIXELS",
    "MAX_COMPRESSION_RATIO",
    "MAX_PIXELS_ENV",
    "REFERENCE_BYTES_PER_PIXEL",
    "ImageHeader",
    "check_image_size",
    "max_image_pixels",
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
    name = show_path(path) if path is not None else "the image"
    size = f"{header.width}x{header.height}"
    if header.pixels > budget:
        raise ImageTooLargeError(
            f"'{name}' declares {size} pixels ({pixel_amount(header.pixels)}), more than the "
            f"{pixel_amount(budget)} allowed; set {MAX_PIXELS_ENV}={_suggest(header.pixels)} to allow it"
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


def _suggest(n: int) -> str:
    """A value of TEXSYN_MAX_PIXELS at least ``n``, rounded up to a whole unit."""
    return f"{-(-n // 10**6)}M" if n >= 10**6 else f"{-(-n // 10**3)}K"
