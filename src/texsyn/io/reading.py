"""Reading image files: float32 [0, 1] arrays out, header first, never a hang or a bomb.

Read: PNG (1-16 bit, grey, grey + alpha, RGB, RGBA, palette), JPEG (grey, RGB, CMYK),
TIFF (1-16 bit integer, 32/64 bit float), BMP, GIF (first frame), WebP, PNM (PBM, PGM,
PPM, plain and raw, maxval up to 65535), ``.npy`` arrays and OpenEXR (with the ``OpenEXR``
package). :func:`read_image` gives float32 in [0, 1]; :func:`read_image_file` gives the
samples at their stored scale (floats of any range), with the file's bit depth and ICC
profile, for the material pipeline (``docs/materials.md``).

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
from dataclasses import dataclass
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
from .files import library_said, open_checked, read_error
from .float_formats import decode_exr, decode_npy_image
from .headers import Probe, probe
from .libraries import pillow_open

__all__ = ["READ_FORMATS", "ImageFile", "read_image", "read_image_file"]

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
    ".npy",
    ".exr",
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
    _, data, scale = _read_samples(path)
    return _to_float(data, scale, path, keep_alpha)


@dataclass(frozen=True)
class ImageFile:
    """An image file's samples as stored, with what the material pipeline keeps of the file.

    Attributes
    ----------
    pixels : ndarray of float32, shape (H, W) or (H, W, C), C from 2 to 4
        Integer samples divided by the largest value of their bit depth (as
        :func:`read_image`); floating-point samples as stored, any finite range. Alpha is kept.
    bit_depth : int
        8, 16 (integer samples: 1-8 bit and 9-16 bit files) or 32 (floating point, the
        ``32f`` of the command line; half-float EXR and 64-bit data included).
    format : str
        ``'PNG'``, ``'JPEG'``, ``'TIFF'``, ``'NPY'``, ``'EXR'``...
    icc_profile : bytes or None
        The embedded ICC colour profile (PNG ``iCCP``, JPEG ``APP2``, TIFF tag 34675, WebP).
    """

    pixels: np.ndarray
    bit_depth: int
    format: str
    icc_profile: bytes | None = None

    @property
    def is_float(self) -> bool:
        return self.bit_depth == 32


def read_image_file(path: str | os.PathLike) -> ImageFile:
    """Read an image file keeping its alpha, bit depth, floating-point range and ICC profile.

    The same header-first read as :func:`read_image` (``docs/reading.md``); what differs is
    the result (``docs/materials.md``): float samples keep their values, whatever their range
    (non-finite values are refused), and the alpha channel is kept.

    Parameters
    ----------
    path : str or path-like
        Any file :func:`read_image` reads, ``.npy`` and OpenEXR included.

    Returns
    -------
    ImageFile

    Raises
    ------
    ImageReadError, ImageTooLargeError, FileNotFoundError, InputError
        As :func:`read_image`.

    Examples
    --------
    >>> import os, tempfile
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = os.path.join(folder.name, "height.npy")
    >>> np.save(path, np.linspace(-2.0, 3.0, 12, dtype=np.float32).reshape(3, 4))
    >>> found = read_image_file(path)
    >>> found.bit_depth, found.format, float(found.pixels.min()), float(found.pixels.max())
    (32, 'NPY', -2.0, 3.0)
    >>> folder.cleanup()
    """
    found, data, scale = _read_samples(path)
    depth = _stored_depth(data, scale, found)
    pixels = _to_float(data, scale, path, keep_alpha=True, any_range=True)
    return ImageFile(pixels, depth, found.header.format, _icc_profile(path, found))


def _read_samples(path: str | os.PathLike) -> tuple[Probe, np.ndarray, float]:
    """Header, budget, then the decoder: the samples as stored and the value that means 1.0."""
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
    return found, data, scale


def _stored_depth(data: np.ndarray, scale: float, found: Probe) -> int:
    """8, 16 or 32 (float): the bit depth an output keeps by default (``docs/materials.md``)."""
    if data.dtype.kind == "f":
        return 32
    return 8 if data.dtype == bool or scale <= 255.0 else 16


def _icc_profile(path: str | os.PathLike, found: Probe) -> bytes | None:
    """The embedded ICC profile, read from the header (Pillow's lazy open, or tifffile's tags)."""
    fmt = found.header.format
    if fmt not in ("PNG", "JPEG", "TIFF", "WEBP"):
        return None
    try:
        if found.decoder == "tifffile":
            import tifffile

            with tifffile.TiffFile(path) as tif:
                icc = tif.pages.first.iccprofile
        else:
            fh, _ = open_checked(path)
            with fh, pillow_open(fh, fmt, path) as im:
                icc = im.info.get("icc_profile")
    except Exception:  # a profile that cannot be read is not kept; the pixels were read
        return None
    return bytes(icc) if icc else None


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
    if found.decoder == "npy":
        return decode_npy_image(path)
    if found.decoder == "exr":
        return decode_exr(path, found.header)
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


def _to_float(
    arr: np.ndarray, scale: float, path: str | os.PathLike, keep_alpha: bool, *, any_range: bool = False
) -> np.ndarray:
    """Integer (or float) samples to float32 in [0, 1], alpha handled on the integer data;
    with ``any_range``, float samples keep their values (finite ones only)."""
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3, 4)):
        raise read_error(path, f"unsupported layout {arr.shape}; expected a grey or colour image")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise read_error(path, "it is an empty image")
    if arr.dtype.kind == "f":
        if arr.size and not np.all(np.isfinite(arr)):
            raise read_error(path, "it holds NaN or infinite values")
        if arr.size and not any_range and (arr.min() < 0 or arr.max() > 1):
            raise read_error(
                path,
                "it holds floating-point values outside [0, 1] (texsyn synth reads them: docs/materials.md)",
            )
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
