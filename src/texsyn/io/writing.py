"""Writing images, arrays, text and videos: all or nothing, never over an input.

Every output goes to a hidden temporary file (or folder) beside it, named
``.NAME.XXXXXXXX.part``, and is renamed into place only once it is complete. Several
outputs of one command form an :class:`OutputSet`: they are all written to temporaries
first and renamed together only when every one of them is complete, so a failure (a full
disk, an error, Ctrl-C, SIGTERM) leaves neither a partial file nor the first outputs of a
command whose later outputs failed.

Write: PNG, JPEG and TIFF (8 bit; 16 bit for PNG and TIFF on request), ``.npy`` arrays,
UTF-8 text (JSON sidecars, HTML reports), MP4/GIF videos and folders of PNG frames.
"""

from __future__ import annotations

import errno
import math
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterable
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import (
    InputError,
    OutputExistsError,
    OutputFolderNotFoundError,
    OutputPathError,
    OutputWriteError,
)

__all__ = [
    "VIDEO_FORMATS",
    "WRITE_FORMATS",
    "OutputSet",
    "atomic_write",
    "check_output_path",
    "sidecar_path",
    "write_array",
    "write_frames",
    "write_image",
]

WRITE_FORMATS = {".png": (8, 16), ".jpg": (8,), ".jpeg": (8,), ".tif": (8, 16), ".tiff": (8, 16)}
ARRAY_FORMATS = {".npy": (8,)}
JSON_FORMATS = {".json": (8,)}
VIDEO_FORMATS = {".mp4": (8,), ".gif": (8,)}
FRAME_NAME = "frame_{:05d}.png"
_FRAME_RE = re.compile(r"frame_[0-9]{5,}\.png")
_TEMP_SUFFIX = ".part"


def sidecar_path(output: str | os.PathLike) -> Path:
    """The JSON sidecar of an output: the output's full name followed by ``.json``.

    ``out.png`` -> ``out.png.json``, ``anim.mp4`` -> ``anim.mp4.json``, a frame folder
    ``frames`` -> ``frames.json``.
    """
    p = Path(output)
    return p.with_name(p.name + ".json")


# ---------------------------------------------------------------------------- checks
def _check_format(p: Path, formats: dict, bit_depth: int) -> None:
    suffix = p.suffix.lower()
    if suffix not in formats:
        raise OutputPathError(
            f"cannot write '{p}': unsupported file type '{suffix or '(none)'}'; "
            f"use one of {', '.join(sorted(formats))}"
        )
    depths = formats[suffix]
    if bit_depth not in depths:
        raise OutputPathError(
            f"cannot write '{p}' with {bit_depth}-bit depth; {suffix} allows "
            f"{' or '.join(str(d) for d in depths)} bit"
        )


def _check_folder(p: Path) -> None:
    parent = p.parent
    if not parent.is_dir():
        raise OutputFolderNotFoundError(f"cannot write '{p}': folder '{parent}' does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"cannot write '{p}': folder '{parent}' is not writable")


def check_output_path(path: str | os.PathLike, *, bit_depth: int = 8, formats=None) -> Path:
    """Check that ``path`` can be written: known format, bit depth allowed, folder exists and is writable.

    Raises :class:`~texsyn.errors.OutputPathError` (unsupported format or depth, read-only
    folder, ``path`` is a folder) or :class:`~texsyn.errors.OutputFolderNotFoundError`
    (missing folder, also a ``FileNotFoundError``) before any work is done.
    """
    p = Path(path)
    _check_format(p, WRITE_FORMATS if formats is None else formats, bit_depth)
    _check_folder(p)
    if p.is_dir():
        raise OutputPathError(f"cannot write '{p}': it is a folder")
    return p


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: same resolved path, or (both existing) same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _inside(path: Path, folder: Path) -> bool:
    real, top = os.path.realpath(path), os.path.realpath(folder)
    return real != top and os.path.commonpath([real, top]) == top


def _remove(path: Path) -> None:
    """Remove a file, a link or a folder tree; ignore what is already gone."""
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync(path: Path) -> None:
    """Flush a file (or every file of a folder, then the folder) to disk.

    A full disk on file systems with delayed allocation shows up here, not in ``write``.
    """
    if path.is_dir():
        for entry in os.scandir(path):
            if entry.is_file(follow_symlinks=False):
                _fsync(Path(entry.path))
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):  # e.g. folders on some file systems
            raise
    finally:
        os.close(fd)


def _write_error(target: Path, exc: OSError) -> OutputWriteError:
    reason = exc.strerror or str(exc) or type(exc).__name__
    return OutputWriteError(exc.errno, f"cannot write '{target}': {' '.join(reason.split())}", str(target))


# ---------------------------------------------------------------------------- output sets
class OutputSet:
    """The outputs of one command: checked up front, written to temporaries, renamed together.

    Parameters
    ----------
    overwrite : bool
        Replace existing outputs. Without it an existing output raises
        :class:`~texsyn.errors.OutputExistsError` (an existing *empty* folder may receive
        frames). An output that names an input or another output is refused either way.
    inputs : iterable of path or (label, path)
        Files the command reads; no output may name one (compared by resolved path and by
        inode, so ``./a.png``, symbolic and hard links are caught).
    overwrite_hint : str
        How the user asks to overwrite, quoted in the error (``--overwrite`` on the command line).

    Examples
    --------
    >>> outputs = OutputSet(inputs=[("exemplar", "in.png")])        # doctest: +SKIP
    >>> out = outputs.claim("out.png")                              # checks now, before any work
    >>> side = outputs.claim(sidecar_path(out), formats=JSON_FORMATS)
    >>> with outputs:                                               # all or nothing
    ...     outputs.write_image(out, image)
    ...     outputs.write_text(side, "{}")

    Leaving the ``with`` block normally renames every temporary into place; leaving it with
    any exception (``KeyboardInterrupt`` included) removes them all. If a rename fails
    half-way, the outputs already renamed are removed again and the files they replaced are
    put back (they were moved aside, not deleted, until every rename had succeeded).
    """

    def __init__(
        self,
        *,
        overwrite: bool = False,
        inputs: Iterable = (),
        overwrite_hint: str = "overwrite=True",
    ) -> None:
        self.overwrite = bool(overwrite)
        self.overwrite_hint = overwrite_hint
        self._inputs: list[tuple[str, Path]] = []
        self._targets: dict[Path, tuple[str, bool]] = {}
        self._staged: dict[Path, Path] = {}
        self.committed = False
        for item in inputs:
            if isinstance(item, tuple):
                self.add_input(item[1], item[0])
            else:
                self.add_input(item)

    # -------------------------------------------------------------- declaring
    def add_input(self, path: str | os.PathLike | None, label: str = "input") -> None:
        """Declare a file the command reads; outputs may not name it."""
        if path is None:
            return
        p = Path(path)
        for target, (what, folder) in self._targets.items():
            self._check_not_input(target, what, folder, label, p)
        self._inputs.append((label, p))

    @staticmethod
    def _check_not_input(target: Path, what: str, folder: bool, label: str, source: Path) -> None:
        if _same_file(target, source):
            raise OutputPathError(
                f"{what} '{target}' is the {label} '{source}'; texsyn never writes over its inputs, choose another name"
            )
        if folder and _inside(source, target):
            raise OutputPathError(
                f"{what} '{target}' is the folder of the {label} '{source}'; choose another folder"
            )

    def claim(
        self,
        path: str | os.PathLike,
        *,
        what: str = "output",
        formats: dict | None = None,
        bit_depth: int = 8,
        folder: bool = False,
    ) -> Path:
        """Check an output before any work and reserve it; return it as a ``Path``.

        Parameters
        ----------
        path : str or path-like
        what : str
            How errors name it (``"output"``, ``"source map"``, ``"sidecar"``...).
        formats : dict, optional
            Allowed suffixes and their bit depths (default: PNG, JPEG, TIFF); ignored for folders.
        bit_depth : int
        folder : bool
            The output is a folder of frames (no suffix).
        """
        p = Path(path)
        if p.name in ("", ".", ".."):
            raise OutputPathError(f"{what} '{path}' needs a file or folder name")
        if not folder:
            _check_format(p, WRITE_FORMATS if formats is None else formats, bit_depth)
        _check_folder(p)
        for label, source in self._inputs:
            self._check_not_input(p, what, folder, label, source)
        for other, (other_what, other_folder) in self._targets.items():
            if _same_file(p, other) or (other_folder and _inside(p, other)) or (folder and _inside(other, p)):
                raise OutputPathError(f"{what} '{p}' and {other_what} '{other}' name the same file; give them different names")
        self._check_existing(p, what, folder)
        self._targets[p] = (what, folder)
        return p

    def claimed(self, path: str | os.PathLike) -> bool:
        return Path(path) in self._targets

    def _check_existing(self, p: Path, what: str, folder: bool) -> None:
        if not os.path.lexists(p):
            return
        if folder:
            if p.is_dir() and not p.is_symlink():
                entries = list(os.scandir(p))
                if not entries:
                    return  # an empty folder receives the frames; nothing is lost
                if not self.overwrite:
                    raise OutputExistsError(
                        f"folder '{p}' already exists and is not empty; use {self.overwrite_hint} to replace it"
                    )
                if any(not (_FRAME_RE.fullmatch(e.name) and e.is_file(follow_symlinks=False)) for e in entries):
                    raise OutputPathError(
                        f"cannot replace folder '{p}': it holds files other than frame_NNNNN.png "
                        "(texsyn replaces only frame folders it could have written)"
                    )
                return
            if not self.overwrite:
                raise OutputExistsError(f"'{p}' already exists; use {self.overwrite_hint} to replace it")
            raise OutputPathError(f"cannot write frames to '{p}': it is a file, not a folder")
        if p.is_dir():
            raise OutputPathError(f"cannot write {what} '{p}': it is a folder")
        if not self.overwrite:
            raise OutputExistsError(f"'{p}' already exists; use {self.overwrite_hint} to replace it")

    # -------------------------------------------------------------- writing
    def _temporary(self, target: Path, folder: bool) -> Path:
        if target not in self._targets:
            raise RuntimeError(f"output '{target}' was not claimed before writing")
        if target in self._staged:
            raise RuntimeError(f"output '{target}' is written twice")
        prefix = f".{target.name}."
        if folder:
            tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=_TEMP_SUFFIX, dir=target.parent))
        else:
            fd, name = tempfile.mkstemp(prefix=prefix, suffix=_TEMP_SUFFIX, dir=target.parent)
            os.close(fd)
            tmp = Path(name)
        self._staged[target] = tmp
        return tmp

    def write(self, path: str | os.PathLike, writer: Callable[[Path], None]) -> Path:
        """Stage one output: ``writer(temporary_path)`` writes it; renamed at :meth:`commit`.

        Any exception discards the whole set (all or nothing); an ``OSError`` of the writer
        becomes :class:`~texsyn.errors.OutputWriteError` naming the output.
        """
        target = Path(path)
        folder = self._targets.get(target, ("", False))[1]
        try:
            tmp = self._temporary(target, folder)
            writer(tmp)
            _fsync(tmp)
        except InputError:
            self.discard()
            raise
        except OSError as exc:
            self.discard()
            raise _write_error(target, exc) from exc
        except BaseException:
            self.discard()
            raise
        return target

    def write_image(self, path: str | os.PathLike, image: np.ndarray, *, bit_depth: int = 8) -> Path:
        """Stage a float image in [0, 1] (or uint8/uint16) as PNG, JPEG or TIFF."""
        target = Path(path)
        data = _image_data(image, bit_depth)
        suffix = target.suffix.lower()
        return self.write(target, lambda tmp: _encode_image(tmp, data, suffix))

    def write_array(self, path: str | os.PathLike, array: np.ndarray) -> Path:
        """Stage a NumPy array as ``.npy``."""
        arr = np.asarray(array)
        return self.write(path, lambda tmp: _encode_array(tmp, arr))

    def write_text(self, path: str | os.PathLike, text: str) -> Path:
        """Stage UTF-8 text (a JSON sidecar, an HTML page)."""
        return self.write(path, lambda tmp: _encode_text(tmp, text))

    def write_frames(self, path: str | os.PathLike, frames: Iterable[np.ndarray], *, fps: float = 24.0) -> Path:
        """Stage a video (``.mp4``, ``.gif``) or a claimed folder of PNG frames.

        ``frames`` is consumed one at a time; the video is checked after writing (``.mp4``:
        ffmpeg's exit status and the frame count read back from the file).
        """
        target = Path(path)
        if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not (
            math.isfinite(fps) and fps > 0
        ):
            raise InputError(f"fps must be a finite positive number, got {fps!r}")
        folder = self._targets.get(target, ("", False))[1]
        suffix = target.suffix.lower()
        if folder:
            return self.write(target, lambda tmp: _encode_frame_folder(tmp, frames))
        if suffix == ".gif":
            return self.write(target, lambda tmp: _encode_gif(tmp, frames, float(fps)))
        if suffix == ".mp4":
            return self.write(target, lambda tmp: _encode_mp4(tmp, frames, float(fps)))
        raise InputError(f"cannot write {suffix!r} animations; use .mp4, .gif or a folder name (PNG frames)")

    # -------------------------------------------------------------- commit / discard
    def commit(self) -> list[Path]:
        """Rename every staged output into place, all or none; return the outputs."""
        if self.committed:
            return list(self._staged)
        try:
            for target in self._staged:
                what, folder = self._targets[target]
                self._check_existing(target, what, folder)  # appeared while we worked?
        except BaseException:
            self.discard()
            raise
        mask = _umask()
        done: list[tuple[Path, Path | None, bool]] = []
        current = None
        try:
            for target, tmp in self._staged.items():
                current = target
                folder = self._targets[target][1]
                os.chmod(tmp, (0o777 if folder else 0o666) & ~mask)
                backup = None
                was_empty_folder = folder and target.is_dir() and not target.is_symlink() and not any(target.iterdir())
                if os.path.lexists(target) and not was_empty_folder:
                    backup = self._backup(target)
                    os.replace(target, backup)
                done.append((target, backup, was_empty_folder))
                os.replace(tmp, target)
        except BaseException as exc:
            self._rollback(done)
            self.discard()
            if isinstance(exc, OSError) and not isinstance(exc, InputError) and current is not None:
                raise _write_error(current, exc) from exc
            raise
        for _, backup, _ in done:
            if backup is not None:
                _remove(backup)
        for parent in {t.parent for t in self._staged}:
            try:
                _fsync(parent)
            except OSError:
                pass
        self.committed = True
        return list(self._staged)

    @staticmethod
    def _backup(target: Path) -> Path:
        """A fresh hidden name beside ``target`` for moving it aside until the commit succeeds."""
        prefix = f".{target.name}."
        if target.is_dir() and not target.is_symlink():
            return Path(tempfile.mkdtemp(prefix=prefix, suffix=".old", dir=target.parent))
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=".old", dir=target.parent)
        os.close(fd)
        return Path(name)

    @staticmethod
    def _rollback(done: list[tuple[Path, Path | None, bool]]) -> None:
        for target, backup, was_empty_folder in reversed(done):
            try:
                if backup is not None:
                    if os.path.lexists(target):
                        _remove(target)
                    os.replace(backup, target)
                else:
                    _remove(target)
                    if was_empty_folder:
                        os.mkdir(target)
            except OSError:  # best effort: keep undoing the others
                pass

    def discard(self) -> None:
        """Remove every temporary of this set (nothing is renamed)."""
        for tmp in self._staged.values():
            _remove(tmp)
        if not self.committed:
            self._staged.clear()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
        return False


# ---------------------------------------------------------------------------- encoders
def _image_data(image: np.ndarray, bit_depth: int) -> np.ndarray:
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


def _encode_image(tmp: Path, data: np.ndarray, suffix: str) -> None:
    import imageio.v3 as iio

    if suffix == ".png" and data.dtype == np.uint16:
        import png  # Pillow cannot write 16-bit colour PNG

        planes = 1 if data.ndim == 2 else data.shape[2]
        with open(tmp, "wb") as fh:
            png.Writer(data.shape[1], data.shape[0], greyscale=planes == 1, bitdepth=16).write_array(
                fh, data.reshape(-1)
            )
        return
    kwargs = {"quality": 95} if suffix in (".jpg", ".jpeg") else {}
    iio.imwrite(tmp, data, extension=suffix, **kwargs)


def _encode_array(tmp: Path, array: np.ndarray) -> None:
    with open(tmp, "wb") as fh:
        np.save(fh, array, allow_pickle=False)


def _encode_text(tmp: Path, text: str) -> None:
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)


def _to_uint8(frame: np.ndarray) -> np.ndarray:
    arr = np.asarray(frame, dtype=np.float64)
    if not np.all(np.isfinite(arr)) or arr.min() < 0 or arr.max() > 1:
        raise InputError("frame values must be finite and lie in [0, 1]")
    return np.rint(arr * 255.0).astype(np.uint8)


def _encode_frame_folder(tmp: Path, frames: Iterable[np.ndarray]) -> None:
    import imageio.v3 as iio

    count = 0
    for i, frame in enumerate(frames):
        iio.imwrite(tmp / FRAME_NAME.format(i), _to_uint8(frame), extension=".png")
        count += 1
    if count == 0:
        raise InputError("no frames to write")


def _encode_gif(tmp: Path, frames: Iterable[np.ndarray], fps: float) -> None:
    import imageio.v3 as iio

    images = [_to_uint8(f) for f in frames]
    if not images:
        raise InputError("no frames to write")
    iio.imwrite(tmp, images, extension=".gif", duration=1000.0 / fps, loop=0)
    if tmp.stat().st_size == 0:
        raise OSError(errno.EIO, "the GIF writer produced an empty file")


def _ffmpeg_exe() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


class _FfmpegWriter:
    """H.264 MP4 through an ffmpeg process whose exit status and messages are checked.

    imageio's writer ignores ffmpeg's exit status (a full disk gave a corrupt file and no
    error), so texsyn drives ffmpeg itself: frames go to its stdin as raw RGB, its messages
    to an anonymous temporary file, and any failure raises ``OSError`` with ffmpeg's reason.
    """

    def __init__(self, path: Path, fps: float) -> None:
        self.path = Path(path)
        self.fps = Fraction(fps).limit_denominator(1001)
        self.count = 0
        self.size: tuple[int, int] | None = None
        self._proc: subprocess.Popen | None = None
        self._log = tempfile.TemporaryFile()

    def _start(self, h: int, w: int) -> None:
        cmd = [
            _ffmpeg_exe(), "-y", "-v", "error", "-nostats",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", str(self.fps), "-i", "-",
            "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "10",
            "-f", "mp4", str(self.path),
        ]  # fmt: skip
        self._proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            start_new_session=True,  # Ctrl-C reaches texsyn only; texsyn stops ffmpeg itself
        )
        self.size = (h, w)

    def append(self, frame: np.ndarray) -> None:
        data = _to_uint8(frame)
        if data.ndim == 2:
            data = np.repeat(data[..., None], 3, axis=2)
        elif data.shape[2] == 4:
            data = data[..., :3]
        h, w = data.shape[:2]
        data = np.pad(data, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")  # yuv420p needs even sizes
        if self._proc is None:
            self._start(*data.shape[:2])
        elif data.shape[:2] != self.size:
            raise InputError(f"every frame must have the size of the first, {self.size}, got {data.shape[:2]}")
        try:
            self._proc.stdin.write(np.ascontiguousarray(data).tobytes())
        except OSError:  # ffmpeg stopped reading (it failed): report its reason
            self._finish()
            raise self._failure() from None
        self.count += 1

    def _finish(self) -> int:
        proc = self._proc
        if proc.stdin is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
        return proc.wait()

    def _failure(self) -> OSError:
        self._log.seek(0)
        text = self._log.read().decode("utf-8", "replace")
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        code = self._proc.returncode if self._proc is not None else None
        if "No space left on device" in text:
            return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        if "Permission denied" in text:
            return OSError(errno.EACCES, os.strerror(errno.EACCES))
        reason = lines[-1] if lines else f"exit status {code}"
        return OSError(errno.EIO, f"ffmpeg failed: {reason}")

    def close(self) -> None:
        """Wait for ffmpeg; raise ``OSError`` unless it succeeded and the file holds every frame."""
        try:
            if self._proc is None:
                raise InputError("no frames to write")
            if self._finish() != 0:
                raise self._failure()
            if self.path.stat().st_size == 0:
                raise OSError(errno.EIO, "ffmpeg wrote an empty file")
            written = _count_video_frames(self.path)
            if written != self.count:
                raise OSError(errno.EIO, f"the video holds {written} of {self.count} frames")
        finally:
            self._log.close()

    def abort(self) -> None:
        """Stop ffmpeg at once (on an error or an interruption)."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc is not None and proc.stdin is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
        self._log.close()


def _count_video_frames(path: Path) -> int:
    import imageio_ffmpeg

    try:
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    except (RuntimeError, OSError) as exc:
        raise OSError(errno.EIO, f"the video written cannot be read back ({' '.join(str(exc).split())[:200]})") from None
    return int(frames)


def _encode_mp4(tmp: Path, frames: Iterable[np.ndarray], fps: float) -> None:
    writer = _FfmpegWriter(tmp, fps)
    try:
        for frame in frames:
            writer.append(frame)
        writer.close()
    except BaseException:
        writer.abort()
        raise


# ---------------------------------------------------------------------------- one-file writers
def atomic_write(path: Path, writer, *, suffix: str = _TEMP_SUFFIX) -> None:
    """Call ``writer(temporary_path)`` in ``path``'s folder, then rename it to ``path``.

    ``suffix`` ends the temporary name (writers that choose the format from it need the
    real one). Replaces an existing ``path``; for several outputs use :class:`OutputSet`.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        writer(tmp)
        _fsync(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_image(path: str | os.PathLike, image: np.ndarray, *, bit_depth: int = 8, overwrite: bool = True) -> Path:
    """Write a float image in [0, 1] to PNG, JPEG or TIFF, atomically.

    Parameters
    ----------
    path : str or path-like
        Its suffix chooses the format.
    image : ndarray, shape (H, W) or (H, W, 3)
        Values outside [0, 1] are rejected (not clipped silently).
    bit_depth : {8, 16}
        16 bit is allowed for PNG and TIFF.
    overwrite : bool
        Replace an existing file (default); ``False`` raises ``OutputExistsError``.
    """
    outputs = OutputSet(overwrite=overwrite)
    p = outputs.claim(path, bit_depth=bit_depth)
    with outputs:
        outputs.write_image(p, image, bit_depth=bit_depth)
    return p


def write_array(path: str | os.PathLike, array: np.ndarray, *, overwrite: bool = True) -> Path:
    """Write a NumPy array to a ``.npy`` file, atomically."""
    outputs = OutputSet(overwrite=overwrite)
    p = outputs.claim(path, formats=ARRAY_FORMATS)
    with outputs:
        outputs.write_array(p, array)
    return p


def write_frames(
    path: str | os.PathLike, frames: Iterable[np.ndarray], *, fps: float = 24.0, overwrite: bool = True
) -> Path:
    """Write a sequence of float frames in [0, 1] as a video, a GIF or a folder of PNGs, atomically.

    Parameters
    ----------
    path : str or path-like
        ``.mp4`` (H.264 through the ffmpeg of imageio-ffmpeg; odd sizes are padded by one
        edge row/column; ffmpeg's exit status and the frame count are checked), ``.gif``
        (looping), or a path without suffix: a folder that receives ``frame_00000.png``, ...
        (a new or empty folder; with ``overwrite`` also a folder holding only such frames).
    frames : iterable of ndarray, shape (H, W) or (H, W, 3)
        Consumed one at a time (a generator is fine); nothing is left behind on error.
    fps : float
        Frames per second.
    overwrite : bool
        Replace an existing video or frame folder (default).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    outputs = OutputSet(overwrite=overwrite)
    if suffix:
        outputs.claim(p, formats=VIDEO_FORMATS, what="video")
    else:
        outputs.claim(p, folder=True, what="frame folder")
    with outputs:
        outputs.write_frames(p, frames, fps=fps)
    return p
