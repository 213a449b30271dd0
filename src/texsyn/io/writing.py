"""Writing images, arrays, text and videos: all or nothing, never over an input.

Every output goes to a hidden temporary file (or folder) beside it, named
``.NAME.XXXXXXXX.part``, and is renamed into place only once it is complete. Several
outputs of one command form an :class:`OutputSet`: they are all written to temporaries
first and renamed together only when every one of them is complete, so a failure (a full
disk, an error, Ctrl-C, SIGTERM) leaves neither a partial file nor the first outputs of a
command whose later outputs failed.

Write: PNG, JPEG and TIFF (8 bit; 16 bit for PNG and TIFF on request; 32-bit float TIFF),
``.npy`` images (uint8, uint16, float32) and OpenEXR (float), with the ICC profile given,
``.npy`` arrays, UTF-8 text (JSON sidecars, HTML reports), MP4, WebM and GIF videos and folders of PNG frames.

The path checks and file-system steps are in :mod:`texsyn.io.output_paths`, the encoders
in :mod:`texsyn.io.encoders` and :mod:`texsyn.io.video`, the writers of outputs streamed
band by band in :mod:`texsyn.io.streaming`; the encoders are called here through module
names (``_encode_image``...) so that a test can make one fail.

Why this module is long: :class:`OutputSet` is one class whose steps (claim, stage whole or
streamed outputs, commit, discard) share its staging state; the all-or-nothing rule lives
in their interplay, and splitting the class would scatter it.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Literal

import numpy as np

from ..errors import InputError, OutputPathError
from .encoders import encode_array as _encode_array
from .encoders import encode_frame_folder, encode_gif, image_data
from .encoders import encode_image as _encode_image
from .encoders import encode_text as _encode_text
from .output_paths import (
    ARRAY_FORMATS,
    FRAME_NAME,
    JSON_FORMATS,
    TEMP_SUFFIX,
    VIDEO_FORMATS,
    WRITE_FORMATS,
    animation_format_error,
    atomic_write,
    backup_name,
    check_existing,
    check_folder,
    check_format,
    check_not_input,
    check_output_path,
    current_umask,
    fsync_entry,
    fsync_path,
    inside,
    remove_path,
    restore,
    same_file,
    sidecar_path,
    write_error,
)
from .streaming import StagedRows, open_row_writer
from .video import VIDEO_CODECS, encode_video
from .video import FfmpegWriter as _FfmpegWriter  # noqa: F401 - a test makes ffmpeg fail through it
from .video import ffmpeg_exe as _ffmpeg_exe

__all__ = [
    "ARRAY_FORMATS",
    "FRAME_NAME",
    "JSON_FORMATS",
    "VIDEO_FORMATS",
    "WRITE_FORMATS",
    "OutputSet",
    "StagedRows",
    "atomic_write",
    "check_output_path",
    "sidecar_path",
    "write_array",
    "write_frames",
    "write_image",
]


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
    >>> import os, tempfile
    >>> import numpy as np
    >>> folder = tempfile.TemporaryDirectory()
    >>> outputs = OutputSet(inputs=[("exemplar", os.path.join(folder.name, "in.png"))])
    >>> out = outputs.claim(os.path.join(folder.name, "out.png"))  # checks now, before any work
    >>> side = outputs.claim(sidecar_path(out), formats=JSON_FORMATS)
    >>> with outputs:  # all or nothing
    ...     _ = outputs.write_image(out, np.zeros((8, 8)))
    ...     _ = outputs.write_text(side, "{}")
    >>> sorted(os.listdir(folder.name))
    ['out.png', 'out.png.json']
    >>> folder.cleanup()

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
        self._open_rows: list[StagedRows] = []
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
            check_not_input(target, what, folder, label, p)
        self._inputs.append((label, p))

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
            check_format(p, WRITE_FORMATS if formats is None else formats, bit_depth)
        check_folder(p)
        for label, source in self._inputs:
            check_not_input(p, what, folder, label, source)
        for other, (other_what, other_folder) in self._targets.items():
            if same_file(p, other) or (other_folder and inside(p, other)) or (folder and inside(other, p)):
                raise OutputPathError(
                    f"{what} '{p}' and {other_what} '{other}' name the same file; give them different names"
                )
        self._check_existing(p, what, folder)
        self._targets[p] = (what, folder)
        return p

    def claimed(self, path: str | os.PathLike) -> bool:
        return Path(path) in self._targets

    def _check_existing(self, p: Path, what: str, folder: bool) -> None:
        check_existing(p, what, folder, overwrite=self.overwrite, hint=self.overwrite_hint)

    # -------------------------------------------------------------- writing
    def _temporary(self, target: Path, folder: bool) -> Path:
        if target not in self._targets:
            raise RuntimeError(f"output '{target}' was not claimed before writing")
        if target in self._staged:
            raise RuntimeError(f"output '{target}' is written twice")
        prefix = f".{target.name}."
        if folder:
            tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=TEMP_SUFFIX, dir=target.parent))
        else:
            fd, name = tempfile.mkstemp(prefix=prefix, suffix=TEMP_SUFFIX, dir=target.parent)
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
            fsync_path(tmp)
        except InputError:
            self.discard()
            raise
        except OSError as exc:
            self.discard()
            raise write_error(target, exc) from exc
        except BaseException:
            self.discard()
            raise
        return target

    def open_rows(
        self,
        path: str | os.PathLike,
        shape: tuple[int, ...],
        *,
        bit_depth: int = 8,
        dtype: np.dtype | type | None = None,
        icc_profile: bytes | None = None,
    ) -> StagedRows:
        """Stage an output written band by band (:mod:`texsyn.io.streaming`).

        Parameters
        ----------
        path : str or path-like
            A claimed output: an image (``.png``, ``.tif``, ``.jpg``), or ``.npy`` (then
            ``dtype`` is the array's).
        shape : tuple
            ``(height, width)`` or ``(height, width, channels)`` of the whole output.
        bit_depth : int
            Of an image (8, 16, or 32 for float samples).
        dtype : dtype, optional
            Of an ``.npy`` array (a source map); ``None`` for an ``.npy`` image (its samples
            follow ``bit_depth``).
        icc_profile : bytes, optional
            Embedded in a PNG, TIFF or JPEG image.

        Returns
        -------
        StagedRows
            ``write(rows)`` for each band, top to bottom, then ``close()``; renamed into
            place with the set at :meth:`commit`, removed with it on any failure.
        """
        target = Path(path)
        tmp = self._temporary(target, False)
        staged = StagedRows(
            target,
            lambda: open_row_writer(
                tmp, target.suffix.lower(), shape, bit_depth=bit_depth, dtype=dtype, icc_profile=icc_profile
            ),
            discard=self.discard,
            closed=self._open_rows.remove,
        )
        self._open_rows.append(staged)
        return staged

    def write_image(
        self,
        path: str | os.PathLike,
        image: np.ndarray,
        *,
        bit_depth: int = 8,
        icc_profile: bytes | None = None,
    ) -> Path:
        """Stage a float image in [0, 1] (or uint8/uint16) as PNG, JPEG, TIFF, ``.npy`` or EXR;
        with ``bit_depth=32`` float samples of any finite value (TIFF, ``.npy``, EXR)."""
        target = Path(path)
        data = image_data(image, bit_depth)
        suffix = target.suffix.lower()
        if icc_profile is None:  # the encoder as it was called before ICC profiles existed
            return self.write(target, lambda tmp: _encode_image(tmp, data, suffix))
        return self.write(target, lambda tmp: _encode_image(tmp, data, suffix, icc_profile))

    def write_array(self, path: str | os.PathLike, array: np.ndarray) -> Path:
        """Stage a NumPy array as ``.npy``."""
        arr = np.asarray(array)
        return self.write(path, lambda tmp: _encode_array(tmp, arr))

    def write_text(self, path: str | os.PathLike, text: str) -> Path:
        """Stage UTF-8 text (a JSON sidecar, an HTML page)."""
        return self.write(path, lambda tmp: _encode_text(tmp, text))

    def write_frames(
        self, path: str | os.PathLike, frames: Iterable[np.ndarray], *, fps: float = 24.0
    ) -> Path:
        """Stage a video (``.mp4``, ``.webm``, ``.gif``) or a claimed folder of PNG frames.

        ``frames`` is consumed one at a time; the video is checked after writing (``.mp4``
        and ``.webm``: ffmpeg's exit status and the frame count read back from the file).
        """
        target = Path(path)
        if (
            isinstance(fps, bool)
            or not isinstance(fps, (int, float, np.integer, np.floating))
            or not (math.isfinite(fps) and fps > 0)
        ):
            raise InputError(f"fps must be a finite positive number, got {fps!r}")
        folder = self._targets.get(target, ("", False))[1]
        suffix = target.suffix.lower()
        if folder:
            return self.write(target, lambda tmp: encode_frame_folder(tmp, frames))
        if suffix == ".gif":
            return self.write(target, lambda tmp: encode_gif(tmp, frames, float(fps)))
        if suffix in VIDEO_CODECS:
            codec = VIDEO_CODECS[suffix]
            return self.write(
                target, lambda tmp: encode_video(tmp, frames, float(fps), codec, executable=_ffmpeg_exe())
            )
        raise animation_format_error(suffix)

    # -------------------------------------------------------------- commit / discard
    def commit(self) -> list[Path]:
        """Rename every staged output into place, all or none; return the outputs."""
        if self.committed:
            return list(self._staged)
        try:
            if self._open_rows:
                raise RuntimeError(f"output '{self._open_rows[0].target}' was not closed before the commit")
            for target in self._staged:
                what, folder = self._targets[target]
                self._check_existing(target, what, folder)  # appeared while we worked?
        except BaseException:
            self.discard()
            raise
        mask = current_umask()
        done: list[tuple[Path, Path | None, bool]] = []
        current = None
        try:
            for target, tmp in self._staged.items():
                current = target
                folder = self._targets[target][1]
                os.chmod(tmp, (0o777 if folder else 0o666) & ~mask)
                backup = None
                was_empty_folder = (
                    folder and target.is_dir() and not target.is_symlink() and not any(target.iterdir())
                )
                if os.path.lexists(target) and not was_empty_folder:
                    backup = backup_name(target)
                    os.replace(target, backup)
                done.append((target, backup, was_empty_folder))
                os.replace(tmp, target)
        except BaseException as exc:
            restore(done)
            self.discard()
            if isinstance(exc, OSError) and not isinstance(exc, InputError) and current is not None:
                raise write_error(current, exc) from exc
            raise
        for _, backup, _ in done:
            if backup is not None:
                remove_path(backup)
        for parent in {t.parent for t in self._staged}:
            try:  # the renames; the folder's other files are not ours to flush
                fsync_entry(parent)
            except OSError:
                pass
        self.committed = True
        return list(self._staged)

    def discard(self) -> None:
        """Remove every temporary of this set (nothing is renamed)."""
        for rows in self._open_rows:
            rows.writer.abort()
        self._open_rows.clear()
        for tmp in self._staged.values():
            remove_path(tmp)
        if not self.committed:
            self._staged.clear()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
        return False


# ---------------------------------------------------------------------------- one-file writers
def write_image(
    path: str | os.PathLike,
    image: np.ndarray,
    *,
    bit_depth: int = 8,
    overwrite: bool = True,
    icc_profile: bytes | None = None,
) -> Path:
    """Write a float image to PNG, JPEG, TIFF, ``.npy`` or OpenEXR, atomically.

    Parameters
    ----------
    path : str or path-like
        Its suffix chooses the format.
    image : ndarray, shape (H, W) or (H, W, C), C from 1 to 4
        For 8 and 16 bits, values outside [0, 1] are rejected (not clipped silently).
    bit_depth : {8, 16, 32}
        16 bit is allowed for PNG, TIFF and ``.npy``; 32 (float samples, any finite values)
        for TIFF, ``.npy`` and EXR (``docs/materials.md``).
    overwrite : bool
        Replace an existing file (default); ``False`` raises ``OutputExistsError``.
    icc_profile : bytes, optional
        An ICC colour profile to embed (PNG, JPEG, TIFF).
    """
    outputs = OutputSet(overwrite=overwrite)
    p = outputs.claim(path, bit_depth=bit_depth)
    with outputs:
        outputs.write_image(p, image, bit_depth=bit_depth, icc_profile=icc_profile)
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
        ``.mp4`` (H.264; odd sizes are padded by one edge row/column) or ``.webm`` (VP9),
        both through the ffmpeg of imageio-ffmpeg, whose exit status and the frame count
        read back are checked; ``.gif`` (looping); or a path without suffix: a folder that
        receives ``frame_00000.png``, ... (a new or empty folder; with ``overwrite`` also a
        folder holding only such frames).
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
