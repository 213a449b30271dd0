"""Writing images, arrays and videos, always through a temporary file renamed into place,
so that a failed or interrupted write never leaves a partial file.

Write: PNG, JPEG and TIFF (8 bit; 16 bit for PNG and TIFF on request), ``.npy`` arrays,
MP4/GIF videos and folders of PNG frames.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import InputError, InputFileNotFoundError, OutputExistsError

WRITE_FORMATS = {".png": (8, 16), ".jpg": (8,), ".jpeg": (8,), ".tif": (8, 16), ".tiff": (8, 16)}
def check_output_path(path: str | os.PathLike, *, bit_depth: int = 8, formats=None) -> Path:
    """Check that ``path`` can be written: known format, bit depth allowed, folder exists.

    Raises ``ValueError`` (unsupported format or depth) or ``FileNotFoundError`` (missing
    folder) before any work is done.
    """
    p = Path(path)
    formats = WRITE_FORMATS if formats is None else formats
    suffix = p.suffix.lower()
    if suffix not in formats:
        raise InputError(
            f"cannot write '{p}': unsupported file type '{suffix or '(none)'}'; "
            f"use one of {', '.join(sorted(formats))}"
        )
    depths = formats[suffix]
    if bit_depth not in depths:
        raise InputError(
            f"cannot write '{p}' with {bit_depth}-bit depth; {suffix} allows "
            f"{' or '.join(str(d) for d in depths)} bit"
        )
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputFileNotFoundError(f"cannot write '{p}': folder '{parent}' does not exist")
    if p.is_dir():
        raise InputError(f"cannot write '{p}': it is a folder")
    return p


def atomic_write(path: Path, writer, *, suffix: str = ".part") -> None:
    """Call ``writer(temporary_path)`` in ``path``'s folder, then rename it to ``path``.

    ``suffix`` ends the temporary name (writers that choose the format from it need the real one).
    """
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent or ".")
    os.close(fd)
    try:
        writer(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_image(path: str | os.PathLike, image: np.ndarray, *, bit_depth: int = 8) -> Path:
    """Write a float image in [0, 1] to PNG, JPEG or TIFF, atomically.

    Parameters
    ----------
    path : str or path-like
        Its suffix chooses the format.
    image : ndarray, shape (H, W) or (H, W, 3)
        Values outside [0, 1] are rejected (not clipped silently).
    bit_depth : {8, 16}
        16 bit is allowed for PNG and TIFF.
    """
    import imageio.v3 as iio

    p = check_output_path(path, bit_depth=bit_depth)
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise InputError(f"image must have shape (H, W) or (H, W, 3), got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
            raise InputError("image values must be finite and lie in [0, 1]")
        scale = 65535.0 if bit_depth == 16 else 255.0
        data = np.rint(arr.astype(np.float64) * scale).astype(np.uint16 if bit_depth == 16 else np.uint8)
    elif arr.dtype == np.uint8 and bit_depth == 8 or arr.dtype == np.uint16 and bit_depth == 16:
        data = arr
    else:
        raise InputError(f"image dtype {arr.dtype} does not fit {bit_depth}-bit output")
    suffix = p.suffix.lower()

    def writer(tmp: str) -> None:
        if suffix == ".png" and data.dtype == np.uint16:
            import png  # Pillow cannot write 16-bit colour PNG

            planes = 1 if data.ndim == 2 else data.shape[2]
            with open(tmp, "wb") as fh:
                png.Writer(
                    data.shape[1], data.shape[0], greyscale=planes == 1, bitdepth=16
                ).write_array(fh, data.reshape(-1))
            return
        kwargs = {"quality": 95} if suffix in (".jpg", ".jpeg") else {}
        iio.imwrite(tmp, data, extension=suffix, **kwargs)

    atomic_write(p, writer)
    return p


def write_array(path: str | os.PathLike, array: np.ndarray) -> Path:
    """Write a NumPy array to a ``.npy`` file, atomically."""
    p = check_output_path(path, formats={".npy": (8,)})

    def writer(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.save(fh, np.asarray(array))

    atomic_write(p, writer)
    return p


def _to_uint8(frame: np.ndarray) -> np.ndarray:
    arr = np.asarray(frame, dtype=np.float64)
    if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
        raise InputError("frame values must be finite and lie in [0, 1]")
    return np.rint(arr * 255.0).astype(np.uint8)


def write_frames(path: str | os.PathLike, frames, *, fps: float = 24.0) -> Path:
    """Write a sequence of float frames in [0, 1] as a video, a GIF or a folder of PNGs, atomically.

    Parameters
    ----------
    path : str or path-like
        ``.mp4`` (H.264 through imageio-ffmpeg; odd sizes are padded by one edge row/column),
        ``.gif`` (looping), or a path without suffix: a new (or empty) folder that receives
        ``frame_00000.png``, ... .
    frames : iterable of ndarray, shape (H, W) or (H, W, 3)
        Consumed one at a time (a generator is fine); nothing is left behind on error.
    fps : float
        Frames per second.
    """
    import shutil

    import imageio.v3 as iio

    p = Path(path)
    suffix = p.suffix.lower()
    if not p.parent.is_dir():
        raise InputFileNotFoundError(f"cannot write '{p}': folder '{p.parent}' does not exist")
    if suffix == ".gif":

        def write_gif(tmp: str) -> None:
            images = [_to_uint8(f) for f in frames]
            if not images:
                raise InputError("no frames to write")
            iio.imwrite(tmp, images, extension=".gif", duration=1000.0 / fps, loop=0)

        atomic_write(p, write_gif, suffix=".gif")
    elif suffix == ".mp4":
        import imageio.v2 as iio2

        def write_mp4(tmp: str) -> None:
            count = 0
            with iio2.get_writer(tmp, format="FFMPEG", fps=fps, codec="libx264", quality=8, macro_block_size=1, pixelformat="yuv420p") as writer:
                for frame in frames:
                    data = _to_uint8(frame)
                    if data.ndim == 2:
                        data = np.repeat(data[..., None], 3, axis=2)
                    h, w = data.shape[:2]
                    data = np.pad(data, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
                    writer.append_data(data)
                    count += 1
            if count == 0:
                raise InputError("no frames to write")

        atomic_write(p, write_mp4, suffix=".mp4")
    elif suffix == "":
        if p.exists() and (not p.is_dir() or any(p.iterdir())):
            raise OutputExistsError(f"'{p}' exists and is not an empty folder")
        tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.", dir=p.parent))
        try:
            for i, frame in enumerate(frames):
                iio.imwrite(tmp / f"frame_{i:05d}.png", _to_uint8(frame))
            if p.exists():
                p.rmdir()
            os.replace(tmp, p)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    else:
        raise InputError(f"cannot write {suffix!r} animations; use .mp4, .gif or a folder name (PNG frames)")
    return p
