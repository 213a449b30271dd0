"""Portilla-Simoncelli texture statistics on a complex steerable pyramid, and their projections.

J. Portilla, E. Simoncelli, "A parametric texture model based on joint statistics of complex
wavelet coefficients", IJCV 40(1), 2000, sections 3-4; colour with cross-channel statistics
as in the authors' colour extension and in Vacher and Briand, "The Portilla-Simoncelli
texture model: towards understanding the early visual cortex", IPOL 11 (2021).

Everything works for any image size: the pyramid crops spectra (exact for odd sizes), the
statistics are spatial averages, and auto-correlation windows shrink where a band is small.
Images are handled channel-first internally, ``(C, H, W)``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
import numpy as np
import scipy.fft as sfft

from .steerable import _crop_indices, oriented_windows, pyramid_sizes, radial_lowpass

__all__ = [
    "ComplexSteerablePyramid",
    "PSStatistics",
    "adjust_correlation",
    "adjust_cross_correlation",
    "central_autocorrelation",
    "impose_autocorrelation",
    "impose_kurtosis",
    "impose_skewness",
    "max_scales",
    "parent_features",
    "phase_doubled",
    "pixel_statistics",
    "ps_statistics",
    "ps_synthesis",
]


# ---------------------------------------------------------------------- pyramid
class ComplexSteerablePyramid:
    """Complex (analytic) steerable pyramid of a fixed size, batched over channels.

    The real part of every band is the real steerable band of
    :class:`texsyn.ops.SteerablePyramid`; the complex band keeps only the half of the spectrum
    that the orientation points to, doubled (Portilla and Simoncelli 2000, section 2.1).

    Parameters
    ----------
    shape : (int, int)
    n_scales, n_orientations : int
    single : bool
        Compute the Fourier transforms in single precision (twice as fast; reconstruction
        error ~1e-6 instead of ~1e-15). The synthesis loop uses it; statistics do not.
    """

    def __init__(self, shape: tuple[int, int], n_scales: int = 4, n_orientations: int = 4, *, single: bool = False):
        self.shape = (int(shape[0]), int(shape[1]))
        self.real_dtype = np.float32 if single else np.float64
        self.n_scales = int(n_scales)
        self.n_orientations = k = int(n_orientations)
        if min(self.shape) < 2 ** (self.n_scales + 1):
            raise ValueError(
                f"image of {self.shape[1]}x{self.shape[0]} pixels is too small for {self.n_scales} "
                f"scales; need at least {2 ** (self.n_scales + 1)} pixels per side"
            )
        self.sizes = pyramid_sizes(self.shape, self.n_scales)
        r0, _ = self._polar(self.shape)
        self.lo0 = radial_lowpass(r0 / 2.0)
        self.hi0 = np.sqrt(np.maximum(1.0 - self.lo0**2, 0.0))
        self.lo, self.real_filters, self.analytic_filters, self.half_planes = [], [], [], []
        for size in self.sizes[: self.n_scales]:
            r, theta = self._polar(size)
            lo = radial_lowpass(r)
            reals = oriented_windows(theta, np.sqrt(np.maximum(1.0 - lo**2, 0.0)), k)
            # analytic bands: the half plane each orientation points to, doubled
            c = np.cos(theta[None] - (np.pi * np.arange(k) / k)[:, None, None])
            halves = np.where(c > 1e-12, 2.0, np.where(c < -1e-12, 0.0, 1.0))
            halves[:, 0, 0] = 1.0
            analytic = reals * halves
            rd, cd = self.real_dtype, np.result_type(self.real_dtype, np.complex64)
            self.lo.append(lo.astype(rd))
            self.real_filters.append(reals.astype(cd))
            self.analytic_filters.append(analytic.astype(cd))
            self.half_planes.append(halves.astype(rd))
        self.lo0 = self.lo0.astype(self.real_dtype)
        self.hi0 = self.hi0.astype(self.real_dtype)
        # L(r/2) at every level's resolution: the low-pass that the partially reconstructed
        # images of Portilla-Simoncelli carry (paper section 3.1; the MATLAB code's lo0 mask).
        # Level s + 1 takes level s's low-pass window at the same frequency indices, which keeps
        # the reconstruction exact for odd sizes too (where the grids are not exactly 2x apart).
        self.mid = [self.lo0]
        for level in range(self.n_scales):
            rows = _crop_indices(self.sizes[level][0], self.sizes[level + 1][0])
            cols = _crop_indices(self.sizes[level][1], self.sizes[level + 1][1])
            self.mid.append(self.lo[level][rows[:, None], cols[None, :]])

    def _fft(self, x):
        x = np.asarray(x)
        dtype = np.result_type(self.real_dtype, np.complex64) if np.iscomplexobj(x) else self.real_dtype
        return sfft.fft2(x.astype(dtype, copy=False))

    def _ifft(self, x):
        return sfft.ifft2(x)

    @staticmethod
    def _polar(shape):
        fy = 2 * np.pi * np.fft.fftfreq(shape[0])[:, None]
        fx = 2 * np.pi * np.fft.fftfreq(shape[1])[None, :]
        return np.hypot(fx, fy), np.arctan2(fy, fx)

    @staticmethod
    def resize_spectrum(spec: np.ndarray, size_from, size_to) -> np.ndarray:
        """Crop or zero-pad a full 2-D spectrum (last two axes), keeping amplitudes."""
        scale = (size_to[0] * size_to[1]) / (size_from[0] * size_from[1])
        if size_to[0] <= size_from[0]:
            rows = _crop_indices(size_from[0], size_to[0])
            cols = _crop_indices(size_from[1], size_to[1])
            return spec[..., rows[:, None], cols[None, :]] * scale
        rows = _crop_indices(size_to[0], size_from[0])
        cols = _crop_indices(size_to[1], size_from[1])
        out = np.zeros(spec.shape[:-2] + tuple(size_to), dtype=complex)
        out[..., rows[:, None], cols[None, :]] = spec * scale
        return out

    def expand(self, image: np.ndarray, level: int) -> np.ndarray:
        """Interpolate ``(..., h, w)`` arrays of level ``level + 1`` to the size of ``level``."""
        spec = self._fft(image)
        out = self._ifft(self.resize_spectrum(spec, self.sizes[level + 1], self.sizes[level]))
        return out if np.iscomplexobj(image) else out.real

    def forward(self, image: np.ndarray, *, spectra: bool = False, all_lows: bool = True):
        """``(highpass, bands, lows)`` of ``(C, H, W)`` images (and the bands' spectra).

        ``bands[s]`` is complex ``(C, K, h_s, w_s)``; ``lows[s]`` the real low-pass image that
        enters level ``s`` (``lows[0]`` is the image low-passed once, ``lows[-1]`` the residual).
        With ``spectra=True`` a fourth item lists the Fourier transforms of the bands; with
        ``all_lows=False`` only the residual ``lows[-1]`` is computed (the others are None).
        """
        x = np.asarray(image, dtype=np.float64)
        spec = self._fft(x)
        highpass = self._ifft(spec * self.hi0).real
        low = spec * self.lo0
        bands, lows, band_spectra = [], [], []
        for s in range(self.n_scales):
            lows.append(self._ifft(low).real if all_lows else None)
            band_spectra.append(low[:, None] * self.analytic_filters[s])
            bands.append(self._ifft(band_spectra[-1]))
            low = self.resize_spectrum(low * self.lo[s], self.sizes[s], self.sizes[s + 1])
        lows.append(self._ifft(low).real)
        return (highpass, bands, lows, band_spectra) if spectra else (highpass, bands, lows)

    def lowpass_image(self, residual: np.ndarray) -> np.ndarray:
        """The coarsest partially reconstructed image: the low-pass residual filtered by ``L(r/2)``."""
        return self._ifft(self._fft(residual) * self.mid[-1]).real

    def reconstruct_level(self, coarser: np.ndarray, real_bands: np.ndarray, level: int, *, real_spectra=None) -> np.ndarray:
        """Partially reconstructed image of ``level`` from the one of the level below and the
        level's real bands (or their Fourier transforms ``real_spectra``).

        Both images carry the low-pass ``L(r/2)`` of their own resolution (Portilla and
        Simoncelli's partially reconstructed low-pass images), so the finest one is the
        image's low-pass part and :meth:`reconstruct` only adds the high-pass residual.
        """
        spec = self.resize_spectrum(self._fft(coarser), self.sizes[level + 1], self.sizes[level])
        if real_spectra is None:
            real_spectra = self._fft(real_bands)
        spec = spec + np.sum(real_spectra * np.conj(self.real_filters[level]), axis=-3)
        return self._ifft(spec * self.mid[level]).real

    def reconstruct(self, low0: np.ndarray, highpass: np.ndarray) -> np.ndarray:
        """The image from the finest partially reconstructed image and the high-pass residual."""
        return self._ifft(self._fft(low0) + self._fft(highpass) * self.hi0).real

    def analytic(self, real_bands: np.ndarray, level: int, *, real_spectra=None):
        """Re-create the complex bands ``(..., K, h, w)`` from their real parts; returns
        ``(bands, their spectra)``."""
        if real_spectra is None:
            real_spectra = self._fft(real_bands)
        spectra = real_spectra * self.half_planes[level]
        return self._ifft(spectra), spectra


# ---------------------------------------------------------------------- small statistics
def central_autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    """Central ``(2l+1) x (2l+1)`` periodic auto-correlation of ``(..., h, w)`` arrays, divided by ``h w``.

    ``l = min(lags, min(h, w) // 2 - 1)`` (at least 0): small bands get smaller windows.
    """
    h, w = x.shape[-2:]
    lag = max(0, min(lags, min(h, w) // 2 - 1))
    ac = sfft.ifft2(np.abs(sfft.fft2(x)) ** 2).real / (h * w)
    rows = np.arange(-lag, lag + 1) % h
    cols = np.arange(-lag, lag + 1) % w
    return ac[..., rows[:, None], cols[None, :]]


def _moments(x: np.ndarray):
    m = x.mean(axis=(-2, -1), keepdims=True)
    d = x - m
    var = np.mean(d**2, axis=(-2, -1))
    safe = np.where(var > 0, var, 1.0)
    skew = np.mean(d**3, axis=(-2, -1)) / safe**1.5
    kurt = np.mean(d**4, axis=(-2, -1)) / safe**2
    return m[..., 0, 0], var, np.where(var > 0, skew, 0.0), np.where(var > 0, kurt, 3.0)


def impose_autocorrelation(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Filter ``x`` so that its central auto-correlation becomes ``target`` (PS ``modacor22``).

    Solves for the symmetric auto-correlation ``c_h`` of a filter such that
    ``(c_x * c_h)(t) = target(t)`` on the window, then multiplies the spectrum of ``x`` by
    ``sqrt(|FT c_h|)``. Batched: ``x`` is ``(..., h, w)`` and ``target`` ``(..., a, a)``.
    """
    x = np.asarray(x, dtype=np.float64)
    h, w = x.shape[-2:]
    batch = x.shape[:-2]
    lag = (target.shape[-1] - 1) // 2
    if lag == 0:
        cur = np.mean(x**2, axis=(-2, -1), keepdims=True)
        return x * np.sqrt(target[..., :1, :1] / np.where(cur > 0, cur, 1.0))
    spec = sfft.rfft2(x.astype(np.float32))
    cx = sfft.irfft2(spec.real**2 + spec.imag**2, s=(h, w)).astype(np.float64) / (h * w)
    half = _half_offsets(lag)
    diff = half[:, None, :] - half[None, :, :]
    summ = half[:, None, :] + half[None, :, :]
    nonzero = np.any(half != 0, axis=1)
    a = cx[..., diff[..., 0] % h, diff[..., 1] % w]
    a = a + np.where(nonzero[None, :], cx[..., summ[..., 0] % h, summ[..., 1] % w], 0.0)
    b = target[..., half[:, 0] + lag, half[:, 1] + lag]
    try:
        coef = np.linalg.solve(a, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        coef = np.stack([np.linalg.lstsq(ai, bi, rcond=None)[0] for ai, bi in zip(a.reshape((-1,) + a.shape[-2:]), b.reshape(-1, b.shape[-1]))]).reshape(b.shape)
    ch = np.zeros(batch + (h, w))
    ch[..., half[:, 0] % h, half[:, 1] % w] = coef
    ch[..., -half[:, 0] % h, -half[:, 1] % w] = coef
    gain = np.sqrt(np.abs(sfft.rfft2(ch.astype(np.float32)).real))
    return sfft.irfft2(spec * gain, s=(h, w)).astype(np.float64)


@functools.lru_cache(maxsize=None)
def _half_offsets(lag: int) -> np.ndarray:
    """Lags ``(i, j)`` of a ``(2 lag + 1)^2`` window, one of each ``+/-`` pair, zero first."""
    pairs = [(i, j) for i in range(-lag, lag + 1) for j in range(-lag, lag + 1) if (i, j) >= (0, 0)]
    return np.array(pairs, dtype=np.int64)


def _closest_lambda(num, den, target, power, scale):
    """The step (0 included) whose moment ratio ``num / den^power`` is closest to ``target``."""
    grid = np.concatenate([[0.0], np.linspace(-4.0, 4.0, 4001) * scale])
    values = np.polynomial.polynomial.polyval(grid, num) / np.polynomial.polynomial.polyval(grid, den) ** power
    return grid[np.argmin(np.abs(values - target))]


def _solve_lambda(coeffs_num, coeffs_den, target, power):
    """Smallest |lambda| with num(l)^2 = target^2 den(l)^power (sign of num = sign of target)."""
    num = np.polynomial.Polynomial(coeffs_num)
    den = np.polynomial.Polynomial(coeffs_den)
    if power == 3:  # skewness: num / den^1.5 = t  ->  num^2 - t^2 den^3 = 0, sign(num) = sign(t)
        poly = num**2 - target**2 * den**3
    else:  # kurtosis: num / den^2 = t  ->  num - t den^2 = 0
        poly = num - target * den**2
    roots = poly.roots()
    real = roots[np.abs(roots.imag) < 1e-6 * np.maximum(1.0, np.abs(roots.real))].real
    if power == 3:
        real = real[np.sign(num(real)) == np.sign(target)] if target != 0 else real
    if real.size == 0:
        return None
    return real[np.argmin(np.abs(real))]


def impose_skewness(x: np.ndarray, target: float) -> np.ndarray:
    """Move ``x`` along the skewness gradient until its skewness is ``target`` (PS ``modskew``).

    ``y = x + l (d^2 - (m3/m2) d - m2)`` (``d`` = centred ``x``): the direction is orthogonal to
    the mean and to ``d``, so mean and variance change only to second order and are restored.
    The skewness of ``y`` is a ratio of polynomials in ``l`` whose coefficients are moments;
    the root of smallest ``|l|`` is taken.
    """
    mean = x.mean()
    d = (x - mean).ravel()
    d2 = d * d
    m2 = d2.mean()
    if m2 <= 0:
        return x
    m3 = np.dot(d2, d) / d.size
    g = d2 - (m3 / m2) * d - m2
    g2 = g * g
    num = [m3, 3 * np.dot(d2, g) / d.size, 3 * np.dot(d, g2) / d.size, np.dot(g2, g) / d.size]
    den = [m2, 2 * np.dot(d, g) / d.size, g2.mean()]
    lam = _solve_lambda(num, den, target, 3)
    if lam is None:  # unreachable target: go to the closest reachable skewness instead
        lam = _closest_lambda(num, den, target, 1.5, np.sqrt(m2 / max(den[2], 1e-300)))
    y = d + lam * g
    y *= np.sqrt(m2 / np.mean(y * y))
    return (y + mean).reshape(x.shape)


def impose_kurtosis(x: np.ndarray, target: float) -> np.ndarray:
    """Move ``x`` along the kurtosis gradient until its kurtosis is ``target`` (PS ``modkurt``).

    ``y = x + l g`` with ``g`` the part of ``d^3`` orthogonal to ``1, d, d^2`` (normal equations
    from the moments), so that mean, variance and skewness change only to second order; the
    mean and variance are restored exactly.
    """
    mean = x.mean()
    d = (x - mean).ravel()
    n = d.size
    d2 = d * d
    d3 = d2 * d
    m = [1.0, 0.0, d2.mean(), d3.mean(), np.dot(d2, d2) / n, np.dot(d3, d2) / n, np.dot(d3, d3) / n]
    if m[2] <= 0:
        return x
    gram = np.array([[m[i + j] for j in range(3)] for i in range(3)])
    rhs = np.array([m[3], m[4], m[5]])
    try:
        coef = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(gram, rhs, rcond=None)[0]
    g = d3 - coef[0] - coef[1] * d - coef[2] * d2
    g2 = g * g
    num = [m[4], 4 * np.dot(d3, g) / n, 6 * np.dot(d2, g2) / n, 4 * np.dot(d, g2 * g) / n, np.dot(g2, g2) / n]
    den = [m[2], 2 * np.dot(d, g) / n, g2.mean()]
    lam = _solve_lambda(num, den, target, 4)
    if lam is None:
        lam = _closest_lambda(num, den, target, 2.0, np.sqrt(m[2] / max(den[2], 1e-300)))
    y = d + lam * g
    y -= y.mean()
    y *= np.sqrt(m[2] / np.mean(y * y))
    return (y + mean).reshape(x.shape)


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
    """Linearly transform the columns of ``x`` (N, k) so that ``x^T x / N = target`` (PS ``adjustCorr1s``)."""
    current = x.T @ x / x.shape[0]
    return x @ (_sqrtm(current, inverse=True) @ _sqrtm(target))


def adjust_cross_correlation(x: np.ndarray, target: np.ndarray, y: np.ndarray, target_xy: np.ndarray) -> np.ndarray:
    """Modify ``x`` (N, k), given fixed ``y`` (N, m), so that ``x^T x / N = target`` and
    ``x^T y / N = target_xy`` (PS ``adjustCorr2s``).

    The part of ``x`` explained by ``y`` is replaced by the target regression and the
    residual is rescaled to the target residual covariance (clipped to be positive).
    """
    n, k = x.shape
    rows = np.concatenate([x.T, y.T], axis=0)  # (k + m, N), contiguous rows for BLAS
    gram = rows @ rows.T / n
    bxx, bxy, byy = gram[:k, :k], gram[:k, k:], gram[k:, k:]
    ibyy = np.linalg.pinv(byy)
    regression = ibyy @ bxy.T  # (m, k)
    current = bxx - bxy @ regression
    desired = target - target_xy @ ibyy @ target_xy.T
    m = _sqrtm(current, inverse=True) @ _sqrtm(desired)
    # (x - y regression) m + y ibyy target_xy^T, with two products of N-column matrices
    return (m.T @ rows[:k] + (ibyy @ target_xy.T - regression @ m).T @ rows[k:]).T


# ---------------------------------------------------------------------- the statistics
@dataclass
class PSStatistics:
    """The Portilla-Simoncelli statistics of an image (paper section 3; colour: all channels jointly).

    Shapes use ``C`` channels, ``S`` scales, ``K`` orientations, ``A = 2 lags + 1``.

    Attributes
    ----------
    pixel_moments : (C, 4)  mean, variance, skewness, kurtosis of every channel
    pixel_range : (C, 2)  minimum and maximum
    colour_covariance : (C, C)
    low_skew_kurt : (C, S+1, 2)  skewness and kurtosis of the partially reconstructed low-pass images
    low_autocorr : list of (C, a, a), one per level 0..S (windows shrink for small bands)
    magnitude_means : (S, C, K)
    magnitude_autocorr : list of (C, K, a, a), one per scale
    magnitude_cross : list of (CK, CK)  magnitude covariance across orientations and channels
    magnitude_parent : list of (CK, CK)  with the parent scale's magnitudes (scales 0..S-2)
    real_cross : list of (CK, CK)  covariance of real parts across orientations and channels
    real_parent : list of (CK, 2CK)  with the parent's phase-doubled bands; last scale: (CK, 5C) with
        the low-pass residual and its four one-pixel shifts
    highpass_variance : (C,)
    """

    pixel_moments: np.ndarray
    pixel_range: np.ndarray
    colour_covariance: np.ndarray
    low_skew_kurt: np.ndarray
    low_autocorr: list
    magnitude_means: np.ndarray
    magnitude_autocorr: list
    magnitude_cross: list
    magnitude_parent: list
    real_cross: list
    real_parent: list
    highpass_variance: np.ndarray
    shape: tuple = field(default=(0, 0))

    def vector(self) -> np.ndarray:
        """All statistics as one flat vector (a texture descriptor)."""
        parts = [self.pixel_moments, self.pixel_range, self.colour_covariance, self.low_skew_kurt,
                 self.magnitude_means, self.highpass_variance]
        parts += self.low_autocorr + self.magnitude_autocorr + self.magnitude_cross
        parts += self.magnitude_parent + self.real_cross + self.real_parent
        return np.concatenate([np.ravel(p) for p in parts])

    def groups(self) -> dict:
        """The statistics by family, for per-family distances."""
        return {
            "pixel": np.concatenate([self.pixel_moments.ravel(), self.pixel_range.ravel(), self.colour_covariance.ravel()]),
            "low": np.concatenate([self.low_skew_kurt.ravel()] + [a.ravel() for a in self.low_autocorr]),
            "magnitude": np.concatenate([self.magnitude_means.ravel()] + [a.ravel() for a in self.magnitude_autocorr]),
            "cross": np.concatenate([a.ravel() for a in self.magnitude_cross + self.magnitude_parent]),
            "phase": np.concatenate([a.ravel() for a in self.real_cross + self.real_parent]),
            "highpass": self.highpass_variance.ravel(),
        }


def phase_doubled(parent: np.ndarray) -> np.ndarray:
    """``|p| exp(2 i atan2(re p, im p))``: parents rotated to the child's phase (PS section 3.3)."""
    re, im = parent.real, parent.imag
    size = np.sqrt(re * re + im * im)
    inv = np.divide(1.0, size, out=np.zeros_like(size), where=size > 0)
    out = np.empty(parent.shape, dtype=complex)
    out.real = (im * im - re * re) * inv
    out.imag = 2.0 * re * im * inv
    return out


def parent_features(pyramid: ComplexSteerablePyramid, band_spectra: list, lows: list, level: int):
    """Magnitude and real regressors of the scale above ``level``, expanded to its size.

    Parameters
    ----------
    band_spectra : list of ndarray
        Fourier transforms of the complex bands, per level.

    Returns ``(magnitudes (N, CK) or None, reals (N, 2CK) or (N, 5C))``.
    """
    if level < pyramid.n_scales - 1:
        up = pyramid._ifft(pyramid.resize_spectrum(band_spectra[level + 1], pyramid.sizes[level + 1], pyramid.sizes[level]))
        doubled = phase_doubled(up)
        c, k = up.shape[:2]
        mags = np.abs(up)  # phase doubling keeps the magnitude
        mags = mags - mags.mean(axis=(-2, -1), keepdims=True)
        reals = np.concatenate([doubled.real, doubled.imag], axis=1)
        return mags.reshape(c * k, -1).T, reals.reshape(2 * c * k, -1).T
    low = pyramid.expand(lows[-1], level)  # (C, h, w)
    shifts = [low, np.roll(low, 1, -1), np.roll(low, -1, -1), np.roll(low, 1, -2), np.roll(low, -1, -2)]
    return None, np.stack(shifts, axis=1).reshape(5 * low.shape[0], -1).T


def pixel_statistics(channels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel statistics of ``(C, H, W)`` channels (paper section 3.1, colour: plus covariance).

    Returns
    -------
    moments : (C, 4)  mean, variance, skewness, kurtosis
    value_range : (C, 2)  minimum and maximum
    covariance : (C, C)
    """
    x = np.asarray(channels, dtype=np.float64)
    flat = x.reshape(x.shape[0], -1)
    centred = flat - flat.mean(axis=1, keepdims=True)
    moments = np.stack(_moments(x), axis=-1)
    value_range = np.stack([flat.min(axis=1), flat.max(axis=1)], axis=-1)
    return moments, value_range, centred @ centred.T / centred.shape[1]


def max_scales(shape: tuple[int, int], wanted: int = 4) -> int:
    """The largest number of pyramid scales up to ``wanted`` that an image of ``shape`` supports
    (:class:`ComplexSteerablePyramid` needs ``2^(scales + 1)`` pixels per side)."""
    return int(max(1, min(wanted, math.floor(math.log2(max(min(shape), 4))) - 1)))


def ps_statistics(
    image: np.ndarray,
    *,
    n_scales: int = 4,
    n_orientations: int = 4,
    lags: int = 3,
    pyramid: ComplexSteerablePyramid | None = None,
) -> PSStatistics:
    """Portilla-Simoncelli statistics of an image ``(H, W)`` or ``(H, W, C)`` (paper section 3).

    Colour images are described jointly: the cross-orientation and cross-scale correlations
    run over every (orientation, channel) pair, plus the colour covariance (Vacher and Briand
    2021, section 4).

    Parameters
    ----------
    n_scales, n_orientations : int
        Pyramid size (the paper uses 4 and 4).
    lags : int
        Half-width of the auto-correlation windows (``N_a = 2 lags + 1``; the paper uses 7).
    """
    img = np.asarray(image, dtype=np.float64)
    x = img[None] if img.ndim == 2 else np.moveaxis(img, -1, 0)
    pyramid = pyramid or ComplexSteerablePyramid(x.shape[1:], n_scales, n_orientations)
    c = x.shape[0]
    moments, value_range, covariance = pixel_statistics(x)
    highpass, bands, lows, spectra = pyramid.forward(x, spectra=True)
    lows[-1] = lows[-1] - lows[-1].mean(axis=(-2, -1), keepdims=True)
    # partially reconstructed low-pass images, coarse to fine
    partial = [None] * (pyramid.n_scales + 1)
    partial[-1] = pyramid.lowpass_image(lows[-1])
    for s in range(pyramid.n_scales - 1, -1, -1):
        partial[s] = pyramid.reconstruct_level(partial[s + 1], bands[s].real, s)
    low_sk = np.stack([np.stack(_moments(p)[2:], axis=-1) for p in partial], axis=1)
    stats = PSStatistics(
        pixel_moments=moments,
        pixel_range=value_range,
        colour_covariance=covariance,
        low_skew_kurt=low_sk,
        low_autocorr=[central_autocorrelation(p, lags) for p in partial],
        magnitude_means=np.stack([np.abs(b).mean(axis=(-2, -1)) for b in bands]),
        magnitude_autocorr=[],
        magnitude_cross=[],
        magnitude_parent=[],
        real_cross=[],
        real_parent=[],
        highpass_variance=np.mean(highpass**2, axis=(-2, -1)),
        shape=tuple(x.shape[1:]),
    )
    for s, band in enumerate(bands):
        k = band.shape[1]
        mags = np.abs(band)
        mags = mags - mags.mean(axis=(-2, -1), keepdims=True)
        stats.magnitude_autocorr.append(central_autocorrelation(mags, lags))
        n = mags.shape[-1] * mags.shape[-2]
        m = mags.reshape(c * k, n).T
        r = band.real.reshape(c * k, n).T
        stats.magnitude_cross.append(m.T @ m / n)
        stats.real_cross.append(r.T @ r / n)
        parent_mags, parent_reals = parent_features(pyramid, spectra, lows, s)
        if parent_mags is not None:
            stats.magnitude_parent.append(m.T @ parent_mags / n)
        stats.real_parent.append(r.T @ parent_reals / n)
    return stats


# ---------------------------------------------------------------------- the synthesis loop
def _fit_window(target: np.ndarray, shape: tuple[int, int], lags: int) -> np.ndarray:
    """Crop a target auto-correlation window to what a band of ``shape`` allows."""
    allowed = max(0, min(lags, min(shape) // 2 - 1))
    have = (target.shape[-1] - 1) // 2
    cut = have - min(allowed, have)
    return target[..., cut : target.shape[-2] - cut, cut : target.shape[-1] - cut]


def _fix_low(images: np.ndarray, autocorr: np.ndarray, skew_kurt: np.ndarray, pixel_var: np.ndarray, lags: int) -> np.ndarray:
    """Impose auto-correlation, skewness and kurtosis on every channel of a low-pass image."""
    window = _fit_window(autocorr, images.shape[-2:], lags)
    centre = (window.shape[-1] - 1) // 2
    target_var = window[:, centre, centre]
    active = target_var / np.maximum(pixel_var, 1e-300) > 1e-4
    out = np.array(images, dtype=np.float64)
    if active.any():
        out[active] = impose_autocorrelation(out[active], window[active])
    for c in range(out.shape[0]):
        if active[c]:
            out[c] = impose_kurtosis(impose_skewness(out[c], skew_kurt[c, 0]), skew_kurt[c, 1])
        else:
            current = np.mean((out[c] - out[c].mean()) ** 2)
            if current > 0:
                out[c] *= np.sqrt(target_var[c] / current)
    return out


def _impose_parent_regression(reals: np.ndarray, parents: np.ndarray, target_xp: np.ndarray) -> np.ndarray:
    """Give every column of ``reals`` its target correlation with ``parents``, keeping its variance."""
    n, k = reals.shape
    rows = np.concatenate([reals.T, parents.T], axis=0).astype(np.float32)  # (k + m, N)
    gram = (rows @ rows.T).astype(np.float64) / n
    own = np.diag(gram)[:k]
    cross = gram[k:, :k]  # (m, k): parents^T reals / n
    ibyy = np.linalg.pinv(gram[k:, k:])
    regression = ibyy @ cross
    fit = ibyy @ target_xp.T
    current = own - np.einsum("mk,mk->k", cross, regression)
    desired = np.maximum(own - np.einsum("km,mk->k", target_xp, fit), 0.0)
    scale = np.sqrt(desired / np.where(current > 0, current, 1.0))
    mix = (fit - regression * scale).T.astype(np.float32)
    return (rows[:k] * scale[:, None].astype(np.float32) + mix @ rows[k:]).T.astype(np.float64)


def ps_synthesis(
    target: PSStatistics,
    initial: np.ndarray,
    n_iterations: int,
    *,
    lags: int = 3,
    pyramid: ComplexSteerablePyramid | None = None,
    callback=None,
) -> np.ndarray:
    """Portilla-Simoncelli alternating projections from ``initial`` (``(C, H, W)``), paper section 4.

    Every iteration analyses the current image, imposes the statistics coarse to fine (low-pass
    auto-correlation and moments; magnitude correlations across orientations, channels and
    the parent scale; magnitude auto-correlations; real-part correlations with the
    phase-doubled parents; auto-correlation and moments of each partial reconstruction),
    clamps the high-pass variance and finally imposes the pixel statistics (mean and colour
    covariance, skewness, kurtosis, range). Any image size works.

    Returns
    -------
    ndarray, shape (C, H, W)
    """
    x = np.asarray(initial, dtype=np.float64).copy()
    c = x.shape[0]
    pyramid = pyramid or ComplexSteerablePyramid(x.shape[1:], len(target.magnitude_cross), target.magnitude_means.shape[-1], single=True)
    n_scales = pyramid.n_scales
    mean0 = target.pixel_moments[:, 0]
    var0 = target.pixel_moments[:, 1]
    for iteration in range(n_iterations):
        highpass, bands, lows, spectra = pyramid.forward(x, spectra=True, all_lows=False)
        low = lows[-1] - lows[-1].mean(axis=(-2, -1), keepdims=True)
        lows[-1] = low
        image = _fix_low(pyramid.lowpass_image(low), target.low_autocorr[n_scales], target.low_skew_kurt[:, n_scales], var0, lags)
        for s in range(n_scales - 1, -1, -1):
            band = bands[s]
            k = band.shape[1]
            n = band.shape[-1] * band.shape[-2]
            parent_mags, parent_reals = parent_features(pyramid, spectra, lows, s)
            current = np.abs(band)
            mags = current - current.mean(axis=(-2, -1), keepdims=True)
            m = mags.reshape(c * k, n).T
            if parent_mags is None:
                m = adjust_correlation(m, target.magnitude_cross[s])
            else:
                m = adjust_cross_correlation(m, target.magnitude_cross[s], parent_mags, target.magnitude_parent[s])
            mags = m.T.reshape(mags.shape)
            mags = impose_autocorrelation(mags, _fit_window(target.magnitude_autocorr[s], mags.shape[-2:], lags))
            magnitude = np.maximum(mags + target.magnitude_means[s][..., None, None], 0.0)
            band = band * (magnitude / np.where(current > 0, current, 1.0))
            if s < n_scales - 1:
                reals = _impose_parent_regression(band.real.reshape(c * k, n).T, parent_reals, target.real_parent[s])
                real = reals.T.reshape(band.shape)
            else:
                real = band.real
            real_spectra = pyramid._fft(real)
            bands[s], spectra[s] = pyramid.analytic(real, s, real_spectra=real_spectra)
            image = pyramid.reconstruct_level(image, real, s, real_spectra=real_spectra)
            image = _fix_low(image, target.low_autocorr[s], target.low_skew_kurt[:, s], var0, lags)
        hp_var = np.mean(highpass**2, axis=(-2, -1))
        shrink = np.where(hp_var > target.highpass_variance, np.sqrt(target.highpass_variance / np.where(hp_var > 0, hp_var, 1.0)), 1.0)
        x = pyramid.reconstruct(image, highpass * shrink[:, None, None])
        # pixel statistics: mean and (colour) covariance, skewness, kurtosis, range
        flat = x.reshape(c, -1)
        centred = (flat - flat.mean(axis=1, keepdims=True)).T
        flat = adjust_correlation(centred, target.colour_covariance).T + mean0[:, None]
        for ci in range(c):
            if var0[ci] > 0:
                flat[ci] = impose_skewness(flat[ci], target.pixel_moments[ci, 2])
                flat[ci] = impose_kurtosis(flat[ci], target.pixel_moments[ci, 3])
        flat = np.clip(flat, target.pixel_range[:, :1], target.pixel_range[:, 1:])
        x = flat.reshape(x.shape)
        if callback is not None:
            callback(iteration + 1, x)
    return x
