"""SciPy's pocketfft transforms without the start-up cost of importing ``scipy.fft``.

``import scipy.fft`` costs about 0.15 s of every command that uses it (its package imports
``scipy.special`` and SciPy's array-API layer, which imports ``numpy.f2py``,
``numpy.testing`` ...), more than a Portilla-Simoncelli synthesis of a grey 256x256 image
spends in a tenth of its iterations. The transforms themselves are one compiled module,
``scipy.fft._pocketfft.pypocketfft``: this module loads that file alone, under its own name
but not entered in ``sys.modules`` (an entry there would make a later ``import scipy.fft``
take it without binding it to its package ``scipy.fft._pocketfft``: dotted access to it would
fail), and calls it with the arguments ``scipy.fft`` passes to it, which gives the same bytes (``tests/test_ops_fft.py``). Where the
file cannot be found or loaded (another SciPy layout), ``scipy.fft`` itself is used.

Only the forms the steerable pyramids need are offered: 2-D transforms over the last two
axes and 1-D transforms along one axis, complex or real, in the input's precision
(``float32``/``complex64`` stay single precision), ``workers`` threads (pocketfft
transforms each line on one thread: the bytes do not depend on it,
``docs/determinism.md``). ``docs/performance.md`` ("Start-up") measures the saving.
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import os
import sys

import numpy as np
from numpy.lib.array_utils import normalize_axis_index

__all__ = ["fft2", "ifft", "ifft2", "inverse_norm", "irfft2", "rfft2"]

#: the compiled module of SciPy that every ``scipy.fft`` transform of NumPy arrays ends in
_MODULE = "scipy.fft._pocketfft.pypocketfft"
#: pocketfft's normalisation codes (``scipy.fft``'s ``_NORM_MAP``): 0 none, 2 ``1 / n``
_NONE, _INVERSE = 0, 2


@functools.cache
def _pocketfft():
    """SciPy's ``pypocketfft`` module, loaded without its package; None if it cannot be."""
    module = sys.modules.get(_MODULE)
    if module is not None:
        return module
    try:
        scipy = importlib.util.find_spec("scipy")
        if scipy is None or scipy.origin is None:
            return None
        folder = os.path.join(os.path.dirname(scipy.origin), "fft", "_pocketfft")
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(folder, "pypocketfft" + suffix)
            if os.path.isfile(path):
                break
        else:
            return None
        spec = importlib.util.spec_from_file_location(_MODULE, path)
        if spec is None or spec.loader is None:
            return None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        # the same call scipy.fft makes for fft2 of a small array: checks the interface
        module.c2c(np.ones((2, 2)), (0, 1), True, _NONE, None, 1)
    except Exception:  # another layout or interface: scipy.fft below
        return None
    return module


def _scipy_fft():
    import scipy.fft

    return scipy.fft


def _as_float(x) -> np.ndarray:
    """The array pocketfft transforms: ``scipy.fft``'s conversion (floating point kept as it
    is, float16 to float32, other types to float64; native byte order, aligned)."""
    x = np.asarray(x)
    if x.dtype == np.float16:
        return x.astype(np.float32)
    if x.dtype.kind not in "fc":
        return x.astype(np.float64)
    dtype = x.dtype.newbyteorder("=")
    return np.array(x, dtype=dtype, copy=None if x.flags.aligned else True)


def _threads(workers: int) -> int:
    """``scipy.fft``'s reading of ``workers``: a negative count from the CPUs (-1 all of them),
    zero refused (pocketfft itself would take 0 as every hardware thread)."""
    workers = int(workers)
    if workers < 0:
        cpus = os.cpu_count() or 1
        if workers < -cpus:
            raise ValueError(f"workers value out of range; got {workers}, must not be less than {-cpus}")
        workers += 1 + cpus
    elif workers == 0:
        raise ValueError("workers must not be zero")
    return workers


def _check_out(out: np.ndarray, shape: tuple[int, ...], dtype: np.dtype) -> None:
    """Refuse an ``out`` that is not the transform's: ``shape``, and the complex type of the
    input's precision (of ``dtype`` as :func:`_as_float` converts it). pocketfft checks the
    type only and writes the input's shape through ``out``'s strides, past its end when it is
    smaller; ``scipy.fft``'s result would be broadcast or cast into it."""
    if dtype == np.float16 or dtype.kind in "fc":
        expected = np.result_type(np.float32 if dtype == np.float16 else dtype, np.complex64)
    else:
        expected = np.dtype(np.complex128)
    if not isinstance(out, np.ndarray) or out.dtype != expected:
        got = out.dtype if isinstance(out, np.ndarray) else type(out).__name__
        raise TypeError(f"out must be an array of {expected}, got {got}")
    if out.shape != shape:
        raise ValueError(f"out must have the shape {shape}, got {out.shape}")


def _written(result: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """``scipy.fft``'s ``result`` (the fallback), copied into ``out`` where one is given."""
    if out is None:
        return result
    out[...] = result
    return out


def _last_two(x: np.ndarray) -> tuple[int, int]:
    if x.ndim < 2:
        raise ValueError("a 2-D transform needs at least two axes")
    return (x.ndim - 2, x.ndim - 1)


def fft2(x, *, workers: int = 1, overwrite_x: bool = False, out: np.ndarray | None = None) -> np.ndarray:
    """``scipy.fft.fft2(x, workers=workers, overwrite_x=overwrite_x)`` (last two axes); written
    into ``out`` if given (complex, of ``x``'s shape and precision)."""
    if out is not None:
        x = np.asarray(x)
        _check_out(out, x.shape, x.dtype)
    return _complex_2d(x, True, workers, overwrite_x, out)


def ifft2(x, *, workers: int = 1, overwrite_x: bool = False) -> np.ndarray:
    """``scipy.fft.ifft2(x, workers=workers, overwrite_x=overwrite_x)`` (last two axes)."""
    return _complex_2d(x, False, workers, overwrite_x)


def _complex_2d(
    x, forward: bool, workers: int, overwrite_x: bool, out: np.ndarray | None = None
) -> np.ndarray:
    """The complex transform of the last two axes, forward or inverse, as ``scipy.fft`` makes it."""
    module = _pocketfft()
    if module is None:
        transform = _scipy_fft().fft2 if forward else _scipy_fft().ifft2
        return _written(transform(x, workers=workers, overwrite_x=overwrite_x), out)
    a = _as_float(x)
    if out is None and overwrite_x and a.dtype.kind == "c":
        out = a
    return module.c2c(a, _last_two(a), forward, _NONE if forward else _INVERSE, out, _threads(workers))


def ifft(x, axis: int = -1, *, norm: str | None = None, workers: int = 1, overwrite_x: bool = False):
    """``scipy.fft.ifft(x, axis=axis, norm=norm, ...)``; ``norm`` None (``1 / n``) or ``"forward"`` (none)."""
    module = _pocketfft()
    if module is None:
        return _scipy_fft().ifft(x, axis=axis, norm=norm, workers=workers, overwrite_x=overwrite_x)
    if norm not in (None, "backward", "forward"):
        raise ValueError(f"norm must be None, 'backward' or 'forward', not {norm!r}")
    a = _as_float(x)
    out = a if overwrite_x and a.dtype.kind == "c" else None
    axes = (normalize_axis_index(axis, a.ndim),)  # an axis out of range is refused, as scipy.fft does
    return module.c2c(a, axes, False, _NONE if norm == "forward" else _INVERSE, out, _threads(workers))


def rfft2(x, *, workers: int = 1, out: np.ndarray | None = None) -> np.ndarray:
    """``scipy.fft.rfft2(x, workers=workers)`` of a real array (last two axes); written into
    ``out`` if given (complex, ``x``'s shape but ``w // 2 + 1`` columns, its precision)."""
    if out is not None:
        x = np.asarray(x)
        _check_out(out, x.shape[:-1] + (x.shape[-1] // 2 + 1,), x.dtype)
    module = _pocketfft()
    if module is None:
        return _written(_scipy_fft().rfft2(x, workers=workers), out)
    a = _as_float(x)
    if a.dtype.kind == "c":
        raise TypeError("rfft2 needs a real array")
    return module.r2c(a, _last_two(a), True, _NONE, out, _threads(workers))


def irfft2(x, s: tuple[int, int], *, workers: int = 1, overwrite_x: bool = False) -> np.ndarray:
    """``scipy.fft.irfft2(x, s=s, workers=workers)``: the real ``s``-sized images of half
    spectra ``x`` whose last axis has ``s[1] // 2 + 1`` columns and the one before ``s[0]`` rows.

    With ``overwrite_x`` a complex ``x`` is overwritten (unless it is read-only, which
    ``scipy.fft`` accepts too): pocketfft's two passes (the columns'
    complex transforms, then the rows' real ones, scaled by ``1 / (h w)`` after the second,
    as one call scales them) run as two calls, the first in place, instead of the first
    writing a new array of the size of ``x``. The same bytes; measured on the 2-core
    machine in a Portilla-Simoncelli synthesis, twelve 256x256 half spectra took 1.8 instead
    of 3.7 ms, the memory traffic of that array saved (``docs/performance.md``, "FFTs").
    """
    module = _pocketfft()
    if module is None:
        return _scipy_fft().irfft2(x, s=s, workers=workers, overwrite_x=overwrite_x)
    a = _as_float(x)
    if a.dtype.kind != "c":
        a = a + 0j
    h, w = int(s[0]), int(s[1])
    if a.shape[-2:] != (h, w // 2 + 1):
        raise ValueError(f"half spectra of {a.shape[-2:]} do not fit images of {(h, w)}")
    threads = _threads(workers)
    if not (overwrite_x and a.flags.writeable):  # a read-only array: as scipy.fft, not written
        return module.c2r(a, _last_two(a), w, False, _INVERSE, None, threads)
    columns, rows = _last_two(a)
    module.c2c(a, (columns,), False, _NONE, a, threads)
    out = module.c2r(a, (rows,), w, False, _NONE, None, threads)
    out *= inverse_norm(h * w, out.dtype)  # pocketfft's factor, applied as it applies it
    return out


def inverse_norm(n: int, dtype) -> np.ndarray:
    """pocketfft's ``1 / n`` normalisation factor, a 0-d array of ``dtype``: computed in long
    double, then rounded once (``norm_fct`` of scipy's ``pypocketfft``); read-only, computed
    once per size and type (a synthesis asks for it many times an iteration)."""
    return _inverse_norm(int(n), np.dtype(dtype))


@functools.cache
def _inverse_norm(n: int, dtype: np.dtype) -> np.ndarray:
    factor = np.asarray(np.longdouble(1) / np.longdouble(n)).astype(dtype)
    factor.flags.writeable = False
    return factor
