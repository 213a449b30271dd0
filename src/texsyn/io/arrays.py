"""NumPy files from anyone: ``.npy`` and ``.npz`` read header first, refused before allocating.

A NumPy file names its arrays' shapes and data types in a small header. This module reads
those headers before any data and refuses, with one :class:`~texsyn.errors.InputError` line,
what a texsyn file never holds: Python objects (no pickle), records, compressions numpy never
writes, arrays declaring more bytes than the file could hold (a decompression bomb) or more
than ``TEXSYN_MEMORY_LIMIT`` (``docs/memory.md``). Folders, pipes and devices are refused
without blocking. Used by :func:`texsyn.load` (``docs/persistence.md``) and by the flow files
of the command line.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import IO, BinaryIO

import numpy as np

from .._validation import check_memory, human_bytes
from ..errors import InputError, InputFileNotFoundError
from .files import show_path

__all__ = [
    "COMPRESSION_FLOOR_BYTES",
    "MAX_COMPRESSION_RATIO",
    "ArrayMember",
    "NpzArchive",
    "load_npy",
    "one_line",
    "open_regular_file",
    "read_npy_header",
    "unsafe_array",
]

ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a local file header; an empty archive
NPY_HEADER_BYTES = 10_000  # numpy's own limit of an .npy header
DTYPE_KINDS = "biufcUS"  # numbers and text: no objects, records or raw bytes
MAX_ARRAYS = 4096  # a sparse model holds 7 per scale
#: the largest ratio of the bytes a file's arrays declare to the file's length. numpy's
#: ``savez_compressed`` (and :func:`texsyn.save`) compress with DEFLATE, which cannot exceed
#: 1032:1 (a constant array comes close), so every honest archive passes; a small file
#: declaring more (other zip compressions such as bzip2 reach millions to one) is refused as
#: a decompression bomb before anything is read
MAX_COMPRESSION_RATIO = 1100
#: files whose arrays declare at most this many bytes are accepted whatever their compression
COMPRESSION_FLOOR_BYTES = 1 << 20


def one_line(exc: BaseException) -> str:
    """A library's complaint in one short line."""
    return (" ".join(str(exc).split()) or type(exc).__name__)[:120]


def open_regular_file(path: Path, kind: str) -> BinaryIO:
    """``path`` opened for reading; never a folder, a pipe or a device (a read could block).

    Raises
    ------
    InputFileNotFoundError
        No such file.
    InputError
        Unreadable, a folder, or not a regular file (the message says it is not ``kind``).
    """
    name = show_path(path)
    try:  # without blocking: opening a pipe waits for a writer
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise InputFileNotFoundError(f"no such file: '{name}'") from None
    except OSError as exc:
        raise InputError(f"cannot read '{name}' ({exc.strerror or type(exc).__name__})") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise InputError(f"'{name}' is a folder, not {kind}")
        raise InputError(f"'{name}' is not {kind} (not a regular file: a device, pipe or socket)")
    return os.fdopen(fd, "rb")


def read_npy_header(fp: IO[bytes]) -> tuple[tuple[int, ...], np.dtype]:
    """``(shape, dtype)`` from the ``.npy`` header at the start of ``fp`` (no data read).

    Raises
    ------
    ValueError
        Not an ``.npy`` header, or a format version numpy does not define.
    """
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(fp, NPY_HEADER_BYTES)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(fp, NPY_HEADER_BYTES)
    else:
        raise ValueError(f".npy format version {version[0]}.{version[1]} is not supported")
    return tuple(int(n) for n in shape), dtype


def unsafe_array(shape: tuple[int, ...], dtype: np.dtype) -> str | None:
    """Why an array of this header is never read (``None`` when it may be).

    Examples
    --------
    >>> unsafe_array((2, 3), np.dtype(object))
    'holds Python objects, which texsyn never saves nor loads'
    >>> unsafe_array((2, 3), np.dtype(np.float32)) is None
    True
    """
    if dtype.hasobject:
        return "holds Python objects, which texsyn never saves nor loads"
    if dtype.kind not in DTYPE_KINDS or dtype.fields is not None or dtype.subdtype is not None:
        return f"has the data type {dtype}, which texsyn never saves"
    if any(n < 0 for n in shape):
        return f"declares the shape {shape}"
    return None


def load_npy(path: str | os.PathLike, kind: str = "a NumPy array") -> np.ndarray:
    """An ``.npy`` file's array, its header checked first (:func:`unsafe_array`, memory, size).

    Raises
    ------
    InputError
        Not an ``.npy`` file, an unsafe header, more data declared than the file holds, or more
        memory than ``TEXSYN_MEMORY_LIMIT``.
    """
    p = Path(path)
    name = show_path(p)
    with open_regular_file(p, kind) as fp:
        try:
            shape, dtype = read_npy_header(fp)
        except Exception as exc:  # numpy format errors, RecursionError of a nested header
            raise InputError(f"'{name}' is not {kind} ({one_line(exc)})") from None
        why = unsafe_array(shape, dtype)
        if why:
            raise InputError(f"'{name}' is not {kind} (it {why})")
        nbytes = math.prod(shape) * dtype.itemsize
        if nbytes > os.fstat(fp.fileno()).st_size - fp.tell():
            raise InputError(
                f"'{name}' declares {human_bytes(nbytes)} of data but holds less: truncated or forged"
            )
        check_memory(nbytes, what=f"reading '{name}'", advice="use a smaller array")
        fp.seek(0)
        try:
            return np.lib.format.read_array(fp, allow_pickle=False, max_header_size=NPY_HEADER_BYTES)
        except Exception as exc:
            raise InputError(f"'{name}' is damaged ({one_line(exc)})") from None


@dataclass(frozen=True)
class ArrayMember:
    """One array of an archive as its ``.npy`` header declares it (no data read)."""

    info: zipfile.ZipInfo
    shape: tuple[int, ...]
    dtype: np.dtype

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize


class NpzArchive:
    """An ``.npz`` file opened for reading: its arrays' headers read and checked, data on demand.

    Every failure is an :class:`~texsyn.errors.InputError` naming the file and saying it is not
    ``kind`` (e.g. ``"a saved texsyn model"``).

    Parameters
    ----------
    path : path
        The archive.
    kind : str
        What the file should be, for the messages.
    """

    def __init__(self, path: Path, kind: str = "a NumPy archive") -> None:
        self.path = path
        self.kind = kind
        self.name = show_path(path)
        self._fh = fh = open_regular_file(path, kind)
        try:
            self.file_size = os.fstat(fh.fileno()).st_size
            if fh.read(4) not in ZIP_MAGIC:
                raise self.refuse("not an .npz archive")
            fh.seek(0)
            self.zip = zipfile.ZipFile(fh)
        except InputError:
            fh.close()
            raise
        except Exception as exc:  # damaged or truncated archives: zipfile, OSError
            fh.close()
            raise self.refuse(f"a damaged or truncated .npz archive: {one_line(exc)}") from None
        try:
            self.members = self._scan()
        except BaseException:
            self.close()
            raise

    def refuse(self, why: str) -> InputError:
        """The error that says this file is not :attr:`kind`, and why."""
        return InputError(f"'{self.name}' is not {self.kind} ({why})")

    def _scan(self) -> dict[str, ArrayMember]:
        """The ``.npy`` header of every array in the archive, read without its data."""
        infos = [info for info in self.zip.infolist() if info.filename.endswith(".npy")]
        if len(infos) > MAX_ARRAYS:  # np.savez writes .npy members only; others are never read
            raise self.refuse(f"it holds {len(infos)} arrays, more than the {MAX_ARRAYS} texsyn allows")
        members: dict[str, ArrayMember] = {}
        for info in infos:
            key = info.filename[: -len(".npy")]
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise self.refuse(
                    f"its array {key!r:.60} is compressed in a way numpy never writes (zip method "
                    f"{info.compress_type})"
                )
            try:
                with self.zip.open(info) as fp:
                    shape, dtype = read_npy_header(fp)
            except Exception as exc:  # zipfile, zlib, numpy format errors (RecursionError too)
                raise self.refuse(f"its array {key!r:.60} is unreadable: {one_line(exc)}") from None
            why = unsafe_array(shape, dtype)
            if why:
                raise self.refuse(f"its array {key!r:.60} {why}")
            members[key] = ArrayMember(info, shape, dtype)
        return members

    def check_sizes(self, keys: list[str]) -> None:
        """Refuse arrays whose data the file cannot hold or memory cannot take, before reading them."""
        need = sum(self.members[k].nbytes for k in keys)
        if need > max(COMPRESSION_FLOOR_BYTES, MAX_COMPRESSION_RATIO * self.file_size):
            raise InputError(
                f"'{self.name}' declares {human_bytes(need)} of arrays in {self.file_size} bytes, over "
                f"{MAX_COMPRESSION_RATIO}:1: refused as a decompression bomb"
            )
        check_memory(
            need, what=f"loading the arrays of '{self.name}'", advice="load it on a machine with more memory"
        )

    def read(self, key: str) -> np.ndarray:
        """The array ``key``; refused if it declares more bytes than its archive member holds."""
        member = self.members[key]
        if member.nbytes > member.info.file_size:
            raise self.refuse(
                f"its array {key!r:.60} declares {human_bytes(member.nbytes)} but holds "
                f"{member.info.file_size} bytes: truncated or forged"
            )
        try:
            with self.zip.open(member.info) as fp:
                return np.lib.format.read_array(fp, allow_pickle=False, max_header_size=NPY_HEADER_BYTES)
        except Exception as exc:  # damaged data: zipfile (CRC), zlib, EOF, numpy
            raise self.refuse(f"its array {key!r:.60} is damaged: {one_line(exc)}") from None

    def text(self, key: str, what: str, max_chars: int) -> str:
        """The 0-d text array ``key`` (``what``, for messages), at most ``max_chars`` long."""
        member = self.members[key]
        if member.dtype.kind != "U" or member.shape != ():
            raise self.refuse(f"its {what} is not a text")
        if member.dtype.itemsize > 4 * max_chars:
            raise self.refuse(f"its {what} is over {max_chars:,} characters long")
        return str(self.read(key)[()])

    def close(self) -> None:
        self.zip.close()  # leaves the file object it was given open
        self._fh.close()

    def __enter__(self) -> NpzArchive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
