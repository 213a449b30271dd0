"""The image libraries texsyn reads with (Pillow, tifffile), opened the way texsyn needs.

Pillow is opened lazily (the header is read, nothing is decoded) and without its own
pixel-count check, so that texsyn's pixel budget answers first (``docs/reading.md``); the
libraries' log records about broken files are kept off stderr, so that an error stays one
line.
"""

from __future__ import annotations

import functools
import os
import warnings
from typing import BinaryIO

from ..errors import ImageTooLargeError
from .files import library_said, pixel_amount, read_error, show_path

__all__ = ["PILLOW_FORMATS", "mode_bits", "pillow", "pillow_open", "pillow_target", "quiet_library_logs"]

#: The Pillow formats texsyn reads (PNM is recognised by texsyn itself, see
#: :func:`texsyn.io.probes.probe_pnm`).
PILLOW_FORMATS = ("PNG", "JPEG", "TIFF", "GIF", "WEBP", "BMP")

#: Pillow mode -> the mode texsyn decodes it to (``P``: RGB, or RGBA with transparency).
_PIL_TARGETS = {
    "1": "1", "L": "L", "LA": "LA", "RGB": "RGB", "RGBA": "RGBA", "I": "I", "F": "F",
    "I;16": "I;16", "I;16L": "I;16L", "I;16B": "I;16B", "I;16N": "I;16N",
    "PA": "RGBA", "La": "LA", "RGBa": "RGBA", "RGBX": "RGB",
    "CMYK": "RGB", "YCbCr": "RGB", "LAB": "RGB", "HSV": "RGB",
}  # fmt: skip


@functools.cache
def quiet_library_logs() -> None:
    """Keep Pillow's and tifffile's log records about odd files off stderr.

    Both log complaints about a broken file (e.g. Pillow's TIFF plugin: "More samples per
    pixel than can be decoded") before raising; with no handler configured, Python's
    last-resort handler would print them beside texsyn's one-line error. A ``NullHandler``
    on their loggers stops that; an application that configures logging still gets them.
    """
    import logging

    for name in ("PIL", "tifffile"):
        logging.getLogger(name).addHandler(logging.NullHandler())


@functools.cache
def pillow():
    """PIL.Image with the plugins of the formats texsyn reads registered."""
    quiet_library_logs()
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


def pillow_open(fh: BinaryIO, fmt: str, path: str | os.PathLike):
    """Pillow's lazy open of ``fh`` as format ``fmt``: the header is read, nothing is decoded.

    This is ``Image.open(fh, formats=[fmt])`` without its last step, Pillow's pixel-count
    check (``Image.MAX_IMAGE_PIXELS``), which would refuse or warn about an image before
    texsyn can check its own budget, and whose error does not say the image's size.
    Where a plugin still runs that check itself (a WebP, GIF frame or TIFF tile beyond
    Pillow's limit), its error becomes an :class:`~texsyn.errors.ImageTooLargeError`.

    Raises
    ------
    ImageReadError
        Pillow cannot read the header; the message is Pillow's, in one line.
    """
    Image = pillow()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # EXIF and metadata complaints are not the user's concern
            return Image.OPEN[fmt][0](fh, os.fspath(path))
    except Image.DecompressionBombError:
        raise ImageTooLargeError(
            f"'{show_path(path)}' declares more than {pixel_amount(2 * (Image.MAX_IMAGE_PIXELS or 0))} pixels, "
            f"which Pillow refuses to decode (PIL.Image.MAX_IMAGE_PIXELS)"
        ) from None
    except MemoryError:
        raise
    except Exception as exc:  # SyntaxError, OSError, ValueError, struct.error...
        raise read_error(path, f"corrupt or unsupported {fmt} file ({library_said(exc, path)})") from None


def pillow_target(im) -> str:
    """The Pillow mode texsyn decodes an image of mode ``im.mode`` to ("" if none)."""
    if im.mode == "P":
        return "RGBA" if "transparency" in im.info else "RGB"
    return _PIL_TARGETS.get(im.mode, "")


def mode_bits(mode: str) -> int:
    """Bits per sample of a Pillow mode: 1 (bilevel), 8, 16 (``I;16*``) or 32 (``I``, ``F``)."""
    return 1 if mode == "1" else 16 if mode.startswith("I;16") else 32 if mode in ("I", "F") else 8
