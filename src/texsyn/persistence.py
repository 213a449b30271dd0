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

The archive itself is read by :class:`texsyn.io.arrays.NpzArchive` (headers first, no pickle,
sizes checked); this module checks what a model file must hold: its header, its exemplar and
texsyn 0.1's layout.

Files written by texsyn 0.1's ``texsyn.io.save_fitted`` (the ``sparse`` method only) are
read too.

A file holds every parameter its method had when it was written, so a parameter missing from
it is one the method gained since. :data:`ADDED_PARAMS` records, for each such parameter,
the value that gives what the file's model did; :func:`load` fills it in and says so in one
warning, instead of letting the newer default change the model's outputs silently.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ._validation import as_exemplar
from ._version import __version__
from .errors import InputError, MemoryLimitError
from .io import OutputSet, max_image_pixels
from .io.arrays import COMPRESSION_FLOOR_BYTES, MAX_COMPRESSION_RATIO, NpzArchive
from .io.budget import MAX_PIXELS_ENV
from .io.files import pixel_amount
from .methods import METHODS, TextureSynthesizer
from .methods.added_params import ADDED_PARAMS, DEFAULT, AddedParam

__all__ = [
    "ADDED_PARAMS",
    "COMPRESSION_FLOOR_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_COMPRESSION_RATIO",
    "MAX_HEADER_CHARS",
    "AddedParam",
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
_FITTED = "fitted/"
_LEGACY_KEYS = ("format_version", "method", "params", "exemplar")


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


def _json(text: str) -> Any:
    """The JSON value of ``text``, or None when it is not JSON (or nested too deeply)."""
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        return None


def _header(archive: NpzArchive) -> tuple[dict, list[str]]:
    """The header of a file (of this format or of texsyn 0.1's) and the keys of its fitted arrays."""
    members = archive.members
    if "header" in members:
        header = _json(archive.text("header", "header", MAX_HEADER_CHARS))
        if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
            raise archive.refuse(f"its header is not a {FORMAT_NAME} header")
        fitted = [k for k in members if k.startswith(_FITTED)]
    elif all(k in members for k in _LEGACY_KEYS):  # texsyn 0.1: io.save_fitted of 'sparse'
        params = _json(archive.text("params", "texsyn 0.1 header", MAX_HEADER_CHARS))
        method = archive.text("method", "texsyn 0.1 method name", MAX_HEADER_CHARS)
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


def _check_exemplar(archive: NpzArchive, model: TextureSynthesizer) -> tuple[int, ...]:
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
    with NpzArchive(Path(path), "a saved texsyn model") as archive:
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
        filled = _fill_added_params(name, values, specs)
        for key, spec in specs.items():
            if spec.type is tuple and isinstance(values.get(key), list):
                values[key] = tuple(values[key])
        model = cls(**values)
        _check_exemplar(archive, model)
        model.check_fitted_names([k[len(_FITTED) :] if k.startswith(_FITTED) else k for k in fitted_keys])
        archive.check_sizes(["exemplar", *fitted_keys])
        exemplar = as_exemplar(archive.read("exemplar"), name=f"the exemplar in '{archive.name}'")
        fitted = {k[len(_FITTED) :] if k.startswith(_FITTED) else k: archive.read(k) for k in fitted_keys}
    restored = model.restore_fitted(exemplar, fitted)
    if filled:
        version = header.get("texsyn_version", "?")
        warnings.warn(
            f"'{archive.name}' was written by texsyn {version!s:.20} before method {name!r} had the "
            f"parameter{'s' if len(filled) > 1 else ''} {', '.join(filled)}: loaded with "
            f"{', '.join(filled.values())}; pass other values to texsyn.load to change them",
            UserWarning,
            stacklevel=2,
        )
    return restored


def _fill_added_params(name: str, values: dict[str, Any], specs: dict) -> dict[str, str]:
    """Fill the parameters ``values`` lacks from :data:`ADDED_PARAMS`.

    Returns what the warning says of each parameter set off its current default, and of each
    missing parameter the table does not know (it keeps its default: a file edited by hand,
    or a table to complete).
    """
    reported: dict[str, str] = {}
    for key, spec in specs.items():
        if key in values:
            continue
        added = ADDED_PARAMS.get(name, {}).get(key)
        if added is None:
            reported[key] = f"{key}={spec.default!r} (its default; texsyn does not know its older value)"
        elif added.old is not DEFAULT:
            values[key] = added.old
            if added.old != spec.default:
                reported[key] = (
                    f"{key}={added.old!r} (as that model had it; the default now is {spec.default!r})"
                )
    return reported
