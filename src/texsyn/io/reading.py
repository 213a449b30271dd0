"""Reading image files: float32 [0, 1] arrays out.

Read: PNG, JPEG, TIFF, BMP, GIF (first frame), WebP, PGM/PPM; 8 and 16 bit; grey, grey +
alpha, RGB, RGBA and palette images.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import ImageReadError, InputFileNotFoundError

READ_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".gif", ".webp", ".pgm", ".ppm", ".pnm", ".pbm")
_READ_NAMES = "PNG, JPEG, TIFF, BMP, GIF, WebP, PGM/PPM"


def read_image(path: str | os.PathLike, *, keep_alpha: bool = False) -> np.ndarray:
    """Read an image file as float32 in [0, 1], shape ``(H, W)`` or ``(H, W, 3)``.

    Parameters
    ----------
    path : str or path-like
    keep_alpha : bool
        Return ``(H, W, 4)`` (or ``(H, W, 2)`` for grey) when the file has an alpha channel.
        By default the alpha channel is dropped, with a warning when it is not fully opaque.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ImageReadError
        The file exists but is not a readable image (wrong format, truncated, ...).
    """
    import imageio.v3 as iio

    p = Path(path)
    if not p.exists():
        raise InputFileNotFoundError(f"no such file: '{p}'")
    if p.is_dir():
        raise ImageReadError(f"'{p}' is a folder, not an image file")
    try:
        data = _read_high_depth(p)
        if data is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                data = iio.imread(p, index=0)
    except Exception as exc:  # imageio raises many types for unreadable files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ImageReadError(
            f"cannot read '{p}' as an image ({reason[:120]}); texsyn reads {_READ_NAMES}"
        ) from None
    arr = np.asarray(data)
    if arr.dtype == bool:
        arr = arr.astype(np.float32)
    elif arr.dtype == np.uint8:
        arr = arr.astype(np.float32) / 255.0
    elif arr.dtype in (np.uint16, np.int32, np.int64, np.uint32):
        # 16-bit data; Pillow gives 16-bit PGM/PPM as 32-bit integers
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise ImageReadError(f"'{p}' holds integers outside the 16-bit range; texsyn reads 8 and 16 bit images")
        arr = arr.astype(np.float32) / 65535.0
    elif np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float32)
        if arr.size and (not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1):
            raise ImageReadError(f"'{p}' holds floating-point values outside [0, 1]")
    else:
        raise ImageReadError(f"'{p}' has an unsupported pixel type {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim == 3 and arr.shape[2] in (2, 4) and not keep_alpha:
        if np.any(arr[..., -1] < 1.0):
            warnings.warn(
                f"'{p.name}' has transparency; the alpha channel is dropped", UserWarning, stacklevel=2
            )
        arr = arr[..., :-1]
        if arr.shape[2] == 1:
            arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (2, 3, 4)):
        raise ImageReadError(f"'{p}' has an unsupported layout {arr.shape}; expected a grey or colour image")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ImageReadError(f"'{p}' is an empty image")
    return np.ascontiguousarray(arr)


def _read_high_depth(path: Path) -> np.ndarray | None:
    """Read 16-bit PNG and PGM/PPM files, which Pillow truncates to 8 bits in colour.

    Returns ``uint16`` data (PNG) or float32 data in [0, 1] (PNM, scaled by its maxval), or
    ``None`` when the file is not such a file and the general reader should be used.
    """
    with open(path, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"\x89PNG\r\n\x1a\n") and len(head) > 24 and head[24] == 16:
        import png

        width, height, rows, info = png.Reader(filename=str(path)).asDirect()
        planes = info["planes"]
        data = np.vstack([np.asarray(row, dtype=np.uint16) for row in rows])
        return data.reshape(height, width, planes) if planes > 1 else data.reshape(height, width)
    if head[:2] in (b"P5", b"P6"):
        raw = path.read_bytes()
        tokens: list[bytes] = []
        pos = 2
        while len(tokens) < 3:
            while raw[pos : pos + 1].isspace():
                pos += 1
            if raw[pos : pos + 1] == b"#":
                pos = raw.index(b"\n", pos) + 1
                continue
            end = pos
            while not raw[end : end + 1].isspace():
                end += 1
            tokens.append(raw[pos:end])
            pos = end
        width, height, maxval = (int(t) for t in tokens)
        if maxval < 256:
            return None
        planes = 3 if head[:2] == b"P6" else 1
        count = width * height * planes
        body = np.frombuffer(raw, dtype=">u2", count=count, offset=pos + 1)
        scaled = (body.astype(np.float64) / maxval).astype(np.float32)
        return scaled.reshape(height, width, planes) if planes > 1 else scaled.reshape(height, width)
    return None


