"""The projections that impose Portilla–Simoncelli statistics on an image or its bands.

J. Portilla, E. Simoncelli, IJCV 40(1), 2000, section 4: each set of statistics is imposed
by the smallest change that reaches it (a gradient step along the statistic for skewness and
kurtosis, :mod:`texsyn.models.portilla_moments`; a linear transform for covariances; a
filter for auto-correlations). The names in
parentheses are those of the authors' reference code. The statistics themselves are in
:mod:`texsyn.models.portilla`; the order in which one synthesis iteration applies these
projections is :func:`texsyn.methods.portilla_simoncelli.project_statistics`
(``docs/methods/portilla_simoncelli.md``).

Why this module is long: next to each projection's public form, the synthesis loop uses a
form that works on rows filled in place, band by band, and transforms that skip the zero
lines of their inputs (issue 20, "Performance" in the method's page); both give the same
bytes and are kept together so that they stay so (``tests/test_portilla_fast_paths.py``).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from ..ops import fft as pocketfft
from ..ops.linalg import add_product
from ..transforms.complex_steerable import fft_workers, for_each_band, shared_stack
from .portilla import PSStatistics
from .portilla_moments import FLAT_VARIANCE as FLAT_VARIANCE  # re-exported (round 1's home)
from .portilla_moments import impose_kurtosis, impose_skewness
from .portilla_moments import is_flat as is_flat

__all__ = [
    "adjust_correlation",
    "adjust_cross_correlation",
    "adjust_cross_correlation_rows",
    "centred_magnitudes",
    "filter_autocorrelation",
    "filter_autocorrelation_spectrum",
    "fit_window",
    "impose_autocorrelation",
    "impose_kurtosis",
    "impose_lowpass_statistics",
    "impose_magnitude_statistics",
    "impose_parent_regression",
    "impose_pixel_statistics",
    "impose_skewness",
    "adjusted_magnitudes",
    "magnitude_real_parts",
    "parent_regression_rows",
    "real_part_of_product",
    "highpass_shrink_factor",
    "shrink_highpass",
    "shrink_image_highpass",
]


def impose_autocorrelation(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Filter ``x`` so that its central auto-correlation becomes ``target`` (the reference code's ``modacor22``).

    Solves for the symmetric auto-correlation ``c_h`` of a filter such that
    ``(c_x * c_h)(t) = target(t)`` on the window, then multiplies the spectrum of ``x`` by
    ``sqrt(|FT c_h|)``. Batched: ``x`` is ``(..., h, w)`` and ``target`` ``(..., a, a)``.
    """
    return np.asarray(filter_autocorrelation(np.asarray(x, dtype=np.float64), target), dtype=np.float64)


def filter_autocorrelation(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """:func:`impose_autocorrelation` without the final conversion to double precision.

    With a window wider than one pixel the filtering runs in single precision (``x`` is
    rounded to it) and its result is returned as such; the synthesis adds it to double
    precision values, which widens it exactly as the conversion would.
    """
    h, w = x.shape[-2:]
    lag = (target.shape[-1] - 1) // 2
    if lag == 0:
        x = np.asarray(x, dtype=np.float64)
        cur = np.mean(x**2, axis=(-2, -1), keepdims=True)
        return x * np.sqrt(target[..., :1, :1] / np.where(cur > 0, cur, 1.0))
    x = np.asarray(x, dtype=np.float32)
    count = x.size // (h * w)
    if shared_stack(count, h * w) and target.shape[:-2] == x.shape[:-2] and x.flags.c_contiguous:
        # a shared stack (a 256x256 level's bands): half of them on a second thread, each band
        # filtered as it is alone (the same bytes)
        images, targets = x.reshape(count, h, w), target.reshape((count,) + target.shape[-2:])
        out = np.empty((count, h, w), dtype=np.float32)

        def run(bands: slice) -> None:
            spec = pocketfft.rfft2(images[bands])
            out[bands] = filter_autocorrelation_spectrum(spec, targets[bands], (h, w), least_squares=False)

        try:
            for_each_band(run, count, h * w)
            return out.reshape(x.shape)
        except np.linalg.LinAlgError:
            # a singular system (a band of zeros: a constant channel) makes the least squares
            # replace the solves of the whole stack, not of its half: the stack at once
            # below, as on one CPU (the bytes do not depend on the halves)
            pass
    spec = pocketfft.rfft2(x, workers=fft_workers(x.size))
    return filter_autocorrelation_spectrum(spec, target, (h, w))


def filter_autocorrelation_spectrum(
    spec: np.ndarray, target: np.ndarray, shape: tuple, *, least_squares: bool = True
) -> np.ndarray:
    """:func:`filter_autocorrelation` of the images of size ``shape`` given by their half
    spectra ``spec`` (``rfft2``, single precision; overwritten), for a window wider than a
    pixel: the synthesis loop's partial reconstructions are spectra already
    (``docs/methods/portilla_simoncelli.md``, "Performance").

    Where one image's system is singular, every image's filter is solved by least squares;
    without ``least_squares``, :class:`numpy.linalg.LinAlgError` is raised instead.
    """
    h, w = shape
    lag = (target.shape[-1] - 1) // 2
    power = np.square(spec.real)
    power += np.square(spec.imag)
    plan = _window_plan(lag, h, w)
    cx = _autocorrelation_values(power, plan, h, w)
    a = cx[..., plan.diff_rows, plan.diff_cols]
    a = a + np.where(plan.nonzero[None, :], cx[..., plan.sum_rows, plan.sum_cols], 0.0)
    b = target[..., plan.half[:, 0] + lag, plan.half[:, 1] + lag]
    try:
        coef = np.linalg.solve(a, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        if not least_squares:
            raise
        coef = np.stack(
            [
                np.linalg.lstsq(ai, bi, rcond=None)[0]
                for ai, bi in zip(a.reshape((-1,) + a.shape[-2:]), b.reshape(-1, b.shape[-1]))
            ]
        ).reshape(b.shape)
    spec *= _symmetric_filter_gain(coef, plan)
    return pocketfft.irfft2(spec, s=(h, w), workers=fft_workers(2 * spec.size), overwrite_x=True)


class _WindowPlan(NamedTuple):
    """Index arrays and cosine tables of :func:`filter_autocorrelation` for one window and
    band size (cached)."""

    half: np.ndarray  # the window's lags, one of each +/- pair (:func:`_half_offsets`)
    nonzero: np.ndarray  # which of them are not (0, 0)
    multiplicity: np.ndarray  # 1 for the lag (0, 0), 2 for the others (+half and -half)
    diff_rows: np.ndarray  # positions in the table of auto-correlation values of the lag
    diff_cols: np.ndarray  # differences (rows, columns) ...
    sum_rows: np.ndarray  # ... and of the lag sums
    sum_cols: np.ndarray
    lag_rows: np.ndarray  # (2, R, h) float64: cos and sin of 2 pi u r / h for the table's row lags r
    lag_cols: np.ndarray  # (w // 2 + 1, 2 Q) float32: m_v cos, then m_v sin, of 2 pi v q / w
    row_tables: np.ndarray  # (h, 2 (lag + 1)) float32 (:func:`_filter_tables`)
    column_tables: np.ndarray  # (2, 2 lag + 1, w // 2 + 1)


@functools.cache
def _window_plan(lag: int, h: int, w: int) -> _WindowPlan:
    half = _half_offsets(lag)
    diff = half[:, None, :] - half[None, :, :]
    summ = half[:, None, :] + half[None, :, :]
    rows = _sorted_distinct(np.concatenate([diff[..., 0].ravel(), summ[..., 0].ravel()]) % h)
    cols = _sorted_distinct(np.concatenate([diff[..., 1].ravel(), summ[..., 1].ravel()]) % w)
    u, v = np.arange(h), np.arange(w // 2 + 1)
    angle_rows = 2.0 * np.pi * ((rows[:, None] * u[None, :]) % h) / h  # (R, h)
    angle_cols = 2.0 * np.pi * ((v[:, None] * cols[None, :]) % w) / w  # (V, Q)
    # the half spectrum's columns stand for themselves and their mirrors (but 0 and w / 2)
    mirrored = np.where((v == 0) | (2 * v == w), 1.0, 2.0)[:, None]
    lag_cols = np.concatenate([mirrored * np.cos(angle_cols), mirrored * np.sin(angle_cols)], axis=1)
    return _WindowPlan(
        half=half,
        nonzero=np.any(half != 0, axis=1),
        multiplicity=np.where(np.any(half != 0, axis=1), 2.0, 1.0),
        diff_rows=np.searchsorted(rows, diff[..., 0] % h),
        diff_cols=np.searchsorted(cols, diff[..., 1] % w),
        sum_rows=np.searchsorted(rows, summ[..., 0] % h),
        sum_cols=np.searchsorted(cols, summ[..., 1] % w),
        lag_rows=np.stack([np.cos(angle_rows), np.sin(angle_rows)]),
        lag_cols=lag_cols.astype(np.float32),
        **_filter_tables(lag, h, w),
    )


def _sorted_distinct(values: np.ndarray) -> np.ndarray:
    """``numpy.unique(values)`` of integers, without it: its first call imports ``numpy.ma``
    (6 ms of a command's start-up)."""
    values = np.sort(values)
    return values[np.concatenate([[True], values[1:] != values[:-1]])]


def _filter_tables(lag: int, h: int, w: int) -> dict:
    """The cosine and sine tables of :func:`_symmetric_filter_gain`.

    ``row_tables[u]``: ``cos(2 pi u i / h)`` for ``i = 0 .. lag``, then ``-sin(2 pi u i / h)``
    (single precision); ``column_tables``: ``cos(2 pi v j / w)`` and ``sin(2 pi v j / w)``
    for ``j = -lag .. lag``, ``v = 0 .. w // 2``. The filter's spectrum is then
    ``row_tables @ [W @ cos; W @ sin]`` for its weights ``W[i, j + lag]``.
    """
    i = np.arange(lag + 1)
    j = np.arange(-lag, lag + 1)
    u = np.arange(h)
    v = np.arange(w // 2 + 1)
    a = 2.0 * np.pi * ((u[:, None] * i[None, :]) % h) / h  # (h, lag + 1)
    b = 2.0 * np.pi * ((v[None, :] * j[:, None]) % w) / w  # (2 lag + 1, w // 2 + 1)
    rows = np.concatenate([np.cos(a), -np.sin(a)], axis=1).astype(np.float32)
    return {"row_tables": rows, "column_tables": np.stack([np.cos(b), np.sin(b)])}


def _autocorrelation_values(power: np.ndarray, plan: _WindowPlan, h: int, w: int) -> np.ndarray:
    """The periodic auto-correlation ``irfft2(power, s=(h, w)) / (h w)`` (double precision) at
    the lags the system needs: a table ``(..., R, Q)`` that ``plan.diff_rows`` ... index.

    ``power`` is the single-precision half spectrum ``|rfft2(x)|^2``; the auto-correlation at
    ``(r, q)`` is ``sum_(u, v) P(u, v) cos(2 pi (u r / h + v q / w)) / (h w)^2``, separable
    (``cos(a + b) = cos a cos b - sin a sin b``): one single-precision product over the
    columns (the half spectrum's columns counted twice for their mirrors), one in double
    precision over the rows, instead of transforms of the whole spectrum.
    """
    q = plan.lag_cols.shape[1] // 2
    columns = (power @ plan.lag_cols).astype(np.float64)  # (..., h, 2 Q)
    values = plan.lag_rows[0] @ columns[..., :q]
    values -= plan.lag_rows[1] @ columns[..., q:]
    return values / (float(h * w) ** 2)


def _symmetric_filter_gain(coef: np.ndarray, plan: _WindowPlan) -> np.ndarray:
    """``sqrt(|rfft2(filter)|)`` (single precision) of the symmetric filters with ``coef`` at
    the lags ``+/- plan.half`` (the gain of :func:`filter_autocorrelation`).

    The filter's spectrum is real, ``G(u, v) = sum_(i, j) m_ij c_ij cos(2 pi (u i / h + v j / w))``
    (``m = 2`` but at lag ``(0, 0)``), and separable: ``cos(a + b) = cos a cos b - sin a sin b``
    makes it two small matrix products (:class:`_WindowPlan`'s cosine and sine tables)
    instead of a 2-D transform.
    """
    lag = plan.row_tables.shape[-1] // 2 - 1
    weights = np.zeros(coef.shape[:-1] + (lag + 1, 2 * lag + 1))
    weights[..., plan.half[:, 0], plan.half[:, 1] + lag] = coef * plan.multiplicity
    columns = weights[..., None, :, :] @ plan.column_tables  # (..., 2, lag + 1, w // 2 + 1)
    columns = columns.reshape(columns.shape[:-3] + (-1, columns.shape[-1])).astype(np.float32)
    gain = np.matmul(plan.row_tables, columns)  # (..., h, w // 2 + 1)
    np.abs(gain, out=gain)
    return np.sqrt(gain, out=gain)


@functools.cache
def _half_offsets(lag: int) -> np.ndarray:
    """Lags ``(i, j)`` of a ``(2 lag + 1)^2`` window, one of each ``+/-`` pair, zero first."""
    pairs = [(i, j) for i in range(-lag, lag + 1) for j in range(-lag, lag + 1) if (i, j) >= (0, 0)]
    return np.array(pairs, dtype=np.int64)


def _sqrtm(c: np.ndarray, inverse: bool = False) -> np.ndarray:
    vals, vecs = np.linalg.eigh((c + c.T) / 2)
    top = max(vals.max(), 0.0)
    vals = np.maximum(vals, 1e-12 * top if top > 0 else 0.0)
    if inverse:
        vals = np.where(vals > 0, 1.0 / np.sqrt(np.where(vals > 0, vals, 1.0)), 0.0)
    else:
        vals = np.sqrt(vals)
    return (vecs * vals) @ vecs.T


def adjust_correlation(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Linearly transform the columns of ``x`` (N, k) so that ``x^T x / N = target`` (``adjustCorr1s``)."""
    current = x.T @ x / x.shape[0]
    return x @ (_sqrtm(current, inverse=True) @ _sqrtm(target))


def adjust_cross_correlation(
    x: np.ndarray, target: np.ndarray, y: np.ndarray, target_xy: np.ndarray
) -> np.ndarray:
    """Modify ``x`` (N, k), given fixed ``y`` (N, m), so that ``x^T x / N = target`` and
    ``x^T y / N = target_xy`` (``adjustCorr2s``).

    The part of ``x`` explained by ``y`` is replaced by the target regression and the
    residual is rescaled to the target residual covariance (clipped to be positive).
    """
    rows = np.concatenate([x.T, y.T], axis=0)  # (k + m, N), contiguous rows for BLAS
    return adjust_cross_correlation_rows(rows, x.shape[1], target, target_xy).T


def adjust_cross_correlation_rows(
    rows: np.ndarray, k: int, target: np.ndarray, target_xy: np.ndarray
) -> np.ndarray:
    """:func:`adjust_cross_correlation` on rows: ``rows`` ``(k + m, N)`` holds ``x^T`` then
    ``y^T`` (C order); returns the new ``x^T`` ``(k, N)``.

    The products with the ``N``-column rows run in the rows' precision (the synthesis gives
    single-precision rows, ``docs/methods/portilla_simoncelli.md``, "Performance"); the
    small ``(k + m)``-square matrices are solved in double precision.
    """
    n = rows.shape[1]
    gram = (rows @ rows.T).astype(np.float64) / n
    bxx, bxy, byy = gram[:k, :k], gram[:k, k:], gram[k:, k:]
    ibyy = np.linalg.pinv(byy)
    regression = ibyy @ bxy.T  # (m, k)
    current = bxx - bxy @ regression
    desired = target - target_xy @ ibyy @ target_xy.T
    m = _sqrtm(current, inverse=True) @ _sqrtm(desired)
    # (x - y regression) m + y ibyy target_xy^T, with two products of N-column matrices
    out = m.T.astype(rows.dtype) @ rows[:k]
    return add_product(
        out, np.ascontiguousarray((ibyy @ target_xy.T - regression @ m).T, rows.dtype), rows[k:]
    )


def fit_window(target: np.ndarray, shape: tuple[int, int], lags: int) -> np.ndarray:
    """Crop a target auto-correlation window to what a band of ``shape`` allows.

    The window of a ``h x w`` band has half-width ``min(lags, min(h, w) // 2 - 1)``, as in
    :func:`texsyn.models.portilla.central_autocorrelation`.

    Examples
    --------
    >>> fit_window(np.zeros((1, 7, 7)), (4, 4), 3).shape
    (1, 3, 3)
    """
    allowed = max(0, min(lags, min(shape) // 2 - 1))
    have = (target.shape[-1] - 1) // 2
    cut = have - min(allowed, have)
    return target[..., cut : target.shape[-2] - cut, cut : target.shape[-1] - cut]


def impose_lowpass_statistics(
    images: np.ndarray | None,
    autocorr: np.ndarray,
    skew_kurt: np.ndarray,
    pixel_var: np.ndarray,
    lags: int,
    *,
    spectrum: np.ndarray | None = None,
    shape: tuple | None = None,
) -> np.ndarray:
    """Impose auto-correlation, skewness and kurtosis on every channel of a low-pass image.

    The partially reconstructed low-pass images of paper section 4 (``(C, h, w)``). A channel
    whose target variance is below ``1e-4`` of its pixel variance ``pixel_var`` only gets its
    variance (its auto-correlation system would be ill-conditioned). The synthesis loop gives
    the images by their half spectra instead (``images=None``, ``spectrum`` from ``rfft2``,
    single precision, overwritten; ``shape`` their size): the filter then starts from them
    (:func:`filter_autocorrelation_spectrum`).
    """
    if spectrum is not None:
        assert shape is not None
        h, w = shape
    else:
        assert images is not None
        h, w = images.shape[-2:]
    window = fit_window(autocorr, (h, w), lags)
    centre = (window.shape[-1] - 1) // 2
    target_var = window[:, centre, centre]
    active = target_var / np.maximum(pixel_var, 1e-300) > 1e-4
    if spectrum is not None and centre > 0 and active.all():  # the loop's usual case
        out = filter_autocorrelation_spectrum(spectrum, window, (h, w)).astype(np.float64)
    else:
        if spectrum is not None:
            workers = fft_workers(2 * spectrum.size)
            images = pocketfft.irfft2(spectrum, s=(h, w), workers=workers, overwrite_x=True)
        assert images is not None
        if active.all():  # no copies in and out of the active channels
            out = np.asarray(filter_autocorrelation(images, window), dtype=np.float64)
        else:
            out = np.array(images, dtype=np.float64)
            if active.any():
                out[active] = filter_autocorrelation(out[active], window[active])

    def run(channels: slice) -> None:
        for c in range(channels.start, channels.stop):
            if active[c]:
                out[c] = impose_kurtosis(impose_skewness(out[c], skew_kurt[c, 0]), skew_kurt[c, 1])
            else:
                current = np.mean((out[c] - out[c].mean()) ** 2)
                if current > 0:
                    out[c] *= np.sqrt(target_var[c] / current)

    for_each_band(run, out.shape[0], out.shape[-1] * out.shape[-2])  # channel by channel
    return out


def impose_parent_regression(reals: np.ndarray, parents: np.ndarray, target_xp: np.ndarray) -> np.ndarray:
    """Give every column of ``reals`` (N, k) its target correlation ``target_xp`` (k, m) with
    ``parents`` (N, m), keeping its variance (paper section 4: the real parts against the
    phase-doubled parents; computed in single precision like the synthesis pyramid)."""
    rows = np.concatenate([reals.T, parents.T], axis=0).astype(np.float32)  # (k + m, N)
    return parent_regression_rows(rows, reals.shape[1], target_xp).T.astype(np.float64)


def parent_regression_rows(rows: np.ndarray, k: int, target_xp: np.ndarray) -> np.ndarray:
    """:func:`impose_parent_regression` on single-precision rows: ``rows`` ``(k + m, N)``
    holds the reals' transpose then the parents'; returns the new reals' transpose ``(k, N)``,
    written over ``rows[:k]``."""
    n = rows.shape[1]
    gram = (rows @ rows.T).astype(np.float64) / n
    own = np.diag(gram)[:k]
    cross = gram[k:, :k]  # (m, k): parents^T reals / n
    ibyy = np.linalg.pinv(gram[k:, k:])
    regression = ibyy @ cross
    fit = ibyy @ target_xp.T
    current = own - np.einsum("mk,mk->k", cross, regression)
    desired = np.maximum(own - np.einsum("km,mk->k", target_xp, fit), 0.0)
    scale = np.sqrt(desired / np.where(current > 0, current, 1.0))
    mix = np.ascontiguousarray((fit - regression * scale).T, np.float32)
    out = rows[:k]
    out *= scale[:, None].astype(np.float32)
    return add_product(out, mix, rows[k:])


def impose_magnitude_statistics(
    band: np.ndarray, target: PSStatistics, level: int, parent_magnitudes: np.ndarray | None, lags: int
) -> np.ndarray:
    """Give the complex bands ``(C, K, h, w)`` of ``level`` their target magnitude statistics.

    Paper section 4: the centred magnitudes get their covariance across orientations and
    channels and with the parent scale's magnitudes (:func:`adjust_cross_correlation`; the
    coarsest scale has no parent: :func:`adjust_correlation`), then their auto-correlation,
    then their mean; the phases are kept.
    """
    c, k = band.shape[:2]
    n = band.shape[-1] * band.shape[-2]
    if parent_magnitudes is None:
        current, mags = centred_magnitudes(band)
        filtered = adjusted_magnitudes(current, mags, None, target, level, lags)
    else:
        rows = np.empty((c * k + parent_magnitudes.shape[1], n))
        current, _ = centred_magnitudes(band, rows[: c * k].reshape(band.shape))
        rows[c * k :] = parent_magnitudes.T
        filtered = adjusted_magnitudes(current, None, rows, target, level, lags)
    ratio = np.add(filtered, target.magnitude_means[level][..., None, None], dtype=np.float64)
    np.maximum(ratio, 0.0, out=ratio)
    return band * (ratio / np.where(current > 0, current, 1.0))


def centred_magnitudes(band: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(|band|, |band| - its mean over each band)`` for bands ``(..., h, w)``, the second
    written into ``out`` if given (band by band: :func:`~texsyn.transforms.complex_steerable.for_each_band`)."""
    h, w = band.shape[-2:]
    current = np.empty(band.shape, dtype=band.real.dtype)
    centred = np.empty(band.shape, dtype=current.dtype) if out is None else out
    flat, mags, result = (a.reshape(-1, h * w) for a in (band, current, centred))

    def run(bands: slice) -> None:
        np.abs(flat[bands], out=mags[bands])
        np.subtract(mags[bands], mags[bands].mean(axis=-1, keepdims=True), out=result[bands])

    for_each_band(run, flat.shape[0], h * w)
    return current, centred


def adjusted_magnitudes(
    current: np.ndarray,
    mags: np.ndarray | None,
    rows: np.ndarray | None,
    target: PSStatistics,
    level: int,
    lags: int,
) -> np.ndarray:
    """The centred magnitudes of :func:`impose_magnitude_statistics` after their covariance
    and auto-correlation steps (single precision when the window is wider than a pixel).

    ``current`` is ``|band|`` ``(C, K, h, w)``; at the coarsest scale ``mags`` holds its
    centred magnitudes and ``rows`` is None, elsewhere ``rows`` ``(CK + M, hw)`` holds them
    (as rows, double precision) followed by the parents' centred magnitudes.
    """
    c, k = current.shape[:2]
    n = current.shape[-1] * current.shape[-2]
    if rows is None:
        assert mags is not None
        m = adjust_correlation(mags.reshape(c * k, n).T, target.magnitude_cross[level]).T
    else:
        m = adjust_cross_correlation_rows(
            rows, c * k, target.magnitude_cross[level], target.magnitude_parent[level]
        )
    window = fit_window(target.magnitude_autocorr[level], current.shape[-2:], lags)
    return filter_autocorrelation(m.reshape(current.shape), window)


def magnitude_real_parts(
    band: np.ndarray, current: np.ndarray, filtered: np.ndarray, means: np.ndarray, out: np.ndarray
) -> np.ndarray:
    """The real parts of :func:`impose_magnitude_statistics`'s result, written into ``out``.

    Band by band: the new magnitude ``max(filtered + mean, 0)`` over the old ``current``
    (0 where the band is 0) multiplies the band's real part (:func:`real_part_of_product`).
    ``means`` is ``(C, K)``; ``out`` may be single precision (the product is rounded once).
    """
    h, w = band.shape[-2:]
    flat, cur, new, res = (a.reshape(-1, h * w) for a in (band, current, filtered, out))
    dtype = np.result_type(filtered.dtype, current.dtype, out.dtype)
    mean = np.asarray(means, dtype=dtype).reshape(-1)

    def run(bands: slice) -> None:
        ratio = np.add(new[bands], mean[bands, None], dtype=dtype)
        np.maximum(ratio, 0.0, out=ratio)
        if cur[bands].min() > 0:
            np.divide(ratio, cur[bands], out=ratio)
        else:
            np.divide(ratio, np.where(cur[bands] > 0, cur[bands], 1.0), out=ratio)
        real_part_of_product(flat[bands], ratio, res[bands])

    for_each_band(run, flat.shape[0], h * w)
    return out


def real_part_of_product(band: np.ndarray, ratio: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``(band * ratio).real`` (complex times real) written into ``out``, without the complex product.

    The complex product's real part is ``re ratio - im 0`` (the real factor's imaginary part
    is ``+0``): the same number as ``re ratio`` except when that is a zero, whose sign the
    ``- im 0`` may flip. The loop's bands have such zeros (a few per cent of the new
    magnitudes are clipped to 0), so the subtraction is done everywhere (two passes, fewer
    than finding and recomputing the zeros).
    """
    np.multiply(band.real, ratio, out=out)
    out -= np.multiply(band.imag, 0.0)  # signed zeros
    return out


def shrink_highpass(highpass: np.ndarray, target_variance: np.ndarray) -> np.ndarray:
    """Scale each channel of the high-pass residual ``(C, H, W)`` down to its target variance.

    Paper section 4: only too much high-frequency energy is removed; a residual below its
    target is left as it is.

    Examples
    --------
    >>> float(shrink_highpass(np.full((1, 2, 2), 2.0), np.array([1.0]))[0, 0, 0])
    1.0
    """
    hp_var = np.mean(highpass**2, axis=(-2, -1))
    shrink = np.where(
        hp_var > target_variance, np.sqrt(target_variance / np.where(hp_var > 0, hp_var, 1.0)), 1.0
    )
    return highpass * shrink[:, None, None]


def highpass_shrink_factor(spectrum: np.ndarray, target_variance: np.ndarray) -> np.ndarray:
    """The factor per channel of :func:`shrink_highpass`, from the residual's Fourier transform.

    The residual's variance is ``sum |F|^2 / (H W)^2`` (Parseval; the residual has zero
    mean): the synthesis loop keeps the residual as a spectrum (issue 20, single-precision step).
    """
    h, w = spectrum.shape[-2:]
    power = np.square(spectrum.real)
    power += np.square(spectrum.imag)
    hp_var = np.sum(power, axis=(-2, -1), dtype=np.float64) / (float(h * w) ** 2)
    return np.where(
        hp_var > target_variance, np.sqrt(target_variance / np.where(hp_var > 0, hp_var, 1.0)), 1.0
    )


def shrink_image_highpass(x: np.ndarray, target: PSStatistics, pyramid) -> np.ndarray:
    """Scale the high frequencies of the image ``(C, H, W)`` itself down to the high-pass variance.

    The iteration shrinks the high-pass residual, but the image it rebuilds also carries the
    high frequencies that the skewness and kurtosis of the partially reconstructed image
    (pointwise maps) created beyond its band, and the pixel step adds its own: measured on the
    output, the high-pass variance stayed up to twice the exemplar's (``color_4``'s green and
    blue). This projection, run once after the last iteration
    (``docs/methods/portilla_simoncelli.md``, "Deviations"), removes ``1 - f`` of the image's
    ``H0^2``-filtered part, ``f`` chosen so that its ``H0``-filtered part has the target
    variance (only too much is removed, as for the residual); the pixel statistics are
    imposed again after it.
    """
    spec = pyramid.fft(x)
    measured = np.mean(pyramid.ifft(spec * pyramid.hi0).real ** 2, axis=(-2, -1))
    wanted = target.highpass_variance
    factor = np.where(measured > wanted, np.sqrt(wanted / np.where(measured > 0, measured, 1.0)), 1.0)
    if np.all(factor == 1.0):
        return x
    high = pyramid.ifft(spec * pyramid.hi0**2).real
    return impose_pixel_statistics(x + high * (factor - 1.0)[:, None, None], target)


def impose_pixel_statistics(x: np.ndarray, target: PSStatistics) -> np.ndarray:
    """Impose the pixel statistics on ``(C, H, W)`` channels (paper section 4, last step).

    Mean and (colour) covariance with :func:`adjust_correlation`, then the skewness and
    kurtosis of every channel with a non-zero target variance, then the value range (clipping).
    """
    c = x.shape[0]
    mean0 = target.pixel_moments[:, 0]
    var0 = target.pixel_moments[:, 1]
    flat = x.reshape(c, -1)
    centred = (flat - flat.mean(axis=1, keepdims=True)).T
    # the product comes out column-major: one copy to rows makes every channel's steps below,
    # and the final reshape, work on contiguous data (1 ms of a 256x256 colour image; same bytes)
    flat = np.ascontiguousarray(adjust_correlation(centred, target.colour_covariance).T + mean0[:, None])

    def run(channels: slice) -> None:
        for ci in range(channels.start, channels.stop):
            if var0[ci] > 0:
                flat[ci] = impose_skewness(flat[ci], target.pixel_moments[ci, 2])
                flat[ci] = impose_kurtosis(flat[ci], target.pixel_moments[ci, 3])

    for_each_band(run, c, flat.shape[1])  # channel by channel
    flat = np.clip(flat, target.pixel_range[:, :1], target.pixel_range[:, 1:])
    return flat.reshape(x.shape)
