"""Portilla-Simoncelli: the optimised iteration gives the same bytes as the plain one.

Issue 20 rewrote the synthesis loop for speed (rows of the regressions filled in place,
band-by-band chains, FFT passes on the non-zero lines only, polynomial arithmetic on
coefficient arrays, threads). This file keeps the loop as it was before, written with plain
NumPy and ``numpy.polynomial``, and checks that the optimised loop gives the same bytes, with
and without threads (``docs/methods/portilla_simoncelli.md``, "Performance"). Its single-precision step moved
the parents and the magnitude step to single precision: the plain loop does the same by
default, and its ``single=False`` form (double precision, as before) stays within a stated
tolerance of the optimised loop. Its half-spectrum step computed four steps differently (the
skewness and kurtosis steps from power sums, the auto-correlation values and filter gains by
cosine products, the finest scale's and the image's reconstruction from half spectra): the
plain loop keeps their previous forms (``previous=True``, within a stated tolerance of the
optimised loop) and otherwise calls the library's new steps, each of which is checked here
against its previous form or against the full transforms.
"""

import functools
import os

import numpy as np
import pytest
import scipy.fft as sfft

import texsyn
from texsyn.methods.portilla_simoncelli import project_statistics
from texsyn.models import portilla_moments as moments
from texsyn.models import portilla_projections as projections
from texsyn.ops import linalg
from texsyn.transforms import complex_steerable
from texsyn.transforms.complex_steerable import ComplexSteerablePyramid
from texsyn.transforms.steerable import crop_indices, oriented_windows, radial_lowpass

# --------------------------------------------------------------------------- reference loop
# The synthesis iteration of texsyn 0.x before issue 20, function by function.


def _fft(pyramid, x):
    x = np.asarray(x)
    dtype = np.result_type(pyramid.real_dtype, np.complex64) if np.iscomplexobj(x) else pyramid.real_dtype
    return sfft.fft2(x.astype(dtype, copy=False))


def _resize(spec, size_from, size_to, dtype=complex):
    scale = (size_to[0] * size_to[1]) / (size_from[0] * size_from[1])
    if size_to[0] <= size_from[0]:
        rows = crop_indices(size_from[0], size_to[0])
        cols = crop_indices(size_from[1], size_to[1])
        return spec[..., rows[:, None], cols[None, :]] * scale
    rows = crop_indices(size_to[0], size_from[0])
    cols = crop_indices(size_to[1], size_from[1])
    out = np.zeros(spec.shape[:-2] + tuple(size_to), dtype=dtype)
    out[..., rows[:, None], cols[None, :]] = spec * scale
    return out


def _forward(pyramid, x):
    spec = _fft(pyramid, np.asarray(x, dtype=np.float64))
    highpass = sfft.ifft2(spec * pyramid.hi0).real
    low = spec * pyramid.lo0
    bands, spectra = [], []
    for s in range(pyramid.n_scales):
        spectra.append(low[:, None] * pyramid.analytic_filters[s])
        bands.append(sfft.ifft2(spectra[-1]))
        low = _resize(low * pyramid.lo[s], pyramid.sizes[s], pyramid.sizes[s + 1])
    return highpass, bands, sfft.ifft2(low).real, spectra, spec * pyramid.hi0


def _reconstruct_level(pyramid, coarser, level, real_spectra, single, previous=True):
    if not previous:  # the half spectrum (rfft2) of the partially reconstructed image
        return pyramid.reconstruct_level_half(coarser, real_spectra, level)
    # single-precision step: zero-padded in its single precision (before: double)
    coarse = _fft(pyramid, coarser)
    dtype = coarse.dtype if single else complex
    spec = _resize(coarse, pyramid.sizes[level + 1], pyramid.sizes[level], dtype)
    spec = spec + np.sum(real_spectra * np.conj(pyramid.real_filters[level]), axis=-3)
    return sfft.ifft2(spec * pyramid.mid[level]).real


def _autocorrelation(x, target):
    x = np.asarray(x, dtype=np.float64)
    h, w = x.shape[-2:]
    lag = (target.shape[-1] - 1) // 2
    if lag == 0:
        cur = np.mean(x**2, axis=(-2, -1), keepdims=True)
        return x * np.sqrt(target[..., :1, :1] / np.where(cur > 0, cur, 1.0))
    spec = sfft.rfft2(x.astype(np.float32))
    cx = sfft.irfft2(spec.real**2 + spec.imag**2, s=(h, w)).astype(np.float64) / (h * w)
    half = np.array([(i, j) for i in range(-lag, lag + 1) for j in range(-lag, lag + 1) if (i, j) >= (0, 0)])
    diff = half[:, None, :] - half[None, :, :]
    summ = half[:, None, :] + half[None, :, :]
    nonzero = np.any(half != 0, axis=1)
    a = cx[..., diff[..., 0] % h, diff[..., 1] % w]
    a = a + np.where(nonzero[None, :], cx[..., summ[..., 0] % h, summ[..., 1] % w], 0.0)
    b = target[..., half[:, 0] + lag, half[:, 1] + lag]
    coef = np.linalg.solve(a, b[..., None])[..., 0]
    ch = np.zeros(x.shape)
    ch[..., half[:, 0] % h, half[:, 1] % w] = coef
    ch[..., -half[:, 0] % h, -half[:, 1] % w] = coef
    gain = np.sqrt(np.abs(sfft.rfft2(ch.astype(np.float32)).real))
    return sfft.irfft2(spec * gain, s=(h, w)).astype(np.float64)


def _monotone_interval(num, den, power):
    num, den = np.polynomial.Polynomial(num), np.polynomial.Polynomial(den)
    roots = (num.deriv() * den - (power / 2.0) * num * den.deriv()).roots()
    real = roots[np.abs(roots.imag) < 1e-6 * np.maximum(1.0, np.abs(roots.real))].real
    below, above = real[real < 0], real[real > 0]
    return (below.max() if below.size else -np.inf), (above.min() if above.size else np.inf)


def _solve_lambda(coeffs_num, coeffs_den, target, power):
    num, den = np.polynomial.Polynomial(coeffs_num), np.polynomial.Polynomial(coeffs_den)
    poly = num**2 - target**2 * den**3 if power == 3 else num - target * den**2
    roots = poly.roots()
    real = roots[np.abs(roots.imag) < 1e-6 * np.maximum(1.0, np.abs(roots.real))].real
    if power == 3:
        real = real[np.sign(num(real)) == np.sign(target)] if target != 0 else real
    low, high = _monotone_interval(coeffs_num, coeffs_den, power)
    real = real[(real >= low) & (real <= high)]
    if real.size:
        return real[np.argmin(np.abs(real))]
    ends = np.array([end for end in (low, high) if np.isfinite(end)])
    if ends.size == 0:
        return None
    return ends[np.argmin(np.abs(num(ends) / den(ends) ** (power / 2.0) - target))]


def _skewness(x, target):
    mean = x.mean()
    d = (x - mean).ravel()
    d2 = d * d
    m2 = d2.mean()
    if moments.is_flat(m2, mean):
        return x
    m3 = np.dot(d2, d) / d.size
    g = d2 - (m3 / m2) * d - m2
    g2 = g * g
    num = [m3, 3 * np.dot(d2, g) / d.size, 3 * np.dot(d, g2) / d.size, np.dot(g2, g) / d.size]
    den = [m2, 2 * np.dot(d, g) / d.size, g2.mean()]
    lam = _solve_lambda(num, den, target, 3)
    y = d + lam * g
    y *= np.sqrt(m2 / np.mean(y * y))
    return (y + mean).reshape(x.shape)


def _kurtosis(x, target):
    mean = x.mean()
    d = (x - mean).ravel()
    n = d.size
    d2 = d * d
    d3 = d2 * d
    m = [1.0, 0.0, d2.mean(), d3.mean(), np.dot(d2, d2) / n, np.dot(d3, d2) / n, np.dot(d3, d3) / n]
    if moments.is_flat(m[2], mean):
        return x
    gram = np.array([[m[i + j] for j in range(3)] for i in range(3)])
    coef = np.linalg.solve(gram, np.array([m[3], m[4], m[5]]))
    g = d3 - coef[0] - coef[1] * d - coef[2] * d2
    g2 = g * g
    num = [m[4], 4 * np.dot(d3, g) / n, 6 * np.dot(d2, g2) / n, 4 * np.dot(d, g2 * g) / n, np.dot(g2, g2) / n]
    den = [m[2], 2 * np.dot(d, g) / n, g2.mean()]
    lam = _solve_lambda(num, den, target, 4)
    y = d + lam * g
    y -= y.mean()
    y *= np.sqrt(m[2] / np.mean(y * y))
    return (y + mean).reshape(x.shape)


def _steps(previous):
    """The skewness, kurtosis and auto-correlation steps: their plain forms above as they were
    before the power sums and cosine products (``previous``), or the library's."""
    if previous:
        return _skewness, _kurtosis, _autocorrelation
    return (
        moments.impose_skewness,
        moments.impose_kurtosis,
        _one_at_a_time(projections.impose_autocorrelation),
    )


def _one_at_a_time(step):
    """``step`` on each image of a stack alone: never shared between two threads, the
    reference of the shared halves (``complex_steerable.shared_stack``)."""

    def run(images, target):
        flat = images.reshape((-1,) + images.shape[-2:])
        targets = np.broadcast_to(target, images.shape[:-2] + target.shape[-2:]).reshape(
            (-1,) + target.shape[-2:]
        )
        return np.stack([step(image, window) for image, window in zip(flat, targets)]).reshape(images.shape)

    return run


def _lowpass(images, autocorr, skew_kurt, pixel_var, lags, previous=True, shape=None):
    """``previous=False``: ``images`` are the half spectra (rfft2) of images of size ``shape``."""
    skewness, kurtosis, autocorrelation = _steps(previous)
    shape = images.shape[-2:] if previous else shape
    window = projections.fit_window(autocorr, shape, lags)
    centre = (window.shape[-1] - 1) // 2
    target_var = window[:, centre, centre]
    active = target_var / np.maximum(pixel_var, 1e-300) > 1e-4
    if not previous and centre > 0 and active.all():  # the filter from the spectrum
        out = projections.filter_autocorrelation_spectrum(images, window, shape).astype(np.float64)
    else:
        if not previous:
            images = sfft.irfft2(images, s=shape)
        out = np.array(images, dtype=np.float64)
        if active.any():
            out[active] = autocorrelation(out[active], window[active])
    for c in range(out.shape[0]):
        if active[c]:
            out[c] = kurtosis(skewness(out[c], skew_kurt[c, 0]), skew_kurt[c, 1])
        else:
            current = np.mean((out[c] - out[c].mean()) ** 2)
            if current > 0:
                out[c] *= np.sqrt(target_var[c] / current)
    return out


def _cross_correlation(x, target, y, target_xy):
    n, k = x.shape
    rows = np.concatenate([x.T, y.T], axis=0)
    gram = (rows @ rows.T).astype(np.float64) / n
    bxx, bxy, byy = gram[:k, :k], gram[:k, k:], gram[k:, k:]
    ibyy = np.linalg.pinv(byy)
    regression = ibyy @ bxy.T
    current = bxx - bxy @ regression
    desired = target - target_xy @ ibyy @ target_xy.T
    m = projections._sqrtm(current, inverse=True) @ projections._sqrtm(desired)
    mix = (ibyy @ target_xy.T - regression @ m).T
    return (m.T.astype(rows.dtype) @ rows[:k] + mix.astype(rows.dtype) @ rows[k:]).T


def _magnitudes(band, target, level, parent_magnitudes, lags, single, previous=True):
    c, k = band.shape[:2]
    n = band.shape[-1] * band.shape[-2]
    current = np.abs(band)
    mags = current - current.mean(axis=(-2, -1), keepdims=True)
    m = mags.reshape(c * k, n).T
    if parent_magnitudes is None:
        m = projections.adjust_correlation(m, target.magnitude_cross[level])
    else:
        m = _cross_correlation(
            m, target.magnitude_cross[level], parent_magnitudes, target.magnitude_parent[level]
        )
    mags = m.T.reshape(mags.shape)
    window = projections.fit_window(target.magnitude_autocorr[level], mags.shape[-2:], lags)
    mags = _steps(previous)[2](mags, window)
    means = target.magnitude_means[level][..., None, None]
    if single:  # single-precision step: the new magnitudes in single precision
        mags, means = mags.astype(np.float32), means.astype(np.float32)
    magnitude = np.maximum(mags + means, 0.0)
    return band * (magnitude / np.where(current > 0, current, 1.0))


def _parent_regression(reals, parents, target_xp):
    n, k = reals.shape
    rows = np.concatenate([reals.T, parents.T], axis=0).astype(np.float32)
    gram = (rows @ rows.T).astype(np.float64) / n
    own = np.diag(gram)[:k]
    cross = gram[k:, :k]
    ibyy = np.linalg.pinv(gram[k:, k:])
    regression = ibyy @ cross
    fit = ibyy @ target_xp.T
    current = own - np.einsum("mk,mk->k", cross, regression)
    desired = np.maximum(own - np.einsum("km,mk->k", target_xp, fit), 0.0)
    scale = np.sqrt(desired / np.where(current > 0, current, 1.0))
    mix = (fit - regression * scale).T.astype(np.float32)
    return (rows[:k] * scale[:, None].astype(np.float32) + mix @ rows[k:]).T.astype(np.float64)


def _parents(pyramid, spectra, level, single):
    # single-precision step: the parents in the spectra's single precision (before: double precision)
    dtype = spectra[level + 1].dtype if single else complex
    up = sfft.ifft2(_resize(spectra[level + 1], pyramid.sizes[level + 1], pyramid.sizes[level], dtype))
    re, im = up.real, up.imag
    doubled = np.empty(up.shape, dtype=complex)
    if single:  # single-precision step: -conj(p)^2 / |p|
        size = np.abs(up)
        safe = np.where(size > 0, size, 1.0)
        square = np.square(up)
        doubled.real = -np.where(size > 0, square.real / safe, 0.0)
        doubled.imag = np.where(size > 0, square.imag / safe, 0.0)
    else:
        size = np.sqrt(re * re + im * im)
        inv = np.divide(1.0, size, out=np.zeros_like(size), where=size > 0)
        doubled.real = (im * im - re * re) * inv
        doubled.imag = 2.0 * re * im * inv
    c, k = up.shape[:2]
    mags = np.abs(up)
    mags = mags - mags.mean(axis=(-2, -1), keepdims=True)
    reals = np.concatenate([doubled.real, doubled.imag], axis=1)
    return mags.reshape(c * k, -1).T, reals.reshape(2 * c * k, -1).T


def _pixels(x, target, previous=True):
    skewness, kurtosis, _ = _steps(previous)
    c = x.shape[0]
    flat = x.reshape(c, -1)
    centred = (flat - flat.mean(axis=1, keepdims=True)).T
    flat = (
        projections.adjust_correlation(centred, target.colour_covariance).T + target.pixel_moments[:, 0, None]
    )
    for ci in range(c):
        if target.pixel_moments[ci, 1] > 0:
            flat[ci] = skewness(flat[ci], target.pixel_moments[ci, 2])
            flat[ci] = kurtosis(flat[ci], target.pixel_moments[ci, 3])
    return np.clip(flat, target.pixel_range[:, :1], target.pixel_range[:, 1:]).reshape(x.shape)


def _reference_iteration(x, target, pyramid, lags, single=True, previous=False):
    """One iteration of the plain loop; ``single=False``: the parents, the magnitude step and the
    partial reconstructions in double precision and the high-pass residual transformed back
    and forth, as before issue 20's single-precision step (and ``previous`` with it); ``previous=True``: the moment
    and auto-correlation steps and the full-spectrum reconstructions as before their power
    sums, cosine products and half spectra."""
    previous = previous or not single
    n_scales = pyramid.n_scales
    pixel_var = target.pixel_moments[:, 1]
    highpass, bands, residual, spectra, hp_spec = _forward(pyramid, x)
    residual = residual - residual.mean(axis=(-2, -1), keepdims=True)
    if previous:
        image = sfft.ifft2(_fft(pyramid, residual) * pyramid.mid[-1]).real
    else:  # its half spectrum
        image = sfft.rfft2(residual.astype(np.float32)) * pyramid.mid[-1][..., : residual.shape[-1] // 2 + 1]
    image = _lowpass(
        image,
        target.low_autocorr[n_scales],
        target.low_skew_kurt[:, n_scales],
        pixel_var,
        lags,
        previous,
        pyramid.sizes[n_scales],
    )
    for s in range(n_scales - 1, -1, -1):
        parent_mags = parent_reals = None
        if s < n_scales - 1:
            parent_mags, parent_reals = _parents(pyramid, spectra, s, single)
        band = _magnitudes(bands[s], target, s, parent_mags, lags, single, previous)
        if s < n_scales - 1:
            c, k = band.shape[:2]
            n = band.shape[-1] * band.shape[-2]
            real = _parent_regression(band.real.reshape(c * k, n).T, parent_reals, target.real_parent[s])
            real = real.T.reshape(band.shape)
        else:
            real = band.real
        if s == 0 and not previous:  # the finest scale's half spectra
            real_spectra = sfft.rfft2(real.astype(pyramid.real_dtype))
        else:
            real_spectra = _fft(pyramid, real)
            spectra[s] = real_spectra * pyramid.half_planes[s]
        image = _reconstruct_level(pyramid, image, s, real_spectra, single, previous)
        image = _lowpass(
            image,
            target.low_autocorr[s],
            target.low_skew_kurt[:, s],
            pixel_var,
            lags,
            previous,
            pyramid.sizes[s],
        )
    wanted = target.highpass_variance
    if single:  # single-precision step: the residual kept as its spectrum, its variance by Parseval
        power = np.square(hp_spec.real) + np.square(hp_spec.imag)
        hp_var = (
            np.sum(power, axis=(-2, -1), dtype=np.float64) / float(hp_spec.shape[-1] * hp_spec.shape[-2]) ** 2
        )
    else:
        hp_var = np.mean(highpass**2, axis=(-2, -1))
    shrink = np.where(hp_var > wanted, np.sqrt(wanted / np.where(hp_var > 0, hp_var, 1.0)), 1.0)
    if not previous:  # half spectra
        half = hp_spec.shape[-1] // 2 + 1
        gain = shrink.astype(np.float32)[:, None, None] * pyramid.hi0[:, :half]
        spec = sfft.rfft2(image.astype(np.float32)) + hp_spec[..., :half] * gain
        return _pixels(sfft.irfft2(spec, s=hp_spec.shape[-2:]), target, previous)
    if single:
        gain = shrink.astype(np.float32)[:, None, None] * pyramid.hi0
        spec = _fft(pyramid, image) + hp_spec * gain
    else:
        spec = _fft(pyramid, image) + _fft(pyramid, highpass * shrink[:, None, None]) * pyramid.hi0
    return _pixels(sfft.ifft2(spec).real, target, previous)


# --------------------------------------------------------------------------- tests


@functools.cache
def _fitted(colour: str):
    rng = np.random.default_rng(3)
    exemplar = texsyn.data.exemplar("gravel", size=64).astype(np.float64)
    if colour == "rgb":
        exemplar = np.clip(np.stack([exemplar, exemplar**1.5, 1 - exemplar], axis=-1), 0, 1)
    exemplar = np.clip(exemplar + 0.02 * rng.standard_normal(exemplar.shape), 0, 1)
    return texsyn.make_method("portilla_simoncelli", n_scales=3, colour=colour).fit(exemplar)


@pytest.mark.parametrize("colour", ["grey", "rgb"])
@pytest.mark.parametrize("shape", [(128, 128), (72, 90)])
@pytest.mark.parametrize("cpus", [1, 3])
def test_the_iteration_gives_the_plain_loops_bytes(colour, shape, cpus, monkeypatch):
    # 128x128 bands go one by one (for_each_band), 72x90 all at once, with odd band sizes;
    # the larger FFTs use ``cpus`` threads, and with more than one CPU the 128x128 stacks
    # are shared between two threads (shared_stack)
    monkeypatch.setattr(complex_steerable, "worker_count", lambda: cpus)
    monkeypatch.setattr(complex_steerable, "_THREADED_FFT", 1 << 12)
    monkeypatch.setattr(complex_steerable, "_THREADED_FFT_REALTIME", 1 << 12)
    monkeypatch.setattr(complex_steerable, "_SHARED_VALUES", 1 << 15)
    model = _fitted(colour)
    target = model.statistics_
    pyramid = ComplexSteerablePyramid(shape, target.n_scales, target.n_orientations, single=True)
    rng = np.random.default_rng(0)
    moments = target.pixel_moments
    x = moments[:, 0, None, None] + np.sqrt(moments[:, 1])[:, None, None] * rng.standard_normal(
        (moments.shape[0],) + shape
    )
    fast, plain, workspace = x, x, {}
    for _ in range(2):
        fast = project_statistics(fast, target, pyramid, model.lags, workspace=workspace)
        plain = _reference_iteration(plain, target, pyramid, model.lags)
        assert fast.dtype == plain.dtype and fast.tobytes() == plain.tobytes()


@pytest.mark.parametrize("colour", ["grey", "rgb"])
@pytest.mark.parametrize("shape", [(128, 128), (72, 90)])
def test_single_precision_steps_stay_close_to_double_precision(colour, shape):
    # issue 20's single-precision step computes the parents, the magnitude step and the partial reconstructions in
    # single precision (the loop above); before, in double precision (``single=False``). One iteration from the
    # same image: at most 4e-3 apart (one 8-bit level), 1e-3 on average (a quarter of one);
    # measured 7e-4-2.2e-3 and 1-4e-4 (docs/methods/portilla_simoncelli.md, "Performance")
    model = _fitted(colour)
    target = model.statistics_
    pyramid = ComplexSteerablePyramid(shape, target.n_scales, target.n_orientations, single=True)
    rng = np.random.default_rng(0)
    moments = target.pixel_moments
    x = moments[:, 0, None, None] + np.sqrt(moments[:, 1])[:, None, None] * rng.standard_normal(
        (moments.shape[0],) + shape
    )
    fast = project_statistics(x, target, pyramid, model.lags)
    double = _reference_iteration(x, target, pyramid, model.lags, single=False)
    assert np.abs(fast - double).max() < 4e-3
    assert np.abs(fast - double).mean() < 1e-3


def test_the_step_solver_gives_numpy_polynomials_bits():
    rng = np.random.default_rng(1)
    cases = 0
    for _ in range(600):
        power = int(rng.choice([3, 4]))
        num = list(rng.standard_normal(power + 1) * 10.0 ** rng.uniform(-3, 3, power + 1))
        den = [abs(rng.standard_normal()) + 1e-3, rng.standard_normal(), abs(rng.standard_normal())]
        if rng.random() < 0.1:
            num[-1] = 0.0  # a zero leading coefficient is trimmed
        if rng.random() < 0.1:
            den[-1] = 0.0
        target = np.float64(rng.standard_normal() * 3)
        with np.errstate(all="ignore"):
            fast = moments._solve_lambda(num, den, target, power)
            plain = _solve_lambda(num, den, target, power)
            interval = moments._monotone_interval(num, den, power)
        if plain is None:
            assert fast is None
            continue
        cases += 1
        assert np.asarray(fast).tobytes() == np.asarray(plain).tobytes()
        assert np.array(interval).tobytes() == np.array(_monotone_interval(num, den, power)).tobytes()
    assert cases > 500


@pytest.mark.parametrize("single", [True, False])
@pytest.mark.parametrize("workers", [1, 2])
def test_the_filters_made_in_row_blocks_are_the_whole_grids(single, workers, monkeypatch):
    # the pyramid computes its filters in blocks of rows on texsyn's threads: odd sizes,
    # blocks of a few rows (several per level), the bytes of the formulas on the whole grid
    monkeypatch.setattr(linalg, "worker_count", lambda: workers)
    monkeypatch.setattr(complex_steerable, "_FILTER_BLOCK", 1 << 8)
    k = 3
    pyramid = ComplexSteerablePyramid((45, 70), 3, k, single=single)
    rd, cd = pyramid.real_dtype, np.result_type(pyramid.real_dtype, np.complex64)
    for level, size in enumerate(pyramid.sizes[:-1]):
        r, theta = ComplexSteerablePyramid._polar(size)
        lo = radial_lowpass(r)
        reals = oriented_windows(theta, np.sqrt(np.maximum(1.0 - lo**2, 0.0)), k)
        c = np.cos(theta[None] - (np.pi * np.arange(k) / k)[:, None, None])
        halves = np.where(c > 1e-12, 2.0, np.where(c < -1e-12, 0.0, 1.0))
        halves[:, 0, 0] = 1.0
        expected = {
            "lo": lo.astype(rd),
            "real_filters": reals.astype(cd),
            "conj_real_filters": np.conj(reals.astype(cd)),
            "analytic_filters": (reals * halves).astype(cd),
            "half_planes": halves.astype(rd),
        }
        for name, value in expected.items():
            made = getattr(pyramid, name)[level]
            assert made.dtype == value.dtype and made.tobytes() == value.tobytes(), (name, level)
        if level == 0:
            lo0 = radial_lowpass(r / 2.0)
            hi0 = np.sqrt(np.maximum(1.0 - lo0**2, 0.0))
            assert pyramid.lo0.tobytes() == lo0.astype(rd).tobytes()
            assert pyramid.hi0.tobytes() == hi0.astype(rd).tobytes()


@pytest.mark.parametrize("shape", [(64, 64), (45, 70), (131, 262)])
def test_the_fft_shortcuts_give_the_full_transforms_bytes(shape):
    # 131 and 262 use pocketfft's Bluestein plans, which scale inside the transform too
    rng = np.random.default_rng(2)
    pyramid = ComplexSteerablePyramid(shape, 2, 4, single=True)
    (hc, wc), (h, w) = pyramid.sizes[1], pyramid.sizes[0]
    spec = (rng.standard_normal((2, 4, hc, wc)) + 1j * rng.standard_normal((2, 4, hc, wc))).astype(
        np.complex64
    )
    spec[:, 1] = 0.0  # a zero band: the signs of the zeros count too
    plain = sfft.ifft2(_resize(spec, (hc, wc), (h, w), spec.dtype))
    assert pyramid.upsampled_ifft(spec, 0).tobytes() == plain.tobytes()
    wide = spec.astype(complex)  # double precision (the exemplar's statistics)
    plain = sfft.ifft2(_resize(wide, (hc, wc), (h, w)))
    assert pyramid.upsampled_ifft(wide, 0).tobytes() == plain.tobytes()
    assert (
        pyramid.resize_spectrum(spec, (hc, wc), (h, w)).tobytes()
        == _resize(spec, (hc, wc), (h, w), spec.dtype).tobytes()
    )
    assert (
        pyramid.resize_spectrum(wide, (hc, wc), (h, w)).tobytes() == _resize(wide, (hc, wc), (h, w)).tobytes()
    )
    full = (rng.standard_normal((2, 4, h, w)) + 1j * rng.standard_normal((2, 4, h, w))).astype(np.complex64)
    assert (
        pyramid.resize_spectrum(full, (h, w), (hc, wc)).tobytes() == _resize(full, (h, w), (hc, wc)).tobytes()
    )
    x = rng.standard_normal((3, h, w))
    window = rng.standard_normal((3, 7, 7))
    window = window + window[:, ::-1, ::-1]
    window[:, 3, 3] += 40.0
    # the auto-correlation values and filter gains by cosine products: within single-precision
    # rounding of the transforms (measured 2e-7 of the largest value)
    fast, plain = projections.impose_autocorrelation(x, window), _autocorrelation(x, window)
    assert np.abs(fast - plain).max() <= 2e-6 * np.abs(plain).max()


@pytest.mark.parametrize("colour", ["grey", "rgb"])
@pytest.mark.parametrize("shape", [(128, 128), (72, 90)])
def test_the_power_sums_cosine_products_and_half_spectra_stay_close_to_the_previous_steps(colour, shape):
    # one iteration from the same image with the moment steps, auto-correlation filters and
    # reconstructions of before (``previous=True``): at most 4e-3 apart (one 8-bit level),
    # 1e-3 on average; measured 4e-4-2e-3 and 5e-5-4e-4 (docs/methods/portilla_simoncelli.md,
    # "Performance")
    model = _fitted(colour)
    target = model.statistics_
    pyramid = ComplexSteerablePyramid(shape, target.n_scales, target.n_orientations, single=True)
    rng = np.random.default_rng(0)
    moments_ = target.pixel_moments
    x = moments_[:, 0, None, None] + np.sqrt(moments_[:, 1])[:, None, None] * rng.standard_normal(
        (moments_.shape[0],) + shape
    )
    fast = project_statistics(x, target, pyramid, model.lags)
    previous = _reference_iteration(x, target, pyramid, model.lags, previous=True)
    assert np.abs(fast - previous).max() < 4e-3
    assert np.abs(fast - previous).mean() < 1e-3


def test_the_moment_steps_from_power_sums_match_the_direct_ones():
    # the skewness and kurtosis steps from power sums against their direct forms: within
    # 1e-9 of the standard deviation (measured 1.5e-10 on heavy tails, kurtosis 18 000)
    rng = np.random.default_rng(4)
    for n in (16, 256):
        cases = [
            rng.standard_normal((n, n)),
            rng.standard_normal((n, n)) ** 3 * 0.1 + 0.5,
            np.exp(2 * rng.standard_normal((n, n))) * 1e-3,
            rng.random((n, n)) * 1e-4 + 3.0,
        ]
        for x in cases:
            scale = x.std()
            for target in (0.3, -0.5, 2.0):
                assert np.abs(moments.impose_skewness(x, target) - _skewness(x, target)).max() < 1e-9 * scale
            for target in (2.5, 4.0, 10.0):
                assert np.abs(moments.impose_kurtosis(x, target) - _kurtosis(x, target)).max() < 1e-9 * scale


@pytest.mark.parametrize("shape", [(64, 64), (45, 70), (66, 37), (32, 48)])
def test_the_half_spectra_give_the_full_spectra_images(shape):
    # zero-padding a half spectrum (even sizes: the Nyquist row and column split in two)
    # and reconstructing from half spectra: the same images as the full spectra, to rounding
    rng = np.random.default_rng(5)
    for single, tol in ((False, 1e-12), (True, 3e-6)):
        pyramid = ComplexSteerablePyramid(shape, 2, 4, single=single)
        (hc, wc), (h, w) = pyramid.sizes[1], pyramid.sizes[0]
        coarse = rng.standard_normal((3, hc, wc))
        full = pyramid.ifft(pyramid.resize_spectrum(pyramid.fft(coarse), (hc, wc), (h, w))).real
        half = sfft.irfft2(pyramid.upsampled_half(pyramid.rfft(coarse), 0), s=(h, w))
        assert np.abs(full - half).max() < tol
        bands = rng.standard_normal((3, 4, h, w))
        full = pyramid.reconstruct_level(coarse, bands, 0)
        half = pyramid.irfft(pyramid.reconstruct_level_half(coarse, pyramid.rfft(bands)))
        assert np.abs(full - half).max() < tol
        coarser = rng.standard_normal((3,) + pyramid.sizes[2])
        bands = rng.standard_normal((3, 4, hc, wc))
        full = pyramid.reconstruct_level(coarser, bands, 1)
        half = pyramid.irfft(pyramid.reconstruct_level_half(coarser, pyramid.fft(bands), 1), 1)
        assert np.abs(full - half).max() < tol
        residual = rng.standard_normal((3,) + pyramid.sizes[2])
        full = pyramid.lowpass_image(residual)
        assert np.abs(full - pyramid.irfft(pyramid.lowpass_half(residual), 2)).max() < tol
        low, gain = rng.standard_normal((3, h, w)), np.array([0.5, 1.0, 0.8])
        residual = pyramid.fft(rng.standard_normal((3, h, w))) * pyramid.hi0
        full = pyramid.reconstruct_spectrum(low, residual, gain)
        half = pyramid.reconstruct_spectrum_half(low, residual, gain)
        assert np.abs(full - half).max() < tol


@pytest.mark.parametrize("realtime", [False, True])
def test_fft_threads_start_at_the_threshold_of_the_scheduling_policy(realtime, monkeypatch):
    # under the default policy a woken pocketfft thread costs more than it saves on a
    # 256x256 level; under a real-time one (``chrt``) it starts at once
    monkeypatch.setattr(complex_steerable, "worker_count", lambda: 2)
    monkeypatch.setattr(complex_steerable, "_realtime_thread", lambda: realtime)
    level = 12 * 256 * 256  # a 256x256 level's twelve colour bands
    assert complex_steerable.fft_workers(level) == (2 if realtime else 1)
    assert complex_steerable.fft_workers(12 * 512 * 512) == 2
    assert complex_steerable.fft_workers(1 << 16) == 1


def test_the_calling_threads_policy_is_read():
    assert complex_steerable._realtime_thread() == (os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR))


def _filters(pyramid):
    arrays = [pyramid.lo0, pyramid.hi0]
    for name in ("lo", "real_filters", "conj_real_filters", "analytic_filters", "half_planes", "mid"):
        arrays += list(getattr(pyramid, name))
    return arrays


@pytest.mark.parametrize("shape", [(64, 64), (72, 90), (256, 256), (257, 255)])
@pytest.mark.parametrize("orientations", [3, 4, 6])
def test_the_synthesis_pyramids_filters_are_those_of_the_plain_power(shape, orientations, monkeypatch):
    # the single-precision pyramid raises the cosines' absolute values to the power
    # (oriented_windows(single=True)); rounded to single precision, the same bytes
    fast = _filters(ComplexSteerablePyramid(shape, 3, orientations, single=True))
    plain = functools.partial(oriented_windows, single=False)
    monkeypatch.setattr(complex_steerable, "oriented_windows", lambda t, h, k, single: plain(t, h, k))
    reference = _filters(ComplexSteerablePyramid(shape, 3, orientations, single=True))
    assert all(a.dtype == b.dtype and a.tobytes() == b.tobytes() for a, b in zip(fast, reference))
    # in double precision the two powers agree to within a unit in the last place
    theta = np.linspace(-np.pi, np.pi, 4001)
    exact = oriented_windows(theta, np.ones_like(theta), orientations)
    quick = oriented_windows(theta, np.ones_like(theta), orientations, single=True)
    assert np.allclose(quick, exact, rtol=4e-16, atol=0)


def test_the_single_precision_windows_round_as_the_plain_powers_where_a_unit_matters():
    # a highpass chosen so that the plain filters' values sit on single-precision rounding
    # midpoints, where a unit of double precision in the power changes the rounding
    k = 4
    theta = np.linspace(-np.pi, np.pi, 20001)
    plain = oriented_windows(theta, np.ones_like(theta), k)
    quick = oriented_windows(theta, np.ones_like(theta), k, single=True)
    band, at = np.nonzero(plain != quick)
    if at.size == 0:
        pytest.skip("this NumPy's power of a negative number is that of its absolute value")
    f = np.float32(0.5) + np.float32(2.0**-24) * np.arange(at.size, dtype=np.float32)
    midpoints = f.astype(np.float64) + np.spacing(f).astype(np.float64) / 2
    highpass = midpoints / np.abs(plain[band, at])
    expected = oriented_windows(theta[at], highpass, k).astype(np.complex64)
    got = oriented_windows(theta[at], highpass, k, single=True).astype(np.complex64)
    assert got.tobytes() == expected.tobytes()


def test_the_solvers_sign_roots_and_eigenvalues_are_numpys():
    for x in (0.0, -0.0, 1.5, -2.0, np.inf, -np.inf, np.nan, 5e-324, -5e-324):
        assert np.asarray(moments._sign(x)).tobytes() == np.sign(np.float64(x)).tobytes()
    rng = np.random.default_rng(7)
    for degree in (2, 3, 4, 6):
        for _ in range(20):
            c = rng.standard_normal(degree + 1)
            expected = np.polynomial.polynomial.polyroots(c)
            got = moments._poly_roots(c)
            assert got.dtype == expected.dtype and got.tobytes() == expected.tobytes()  # sorted
            matrix = rng.standard_normal((degree, degree))
            expected = np.linalg.eigvals(matrix)
            got = moments._eigenvalues(matrix)
            assert got.dtype == expected.dtype and got.tobytes() == expected.tobytes()
    for bad in (np.nan, np.inf):
        matrix = rng.standard_normal((3, 3))
        matrix[1, 2] = bad
        with pytest.raises(np.linalg.LinAlgError):
            moments._eigenvalues(matrix)


def test_a_stack_is_shared_where_it_is_large_enough(monkeypatch):
    # the rule: bands of 2^14 pixels or more, 2^18 values or more in all, more than one CPU
    monkeypatch.setattr(complex_steerable, "worker_count", lambda: 2)
    shared = complex_steerable.shared_stack
    assert shared(4, 256 * 256) and shared(12, 256 * 256) and shared(12, 512 * 512)
    assert not shared(12, 128 * 128)  # a 128x128 colour level: the hand-overs cost what they save
    assert not shared(4, 128 * 128) and not shared(64, 64 * 64) and not shared(1, 1 << 20)
    monkeypatch.setattr(complex_steerable, "worker_count", lambda: 1)
    assert not shared(12, 512 * 512)


@pytest.mark.parametrize("cpus", [1, 2])
def test_the_iterations_stacks_go_in_two_halves_on_more_than_one_cpu(cpus, monkeypatch):
    # the forward bands, their parents, magnitudes, real parts and transforms, and the
    # magnitudes' auto-correlation filter of the 128x128 colour level (lowered threshold)
    model = _fitted("rgb")
    target = model.statistics_
    pyramid = ComplexSteerablePyramid((128, 128), target.n_scales, target.n_orientations, single=True)
    monkeypatch.setattr(complex_steerable, "worker_count", lambda: cpus)
    monkeypatch.setattr(complex_steerable, "_SHARED_VALUES", 1 << 16)  # 12 bands, not 3 channels
    halves: list = []
    share = complex_steerable.parallel_map

    def recorded(function, items):
        halves.append(
            (function.__qualname__.split(".<locals>")[0], [(item.start, item.stop) for item in items])
        )
        return share(function, items)

    monkeypatch.setattr(complex_steerable, "parallel_map", recorded)
    x = np.random.default_rng(0).standard_normal((3, 128, 128)) + 0.5
    project_statistics(x, target, pyramid, model.lags, workspace={})
    if cpus == 1:
        assert halves == []
    else:
        assert all(items == [(0, 6), (6, 12)] for _, items in halves)  # the channels' steps stay whole
        assert {name for name, _ in halves} == {
            "ComplexSteerablePyramid._bands",
            "parent_rows",
            "centred_magnitudes",
            "filter_autocorrelation",
            "magnitude_real_parts",
            "_stack_transform",
        }


@pytest.mark.parametrize("seed", [1, 2])
def test_a_band_of_zeros_gives_the_same_bytes_on_one_and_two_cpus(seed, monkeypatch):
    # a constant channel (a colour exemplar without blue) has bands of zeros: their systems
    # are singular, and the stack's least squares replaces its solves; shared in halves, the
    # other half solved its own, which gave other bits than on one CPU
    from scipy.ndimage import gaussian_filter

    monkeypatch.setattr(complex_steerable, "_SHARED_VALUES", 1 << 14)
    rng = np.random.default_rng(seed)
    x = gaussian_filter(rng.standard_normal((4, 128, 128)), (0, 1 + seed, 2), mode="wrap")
    x = x.astype(np.float32)
    x[seed] = 0.0
    lag = 1 + seed
    decay = np.exp(-np.abs(np.arange(-lag, lag + 1)) / (1 + np.arange(4)[:, None]))
    target = decay[:, :, None] * decay[:, None, :]
    filtered = {}
    for cpus in (1, 2):
        monkeypatch.setattr(complex_steerable, "worker_count", lambda cpus=cpus: cpus)
        filtered[cpus] = projections.filter_autocorrelation(x, target)
    assert filtered[1].tobytes() == filtered[2].tobytes()
