"""Encoders: write one image, array, text or frame sequence to a (temporary) path.

Each takes the temporary path an :class:`texsyn.io.OutputSet` gives it and writes one
complete file there; the set renames it into place. Images are PNG, JPEG (quality 95) or
TIFF, 8 or 16 bit (16-bit colour PNG through pypng, which Pillow cannot write); frames are
a folder of PNGs or a looping GIF. MP4 and WebM are in :mod:`texsyn.io.video`.
"""

from __future__ import annotations

import errno
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .output_paths import FRAME_NAME

__all__ = [
    "encode_array",
    "encode_frame_folder",
    "encode_gif",
    "encode_image",
    "encode_text",
    "image_data",
    "to_uint8",
]


def image_data(image: np.ndarray, bit_depth: int) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise InputError(f"image must have shape (H, W) or (H, W, 3), got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
            raise InputError("image values must be finite and lie in [0, 1]")
        scale = 65535.0 if bit_depth == 16 else 255.0
        return np.rint(arr.astype(np.float64) * scale).astype(np.uint16 if bit_depth == 16 else np.uint8)
    if arr.dtype == np.uint8 and bit_depth == 8 or arr.dtype == np.uint16 and bit_depth == 16:
        return arr
    raise InputError(f"image dtype {arr.dtype} does not fit {bit_depth}-bit output")


def encode_image(tmp: Path, data: np.ndarray, suffix: str) -> None:
    import imageio.v3 as iio

    if suffix == ".png" and data.dtype == np.uint16:
        import png  # Pillow cannot write 16-bit colour PNG

        planes = 1 if data.ndim == 2 else data.shape[2]
        with open(tmp, "wb") as fh:
            png.Writer(data.shape[1], data.shape[0], greyscale=planes == 1, bitdepth=16).write_array(
                fh, data.reshape(-1)
            )
        return
    kwargs: dict[str, Any] = {"quality": 95} if suffix in (".jpg", ".jpeg") else {}
    iio.imwrite(tmp, data, extension=suffix, **kwargs)


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
