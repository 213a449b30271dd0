"""Images that are arrays of numbers: ``.npy`` and OpenEXR, read header first and written whole.

Both hold floating-point samples with no fixed range (a height in metres, HDR radiance), so
they are the formats of material channels that 8 and 16-bit images cannot carry
(``docs/materials.md``). An ``.npy`` image is an array ``(H, W)`` or ``(H, W, C)``, ``C`` from
1 to 4, of floats, ``uint8`` or ``uint16`` (integers mean what they mean in a PNG: divided by
255 or 65535); its header is read and checked first (:func:`texsyn.io.arrays.load_npy`: no
pickle, no truncated or forged sizes). OpenEXR files are read and written through the
``OpenEXR`` package when it is installed (``pip install OpenEXR``, the ``exr`` extra); without
it, one line says so. The header (its ``dataWindow`` and channel list, OpenEXR 2.0
specification, "Header Attributes") is read here first, so that the pixel budget answers
before the library decodes anything.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..errors import InputError
from .arrays import load_npy, open_regular_file, read_npy_header
from .budget import ImageHeader
from .files import read_error

__all__ = [
    "EXR_MAGIC",
    "NPY_MAGIC",
    "decode_exr",
    "decode_npy_image",
    "encode_exr",
    "exr_header",
    "npy_header",
    "openexr",
]

NPY_MAGIC = b"\x93NUMPY"
EXR_MAGIC = b"\x76\x2f\x31\x01"
#: OpenEXR pixel types (0: UINT, 1: HALF, 2: FLOAT) and their bits
_EXR_BITS = {0: 32, 1: 16, 2: 32}
#: the largest EXR header texsyn reads (real headers are a few hundred bytes)
_EXR_HEADER_BYTES = 1 << 16
#: channel names in the order an image's samples take them
_EXR_ORDER = {"R": 0, "G": 1, "B": 2, "A": 3, "Y": 0}


def openexr():
    """The ``OpenEXR`` module, or one :class:`~texsyn.errors.InputError` line naming the package."""
    try:
        import OpenEXR
    except ImportError:
        raise InputError("EXR files need the OpenEXR package: pip install OpenEXR (or texsyn[exr])") from None
    return OpenEXR


def npy_header(path: str | os.PathLike) -> ImageHeader:
    """The :class:`ImageHeader` of an ``.npy`` image, from its array header (no data read)."""
    with open_regular_file(Path(path), "an image file") as fp:
        try:
            shape, dtype = read_npy_header(fp)
        except Exception as exc:
            raise read_error(path, f"not a NumPy array ({' '.join(str(exc).split())[:90]})") from None
    return ImageHeader(*_npy_layout(path, shape, dtype))


def _npy_layout(path, shape: tuple[int, ...], dtype: np.dtype) -> tuple[int, int, int, int, str]:
    if dtype.kind not in "fu" or (dtype.kind == "u" and dtype.itemsize > 2) or dtype.fields is not None:
        raise read_error(path, f"an .npy image holds floats, uint8 or uint16, not {dtype}")
    if len(shape) not in (2, 3) or (len(shape) == 3 and not 1 <= shape[2] <= 4) or 0 in shape:
        raise read_error(path, f"an .npy image has shape (H, W) or (H, W, C) with C from 1 to 4, not {shape}")
    channels = 1 if len(shape) == 2 else shape[2]
    return shape[1], shape[0], channels, dtype.itemsize * 8, "NPY"


def decode_npy_image(path: str | os.PathLike) -> tuple[np.ndarray, float]:
    """The samples of an ``.npy`` image and the value that means 1.0 (1.0 for floats)."""
    arr = load_npy(path, "an image array")
    _npy_layout(path, arr.shape, arr.dtype)
    if arr.dtype.kind == "u":
        return arr, float(np.iinfo(arr.dtype).max)
    return arr, 1.0


def exr_header(path: str | os.PathLike) -> ImageHeader:
    """The :class:`ImageHeader` of an OpenEXR file from its ``dataWindow`` and ``channels``
    attributes, read without the library (and before it decodes any pixel)."""
    with open_regular_file(Path(path), "an image file") as fh:
        head = fh.read(_EXR_HEADER_BYTES)
    if head[:4] != EXR_MAGIC or len(head) < 8:
        raise read_error(path, "not an OpenEXR file")
    pos, attributes = 8, {}
    while pos < len(head) and head[pos] != 0:
        name_end = head.find(b"\0", pos)
        kind_end = head.find(b"\0", name_end + 1)
        if name_end < 0 or kind_end < 0 or kind_end + 4 > len(head):
            raise read_error(path, "truncated or corrupt EXR header")
        (size,) = struct.unpack("<i", head[kind_end + 1 : kind_end + 5])
        start = kind_end + 5
        if size < 0 or start + size > len(head):
            raise read_error(path, "truncated or corrupt EXR header")
        attributes[head[pos:name_end].decode("latin-1")] = head[start : start + size]
        pos = start + size
    if "dataWindow" not in attributes or "channels" not in attributes or len(attributes["dataWindow"]) != 16:
        raise read_error(path, "corrupt EXR header (no dataWindow or channels)")
    x0, y0, x1, y1 = struct.unpack("<4i", attributes["dataWindow"])
    names, bits, chlist = [], 16, attributes["channels"]
    at = 0
    while at < len(chlist) and chlist[at] != 0:
        end = chlist.find(b"\0", at)
        if end < 0 or end + 17 > len(chlist):
            raise read_error(path, "corrupt EXR channel list")
        names.append(chlist[at:end].decode("latin-1"))
        bits = max(bits, _EXR_BITS.get(struct.unpack("<i", chlist[end + 1 : end + 5])[0], 32))
        at = end + 17
    return ImageHeader(x1 - x0 + 1, y1 - y0 + 1, len(names), bits, "EXR")


def decode_exr(path: str | os.PathLike, header: ImageHeader) -> tuple[np.ndarray, float]:
    """The first part of an OpenEXR file as float32 ``(H, W)`` or ``(H, W, C)``.

    Channels ``R``, ``G``, ``B``, ``A`` (or ``Y`` for grey) come in that order; an image with
    other channel names (a multi-layer render) is refused with the names it holds.
    """
    exr = openexr()
    with exr.File(str(path), separate_channels=True) as f:
        channels = {name: ch.pixels for name, ch in f.channels().items()}
    names = sorted(channels, key=lambda n: _EXR_ORDER.get(n, 9))
    if not names or any(n not in _EXR_ORDER for n in names) or ("Y" in names and len(names) > 2):
        raise read_error(
            path, f"texsyn reads EXR channels R, G, B, A or Y; this file holds {', '.join(names)}"
        )
    planes = [np.asarray(channels[n], dtype=np.float32) for n in names]
    arr = planes[0] if len(planes) == 1 else np.stack(planes, axis=-1)
    if arr.shape[:2] != (header.height, header.width):
        raise read_error(path, "the file changed while it was read")
    return arr, 1.0


def encode_exr(tmp: Path, data: np.ndarray) -> None:
    """Write float32 samples ``(H, W)`` (channel ``Y``) or ``(H, W, C)`` (``RGB``, ``RGBA``;
    two channels ``Y``, ``A``) as a ZIP-compressed scanline OpenEXR file."""
    exr = openexr()
    arr = np.ascontiguousarray(data, dtype=np.float32)
    names = {1: "Y", 2: "YA", 3: "RGB", 4: "RGBA"}[1 if arr.ndim == 2 else arr.shape[2]]
    planes = (
        {names: arr} if arr.ndim == 2 else {n: np.ascontiguousarray(arr[..., i]) for i, n in enumerate(names)}
    )
    header = {"compression": exr.ZIP_COMPRESSION, "type": exr.scanlineimage}
    with exr.File(header, planes) as f:
        f.write(str(tmp))
