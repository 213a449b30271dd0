"""``texsyn.ops.fft``: SciPy's pocketfft without ``import scipy.fft``, the same bytes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.fft

from texsyn.ops import fft


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.complex64, np.complex128])
@pytest.mark.parametrize("shape", [(2, 3, 16, 12), (1, 15, 9)])
@pytest.mark.parametrize("use_scipy", [False, True])
def test_transforms_give_scipy_fft_bytes(dtype, shape, use_scipy, monkeypatch):
    if use_scipy:  # the fallback where SciPy's compiled module cannot be loaded alone
        monkeypatch.setattr(fft, "_pocketfft", lambda: None)
    rng = np.random.default_rng(0)
    x = rng.standard_normal(shape).astype(dtype)
    if np.iscomplexobj(x):
        x += 1j * rng.standard_normal(shape).astype(dtype)
    for workers in (1, 2):
        assert _same(fft.fft2(x, workers=workers), scipy.fft.fft2(x, workers=workers))
        assert _same(fft.ifft2(x, workers=workers), scipy.fft.ifft2(x, workers=workers))
        for axis in (-1, -2):
            for norm in (None, "forward"):
                assert _same(
                    fft.ifft(x, axis=axis, norm=norm, workers=workers),
                    scipy.fft.ifft(x, axis=axis, norm=norm, workers=workers),
                )
        if not np.iscomplexobj(x):
            half = scipy.fft.rfft2(x, workers=workers)
            assert _same(fft.rfft2(x, workers=workers), half)
            expected = scipy.fft.irfft2(half, s=shape[-2:])
            assert _same(fft.irfft2(half, s=shape[-2:], workers=workers), expected)
            # in two passes, the first in place on the half spectra: the same bytes
            overwritten = half.copy()
            assert _same(fft.irfft2(overwritten, s=shape[-2:], workers=workers, overwrite_x=True), expected)
            if not use_scipy:
                assert not _same(overwritten, half)  # the input was the first pass's workspace
    # in place where asked, as scipy.fft does for a complex array
    y = x.astype(np.result_type(dtype, np.complex64))
    expected = scipy.fft.ifft2(y)
    assert _same(fft.ifft2(y.copy(), overwrite_x=True), expected)
    # wrong inputs are refused, not transformed
    with pytest.raises(ValueError):
        fft.fft2(np.ones(4))
    if not use_scipy:
        with pytest.raises(ValueError):
            fft.irfft2(np.ones((4, 4), complex), s=(4, 8))
    for axis in (x.ndim, -x.ndim - 1):  # not another axis than the one asked for
        with pytest.raises(IndexError):
            fft.ifft(x, axis=axis)
    assert _same(fft.fft2(x, workers=-1), scipy.fft.fft2(x, workers=-1))  # every CPU, as scipy.fft
    with pytest.raises(ValueError):
        fft.fft2(x, workers=0)  # refused, as scipy.fft does


def test_portilla_simoncelli_imports_no_scipy_fft_package():
    """The method's modules load SciPy's compiled transforms only (``docs/performance.md``)."""
    code = (
        "import texsyn.methods.portilla_simoncelli, texsyn.ops.fft as f, json, sys\n"
        "assert f._pocketfft() is not None\n"
        "print(json.dumps(sorted(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    modules = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert not {m for m in modules if m.startswith("scipy.") and not m.startswith("scipy.fft._pocketfft")}


def test_scipy_fft_imported_after_the_module_is_whole():
    """Loading the compiled module first leaves a later ``import scipy.fft`` its usual package:
    the module bound to ``scipy.fft._pocketfft`` (dotted access), the same transforms."""
    code = (
        "import numpy as np, texsyn.ops.fft as f\n"
        "assert f._pocketfft() is not None\n"
        "import scipy.fft, scipy.fft._pocketfft.pypocketfft\n"
        "x = np.arange(12.0).reshape(3, 4)\n"
        "assert scipy.fft._pocketfft.pypocketfft.good_size(1001) == scipy.fft.next_fast_len(1001)\n"
        "assert scipy.fft.fft2(x).tobytes() == f.fft2(x).tobytes()\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("use_scipy", [False, True])
def test_irfft2_leaves_a_read_only_input_alone_when_it_may_overwrite(use_scipy, monkeypatch):
    # overwrite_x permits, as in scipy.fft.irfft2; a read-only array is transformed unchanged
    if use_scipy:
        monkeypatch.setattr(fft, "_pocketfft", lambda: None)
    half = scipy.fft.rfft2(np.random.default_rng(2).standard_normal((2, 12, 15)))
    half.flags.writeable = False
    kept = half.copy()
    assert _same(fft.irfft2(half, s=(12, 15), overwrite_x=True), scipy.fft.irfft2(kept, s=(12, 15)))
    assert _same(half, kept)


@pytest.mark.parametrize("use_scipy", [False, True])
def test_transforms_write_into_a_given_array(use_scipy, monkeypatch):
    # a stack shared between two threads: each half written into its part of one array
    if use_scipy:
        monkeypatch.setattr(fft, "_pocketfft", lambda: None)
    rng = np.random.default_rng(1)
    x = rng.standard_normal((4, 16, 12)).astype(np.float32)
    half = np.full((4, 16, 7), np.nan, dtype=np.complex64)
    assert fft.rfft2(x[:2], out=half[:2]) is not None and fft.rfft2(x[2:], out=half[2:]) is not None
    assert _same(half, scipy.fft.rfft2(x))
    y = (x + 1j * rng.standard_normal(x.shape)).astype(np.complex64)
    full = np.full(y.shape, np.nan, dtype=np.complex64)
    assert fft.fft2(y[:2], out=full[:2]) is not None and fft.fft2(y[2:], out=full[2:]) is not None
    assert _same(full, scipy.fft.fft2(y))
    # the complex transform of real images (the pyramid's first), into complex halves
    full[:] = np.nan
    assert fft.fft2(x[:2], out=full[:2]) is not None and fft.fft2(x[2:], out=full[2:]) is not None
    assert _same(full, scipy.fft.fft2(x))


@pytest.mark.parametrize("use_scipy", [False, True])
def test_a_given_array_of_another_shape_or_type_is_refused(use_scipy, monkeypatch):
    # pocketfft checks the type of ``out`` only: an array too small was written past its end
    if use_scipy:
        monkeypatch.setattr(fft, "_pocketfft", lambda: None)
    x = np.random.default_rng(2).standard_normal((4, 16, 12)).astype(np.float32)
    stack = np.zeros((4, 16, 12), dtype=np.complex64)
    for transform, columns in ((fft.rfft2, 7), (fft.fft2, 12)):
        with pytest.raises(ValueError, match="shape"):
            transform(x, out=stack[:1, :, :columns])  # the first image's part of a stack
        with pytest.raises(ValueError, match="shape"):
            transform(x[:1], out=stack[:, :, :columns])  # no broadcasting either
        assert not stack.any()
        for dtype in (np.complex128, np.float32):
            with pytest.raises(TypeError, match="complex64"):
                transform(x, out=np.zeros((4, 16, columns), dtype=dtype))
        with pytest.raises(TypeError, match="complex128"):
            transform(x.astype(np.float64), out=np.zeros((4, 16, columns), dtype=np.complex64))
    # of the right shape and type, a strided view is written in place
    view = np.zeros((4, 16, 14), dtype=np.complex64)[..., ::2]
    assert fft.rfft2(x, out=view) is view and _same(view.copy(), scipy.fft.rfft2(x))
