"""Encoders: write one image, array, text or frame sequence to a (temporary) path.

Each takes the temporary path an :class:`texsyn.io.OutputSet` gives it and writes one
complete file there; the set renames it into place. Images are PNG, JPEG (quality 95) or
TIFF, 8 or 16 bit (16-bit colour PNG through pypng, which Pillow cannot write), 32-bit float
TIFF (tifffile), ``.npy`` (uint8, uint16 or float32 samples) or OpenEXR (float,
:mod:`texsyn.io.float_formats`); an ICC profile is embedded on request in PNG (an ``iCCP``
chunk, ISO/IEC 15948 section 11.3.3.3), JPEG and TIFF (``docs/materials.md``). Frames are a
folder of PNGs or a looping GIF. MP4 and WebM are in :mod:`texsyn.io.video`.
"""

from __future__ import annotations

import errno
import struct
import zlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .float_formats import encode_exr
from .output_paths import FRAME_NAME

__all__ = [
    "FLOAT_DEPTH",
    "encode_array",
    "encode_frame_folder",
    "encode_gif",
    "encode_image",
    "encode_text",
    "image_data",
    "png_chunk",
    "to_uint8",
]

#: the bit depth that means 32-bit floating-point samples (``--bit-depth 32f``)
FLOAT_DEPTH = 32


def image_data(image: np.ndarray, bit_depth: int) -> np.ndarray:
    """The samples to encode: uint8 or uint16 from float values in [0, 1]; float32 (any
    finite values) for ``bit_depth=32``."""
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 2, 3, 4)):
        raise InputError(f"image must have shape (H, W) or (H, W, C) with C from 1 to 4, got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if bit_depth == FLOAT_DEPTH:
        if not np.issubdtype(arr.dtype, np.floating) or not np.all(np.isfinite(arr)):
            raise InputError("a 32-bit float image must hold finite floating-point values")
        return arr.astype(np.float32)
    if np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
            raise InputError("image values must be finite and lie in [0, 1]")
        scale = 65535.0 if bit_depth == 16 else 255.0
        return np.rint(arr.astype(np.float64) * scale).astype(np.uint16 if bit_depth == 16 else np.uint8)
    if arr.dtype == np.uint8 and bit_depth == 8 or arr.dtype == np.uint16 and bit_depth == 16:
        return arr
    raise InputError(f"image dtype {arr.dtype} does not fit {bit_depth}-bit output")


def encode_image(tmp: Path, data: np.ndarray, suffix: str, icc_profile: bytes | None = None) -> None:
    """Write samples from :func:`image_data` in the format of ``suffix`` (module docstring)."""
    if suffix == ".npy":
        encode_array(tmp, data)
        return
    if suffix == ".exr":
        encode_exr(tmp, data)
        return
    if suffix in (".tif", ".tiff") and (data.dtype == np.float32 or icc_profile or _planes(data) == 2):
        _encode_tiff(tmp, data, icc_profile)
        return
    if suffix == ".png" and data.dtype == np.uint16:
        import png  # Pillow cannot write 16-bit colour PNG

        planes = _planes(data)
        with open(tmp, "wb") as fh:
            png.Writer(
                data.shape[1], data.shape[0], greyscale=planes in (1, 2), alpha=planes in (2, 4), bitdepth=16
            ).write_array(fh, data.reshape(-1))
    elif suffix == ".png" and data.dtype == np.uint8 and (data.ndim == 2 or data.shape[-1] in (2, 3, 4)):
        # Pillow's PNG writer, which imageio calls with the same arguments, without imageio's
        # import and its registry of every Pillow format (0.05-0.1 s of a command; same bytes)
        from PIL import Image

        with open(tmp, "wb") as fh:
            Image.fromarray(data).save(fh, format="PNG")
    else:
        import imageio.v3 as iio

        kwargs: dict[str, Any] = {"quality": 95} if suffix in (".jpg", ".jpeg") else {}
        if icc_profile and suffix in (".jpg", ".jpeg"):
            kwargs["icc_profile"] = icc_profile
        iio.imwrite(tmp, data, extension=suffix, **kwargs)
    if icc_profile and suffix == ".png":
        _insert_after_header(tmp, png_chunk(b"iCCP", iccp_data(icc_profile)))


def _planes(data: np.ndarray) -> int:
    return 1 if data.ndim == 2 else int(data.shape[2])


def tiff_layout(planes: int) -> dict[str, Any]:
    """tifffile's keywords of an image with ``planes`` samples a pixel (alpha unassociated)."""
    return {
        "photometric": "minisblack" if planes in (1, 2) else "rgb",
        "extrasamples": ("unassalpha",) if planes in (2, 4) else None,
    }


def _encode_tiff(tmp: Path, data: np.ndarray, icc_profile: bytes | None) -> None:
    import tifffile

    tifffile.imwrite(tmp, data, iccprofile=icc_profile or None, **tiff_layout(_planes(data)))


def png_chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data and CRC (ISO/IEC 15948, section 5.3)."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def iccp_data(icc_profile: bytes) -> bytes:
    """The data of an ``iCCP`` chunk: profile name, a null, method 0 and the deflated profile."""
    return b"ICC profile\0\0" + zlib.compress(icc_profile)


def _insert_after_header(path: Path, chunk: bytes) -> None:
    """Put ``chunk`` right after a PNG's IHDR (8-byte signature + 25-byte IHDR chunk)."""
    data = path.read_bytes()
    path.write_bytes(data[:33] + chunk + data[33:])


def encode_array(tmp: Path, array: np.ndarray) -> None:
    with open(tmp, "wb") as fh:
        np.save(fh, array, allow_pickle=False)


def encode_text(tmp: Path, text: str) -> None:
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)


def to_uint8(frame: np.ndarray) -> np.ndarray:
    arr = np.asarray(frame, dtype=np.float64)
    if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
        raise InputError("frame values must be finite and lie in [0, 1]")
    return np.rint(arr * 255.0).astype(np.uint8)


def encode_frame_folder(tmp: Path, frames: Iterable[np.ndarray]) -> None:
    import imageio.v3 as iio

    count = 0
    for i, frame in enumerate(frames):
        iio.imwrite(tmp / FRAME_NAME.format(i), to_uint8(frame), extension=".png")
        count += 1
    if count == 0:
        raise InputError("no frames to write")


def encode_gif(tmp: Path, frames: Iterable[np.ndarray], fps: float) -> None:
    import imageio.v3 as iio

    images = [to_uint8(f) for f in frames]
    if not images:
        raise InputError("no frames to write")
    iio.imwrite(tmp, images, extension=".gif", duration=1000.0 / fps, loop=0)
    if tmp.stat().st_size == 0:
        raise OSError(errno.EIO, "the GIF writer produced an empty file")
