"""Saving and loading fitted models: :func:`save` and :func:`load` (``docs/persistence.md``).

One file format for every method: a NumPy ``.npz`` archive (read with ``allow_pickle=False``:
loading a file never runs code) holding

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

Files written by texsyn 0.1's ``texsyn.io.save_fitted`` (the ``sparse`` method only) are
read too.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ._version import __version__
from .errors import InputError, InputFileNotFoundError
from .io import OutputSet
from .methods import METHODS, TextureSynthesizer

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "load", "save"]

#: the ``format`` entry of every header
FORMAT_NAME = "texsyn-model"
#: the newest format version this texsyn writes and reads
FORMAT_VERSION = 1
#: the suffix of model files
SUFFIX = ".npz"
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


def _read(p: Path) -> dict[str, np.ndarray]:
    if not p.exists():
        raise InputFileNotFoundError(f"no such file: '{p}'")
    if p.is_dir():
        raise InputError(f"'{p}' is a folder, not a saved texsyn model")
    try:
        with np.load(p, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise ValueError("a single array, not an archive")
            return {k: data[k] for k in data.files}
    except (InputError, MemoryError):
        raise
    except Exception as exc:  # truncated or foreign files: zipfile, zlib, numpy format errors
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(f"'{p}' is not a saved texsyn model ({reason})") from None


def _header(p: Path, arrays: dict[str, np.ndarray]) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and the fitted arrays of a file (of this format or of texsyn 0.1's)."""
    if "header" in arrays:
        try:
            header = json.loads(str(arrays["header"]))
        except ValueError:
            header = None
        if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
            raise InputError(f"'{p}' is not a saved texsyn model (its header is not a {FORMAT_NAME} header)")
        fitted = {k[len(_FITTED) :]: v for k, v in arrays.items() if k.startswith(_FITTED)}
    elif all(k in arrays for k in _LEGACY_KEYS):  # texsyn 0.1: io.save_fitted of 'sparse'
        try:
            params = json.loads(str(arrays["params"]))
            legacy = int(arrays["format_version"])
        except (ValueError, TypeError):
            raise InputError(f"'{p}' is not a saved texsyn model (unreadable texsyn 0.1 header)") from None
        if legacy != 1:
            raise InputError(f"'{p}' has texsyn 0.1 format version {legacy}; only version 1 exists")
        header = {
            "format_version": 1,
            "texsyn_version": "0.1",
            "method": str(arrays["method"]),
            "params": params,
        }
        fitted = {k: v for k, v in arrays.items() if k not in _LEGACY_KEYS}
    else:
        raise InputError(f"'{p}' is not a saved texsyn model (it has no header)")
    version = header.get("format_version")
    if not isinstance(version, int) or version < 1:
        raise InputError(f"'{p}' has an invalid model format version {version!r}")
    if version > FORMAT_VERSION:
        raise InputError(
            f"'{p}' was written by texsyn {header.get('texsyn_version', '?')} in model format version "
            f"{version}; this texsyn ({__version__}) reads versions up to {FORMAT_VERSION}: upgrade texsyn"
        )
    if not isinstance(header.get("params"), dict):
        raise InputError(f"'{p}' is not a saved texsyn model (its parameters are not a mapping)")
    return header, fitted


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
        The file is missing (:class:`~texsyn.errors.InputFileNotFoundError`), truncated or not
        a texsyn model, written in a newer format version, for a method this texsyn does not
        know, or ``params`` are unknown or change what fit learned.

    Examples
    --------
    >>> import tempfile, texsyn
    >>> model = texsyn.make_method("heeger_bergen", n_iterations=1).fit(texsyn.data.exemplar("brick", size=32))
    >>> path = save(model, tempfile.mkdtemp() + "/brick.npz")
    >>> load(path, n_iterations=2).n_iterations
    2
    """
    p = Path(path)
    arrays = _read(p)
    header, fitted = _header(p, arrays)
    name = header.get("method")
    if not isinstance(name, str) or name not in METHODS:
        raise InputError(
            f"'{p}' holds a model of method {name!r}, which this texsyn ({__version__}) does not know; "
            f"known methods: {', '.join(sorted(METHODS))}"
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
                f"unknown parameter {unknown[0]!r} {where} for method {name!r}; allowed: {', '.join(specs) or 'none'}"
            )
    if fitted:
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
    exemplar = arrays.get("exemplar")
    if exemplar is None or exemplar.ndim not in (2, 3) or not np.issubdtype(exemplar.dtype, np.number):
        raise InputError(f"'{p}' is not a saved texsyn model (no exemplar image)")
    return cls(**values).restore_fitted(exemplar, fitted)
