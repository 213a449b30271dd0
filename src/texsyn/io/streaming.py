"""Writers that receive an image band by band, so that no command holds a large output whole.

:meth:`texsyn.io.OutputSet.open_rows` gives one of these for a staged output; the command
feeds it the bands a method yields (:meth:`texsyn.methods.TextureSynthesizer.sample_rows`),
top to bottom, and closes it. What each format allows (``docs/performance.md``, "Any size in
bounded memory"):

- PNG: rows are filtered and deflated as they arrive (:class:`PngRows`). The file is a plain
  PNG (ISO/IEC 15948): signature, ``IHDR``, an ``iCCP`` chunk when an ICC profile is given
  (section 11.3.3.3), ``IDAT`` chunks of at most 1 MiB, ``IEND``; each
  row takes the filter (None, Sub, Up, Average or Paeth, section 9) whose output has the
  smallest sum of absolute values, the heuristic the PNG specification recommends (section
  12.8), and zlib level 6.
- TIFF: tifffile writes the header of an uncompressed image (8, 16 bit or 32-bit float, its
  ICC profile) and says where its pixels go; the rows are written there (:class:`TiffRows`).
- ``.npy``: the array header, then the rows (:class:`NpyRows`; an image's samples as
  :func:`~texsyn.io.encoders.image_data` makes them, :class:`NpyImageRows`).
- JPEG and OpenEXR: the formats code blocks of a whole image; the rows are kept as 8-bit (a
  quarter of float32) or float32 samples and encoded at the end (:class:`BufferedRows`).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO, TypeVar

import numpy as np

from ..errors import InputError
from .encoders import FLOAT_DEPTH, encode_image, iccp_data, image_data, tiff_layout
from .output_paths import fsync_path, write_error

T = TypeVar("T")

__all__ = [
    "BufferedRows",
    "NpyImageRows",
    "NpyRows",
    "PngRows",
    "RowWriter",
    "StagedRows",
    "TiffRows",
    "open_row_writer",
]

#: PNG signature (ISO/IEC 15948, section 5.2)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: largest IDAT chunk written
IDAT_BYTES = 1 << 20


class RowWriter:
    """Receives the rows of one image of known shape, top to bottom, into one file.

    Parameters
    ----------
    path : Path
        The (temporary) file to write.
    shape : tuple
        ``(height, width)`` or ``(height, width, channels)`` of the whole image.
    """

    def __init__(self, path: Path, shape: tuple[int, ...]) -> None:
        self.path = Path(path)
        self.shape = tuple(int(v) for v in shape)
        self.rows_written = 0

    def write(self, rows: np.ndarray) -> None:
        """Append the next rows (shape ``(k,) + shape[1:]``)."""
        data = self._prepare(rows)
        if data.shape[1:] != self.shape[1:] or self.rows_written + data.shape[0] > self.shape[0]:
            raise ValueError(
                f"rows of shape {data.shape} do not continue an image of shape {self.shape} "
                f"after {self.rows_written} rows"
            )
        self._write(data)
        self.rows_written += data.shape[0]

    def close(self) -> None:
        """Finish the file; every row must have been written."""
        if self.rows_written != self.shape[0]:
            raise ValueError(f"{self.rows_written} of {self.shape[0]} rows were written")
        self._close()

    def abort(self) -> None:
        """Release the file without finishing it (the caller removes it)."""

    def _prepare(self, rows: np.ndarray) -> np.ndarray:
        return np.asarray(rows)

    def _write(self, data: np.ndarray) -> None:
        raise NotImplementedError  # pragma: no cover - abstract

    def _close(self) -> None:
        raise NotImplementedError  # pragma: no cover - abstract


class _ImageRows(RowWriter):
    """Rows of a float image in [0, 1] (or integer samples) quantised to ``bit_depth`` bits."""

    def __init__(self, path: Path, shape: tuple[int, ...], bit_depth: int) -> None:
        if len(shape) == 3 and shape[2] == 1:
            shape = shape[:2]
        super().__init__(path, shape)
        self.bit_depth = bit_depth

    def _prepare(self, rows: np.ndarray) -> np.ndarray:
        data = image_data(rows, self.bit_depth)
        return data if data.ndim == len(self.shape) else data.reshape(data.shape[:2] + self.shape[2:])


class PngRows(_ImageRows):
    """A PNG written as its rows arrive (module docstring); 8 or 16 bits, grey, grey + alpha,
    RGB or RGBA, with an ICC profile when one is given."""

    def __init__(
        self, path: Path, shape: tuple[int, ...], bit_depth: int, icc_profile: bytes | None = None
    ) -> None:
        super().__init__(path, shape, bit_depth)
        channels = 1 if len(self.shape) == 2 else self.shape[2]
        colour_type = 0 if channels == 1 else {2: 4, 3: 2, 4: 6}.get(channels)
        if colour_type is None or bit_depth not in (8, 16):
            raise InputError(f"a PNG holds 1 to 4 channels of 8 or 16 bits, got {channels} of {bit_depth}")
        self.pixel_bytes = channels * bit_depth // 8
        self._file: BinaryIO = open(self.path, "wb")  # closed in _close or abort
        self._deflate = zlib.compressobj(6)
        self._pending = bytearray()
        self._previous = np.zeros(self.shape[1] * self.pixel_bytes, dtype=np.uint8)
        height, width = self.shape[:2]
        header = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
        self._file.write(PNG_SIGNATURE)
        self._chunk(b"IHDR", header)
        if icc_profile:
            self._chunk(b"iCCP", iccp_data(icc_profile))

    def _chunk(self, kind: bytes, data: bytes) -> None:
        self._file.write(struct.pack(">I", len(data)) + kind + data)
        self._file.write(struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)) & 0xFFFFFFFF))

    def _write(self, data: np.ndarray) -> None:
        big_endian = data.astype(">u2") if self.bit_depth == 16 else data
        raw = np.ascontiguousarray(big_endian).view(np.uint8).reshape(data.shape[0], -1)
        self._pending += self._deflate.compress(filter_rows(raw, self._previous, self.pixel_bytes).tobytes())
        self._previous = raw[-1].copy()
        while len(self._pending) >= IDAT_BYTES:
            self._chunk(b"IDAT", bytes(self._pending[:IDAT_BYTES]))
            del self._pending[:IDAT_BYTES]

    def _close(self) -> None:
        self._pending += self._deflate.flush()
        for start in range(0, len(self._pending), IDAT_BYTES):
            self._chunk(b"IDAT", bytes(self._pending[start : start + IDAT_BYTES]))
        self._chunk(b"IEND", b"")
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def filter_rows(raw: np.ndarray, previous: np.ndarray, pixel_bytes: int) -> np.ndarray:
    """PNG scanlines of ``raw`` rows, each led by its filter type (ISO/IEC 15948, section 9).

    Each row gets the filter whose bytes, read as signed, have the smallest sum of absolute
    values (section 12.8).

    Parameters
    ----------
    raw : ndarray of uint8, shape (k, row_bytes)
    previous : ndarray of uint8, shape (row_bytes,)
        The row above the first one (zeros for the image's first row).
    pixel_bytes : int
        Bytes per pixel (the Sub, Average and Paeth filters look that far left).

    Returns
    -------
    ndarray of uint8, shape (k, 1 + row_bytes)

    Examples
    --------
    >>> filter_rows(np.array([[1, 2, 3]], np.uint8), np.zeros(3, np.uint8), 1).tolist()
    [[1, 1, 1, 1]]
    """
    x = np.ascontiguousarray(raw)
    up = np.concatenate([previous[None], x[:-1]])
    left = np.zeros_like(x)
    left[:, pixel_bytes:] = x[:, :-pixel_bytes]
    up_left = np.zeros_like(x)
    up_left[:, pixel_bytes:] = up[:, :-pixel_bytes]
    # predictors in 16 bits; differences wrap modulo 256, as the format defines them
    a, b, c = left.astype(np.int16), up.astype(np.int16), up_left.astype(np.int16)
    pa, pb, pc = np.abs(b - c), np.abs(a - c), np.abs(a + b - 2 * c)
    paeth = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, up_left))
    average = ((a + b) >> 1).astype(np.uint8)
    out = np.empty((raw.shape[0], raw.shape[1] + 1), dtype=np.uint8)
    best = np.full(raw.shape[0], np.iinfo(np.int64).max)
    for kind, predictor in enumerate((None, left, up, average, paeth)):
        filtered = x if predictor is None else x - predictor
        cost = np.minimum(filtered, 0 - filtered).sum(axis=1, dtype=np.int64)  # |signed byte|
        better = cost < best
        best[better] = cost[better]
        out[better, 0] = kind
        out[better, 1:] = filtered[better]
    return out


class TiffRows(_ImageRows):
    """An uncompressed TIFF: tifffile writes the header, the rows go where it says."""

    def __init__(
        self, path: Path, shape: tuple[int, ...], bit_depth: int, icc_profile: bytes | None = None
    ) -> None:
        super().__init__(path, shape, bit_depth)
        import tifffile

        dtype = {16: np.uint16, FLOAT_DEPTH: np.float32}.get(bit_depth, np.uint8)
        layout = tiff_layout(1 if len(self.shape) == 2 else self.shape[2])
        if icc_profile:
            layout["iccprofile"] = icc_profile
        with tifffile.TiffWriter(self.path) as tiff:
            where = tiff.write(None, shape=self.shape, dtype=dtype, returnoffset=True, **layout)
        if where is None:  # pragma: no cover - tifffile gives it for an uncompressed contiguous image
            raise OSError(f"tifffile gave no data offset for '{self.path}'")
        offset = where[0]
        self._file: BinaryIO = open(self.path, "r+b")  # closed in _close or abort
        self._file.seek(offset)

    def _write(self, data: np.ndarray) -> None:
        self._file.write(np.ascontiguousarray(data).tobytes())

    def _close(self) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class NpyRows(RowWriter):
    """A ``.npy`` array written row band by row band (format version 1.0 header, then the data)."""

    def __init__(self, path: Path, shape: tuple[int, ...], dtype: np.dtype | type) -> None:
        super().__init__(path, shape)
        self.dtype = np.dtype(dtype)
        self._file: BinaryIO = open(self.path, "wb")  # closed in _close or abort
        header = {
            "descr": np.lib.format.dtype_to_descr(self.dtype),
            "fortran_order": False,
            "shape": self.shape,
        }
        np.lib.format.write_array_header_1_0(self._file, header)

    def _prepare(self, rows: np.ndarray) -> np.ndarray:
        return np.asarray(rows, dtype=self.dtype)

    def _write(self, data: np.ndarray) -> None:
        self._file.write(np.ascontiguousarray(data).tobytes())

    def _close(self) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class NpyImageRows(_ImageRows):
    """An ``.npy`` image: uint8, uint16 or float32 samples (``bit_depth``), row band by row band."""

    def __init__(self, path: Path, shape: tuple[int, ...], bit_depth: int) -> None:
        super().__init__(path, shape, bit_depth)
        dtype = np.dtype({16: np.uint16, FLOAT_DEPTH: np.float32}.get(bit_depth, np.uint8))
        self._file: BinaryIO = open(self.path, "wb")  # closed in _close or abort
        header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": self.shape}
        np.lib.format.write_array_header_1_0(self._file, header)

    def _write(self, data: np.ndarray) -> None:
        self._file.write(np.ascontiguousarray(data).tobytes())

    def _close(self) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()


class BufferedRows(_ImageRows):
    """Rows kept as samples and encoded whole at the end (JPEG, OpenEXR)."""

    def __init__(
        self,
        path: Path,
        shape: tuple[int, ...],
        bit_depth: int,
        suffix: str,
        icc_profile: bytes | None = None,
    ) -> None:
        super().__init__(path, shape, bit_depth)
        self.suffix = suffix
        self.icc_profile = icc_profile
        dtype = {16: np.uint16, FLOAT_DEPTH: np.float32}.get(bit_depth, np.uint8)
        self._data = np.empty(self.shape, dtype=dtype)

    def _write(self, data: np.ndarray) -> None:
        self._data[self.rows_written : self.rows_written + data.shape[0]] = data

    def _close(self) -> None:
        if self.icc_profile is None:
            encode_image(self.path, self._data, self.suffix)
        else:
            encode_image(self.path, self._data, self.suffix, self.icc_profile)


def open_row_writer(
    path: Path,
    suffix: str,
    shape: tuple[int, ...],
    *,
    bit_depth: int = 8,
    dtype: np.dtype | type | None = None,
    icc_profile: bytes | None = None,
) -> RowWriter:
    """The writer of an image of ``shape`` in the format of ``suffix`` (module docstring);
    for ``.npy``, of an array of ``dtype``, or without ``dtype`` of an image's samples."""
    if suffix == ".npy":
        if dtype is None:
            return NpyImageRows(path, shape, bit_depth)
        return NpyRows(path, shape, dtype)
    if suffix == ".png":
        return PngRows(path, shape, bit_depth, icc_profile)
    if suffix in (".tif", ".tiff"):
        return TiffRows(path, shape, bit_depth, icc_profile)
    return BufferedRows(path, shape, bit_depth, suffix, icc_profile)


class StagedRows:
    """An output of a :class:`~texsyn.io.OutputSet` written band by band (``OutputSet.open_rows``).

    A failure while opening, writing or closing (an ``OSError``: disk full, permission)
    discards the whole set and is raised as :class:`~texsyn.errors.OutputWriteError` naming
    the output; any other exception discards the set too.

    Parameters
    ----------
    target : Path
        The output (errors name it).
    open_writer : callable
        Makes the :class:`RowWriter` of its temporary file.
    discard : callable
        Removes every temporary of the set.
    closed : callable
        Told when this output is complete.
    """

    def __init__(
        self,
        target: Path,
        open_writer: Callable[[], RowWriter],
        *,
        discard: Callable[[], None],
        closed: Callable[[StagedRows], None],
    ) -> None:
        self.target = target
        self._discard = discard
        self._closed = closed
        self.writer: RowWriter = self._guarded(open_writer)

    def _guarded(self, action: Callable[[], T]) -> T:
        try:
            return action()
        except OSError as exc:
            self._discard()
            raise write_error(self.target, exc) from exc
        except BaseException:
            self._discard()
            raise

    def write(self, rows: np.ndarray) -> None:
        """Append the next rows of the output."""
        self._guarded(lambda: self.writer.write(rows))

    def close(self) -> None:
        """Finish the file (every row written) and flush it to disk."""

        def finish() -> None:
            self.writer.close()
            fsync_path(self.writer.path)

        self._guarded(finish)
        self._closed(self)
