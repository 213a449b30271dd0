"""Output paths: the checks made before any work, and the file-system steps of a safe write.

A path is checked up front (known format, allowed bit depth, existing writable folder, not
an input, not an existing file unless overwriting); the steps of an all-or-nothing write
(flush to disk, move aside, put back, remove) are the building blocks of
:class:`texsyn.io.OutputSet` (``docs/errors.md``).
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import tempfile
from pathlib import Path

from ..errors import (
    OutputExistsError,
    OutputFolderNotFoundError,
    OutputPathError,
    OutputWriteError,
)

__all__ = [
    "atomic_write",
    "ARRAY_FORMATS",
    "FRAME_NAME",
    "FRAME_RE",
    "JSON_FORMATS",
    "TEMP_SUFFIX",
    "VIDEO_FORMATS",
    "WRITE_FORMATS",
    "animation_format_error",
    "backup_name",
    "check_existing",
    "check_folder",
    "check_format",
    "check_not_input",
    "check_output_path",
    "current_umask",
    "fsync_entry",
    "fsync_path",
    "inside",
    "remove_path",
    "restore",
    "same_file",
    "sidecar_path",
    "write_error",
]

#: image formats and their bit depths (32: float samples; docs/materials.md)
WRITE_FORMATS = {
    ".png": (8, 16),
    ".jpg": (8,),
    ".jpeg": (8,),
    ".tif": (8, 16, 32),
    ".tiff": (8, 16, 32),
    ".npy": (8, 16, 32),
    ".exr": (32,),
}
ARRAY_FORMATS = {".npy": (8,)}
JSON_FORMATS = {".json": (8,)}
VIDEO_FORMATS = {".mp4": (8,), ".webm": (8,), ".gif": (8,)}
FRAME_NAME = "frame_{:05d}.png"
FRAME_RE = re.compile(r"frame_[0-9]{5,}\.png")
TEMP_SUFFIX = ".part"


def sidecar_path(output: str | os.PathLike) -> Path:
    """The JSON sidecar of an output: the output's full name followed by ``.json``.

    ``out.png`` -> ``out.png.json``, ``anim.mp4`` -> ``anim.mp4.json``, a frame folder
    ``frames`` -> ``frames.json``.
    """
    p = Path(output)
    return p.with_name(p.name + ".json")


# ---------------------------------------------------------------------------- checks
def animation_format_error(suffix: str) -> OutputPathError:
    """The error for an animation named with a suffix that is not a video format.

    >>> print(animation_format_error(".avi"))
    cannot write '.avi' animations; use .mp4, .webm, .gif or a folder name (PNG frames)
    """
    return OutputPathError(
        f"cannot write {suffix!r} animations; use {', '.join(VIDEO_FORMATS)} or a folder name (PNG frames)"
    )


def check_format(p: Path, formats: dict, bit_depth: int) -> None:
    suffix = p.suffix.lower()
    if suffix not in formats:
        raise OutputPathError(
            f"cannot write '{p}': unsupported file type '{suffix or '(none)'}'; "
            f"use one of {', '.join(sorted(formats))}"
        )
    depths = formats[suffix]
    if bit_depth not in depths:
        named = [f"{d}-bit float" if d == 32 else f"{d}-bit" for d in depths]
        said = "32-bit float" if bit_depth == 32 else f"{bit_depth}-bit"
        raise OutputPathError(f"cannot write '{p}' with {said} depth; {suffix} allows {' or '.join(named)}")


def check_folder(p: Path) -> None:
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
    check_format(p, WRITE_FORMATS if formats is None else formats, bit_depth)
    check_folder(p)
    if p.is_dir():
        raise OutputPathError(f"cannot write '{p}': it is a folder")
    return p


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: same resolved path, or (both existing) same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def inside(path: Path, folder: Path) -> bool:
    real, top = os.path.realpath(path), os.path.realpath(folder)
    return real != top and os.path.commonpath([real, top]) == top


def remove_path(path: Path) -> None:
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


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def fsync_path(path: Path) -> None:
    """Flush a file (or every file of a folder, then the folder) to disk.

    A full disk on file systems with delayed allocation shows up here, not in ``write``.
    """
    if path.is_dir():
        for entry in os.scandir(path):
            if entry.is_file(follow_symlinks=False):
                fsync_path(Path(entry.path))
    fsync_entry(path)


def fsync_entry(path: Path) -> None:
    """Flush one file, or one folder's entries (the names renamed into it), but not the
    other files of the folder."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):  # e.g. folders on some file systems
            raise
    finally:
        os.close(fd)


def write_error(target: Path, exc: OSError) -> OutputWriteError:
    reason = exc.strerror or str(exc) or type(exc).__name__
    return OutputWriteError(exc.errno, f"cannot write '{target}': {' '.join(reason.split())}", str(target))


def check_not_input(target: Path, what: str, folder: bool, label: str, source: Path) -> None:
    """Refuse an output ``target`` that names the input ``source`` (or, as a folder, holds it)."""
    if same_file(target, source):
        raise OutputPathError(
            f"{what} '{target}' is the {label} '{source}'; texsyn never writes over its inputs, choose another name"
        )
    if folder and inside(source, target):
        raise OutputPathError(
            f"{what} '{target}' is the folder of the {label} '{source}'; choose another folder"
        )


def check_existing(p: Path, what: str, folder: bool, *, overwrite: bool, hint: str) -> None:
    """Refuse an existing output unless ``overwrite``; a frame folder is replaced only when it
    holds nothing but frames (an empty folder simply receives them). ``hint`` says how to
    ask for overwriting."""
    if not os.path.lexists(p):
        return
    if folder:
        if p.is_dir() and not p.is_symlink():
            entries = list(os.scandir(p))
            if not entries:
                return  # an empty folder receives the frames; nothing is lost
            if not overwrite:
                raise OutputExistsError(
                    f"folder '{p}' already exists and is not empty; use {hint} to replace it"
                )
            if any(not (FRAME_RE.fullmatch(e.name) and e.is_file(follow_symlinks=False)) for e in entries):
                raise OutputPathError(
                    f"cannot replace folder '{p}': it holds files other than frame_NNNNN.png "
                    "(texsyn replaces only frame folders it could have written)"
                )
            return
        if not overwrite:
            raise OutputExistsError(f"'{p}' already exists; use {hint} to replace it")
        raise OutputPathError(f"cannot write frames to '{p}': it is a file, not a folder")
    if p.is_dir():
        raise OutputPathError(f"cannot write {what} '{p}': it is a folder")
    if not overwrite:
        raise OutputExistsError(f"'{p}' already exists; use {hint} to replace it")


def backup_name(target: Path) -> Path:
    """A fresh hidden name beside ``target`` for moving it aside until a commit succeeds."""
    prefix = f".{target.name}."
    if target.is_dir() and not target.is_symlink():
        return Path(tempfile.mkdtemp(prefix=prefix, suffix=".old", dir=target.parent))
    fd, name = tempfile.mkstemp(prefix=prefix, suffix=".old", dir=target.parent)
    os.close(fd)
    return Path(name)


def restore(done: list[tuple[Path, Path | None, bool]]) -> None:
    """Undo renames already done, last first: ``(target, backup, was_empty_folder)`` each;
    the target is removed and its backup (if any) put back. Best effort: an error on one
    does not stop the others."""
    for target, backup, was_empty_folder in reversed(done):
        try:
            if backup is not None:
                if os.path.lexists(target):
                    remove_path(target)
                os.replace(backup, target)
            else:
                remove_path(target)
                if was_empty_folder:
                    os.mkdir(target)
        except OSError:  # best effort: keep undoing the others
            pass


def atomic_write(path: Path, writer, *, suffix: str = TEMP_SUFFIX) -> None:
    """Call ``writer(temporary_path)`` in ``path``'s folder, then rename it to ``path``.

    ``suffix`` ends the temporary name (writers that choose the format from it need the
    real one). Replaces an existing ``path``; for several outputs use :class:`texsyn.io.OutputSet`.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        writer(tmp)
        fsync_path(Path(tmp))
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
