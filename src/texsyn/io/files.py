"""Opening an image file safely, and the wording of every reading error.

Every message about a file names it once, as the user gave it (shortened in the middle when
long), and says the problem in one short line (``docs/reading.md``, "Errors"). Reading never
opens a folder, a device, a pipe or a socket, so that a read cannot block.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from ..errors import ImageReadError, InputFileNotFoundError

__all__ = ["library_said", "open_checked", "pixel_amount", "read_error", "show_path"]


def show_path(path: str | os.PathLike) -> str:
    """The path as the user gave it, shortened in the middle so that messages stay one short line."""
    text = os.fspath(path)
    if isinstance(text, bytes):  # pragma: no cover - bytes paths
        text = text.decode(errors="replace")
    text = text.replace("\n", "?").replace("\r", "?")
    return text if len(text) <= 70 else text[:20] + "..." + text[-47:]


def read_error(path: str | os.PathLike, problem: str) -> ImageReadError:
    """The :class:`~texsyn.errors.ImageReadError` ``cannot read 'PATH': PROBLEM``, in one line."""
    problem = " ".join(problem.split())
    if len(problem) > 125:
        problem = problem[:122] + "..."
    return ImageReadError(f"cannot read '{show_path(path)}': {problem}")


def library_said(exc: BaseException, path: str | os.PathLike) -> str:
    """A library's complaint, in one short line, without the path (the message names it once)."""
    text = str(exc)
    for name in {os.fspath(path), str(Path(path)), Path(path).name} - {""}:
        text = text.replace(repr(name), "it").replace(name, "it")
    return (" ".join(text.split()) or type(exc).__name__)[:90]


def pixel_amount(n: int) -> str:
    """A pixel count for messages: '40 million', '1.5 million', '250,000'."""
    if n >= 10**6:
        return f"{n / 10**6:.1f}".removesuffix(".0") + " million"
    return f"{n:,}"


def open_checked(path: str | os.PathLike) -> tuple[BinaryIO, int]:
    """Open a regular file for reading; return the open file and its length in bytes.

    Missing files, folders and special files are refused (a pipe is never opened, so that a
    read cannot block).

    Raises
    ------
    InputFileNotFoundError
        The file does not exist (or the name is empty).
    ImageReadError
        It is a folder, a device, a pipe or a socket, or it cannot be opened.
    """
    if not os.fspath(path):  # Path("") is the current folder
        raise InputFileNotFoundError("no such file: '' (an empty file name)")
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise InputFileNotFoundError(f"no such file: '{show_path(path)}'") from None
    except OSError as exc:
        raise read_error(path, f"cannot access it ({exc.strerror or type(exc).__name__})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ImageReadError(f"'{show_path(path)}' is a folder, not an image file")
    if not stat.S_ISREG(st.st_mode):
        raise read_error(path, "not a regular file (a device, pipe or socket)")
    try:
        fh = open(p, "rb")
    except OSError as exc:
        raise read_error(path, f"cannot open it ({exc.strerror or type(exc).__name__})") from None
    return fh, os.fstat(fh.fileno()).st_size
