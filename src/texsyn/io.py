"""Reading and writing images: files in, float32 [0, 1] arrays out, atomic writes.

Read: PNG, JPEG, TIFF, BMP, GIF (first frame), WebP, PGM/PPM; 8 and 16 bit; grey, grey +
alpha, RGB, RGBA and palette images. Write: PNG, JPEG and TIFF (8 bit; 16 bit for PNG and
TIFF on request), always through a temporary file renamed into place, so that a failed or
interrupted write never leaves a partial file.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

__all__ = [
    "ImageReadError",
    "READ_FORMATS",
    "WRITE_FORMATS",
    "read_image",
    "write_image",
    "write_array",
    "check_output_path",
    "atomic_write",
    "save_fitted",
    "load_fitted",
]

READ_FORMATS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".gif", ".webp", ".pgm", ".ppm", ".pnm", ".pbm")
WRITE_FORMATS = {".png": (8, 16), ".jpg": (8,), ".jpeg": (8,), ".tif": (8, 16), ".tiff": (8, 16)}
_READ_NAMES = "PNG, JPEG, TIFF, BMP, GIF, WebP, PGM/PPM"


class ImageReadError(ValueError):
    """A file could not be read as an image."""


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
        raise FileNotFoundError(f"no such file: '{p}'")
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


def check_output_path(path: str | os.PathLike, *, bit_depth: int = 8, formats=None) -> Path:
    """Check that ``path`` can be written: known format, bit depth allowed, folder exists.

    Raises ``ValueError`` (unsupported format or depth) or ``FileNotFoundError`` (missing
    folder) before any work is done.
    """
    p = Path(path)
    formats = WRITE_FORMATS if formats is None else formats
    suffix = p.suffix.lower()
    if suffix not in formats:
        raise ValueError(
            f"cannot write '{p}': unsupported file type '{suffix or '(none)'}'; "
            f"use one of {', '.join(sorted(formats))}"
        )
    depths = formats[suffix]
    if bit_depth not in depths:
        raise ValueError(
            f"cannot write '{p}' with {bit_depth}-bit depth; {suffix} allows "
            f"{' or '.join(str(d) for d in depths)} bit"
        )
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"cannot write '{p}': folder '{parent}' does not exist")
    if p.is_dir():
        raise ValueError(f"cannot write '{p}': it is a folder")
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
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if np.issubdtype(arr.dtype, np.floating):
        if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
            raise ValueError("image values must be finite and lie in [0, 1]")
        scale = 65535.0 if bit_depth == 16 else 255.0
        data = np.rint(arr.astype(np.float64) * scale).astype(np.uint16 if bit_depth == 16 else np.uint8)
    elif arr.dtype == np.uint8 and bit_depth == 8 or arr.dtype == np.uint16 and bit_depth == 16:
        data = arr
    else:
        raise ValueError(f"image dtype {arr.dtype} does not fit {bit_depth}-bit output")
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


def save_fitted(path: str | os.PathLike, method) -> Path:
    """Save what a fitted method learned (e.g. the ``sparse`` dictionaries) to an ``.npz``.

    The file holds plain arrays plus a ``format_version`` tag; it is written atomically.
    """
    if not hasattr(method, "fitted_state"):
        raise ValueError(f"method {getattr(method, 'name', method)!r} has no savable fitted state")
    p = check_output_path(path, formats={".npz": (8,)})
    state = method.fitted_state()

    def writer(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **state)

    atomic_write(p, writer)
    return p


def load_fitted(path: str | os.PathLike, **params):
    """Load a method saved by :func:`save_fitted`; ``params`` may change sampling parameters."""
    from .methods import get_method

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such file: '{p}'")
    try:
        with np.load(p, allow_pickle=False) as data:
            state = {k: data[k] for k in data.files}
    except Exception as exc:
        raise ValueError(f"cannot read '{p}' as a saved texsyn model ({exc})") from None
    if "method" not in state or "format_version" not in state:
        raise ValueError(f"'{p}' is not a saved texsyn model (no method or format_version)")
    cls = get_method(str(state["method"]))
    return cls.from_fitted_state(state, **params)


def _to_uint8(frame: np.ndarray) -> np.ndarray:
    arr = np.asarray(frame, dtype=np.float64)
    if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
        raise ValueError("frame values must be finite and lie in [0, 1]")
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
        raise FileNotFoundError(f"cannot write '{p}': folder '{p.parent}' does not exist")
    if suffix == ".gif":

        def write_gif(tmp: str) -> None:
            images = [_to_uint8(f) for f in frames]
            if not images:
                raise ValueError("no frames to write")
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
                raise ValueError("no frames to write")

        atomic_write(p, write_mp4, suffix=".mp4")
    elif suffix == "":
        if p.exists() and (not p.is_dir() or any(p.iterdir())):
            raise FileExistsError(f"'{p}' exists and is not an empty folder")
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
        raise ValueError(f"cannot write {suffix!r} animations; use .mp4, .gif or a folder name (PNG frames)")
    return p
