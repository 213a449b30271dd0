"""Steerable pyramid built in the Fourier domain, for any image size.

The transform follows Simoncelli and Freeman (1995) and the pyramid of Portilla and
Simoncelli's texture model (2000): a first split into a high-pass residual and a low-pass
band, then at every scale ``K`` oriented band-pass subbands and a low-pass band that is
down-sampled by two by cropping its spectrum. Levels are 0-based, the finest first. The radial and angular windows satisfy

    |L0|^2 + |H0|^2 = 1,    |L|^2 + |H|^2 sum_k |G_k|^2 = 1,

so analysis followed by synthesis with the same (adjoint) filters is the identity. Because
the low-pass window vanishes beyond half the band, cropping the spectrum is exact for every
image size (odd sizes included) and no power-of-two restriction is needed.

The oriented bands here are real (the ``(-i)^(K-1) cos^(K-1)`` angular window); the complex
(analytic) bands of Portilla-Simoncelli are obtained by doubling the window on one half-plane
(:mod:`texsyn.transforms.complex_steerable`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from math import factorial

import numpy as np

from .coefficients import Coefficients

__all__ = [
    "Pyramid",
    "SteerablePyramid",
    "crop_indices",
    "max_scales",
    "oriented_windows",
    "pyramid_sizes",
    "radial_lowpass",
]


@dataclass
class Pyramid(Coefficients):
    """Coefficients of a steerable pyramid (a :class:`~texsyn.transforms.coefficients.Coefficients`).

    Attributes
    ----------
    highpass : ndarray
        High-pass residual, full size.
    bands : list of list of ndarray
        ``bands[level][orientation]``; level 0 is the finest.
    lowpass : ndarray
        Low-pass residual at the coarsest size.

    Coefficients can also be addressed as ``pyr['highpass']``, ``pyr['lowpass']`` and
    ``pyr[level, orientation]``; :meth:`keys` lists every address in a fixed order.
    """

    highpass: np.ndarray
    bands: list[list[np.ndarray]] = field(default_factory=list)
    lowpass: np.ndarray | None = None

    @property
    def levels(self) -> int:
        """Number of band levels."""
        return len(self.bands)

    def keys(self) -> list:
        out: list = ["highpass"]
        out += [(lev, b) for lev in range(len(self.bands)) for b in range(len(self.bands[lev]))]
        out.append("lowpass")
        return out

    def __getitem__(self, key):
        if key == "highpass":
            return self.highpass
        if key == "lowpass":
            return self.lowpass
        level, band = key
        return self.bands[level][band]

    def __setitem__(self, key, value) -> None:
        if key == "highpass":
            self.highpass = value
        elif key == "lowpass":
            self.lowpass = value
        else:
            level, band = key
            self.bands[level][band] = value


def radial_lowpass(r: np.ndarray) -> np.ndarray:
    """Low-pass radial window ``L(r)``: 1 below pi/4, 0 above pi/2, cosine in log2 between.

    The window of the steerable pyramid (Simoncelli and Freeman 1995; Portilla and Simoncelli 2000) and of
    the Laplacian tight frame
    (:class:`texsyn.transforms.pyramids.LaplacianTightFrame`); ``r`` in radians per pixel.
    """
    with np.errstate(divide="ignore"):
        lg = np.log2(np.maximum(r, 1e-300) * 4.0 / np.pi)
    out = np.cos(0.5 * np.pi * np.clip(lg, 0.0, 1.0))
    return np.where(r <= np.pi / 4, 1.0, np.where(r >= np.pi / 2, 0.0, out))


def max_scales(shape: tuple[int, int], wanted: int = 4) -> int:
    """The largest number of pyramid scales up to ``wanted`` that an image of ``shape`` supports.

    :class:`texsyn.transforms.complex_steerable.ComplexSteerablePyramid` needs
    ``2^(scales + 1)`` pixels per side.

    Examples
    --------
    >>> max_scales((64, 64)), max_scales((20, 300)), max_scales((3, 3))
    (4, 3, 1)
    """
    return int(max(1, min(wanted, math.floor(math.log2(max(min(shape), 4))) - 1)))


def _half_size(n: int) -> int:
    return (n + 1) // 2


def crop_indices(n_fine: int, n_coarse: int) -> np.ndarray:
    """Indices of a size-``n_fine`` FFT axis that hold the frequencies of a size-``n_coarse`` FFT.

    Cropping a spectrum to these indices down-samples (and zero-padding into them
    up-samples) a band-limited signal exactly, for odd and even sizes alike.

    Examples
    --------
    >>> crop_indices(8, 4).tolist()
    [0, 1, 6, 7]
    """
    k = np.fft.fftfreq(n_coarse, 1.0 / n_coarse).astype(np.int64)
    return np.mod(k, n_fine)


def pyramid_sizes(shape: tuple[int, int], n_scales: int) -> list[tuple[int, int]]:
    """Sizes of the levels ``0 ... n_scales`` (each the previous one halved, rounded up)."""
    sizes = [(int(shape[0]), int(shape[1]))]
    for _ in range(n_scales):
        h, w = sizes[-1]
        sizes.append((_half_size(h), _half_size(w)))
    return sizes


def oriented_windows(theta: np.ndarray, highpass: np.ndarray, n_orientations: int) -> np.ndarray:
    """The ``K`` oriented band filters ``(-i)^(K-1) alpha cos^(K-1)(theta - pi b / K) H(r)``.

    ``alpha`` makes ``sum_b |G_b|^2 = H^2`` (Simoncelli and Freeman 1995). Returns ``(K, ...)``.
    """
    k = int(n_orientations)
    alpha = 2.0 ** (k - 1) * factorial(k - 1) / np.sqrt(k * factorial(2 * (k - 1)))
    angles = np.pi * np.arange(k) / k
    cosines = np.cos(theta[None] - angles.reshape((k,) + (1,) * theta.ndim))
    return (-1j) ** (k - 1) * alpha * cosines ** (k - 1) * highpass[None]


class SteerablePyramid:
    """Real steerable pyramid of a fixed image shape, computed with real FFTs.

    Parameters
    ----------
    shape : (int, int)
        Image height and width (any sizes of at least ``2^n_scales`` pixels).
    n_scales : int
        Number of band-pass scales.
    n_orientations : int
        Number of oriented bands per scale.

    Notes
    -----
    ``forward`` accepts ``(H, W)`` or ``(H, W, C)`` arrays (channels transformed
    independently in one call); ``inverse(forward(x)) == x`` to rounding error.

    References
    ----------
    E. Simoncelli, W. Freeman, "The steerable pyramid: a flexible architecture for multi-scale
    derivative computation", ICIP 1995. J. Portilla, E. Simoncelli, "A parametric texture
    model based on joint statistics of complex wavelet coefficients", IJCV 40 (2000).
    """

    def __init__(self, shape: tuple[int, int], n_scales: int = 4, n_orientations: int = 4):
        self.shape = (int(shape[0]), int(shape[1]))
        self.n_scales = int(n_scales)
        self.n_orientations = int(n_orientations)
        if self.n_scales < 1 or self.n_orientations < 1:
            raise ValueError("n_scales and n_orientations must be at least 1")
        if min(self.shape) < 2**self.n_scales:
            raise ValueError(
                f"image of {self.shape[1]}x{self.shape[0]} pixels is too small for "
                f"{self.n_scales} scales; need at least {2**self.n_scales} pixels per side"
            )
        self.sizes = pyramid_sizes(self.shape, self.n_scales)
        self._filters = [self._level_filters(s) for s in self.sizes[: self.n_scales]]
        r0, _ = self._polar(self.shape)
        self._lo0 = radial_lowpass(r0 / 2.0)
        self._hi0 = np.sqrt(np.maximum(1.0 - self._lo0**2, 0.0))

    @staticmethod
    def _polar(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        fy = 2 * np.pi * np.fft.fftfreq(shape[0])[:, None]
        fx = 2 * np.pi * np.fft.rfftfreq(shape[1])[None, :]
        return np.hypot(fx, fy), np.arctan2(fy, fx)

    def _level_filters(self, shape: tuple[int, int]):
        r, theta = self._polar(shape)
        lo = radial_lowpass(r)
        hi = np.sqrt(np.maximum(1.0 - lo**2, 0.0))
        return lo, list(oriented_windows(theta, hi, self.n_orientations))

    def band_shape(self, key) -> tuple[int, int]:
        """Size ``(h, w)`` of the coefficient at address ``key`` of a :class:`Pyramid`.

        Examples
        --------
        >>> pyramid = SteerablePyramid((30, 20), n_scales=2, n_orientations=4)
        >>> pyramid.band_shape("highpass"), pyramid.band_shape((1, 3)), pyramid.band_shape("lowpass")
        ((30, 20), (15, 10), (8, 5))
        """
        if key == "highpass":
            return self.sizes[0]
        if key == "lowpass":
            return self.sizes[-1]
        return self.sizes[key[0]]

    def _check(self, image: np.ndarray) -> np.ndarray:
        img = np.asarray(image, dtype=np.float64)
        if img.shape[:2] != self.shape:
            raise ValueError(f"image shape {img.shape[:2]} does not match the pyramid's {self.shape}")
        return img

    def forward(self, image: np.ndarray, *, out: Pyramid | None = None) -> Pyramid:
        """Analyse an image into a :class:`Pyramid`.

        ``out``, a :class:`Pyramid` that ``forward`` gave earlier for an image of the same
        shape and that is no longer needed, receives the coefficients in its arrays (an
        iterative method reuses them instead of faulting in fresh pages: arrays of 32 MiB and
        more are mapped afresh at every allocation; issue 20). Same bytes either way.

        The channels of an ``(H, W, C)`` image are transformed as contiguous ``(C, H, W)``
        planes (the coefficients are ``(h, w, C)`` views of such planes): the transforms
        along the columns then read contiguous lines instead of lines strided by ``C``
        values, which at 2048x2048 missed the caches and grew faster than the pixel count
        (issue 20). Each line's transform is the same, so the bytes are too.
        """
        img = self._check(image)
        planes = np.ascontiguousarray(np.moveaxis(img, -1, 0)) if img.ndim == 3 else img
        spec = np.fft.rfft2(planes)
        product = spec * self._hi0  # one buffer for a level's filtered spectra (fewer fresh pages)
        half = np.empty_like(product)  # and one for their column transforms
        nd = img.ndim
        highpass = _irfft2(product, self.shape, half, None if out is None else out.highpass, nd)
        low = np.multiply(spec, self._lo0, out=spec)
        bands = []
        for level in range(self.n_scales):
            size = self.sizes[level]
            lo, oriented = self._filters[level]
            if level:
                product, half = np.empty_like(low), np.empty_like(low)
            previous = [None] * len(oriented) if out is None else out.bands[level]
            bands.append(
                [
                    _irfft2(np.multiply(low, g, out=product), size, half, reuse, nd)
                    for g, reuse in zip(oriented, previous)
                ]
            )
            low = self._down(np.multiply(low, lo, out=low), size, self.sizes[level + 1])
        lowpass = np.fft.irfft2(low, s=self.sizes[-1])
        return Pyramid(highpass=highpass, bands=bands, lowpass=_channels_last(lowpass, nd))

    def inverse(self, pyramid: Pyramid) -> np.ndarray:
        """Synthesise the image from its coefficients (adjoint of :meth:`forward`; channels as
        ``(C, H, W)`` planes, as there)."""
        if pyramid.lowpass is None:
            raise ValueError("the pyramid has no low-pass residual")
        nd = np.ndim(pyramid.lowpass)
        low = np.fft.rfft2(_channels_first(pyramid.lowpass, nd))
        for level in reversed(range(self.n_scales)):
            size = self.sizes[level]
            lo, oriented = self._filters[level]
            low = self._up(low, self.sizes[level + 1], size)
            low *= lo
            conjugate = np.empty_like(oriented[0])
            rows, spectrum = np.empty_like(low), np.empty_like(low)  # the bands' transforms
            for g, band in zip(oriented, pyramid.bands[level]):
                _rfft2(_channels_first(band, nd), rows, spectrum)
                low += np.multiply(spectrum, np.conjugate(g, out=conjugate), out=spectrum)
        spec = np.multiply(low, self._lo0, out=low)
        spectrum = _rfft2(_channels_first(pyramid.highpass, nd), rows, spectrum)
        spec += np.multiply(spectrum, self._hi0, out=spectrum)
        return _channels_last(np.fft.irfft2(spec, s=self.shape), nd)

    @staticmethod
    def _down(spec: np.ndarray, fine: tuple[int, int], coarse: tuple[int, int]) -> np.ndarray:
        rows = crop_indices(fine[0], coarse[0])
        cols = np.arange(coarse[1] // 2 + 1)
        scale = (coarse[0] * coarse[1]) / (fine[0] * fine[1])
        return spec[..., rows, :][..., cols] * scale

    @staticmethod
    def _up(spec: np.ndarray, coarse: tuple[int, int], fine: tuple[int, int]) -> np.ndarray:
        rows = crop_indices(fine[0], coarse[0])
        out = np.zeros(spec.shape[:-2] + (fine[0], fine[1] // 2 + 1), dtype=complex)
        scale = (fine[0] * fine[1]) / (coarse[0] * coarse[1])
        out[..., rows, : coarse[1] // 2 + 1] = spec * scale
        return out


def _rfft2(x: np.ndarray, rows: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``numpy.fft.rfft2(x)`` in ``out`` (its two passes, as ``rfft2`` makes them: the rows'
    real transforms, in ``rows``, then the columns')."""
    np.fft.rfft(x, axis=-1, out=rows)
    return np.fft.fft(rows, axis=-2, out=out)


def _irfft2(
    spectrum: np.ndarray, size: tuple[int, int], half: np.ndarray, reuse: np.ndarray | None, ndim: int
) -> np.ndarray:
    """``numpy.fft.irfft2(spectrum, s=size)`` as an ``(h, w, C)`` view of ``(C, h, w)`` planes:
    its two passes, as ``irfft2`` makes them (the columns' transforms, in ``half``, then the
    rows' real ones), the result written into ``reuse`` (such a view) when given."""
    np.fft.ifft(spectrum, n=size[0], axis=-2, out=half)
    planes = None if reuse is None else _channels_first(reuse, ndim)
    return _channels_last(np.fft.irfft(half, n=size[1], axis=-1, out=planes), ndim)


def _channels_last(planes: np.ndarray, ndim: int) -> np.ndarray:
    """``(C, H, W)`` planes as an ``(H, W, C)`` view (a 2-D array as it is)."""
    return np.moveaxis(planes, 0, -1) if ndim == 3 else planes


def _channels_first(image: np.ndarray, ndim: int) -> np.ndarray:
    """An ``(H, W, C)`` array as ``(C, H, W)`` planes (a view: contiguous when the array is a
    view of such planes, as :meth:`SteerablePyramid.forward` gives them)."""
    return np.moveaxis(np.asarray(image), -1, 0) if ndim == 3 else np.asarray(image)
