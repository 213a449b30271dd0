"""The exceptions texsyn raises for inputs it does not allow.

Every check of what a user gives (an array, a parameter, a file, an output path, a size
that would not fit in memory) raises an :class:`InputError`. Because ``InputError`` derives
from ``ValueError`` (and :class:`InputTypeError` also from ``TypeError``), Python callers
catch them as usual; the command line turns exactly these into one line and exit status 2,
and treats every other exception as an internal error (exit status 1), so that a bug is
never reported as the user's mistake (``docs/errors.md``).

This module imports nothing from texsyn: every layer may raise these.
"""

from __future__ import annotations

__all__ = [
    "InputError",
    "InputTypeError",
    "InputFileNotFoundError",
    "ImageReadError",
    "ImageTooLargeError",
    "MemoryLimitError",
    "OutputExistsError",
    "OutputFolderNotFoundError",
    "OutputPathError",
    "OutputWriteError",
]


class InputError(ValueError):
    """An input (array, parameter, file, path, size) is not allowed; the message says what is."""


class InputTypeError(InputError, TypeError):
    """An input has the wrong type (e.g. a float where an integer is needed)."""


class InputFileNotFoundError(InputError, FileNotFoundError):
    """An input file named by the user does not exist."""


class ImageReadError(InputError):
    """A file could not be read as an image (unknown format, truncated, lying header...)."""


class ImageTooLargeError(ImageReadError):
    """An image file declares more pixels than ``TEXSYN_MAX_PIXELS`` allows (checked before decoding)."""


class MemoryLimitError(InputError, MemoryError):
    """The work asked for would need more memory than ``TEXSYN_MEMORY_LIMIT`` allows."""


class OutputPathError(InputError):
    """An output path cannot be used (unknown format, missing or read-only folder, names an input)."""


class OutputExistsError(OutputPathError, FileExistsError):
    """An output file exists and ``overwrite`` was not asked for."""


class OutputFolderNotFoundError(OutputPathError, FileNotFoundError):
    """The folder an output should go to does not exist."""


class OutputWriteError(OSError):
    """Writing an output failed (disk full, permission denied, I/O error...).

    Not an :class:`InputError`: the request was valid but the system could not honour it
    (the command line exits with status 1). Nothing of the failed output set is left behind.
    """

    def __str__(self) -> str:
        return self.strerror or super().__str__()
