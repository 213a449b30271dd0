"""Saving and loading fitted models: :func:`save` and :func:`load` (``docs/persistence.md``).

One file format for every method: a NumPy ``.npz`` archive holding

- ``header``: a JSON text with the format name ``"texsyn-model"``, the format version
  (:data:`FORMAT_VERSION`), the texsyn version that wrote it, the method's name and its
  parameters;
- ``exemplar``: the exemplar as ``fit`` saw it (float64 in [0, 1]);
- ``fitted/NAME``: the arrays of the method's :meth:`~texsyn.methods.TextureSynthesizer.fitted_arrays`
  (``sparse``: the learned dictionaries; none for the other methods).

:func:`load` rebuilds the model with
:meth:`~texsyn.methods.TextureSynthesizer.restore_fitted`: from the stored arrays where the
method stores them, otherwise by fitting the stored exemplar again, which gives the same
model bit for bit (fit is deterministic: seeded, sums in a fixed order). Either way,
sampling the loaded model gives the same bytes as sampling the saved one.

A file may come from anyone, so :func:`load` reads it defensively ("Reading a file from
someone else" in ``docs/persistence.md``): it opens the archive itself (never a pipe, never
pickle), reads each array's ``.npy`` header before its data and refuses, with one
:class:`~texsyn.errors.InputError` line, Python objects, a header of more than
:data:`MAX_HEADER_CHARS` characters, an exemplar over the pixel budget of image files
(``TEXSYN_MAX_PIXELS``, ``docs/reading.md``) or whose fit would exceed
``TEXSYN_MEMORY_LIMIT`` (``docs/memory.md``), arrays that would exceed that limit, and
arrays that declare more bytes than the file could hold (:data:`MAX_COMPRESSION_RATIO`),
all before allocating them.

Why this module is long: the file format has two sides, writing and reading, and the reading
side is the one place a file from someone else enters texsyn; its checks (the archive, each
array's declared size, the header, texsyn 0.1's layout) are kept beside the format they
check, so that a change of the format and of its checks is one change.

Files written by texsyn 0.1's ``texsyn.io.save_fitted`` (the ``sparse`` method only) are
read too.
"""

from __future__ import annotations

import json
import math
import os
import stat
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ._validation import as_exemplar, check_memory, human_bytes
from ._version import __version__
from .errors import InputError, InputFileNotFoundError, MemoryLimitError
from .io import OutputSet, max_image_pixels
from .io.budget import MAX_PIXELS_ENV
from .io.files import pixel_amount, show_path
from .methods import METHODS, TextureSynthesizer

__all__ = [
    "COMPRESSION_FLOOR_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_COMPRESSION_RATIO",
    "MAX_HEADER_CHARS",
    "load",
    "save",
]

#: the ``format`` entry of every header
FORMAT_NAME = "texsyn-model"
#: the newest format version this texsyn writes and reads
FORMAT_VERSION = 1
#: the suffix of model files
SUFFIX = ".npz"
#: the longest JSON header (and texsyn 0.1 parameter text) a file may hold, in characters;
#: a real header is under 2,000
MAX_HEADER_CHARS = 1_000_000
#: the largest ratio of the bytes a file's arrays declare to the file's length. :func:`save`
#: compresses with DEFLATE, which cannot exceed 1032:1 (a constant exemplar comes close), so
#: every saved model passes; a small file declaring more (other zip compressions such as
#: bzip2 reach millions to one) is refused as a decompression bomb before anything is read
MAX_COMPRESSION_RATIO = 1100
#: files whose arrays declare at most this many bytes are accepted whatever their compression
COMPRESSION_FLOOR_BYTES = 1 << 20
_FITTED = "fitted/"
_LEGACY_KEYS = ("format_version", "method", "params", "exemplar")
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a local file header; an empty archive
_NPY_HEADER_BYTES = 10_000  # numpy's own limit of an .npy header
_DTYPE_KINDS = "biufcUS"  # numbers and text: no objects, records or raw bytes
_MAX_ARRAYS = 4096  # a sparse model holds 7 per scale


def _plain(value: Any, where: str) -> Any:
    """A parameter value as JSON can hold it (tuples become lists)."""
    if isinstance(value, (np.generic,)):
        value = value.item()
    if isinstance(value, (tuple, list)):
        return [_plain(v, where) for v in value]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise InputError(f"{where} is {value!r}, which a saved model cannot hold")


def save(model: TextureSynthesizer, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Save a fitted model to an ``.npz`` file, atomically.

    Parameters
    ----------
    model : TextureSynthesizer
        A fitted method (``fit`` was called).
    path : str or path-like
        The file to write; its name ends in ``.npz``.
    overwrite : bool
        Replace an existing file (it is never replaced otherwise).

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    InputError
        ``model`` is not a fitted method, or ``path`` cannot be written
        (:class:`~texsyn.errors.OutputExistsError` when it exists and ``overwrite`` is false).

    Examples
    --------
    >>> import tempfile, texsyn
    >>> model = texsyn.make_method("random_phase").fit(texsyn.data.exemplar("gravel", size=32))
    >>> folder = tempfile.mkdtemp()
    >>> path = save(model, folder + "/gravel.npz")
    >>> again = load(path)
    >>> bool(np.array_equal(again.sample(rng=1), model.sample(rng=1)))
    True
    """
    if not isinstance(model, TextureSynthesizer):
        raise InputError(f"texsyn.save needs a fitted texsyn method, got {type(model).__name__}")
    if getattr(model, "exemplar_", None) is None:
        raise InputError(f"method {model.name!r} is not fitted; call fit(exemplar) before saving it")
    params = {
        k: _plain(v, f"parameter {k!r} of method {model.name!r}") for k, v in model.get_params().items()
    }
    header = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "texsyn_version": __version__,
        "method": model.name,
        "params": params,
    }
    arrays = {"header": np.array(json.dumps(header)), "exemplar": np.asarray(model.exemplar_)}
    for key, value in model.fitted_arrays().items():
        arrays[_FITTED + key] = np.asarray(value)

    def writer(tmp: Path) -> None:
        with open(tmp, "wb") as fh:  # a file object: numpy appends no suffix
            np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]

    outputs = OutputSet(overwrite=overwrite)
    target = outputs.claim(path, what="model", formats={SUFFIX: (8,)})
    with outputs:
        outputs.write(target, writer)
    return target


# --------------------------------------------------------------------------- reading


def _one_line(exc: BaseException) -> str:
    """A library's complaint in one short line."""
    return (" ".join(str(exc).split()) or type(exc).__name__)[:120]


@dataclass(frozen=True)
class _Member:
    """One array of an archive as its ``.npy`` header declares it (no data read)."""

    info: zipfile.ZipInfo
    shape: tuple[int, ...]
    dtype: np.dtype

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize


class _Archive:
    """An ``.npz`` file opened for reading: its arrays' headers read and checked, data on demand.

    Every failure is an :class:`~texsyn.errors.InputError` naming the file.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = show_path(path)
        self._fh = fh = self._open()
        try:
            self.file_size = os.fstat(fh.fileno()).st_size
            if fh.read(4) not in _ZIP_MAGIC:
                raise self.refuse("not an .npz archive")
            fh.seek(0)
            self.zip = zipfile.ZipFile(fh)
        except InputError:
            fh.close()
            raise
        except Exception as exc:  # damaged or truncated archives: zipfile, OSError
            fh.close()
            raise self.refuse(f"a damaged or truncated .npz archive: {_one_line(exc)}") from None
        try:
            self.members = self._scan()
        except BaseException:
            self.close()
            raise

    def refuse(self, why: str) -> InputError:
        return InputError(f"'{self.name}' is not a saved texsyn model ({why})")

    def _open(self) -> BinaryIO:
        """The file, opened for reading; never a folder, a pipe or a device (a read could block)."""
        try:  # without blocking: opening a pipe waits for a writer
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        except FileNotFoundError:
            raise InputFileNotFoundError(f"no such file: '{self.name}'") from None
        except OSError as exc:
            raise InputError(f"cannot read '{self.name}' ({exc.strerror or type(exc).__name__})") from None
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            os.close(fd)
            if stat.S_ISDIR(mode):
                raise InputError(f"'{self.name}' is a folder, not a saved texsyn model")
            raise self.refuse("not a regular file: a device, pipe or socket")
        return os.fdopen(fd, "rb")

    def _scan(self) -> dict[str, _Member]:
        """The ``.npy`` header of every array in the archive, read without its data."""
        infos = [info for info in self.zip.infolist() if info.filename.endswith(".npy")]
        if len(infos) > _MAX_ARRAYS:  # np.savez writes .npy members only; others are never read
            raise self.refuse(f"it holds {len(infos)} arrays, more than the {_MAX_ARRAYS} texsyn allows")
        members: dict[str, _Member] = {}
        for info in infos:
            key = info.filename[: -len(".npy")]
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise self.refuse(
                    f"its array {key!r:.60} is compressed in a way numpy never writes (zip method "
                    f"{info.compress_type})"
                )
            try:
                with self.zip.open(info) as fp:
                    version = np.lib.format.read_magic(fp)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(fp, _NPY_HEADER_BYTES)
                    elif version == (2, 0):
                        shape, _, dtype = np.lib.format.read_array_header_2_0(fp, _NPY_HEADER_BYTES)
                    else:
                        raise ValueError(f".npy format version {version[0]}.{version[1]} is not supported")
            except Exception as exc:  # zipfile, zlib, numpy format errors (RecursionError too)
                raise self.refuse(f"its array {key!r:.60} is unreadable: {_one_line(exc)}") from None
            if dtype.hasobject:
                raise self.refuse(
                    f"its array {key!r:.60} holds Python objects, which texsyn never saves nor loads"
                )
            if dtype.kind not in _DTYPE_KINDS or dtype.fields is not None or dtype.subdtype is not None:
                raise self.refuse(
                    f"its array {key!r:.60} has the data type {dtype}, which texsyn never saves"
                )
            if any(n < 0 for n in shape):
                raise self.refuse(f"its array {key!r:.60} declares the shape {shape}")
            members[key] = _Member(info, tuple(shape), dtype)
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
                return np.lib.format.read_array(fp, allow_pickle=False, max_header_size=_NPY_HEADER_BYTES)
        except Exception as exc:  # damaged data: zipfile (CRC), zlib, EOF, numpy
            raise self.refuse(f"its array {key!r:.60} is damaged: {_one_line(exc)}") from None

    def text(self, key: str, what: str) -> str:
        """The 0-d text array ``key`` (a JSON header, a method name), at most MAX_HEADER_CHARS long."""
        member = self.members[key]
        if member.dtype.kind != "U" or member.shape != ():
            raise self.refuse(f"its {what} is not a text")
        if member.dtype.itemsize > 4 * MAX_HEADER_CHARS:
            raise self.refuse(f"its {what} is over {MAX_HEADER_CHARS:,} characters long")
        return str(self.read(key)[()])

    def close(self) -> None:
        self.zip.close()  # leaves the file object it was given open
        self._fh.close()

    def __enter__(self) -> _Archive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _json(text: str) -> Any:
    """The JSON value of ``text``, or None when it is not JSON (or nested too deeply)."""
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        return None


def _header(archive: _Archive) -> tuple[dict, list[str]]:
    """The header of a file (of this format or of texsyn 0.1's) and the keys of its fitted arrays."""
    members = archive.members
    if "header" in members:
        header = _json(archive.text("header", "header"))
        if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
            raise archive.refuse(f"its header is not a {FORMAT_NAME} header")
        fitted = [k for k in members if k.startswith(_FITTED)]
    elif all(k in members for k in _LEGACY_KEYS):  # texsyn 0.1: io.save_fitted of 'sparse'
        params = _json(archive.text("params", "texsyn 0.1 header"))
        method = archive.text("method", "texsyn 0.1 method name")
        stored = members["format_version"]
        if stored.shape != () or stored.dtype.kind not in "iu":
            raise archive.refuse("unreadable texsyn 0.1 header")
        legacy = int(archive.read("format_version"))
        if legacy != 1:
            raise InputError(
                f"'{archive.name}' has texsyn 0.1 format version {legacy}; only version 1 exists"
            )
        header = {"format_version": 1, "texsyn_version": "0.1", "method": method, "params": params}
        fitted = [k for k in members if k not in _LEGACY_KEYS]
    else:
        raise archive.refuse("it has no header")
    version = header.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise InputError(f"'{archive.name}' has an invalid model format version {version!r:.40}")
    if version > FORMAT_VERSION:
        raise InputError(
            f"'{archive.name}' was written by texsyn {header.get('texsyn_version', '?')!s:.20} in model "
            f"format version {version}; this texsyn ({__version__}) reads versions up to {FORMAT_VERSION}: "
            "upgrade texsyn"
        )
    if not isinstance(header.get("params"), dict):
        raise archive.refuse("its parameters are not a mapping")
    return header, fitted


def _check_exemplar(archive: _Archive, model: TextureSynthesizer) -> tuple[int, ...]:
    """The declared shape of the stored exemplar, refused (unread) when it is over the budgets."""
    member = archive.members.get("exemplar")
    if member is None or len(member.shape) not in (2, 3) or member.dtype.kind not in "uif":
        raise archive.refuse("no exemplar image")
    shape = member.shape
    if len(shape) == 3 and shape[2] not in (1, 2, 3, 4):
        raise archive.refuse(f"its exemplar has {shape[2]} channels")
    pixels, budget = shape[0] * shape[1], max_image_pixels()
    if pixels > budget:
        suggest = f"{-(-pixels // 10**6)}M" if pixels >= 10**6 else f"{-(-pixels // 10**3)}K"
        raise InputError(
            f"'{archive.name}' holds a {shape[1]}x{shape[0]} exemplar ({pixel_amount(pixels)} pixels), more "
            f"than the {pixel_amount(budget)} allowed; set {MAX_PIXELS_ENV}={suggest} to allow it"
        )
    try:
        model.check_memory_for(shape)
    except MemoryLimitError as exc:
        raise MemoryLimitError(f"'{archive.name}': {exc}") from None
    return shape


def load(path: str | os.PathLike, **params: Any) -> TextureSynthesizer:
    """Load a model saved by :func:`save`, ready to sample.

    Parameters
    ----------
    path : str or path-like
        A file written by :func:`save` (or by texsyn 0.1's ``texsyn.io.save_fitted``).
    **params
        New values of parameters. Sampling parameters may always change (e.g. ``n_outer``);
        a method whose file holds its learned arrays (``sparse``) refuses changes of the
        parameters they depend on (its ``learned_params``); the others fit the stored
        exemplar again with the new values.

    Returns
    -------
    TextureSynthesizer
        The fitted method; ``load(path).sample(shape, rng=seed)`` gives the same bytes as the
        saved model's ``sample(shape, rng=seed)``.

    Raises
    ------
    InputError
        One line naming the file: it is missing (:class:`~texsyn.errors.InputFileNotFoundError`),
        not an ``.npz`` archive, truncated or damaged, not a texsyn model, written in a newer
        format version, for a method this texsyn does not know; it holds Python objects, a
        header over :data:`MAX_HEADER_CHARS` characters, an exemplar over the pixel budget
        (``TEXSYN_MAX_PIXELS``) or arrays over the memory limit
        (:class:`~texsyn.errors.MemoryLimitError`, ``TEXSYN_MEMORY_LIMIT``) or over
        :data:`MAX_COMPRESSION_RATIO` times the file's size; or ``params`` are unknown or
        change what fit learned. Nothing is allocated for an array before its checks pass.

    Examples
    --------
    >>> import tempfile, texsyn
    >>> model = texsyn.make_method("heeger_bergen", n_iterations=1).fit(texsyn.data.exemplar("brick", size=32))
    >>> path = save(model, tempfile.mkdtemp() + "/brick.npz")
    >>> load(path, n_iterations=2).n_iterations
    2
    """
    with _Archive(Path(path)) as archive:
        header, fitted_keys = _header(archive)
        name = header.get("method")
        if not isinstance(name, str) or name not in METHODS:
            raise InputError(
                f"'{archive.name}' holds a model of method {name!r:.60}, which this texsyn ({__version__}) "
                f"does not know; known methods: {', '.join(sorted(METHODS))}"
            )
        cls = METHODS[name]
        with warnings.catch_warnings():  # old names in a file are not the reader's doing
            warnings.simplefilter("ignore", DeprecationWarning)
            saved = cls.canonical_params(header["params"])
        changes = cls.canonical_params(params, stacklevel=2)
        specs = cls.param_specs()
        for where, names in (("in the file", saved), ("given", changes)):
            unknown = sorted(set(names) - set(specs))
            if unknown:
                raise InputError(
                    f"unknown parameter {unknown[0]!r:.60} {where} for method {name!r}; "
                    f"allowed: {', '.join(specs) or 'none'}"
                )
        if fitted_keys:
            changed = sorted(k for k in changes if k in cls.learned_params and changes[k] != saved.get(k))
            if changed:
                raise InputError(
                    f"cannot change {', '.join(changed)} of a loaded {name!r} model: they change what fit "
                    "learned (fit the exemplar again instead)"
                )
        values = {**saved, **changes}
        for key, spec in specs.items():
            if spec.type is tuple and isinstance(values.get(key), list):
                values[key] = tuple(values[key])
        model = cls(**values)
        _check_exemplar(archive, model)
        archive.check_sizes(["exemplar", *fitted_keys])
        exemplar = as_exemplar(archive.read("exemplar"), name=f"the exemplar in '{archive.name}'")
        fitted = {k[len(_FITTED) :] if k.startswith(_FITTED) else k: archive.read(k) for k in fitted_keys}
    return model.restore_fitted(exemplar, fitted)
