"""Image headers read without decoding pixels: what a file declares, before any work.

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

The header is then compared with the pixel budget (``TEXSYN_MAX_PIXELS``,
:mod:`texsyn.io.budget`) before a single pixel is decoded, so that a small file that
declares a huge image (a "decompression bomb") is refused at once and cheaply. The
per-format reads are in :mod:`texsyn.io.probes`, Pillow's lazy open in
:mod:`texsyn.io.libraries`. See ``docs/reading.md`` for the policy.
"""

from __future__ import annotations

import os
from typing import BinaryIO

from ..errors import ImageReadError, ImageTooLargeError, InputError
from .budget import (
    COMPRESSION_FLOOR_BYTES,
    DEFAULT_MAX_PIXELS,
    MAX_COMPRESSION_RATIO,
    MAX_PIXELS_ENV,
    REFERENCE_BYTES_PER_PIXEL,
    ImageHeader,
    check_image_size,
    max_image_pixels,
)
from .files import library_said, open_checked, read_error
from .float_formats import EXR_MAGIC, NPY_MAGIC, exr_header, npy_header
from .libraries import PILLOW_FORMATS, mode_bits, pillow, pillow_open, pillow_target
from .probes import (  # noqa: F401
    PNM_MAGIC,
    Probe,
    png_raw_size,
    probe_png,
    probe_pnm,
    probe_tiff,
    probe_tifffile,
    probe_webp,
)

__all__ = [
    "COMPRESSION_FLOOR_BYTES",
    "DEFAULT_MAX_PIXELS",
    "MAX_COMPRESSION_RATIO",
    "MAX_PIXELS_ENV",
    "REFERENCE_BYTES_PER_PIXEL",
    "ImageHeader",
    "Probe",
    "check_image_size",
    "max_image_pixels",
    "probe",
    "read_image_header",
]

_FORMAT_NAMES = "PNG, JPEG, TIFF, BMP, GIF, WebP, PNM (PBM/PGM/PPM), .npy, OpenEXR"


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
    >>> import os, tempfile
    >>> import numpy as np
    >>> from texsyn.io import write_image
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = write_image(os.path.join(folder.name, "red.png"), np.ones((48, 64, 3)))
    >>> header = read_image_header(path)
    >>> header.width, header.height, header.channels, header.bit_depth, header.format
    (64, 48, 3, 8, 'PNG')
    >>> folder.cleanup()
    """
    return probe(path).header


def probe(path: str | os.PathLike) -> Probe:
    """Read ``path``'s header and decide how to decode it (:class:`Probe`); see :func:`read_image_header`."""
    fh, size = open_checked(path)
    try:
        with fh:
            found = _probe_open(fh, size, path)
    except InputError:
        raise
    except MemoryError:
        raise read_error(path, "not enough memory to read its header") from None
    except Exception as exc:  # a read error, or a case nobody foresaw
        raise read_error(path, f"unreadable image header ({library_said(exc, path)})") from None
    h = found.header
    if h.width < 1 or h.height < 1 or not 1 <= h.channels <= 4:
        raise read_error(
            path,
            f"the {h.format} header declares an impossible image "
            f"({h.width}x{h.height}, {h.channels} channels)",
        )
    return found


def _probe_open(fh: BinaryIO, size: int, path: str | os.PathLike) -> Probe:
    if size == 0:
        raise read_error(path, "the file is empty (0 bytes)")
    head = fh.read(16)
    if head.startswith(NPY_MAGIC):  # an array of samples (docs/materials.md)
        return Probe(npy_header(path), "npy")
    if head.startswith(EXR_MAGIC):
        return Probe(exr_header(path), "exr")
    if PNM_MAGIC.match(head):
        return probe_pnm(fh, size, path)
    Image = pillow()
    for fmt in PILLOW_FORMATS:
        accepted = Image.OPEN[fmt][1](head)
        if isinstance(accepted, str):  # e.g. "WEBP support not installed"
            raise read_error(path, accepted)
        if accepted:
            break
    else:
        raise read_error(path, f"not an image file texsyn knows; it reads {_FORMAT_NAMES}")
    if fmt == "WEBP":
        return probe_webp(fh, path)
    fh.seek(0)
    try:
        im = pillow_open(fh, fmt, path)
    except ImageTooLargeError:
        raise
    except ImageReadError as exc:
        if fmt == "TIFF":  # Pillow has no mode for it: perhaps tifffile reads it
            return probe_tifffile(path, exc)
        raise
    with im:
        target = pillow_target(im)
        if not target:
            raise read_error(path, f"unsupported {fmt} pixel mode {im.mode}")
        bits = getattr(im, "bits", 8) if fmt == "JPEG" else mode_bits(im.mode)
        header = ImageHeader(im.size[0], im.size[1], Image.getmodebands(target), bits, fmt)
        found = Probe(header, "pillow", im.mode, target)
        if fmt == "PNG":
            return probe_png(im, fh, found, path)
        if fmt == "TIFF":
            return probe_tiff(im, found, path)
        if fmt == "BMP" and im.tile and im.tile[0][0] == "raw":
            # Pillow's raw decoder does not need the last row's padding, so a file cut
            # there would be read: the rows, padding included, must all be in the file
            end = im.tile[0][2] + im.tile[0][3][1] * im.size[1]
            if end > size:
                raise read_error(
                    path,
                    f"truncated BMP file (its pixel data would end at byte {end:,}, "
                    f"the file has {size:,} bytes)",
                )
        return found
