"""The Portilla–Simoncelli texture statistics: what ``fit`` learns from the exemplar.

J. Portilla, E. Simoncelli, "A parametric texture model based on joint statistics of complex
wavelet coefficients", IJCV 40(1), 2000, section 3; colour with every cross-channel
correlation as in the authors' colour extension and in Vacher and Briand, "The
Portilla-Simoncelli texture model: towards understanding the early visual cortex", IPOL 11
(2021). The statistics are spatial averages over a :class:`ComplexSteerablePyramid`, so any
image size works; auto-correlation windows shrink where a band is small. Images are handled
channel-first, ``(C, H, W)``. The projections that impose these statistics are in
:mod:`texsyn.models.portilla_projections`; the page ``docs/methods/portilla_simoncelli.md``
maps the paper's list of statistics to the fields of :class:`PSStatistics`.

Why this module is long: the parents' regressors (:func:`parent_rows`) serve both the
statistics (double precision) and the synthesis loop (single precision, written in place
into the regressions' rows, with its own phase doubling :func:`phase_doubled_square`; issue
20's single-precision step), and are kept next to the statistics they must match.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..ops import fft as pocketfft
from ..transforms.complex_steerable import ComplexSteerablePyramid, for_each_band

__all__ = [
    "PSStatistics",
    "central_autocorrelation",
    "moments",
    "parent_features",
    "parent_rows",
    "phase_doubled",
    "phase_doubled_parts",
    "phase_doubled_square",
    "pixel_statistics",
    "ps_statistics",
    "statistics_distance",
]


def central_autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    """Central ``(2l+1) x (2l+1)`` periodic auto-correlation of ``(..., h, w)`` arrays, divided by ``h w``.

    ``l = min(lags, min(h, w) // 2 - 1)`` (at least 0): small bands get smaller windows
    (Portilla and Simoncelli 2000, section 3: the low-pass and magnitude auto-correlations).

    Examples
    --------
    >>> central_autocorrelation(np.ones((8, 8)), 1)
    array([[1., 1., 1.],
           [1., 1., 1.],
           [1., 1., 1.]])
    """
    h, w = x.shape[-2:]
    lag = max(0, min(lags, min(h, w) // 2 - 1))
    ac = pocketfft.ifft2(np.abs(pocketfft.fft2(x)) ** 2).real / (h * w)
    rows = np.arange(-lag, lag + 1) % h
    cols = np.arange(-lag, lag + 1) % w
    return ac[..., rows[:, None], cols[None, :]]


def moments(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean, variance, skewness and kurtosis over the last two axes of ``x``.

    A constant array has skewness 0 and kurtosis 3 (those of a Gaussian).

    Examples
    --------
    >>> [float(m) for m in moments(np.array([[0.0, 1.0], [0.0, 1.0]]))]
    [0.5, 0.25, 0.0, 1.0]
    """
    m = x.mean(axis=(-2, -1), keepdims=True)
    d = x - m
    var = np.mean(d**2, axis=(-2, -1))
    safe = np.where(var > 0, var, 1.0)
    skew = np.mean(d**3, axis=(-2, -1)) / safe**1.5
    kurt = np.mean(d**4, axis=(-2, -1)) / safe**2
    return m[..., 0, 0], var, np.where(var > 0, skew, 0.0), np.where(var > 0, kurt, 3.0)


def _frozen(value):
    """A read-only array, or a tuple of read-only arrays for a sequence of them."""
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    arr = np.asarray(value)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class PSStatistics:
    """The Portilla–Simoncelli statistics of an image (paper section 3; colour: all channels jointly).

    Built once by :func:`ps_statistics` (and by the method's ``fit``); the arrays are
    read-only and the per-scale lists are tuples, so a fitted model can be shared.
    Shapes use ``C`` channels, ``S`` scales, ``K`` orientations, ``A = 2 lags + 1``.

    Attributes
    ----------
    pixel_moments : (C, 4)  mean, variance, skewness, kurtosis of every channel
    pixel_range : (C, 2)  minimum and maximum
    colour_covariance : (C, C)
    low_skew_kurt : (C, S+1, 2)  skewness and kurtosis of the partially reconstructed low-pass images
    low_autocorr : tuple of (C, a, a), one per level 0..S (windows shrink for small bands)
    magnitude_means : (S, C, K)
    magnitude_autocorr : tuple of (C, K, a, a), one per scale
    magnitude_cross : tuple of (CK, CK)  magnitude covariance across orientations and channels
    magnitude_parent : tuple of (CK, CK)  with the parent scale's magnitudes (scales 0..S-2)
    real_cross : tuple of (CK, CK)  covariance of real parts across orientations and channels
    real_parent : tuple of (CK, 2CK)  with the parent's phase-doubled bands; last scale: (CK, 5C) with
        the low-pass residual and its four one-pixel shifts
    highpass_variance : (C,)
    shape : (int, int)  size of the analysed image
    """

    pixel_moments: np.ndarray
    pixel_range: np.ndarray
    colour_covariance: np.ndarray
    low_skew_kurt: np.ndarray
    low_autocorr: tuple
    magnitude_means: np.ndarray
    magnitude_autocorr: tuple
    magnitude_cross: tuple
    magnitude_parent: tuple
    real_cross: tuple
    real_parent: tuple
    highpass_variance: np.ndarray
    shape: tuple = field(default=(0, 0))

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            if name != "shape":
                object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))

    @property
    def n_scales(self) -> int:
        """Number of pyramid scales the statistics were measured with."""
        return len(self.magnitude_cross)

    @property
    def n_orientations(self) -> int:
        """Number of orientations per scale."""
        return int(self.magnitude_means.shape[-1])

    def vector(self) -> np.ndarray:
        """All statistics as one flat vector (a texture descriptor)."""
        parts = [
            self.pixel_moments,
            self.pixel_range,
            self.colour_covariance,
            self.low_skew_kurt,
            self.magnitude_means,
            self.highpass_variance,
        ]
        parts += self.low_autocorr + self.magnitude_autocorr + self.magnitude_cross
        parts += self.magnitude_parent + self.real_cross + self.real_parent
        return np.concatenate([np.ravel(p) for p in parts])

    def groups(self) -> dict:
        """The statistics by family, for per-family distances."""
        return {
            "pixel": np.concatenate(
                [self.pixel_moments.ravel(), self.pixel_range.ravel(), self.colour_covariance.ravel()]
            ),
            "low": np.concatenate([self.low_skew_kurt.ravel()] + [a.ravel() for a in self.low_autocorr]),
            "magnitude": np.concatenate(
                [self.magnitude_means.ravel()] + [a.ravel() for a in self.magnitude_autocorr]
            ),
            "cross": np.concatenate([a.ravel() for a in self.magnitude_cross + self.magnitude_parent]),
            "phase": np.concatenate([a.ravel() for a in self.real_cross + self.real_parent]),
            "highpass": self.highpass_variance.ravel(),
        }


def statistics_distance(statistics: PSStatistics, reference: PSStatistics) -> dict[str, float]:
    """Relative distance between two sets of statistics, family by family.

    For each family of :meth:`PSStatistics.groups` (pixel, low-pass, magnitude,
    cross-correlation, phase, high-pass): the Euclidean distance divided by the norm of the
    reference's family. Auto-correlation windows cut short by a small image are compared on
    their common part. :func:`texsyn.metrics.ps_distance` is the mean over the families.
    """
    mine = statistics.groups()
    out = {}
    for key, ref in reference.groups().items():
        other = mine[key]
        if other.shape != ref.shape:  # auto-correlation windows cut by a smaller image
            n = min(other.size, ref.size)
            other, ref = other[:n], ref[:n]
        out[key] = float(np.linalg.norm(other - ref) / max(float(np.linalg.norm(ref)), 1e-12))
    return out


def phase_doubled(parent: np.ndarray) -> np.ndarray:
    """``|p| exp(2 i atan2(re p, im p))``: parents rotated to the child's phase (paper section 3,
    cross-scale phase statistics).

    Examples
    --------
    >>> phase_doubled(np.array([1j]))  # the angle measured from the imaginary axis is 0
    array([1.+0.j])
    """
    out = np.empty(parent.shape, dtype=complex)
    phase_doubled_parts(parent, out.real, out.imag)
    return out


def phase_doubled_parts(parent: np.ndarray, real_out: np.ndarray, imag_out: np.ndarray) -> None:
    """Write the real and imaginary parts of :func:`phase_doubled` into two arrays.

    ``(im^2 - re^2) / |p|`` and ``2 re im / |p|`` (0 where ``p = 0``), computed in the
    precision of ``parent`` and rounded once into the outputs, which may be single precision
    (the synthesis puts them straight into the rows of its parent regression).
    """
    re, im = parent.real, parent.imag
    squares = re * re
    size = im * im
    diff = np.subtract(size, squares)  # im^2 - re^2
    size += squares
    np.sqrt(size, out=size)
    if size.size and size.min() > 0:
        inv = np.divide(1.0, size, out=size)
    else:  # 1 / |p| where p != 0, else 0
        inv = np.divide(1.0, size, out=np.zeros_like(size), where=size > 0)
    np.multiply(diff, inv, out=real_out)
    twice = np.multiply(re, 2.0, out=squares)
    twice *= im
    np.multiply(twice, inv, out=imag_out)


def phase_doubled_square(
    parent: np.ndarray, size: np.ndarray, real_out: np.ndarray, imag_out: np.ndarray
) -> None:
    """:func:`phase_doubled_parts` as ``-conj(p)^2 / |p|``, given ``size = |p|``.

    The same numbers up to rounding with fewer passes over the data: the single-precision
    synthesis loop uses it (issue 20's single-precision step, ``docs/methods/portilla_simoncelli.md``,
    "Performance"); the exemplar's statistics keep :func:`phase_doubled_parts`.
    """
    square = np.square(parent)
    if size.size and size.min() > 0:
        np.divide(square.real, size, out=real_out)
        np.divide(square.imag, size, out=imag_out)
    else:  # 0 where p = 0
        real_out[...] = 0.0
        imag_out[...] = 0.0
        np.divide(square.real, size, out=real_out, where=size > 0)
        np.divide(square.imag, size, out=imag_out, where=size > 0)
    np.negative(real_out, out=real_out)


def parent_features(pyramid: ComplexSteerablePyramid, band_spectra: list, lows: list, level: int):
    """Magnitude and real regressors of the scale above ``level``, expanded to its size.

    Paper section 3: the cross-scale magnitude correlations and the cross-scale phase
    statistics (the real parts against the phase-doubled parents); below the coarsest scale the parents are the low-pass residual
    and its four one-pixel shifts.

    Parameters
    ----------
    pyramid : ComplexSteerablePyramid
    band_spectra : list of ndarray
        Fourier transforms of the complex bands, per level.
    lows : list of ndarray
        The pyramid's low-pass images (only the residual ``lows[-1]`` is used).
    level : int
        The child scale (0-based, the finest first).

    Returns
    -------
    ``(magnitudes (N, CK) or None, reals (N, 2CK) or (N, 5C))``.
    """
    if level < pyramid.n_scales - 1:
        c, k = band_spectra[level + 1].shape[:2]
        n = pyramid.sizes[level][0] * pyramid.sizes[level][1]
        mags, reals = np.empty((c * k, n)), np.empty((2 * c * k, n))
        parent_rows(pyramid, band_spectra, level, mags, reals)
        return mags.T, reals.T
    low = pyramid.expand(lows[-1], level)  # (C, h, w)
    shifts = [low, np.roll(low, 1, -1), np.roll(low, -1, -1), np.roll(low, 1, -2), np.roll(low, -1, -2)]
    return None, np.stack(shifts, axis=1).reshape(5 * low.shape[0], -1).T


def parent_rows(
    pyramid: ComplexSteerablePyramid,
    band_spectra: list,
    level: int,
    mags_out: np.ndarray,
    reals_out: np.ndarray,
) -> None:
    """Write the regressors of :func:`parent_features` for a scale with a parent scale as rows.

    The parents (``band_spectra[level + 1]`` transformed back at the size of ``level``:
    :meth:`~texsyn.transforms.complex_steerable.ComplexSteerablePyramid.upsampled_ifft`)
    are computed band by band (:func:`for_each_band`); their centred magnitudes go into
    ``mags_out`` ``(CK, hw)``, the phase-doubled bands' real and imaginary parts into
    ``reals_out`` ``(2CK, hw)`` (per channel: the K real parts, then the K imaginary parts;
    ``reals_out`` may be single precision).
    """
    spec = band_spectra[level + 1]
    c, k = spec.shape[:2]
    flat = spec.reshape((c * k,) + spec.shape[-2:])
    parts = reals_out.reshape(c, 2, k, -1)

    def run(bands: slice) -> None:
        up = pyramid.upsampled_ifft(flat[bands], level).reshape(bands.stop - bands.start, -1)
        mags = mags_out[bands]
        single = up.dtype == np.complex64  # the synthesis loop
        size = np.abs(up) if single else None
        if size is not None:
            np.subtract(size, size.mean(axis=-1, keepdims=True), out=mags)
        else:
            np.abs(up, out=mags)  # phase doubling keeps the magnitude
            mags -= mags.mean(axis=-1, keepdims=True)
        for ci in range(bands.start // k, (bands.stop - 1) // k + 1):  # the channels in the slice
            first, stop = max(bands.start, ci * k) - ci * k, min(bands.stop, (ci + 1) * k) - ci * k
            at = slice(ci * k + first - bands.start, ci * k + stop - bands.start)
            if size is not None:
                phase_doubled_square(up[at], size[at], parts[ci, 0, first:stop], parts[ci, 1, first:stop])
            else:
                phase_doubled_parts(up[at], parts[ci, 0, first:stop], parts[ci, 1, first:stop])

    for_each_band(run, c * k, mags_out.shape[1])


def pixel_statistics(channels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel statistics of ``(C, H, W)`` channels (paper section 3, marginal statistics; colour: plus covariance).

    Returns
    -------
    moments : (C, 4)  mean, variance, skewness, kurtosis
    value_range : (C, 2)  minimum and maximum
    covariance : (C, C)

    Examples
    --------
    >>> m, r, c = pixel_statistics(np.array([[[0.0, 1.0], [0.0, 1.0]]]))
    >>> m.tolist(), r.tolist(), c.tolist()
    ([[0.5, 0.25, 0.0, 1.0]], [[0.0, 1.0]], [[0.25]])
    """
    x = np.asarray(channels, dtype=np.float64)
    flat = x.reshape(x.shape[0], -1)
    centred = flat - flat.mean(axis=1, keepdims=True)
    stats = np.stack(moments(x), axis=-1)
    value_range = np.stack([flat.min(axis=1), flat.max(axis=1)], axis=-1)
    return stats, value_range, centred @ centred.T / centred.shape[1]


def ps_statistics(
    image: np.ndarray,
    *,
    n_scales: int = 4,
    n_orientations: int = 4,
    lags: int = 3,
    pyramid: ComplexSteerablePyramid | None = None,
    pixels: np.ndarray | None = None,
) -> PSStatistics:
    """Portilla–Simoncelli statistics of an image ``(H, W)`` or ``(H, W, C)`` (paper section 3).

    Colour images are described jointly: the cross-orientation and cross-scale correlations
    run over every (orientation, channel) pair, plus the colour covariance (Vacher and Briand
    2021, section 4).

    Parameters
    ----------
    image : ndarray
        The image whose pyramid statistics are measured.
    n_scales, n_orientations : int
        Pyramid size (the paper uses 4 and 4).
    lags : int
        Half-width of the auto-correlation windows (``N_a = 2 lags + 1``; the paper uses 7).
    pyramid : ComplexSteerablePyramid, optional
        A pyramid of the image's size (built when omitted).
    pixels : ndarray, optional
        Take the pixel statistics (moments, range, colour covariance) from these channels
        ``(C, H', W')`` instead of from ``image`` (the method measures them on the exemplar
        itself and everything spatial on its periodic component).

    Examples
    --------
    >>> stats = ps_statistics(np.random.default_rng(0).random((32, 32)), n_scales=2, lags=1)
    >>> stats.n_scales, stats.n_orientations, stats.magnitude_autocorr[0].shape
    (2, 4, (1, 4, 3, 3))
    """
    img = np.asarray(image, dtype=np.float64)
    x = img[None] if img.ndim == 2 else np.moveaxis(img, -1, 0)
    pyramid = pyramid or ComplexSteerablePyramid(x.shape[1:], n_scales, n_orientations)
    c = x.shape[0]
    pixel_moments, value_range, covariance = pixel_statistics(x if pixels is None else pixels)
    highpass, bands, lows, spectra = pyramid.forward(x, spectra=True)
    lows[-1] = lows[-1] - lows[-1].mean(axis=(-2, -1), keepdims=True)
    # partially reconstructed low-pass images, coarse to fine
    partial: list[np.ndarray] = [np.empty(0)] * (pyramid.n_scales + 1)
    partial[-1] = pyramid.lowpass_image(lows[-1])
    for s in range(pyramid.n_scales - 1, -1, -1):
        partial[s] = pyramid.reconstruct_level(partial[s + 1], bands[s].real, s)
    low_sk = np.stack([np.stack(moments(p)[2:], axis=-1) for p in partial], axis=1)
    magnitude_autocorr: list[np.ndarray] = []
    magnitude_cross: list[np.ndarray] = []
    magnitude_parent: list[np.ndarray] = []
    real_cross: list[np.ndarray] = []
    real_parent: list[np.ndarray] = []
    for s, band in enumerate(bands):
        k = band.shape[1]
        mags = np.abs(band)
        mags = mags - mags.mean(axis=(-2, -1), keepdims=True)
        magnitude_autocorr.append(central_autocorrelation(mags, lags))
        n = mags.shape[-1] * mags.shape[-2]
        m = mags.reshape(c * k, n).T
        r = band.real.reshape(c * k, n).T
        magnitude_cross.append(m.T @ m / n)
        real_cross.append(r.T @ r / n)
        parent_mags, parent_reals = parent_features(pyramid, spectra, lows, s)
        if parent_mags is not None:
            magnitude_parent.append(m.T @ parent_mags / n)
        real_parent.append(r.T @ parent_reals / n)
    return PSStatistics(
        pixel_moments=pixel_moments,
        pixel_range=value_range,
        colour_covariance=covariance,
        low_skew_kurt=low_sk,
        low_autocorr=tuple(central_autocorrelation(p, lags) for p in partial),
        magnitude_means=np.stack([np.abs(b).mean(axis=(-2, -1)) for b in bands]),
        magnitude_autocorr=tuple(magnitude_autocorr),
        magnitude_cross=tuple(magnitude_cross),
        magnitude_parent=tuple(magnitude_parent),
        real_cross=tuple(real_cross),
        real_parent=tuple(real_parent),
        highpass_variance=np.mean(highpass**2, axis=(-2, -1)),
        shape=tuple(x.shape[1:]),
    )
