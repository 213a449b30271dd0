"""Saving and loading what a fitted method learned (one versioned ``.npz`` format)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, InputFileNotFoundError
from .writing import atomic_write, check_output_path

def save_fitted(path: str | os.PathLike, method) -> Path:
    """Save what a fitted method learned (e.g. the ``sparse`` dictionaries) to an ``.npz``.

    The file holds plain arrays plus a ``format_version`` tag; it is written atomically.
    """
    if not hasattr(method, "fitted_state"):
        raise InputError(f"method {getattr(method, 'name', method)!r} has no savable fitted state")
    p = check_output_path(path, formats={".npz": (8,)})
    state = method.fitted_state()

    def writer(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **state)

    atomic_write(p, writer)
    return p


def load_fitted(path: str | os.PathLike, **params):
    """Load a method saved by :func:`save_fitted`; ``params`` may change sampling parameters."""
    from ..methods import get_method

    p = Path(path)
    if not p.exists():
        raise InputFileNotFoundError(f"no such file: '{p}'")
    try:
        with np.load(p, allow_pickle=False) as data:
            state = {k: data[k] for k in data.files}
    except Exception as exc:
        raise InputError(f"cannot read '{p}' as a saved texsyn model ({exc})") from None
    if "method" not in state or "format_version" not in state:
        raise InputError(f"'{p}' is not a saved texsyn model (no method or format_version)")
    cls = get_method(str(state["method"]))
    return cls.from_fitted_state(state, **params)


