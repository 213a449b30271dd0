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

import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from .budget import check_image_size, max_image_pixels
from .decoders import (
    check_png,
    decode_pillow,
    decode_png16,
    decode_raw_pnm,
    decode_tifffile,
    undo_pnm_rescale,
)
from .files import library_said, read_error
from .headers import Probe, probe

__all__ = ["READ_FORMATS", "read_image"]

READ_FORMATS = (
    ".png",
    ".jpg",
    ".jpeg",
    ".tif",
    ".tiff",
    ".bmp",
    ".gif",
    ".webp",
    ".pgm",
    ".ppm",
    ".pnm",
    ".pbm",
)


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
    found = probe(path)
    check_image_size(found.header, path, max_pixels=max_image_pixels(), file_size=os.path.getsize(path))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # decoders' warnings (EXIF, palettes) are not the user's concern
            data, scale = _decode(path, found)
    except InputError:
        raise
    except MemoryError:
        raise read_error(path, "not enough memory to decode it (lower TEXSYN_MAX_PIXELS)") from None
    except Exception as exc:  # every decoder failure, whatever its type, is an ImageReadError
        raise read_error(path, _complaint(exc, found, path)) from None
    return _to_float(data, scale, path, keep_alpha)


#: What Pillow's plain PNM decoder says -> the same problem in texsyn's PNM messages.
_PNM_COMPLAINTS = {
    "too large for this mode": "corrupt PNM file (a sample exceeds its maxval {maxval}: {said})",
    "invalid literal for int": "corrupt PNM file (unexpected character in the pixel data: {said})",
    "Invalid token": "corrupt PNM file (unexpected character in the pixel data: {said})",
    "not enough image data": "truncated PNM file (it holds fewer samples than its header declares)",
}


def _complaint(exc: BaseException, found: Probe, path: str | os.PathLike) -> str:
    said, fmt = library_said(exc, path), found.header.format
    for words, ours in _PNM_COMPLAINTS.items() if fmt == "PNM" else ():
        if words in said:
            return ours.format(maxval=found.details["maxval"], said=said)
    return f"corrupt or unsupported {fmt} file ({said})"


def _decode(path: str | os.PathLike, found: Probe) -> tuple[np.ndarray, float]:
    """Decode the pixels: an integer, bool or float array and the value that means 1.0."""
    if found.header.format == "PNG":
        check_png(path, found)
    if found.decoder == "pypng":
        return decode_png16(path, found.header), 65535.0
    if found.decoder == "tifffile":
        return decode_tifffile(path, found.header)
    if found.decoder == "numpy":
        return decode_raw_pnm(path, found)
    arr = decode_pillow(path, found)
    if found.header.format == "PNM" and arr.dtype != bool:
        return undo_pnm_rescale(arr, found.details["maxval"])
    if arr.dtype == bool:
        return arr, 1.0
    if arr.dtype == np.uint8:
        return arr, 255.0
    if arr.dtype.kind == "u" and arr.dtype.itemsize == 2:
        return arr, 65535.0
    if arr.dtype.kind == "i":  # 32-bit integer images: read as 16-bit data
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise read_error(
                path, "it holds integers outside the 16-bit range; texsyn reads 8 and 16 bit images"
            )
        return arr, 65535.0
    return arr, 1.0


# --------------------------------------------------------------------------- to float


def _to_float(arr: np.ndarray, scale: float, path: str | os.PathLike, keep_alpha: bool) -> np.ndarray:
    """Integer (or float) samples to float32 in [0, 1], alpha handled on the integer data."""
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3, 4)):
        raise read_error(path, f"unsupported layout {arr.shape}; expected a grey or colour image")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise read_error(path, "it is an empty image")
    if arr.dtype.kind == "f":
        if arr.size and (not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1):
            raise read_error(path, "it holds floating-point values outside [0, 1]")
        scale = 1.0
    if arr.ndim == 3 and arr.shape[2] in (2, 4) and not keep_alpha:
        opaque = True if arr.dtype == bool else scale
        if np.any(arr[..., -1] < opaque):
            warnings.warn(
                f"'{Path(path).name}' has transparency; the alpha channel is dropped",
                UserWarning,
                stacklevel=3,
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
