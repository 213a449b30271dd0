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

Why this module is long: besides the transform itself it holds its workspace
(:class:`PyramidWorkspace`) and the two passes of each 2-D transform written into given
arrays, which an iterative method (Heeger-Bergen) needs so that no large array is made per
iteration (issue 20); they belong with the transform whose bytes they must reproduce.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from math import factorial

import numpy as np

from ..ops.allocator import scratch_empty
from .coefficients import Coefficients

__all__ = [
    "Pyramid",
    "PyramidWorkspace",
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


@dataclass
class PyramidWorkspace:
    """Scratch spectra of :meth:`SteerablePyramid.forward` and :meth:`SteerablePyramid.inverse`,
    made once (:meth:`SteerablePyramid.workspace`) and passed to every transform of an
    iterative method.

    Arrays of 32 MiB and more (a 2048x2048 colour half spectrum is 100 MB) are mapped afresh
    by the allocator at every allocation and the kernel clears their pages: made once, they
    are not (issue 20; ``docs/methods/heeger_bergen.md``, "Performance"). Which arrays hold
    the scratch does not change any value.

    Attributes
    ----------
    channels : int or None
        The images' channels (``None``: 2-D images).
    spectra : list of tuple of ndarray
        Three complex half spectra of every level ``0 ... n_scales``, ``(C, h, w // 2 + 1)``
        (``(h, w // 2 + 1)`` without channels).
    conjugate : list of ndarray
        One complex array of every band level's filter shape, for a filter's conjugate.
    """

    channels: int | None
    spectra: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    conjugate: list[np.ndarray]


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


def oriented_windows(
    theta: np.ndarray, highpass: np.ndarray, n_orientations: int, *, single: bool = False
) -> np.ndarray:
    """The ``K`` oriented band filters ``(-i)^(K-1) alpha cos^(K-1)(theta - pi b / K) H(r)``.

    ``alpha`` makes ``sum_b |G_b|^2 = H^2`` (Simoncelli and Freeman 1995). Returns ``(K, ...)``.

    ``single``: the filters are to be rounded to single precision (complex64), and rounded
    so they are those of ``single=False`` to the last bit. The power is then taken of the
    cosines' absolute values and the sign put back: NumPy's power of a negative number runs
    about 20 times slower than of a positive one (SIMD ``pow``), and the two agree to the
    last bit of double precision in about 99 % of the values, to within one unit of it in
    the others. Such a unit can change a rounding to single precision (about ``2^-29`` of
    the values; a chosen ``highpass`` makes it happen at will), so every value within
    :data:`_SINGLE_ROUNDING_MARGIN` units of a single-precision rounding boundary is
    computed again with the plain power (:func:`_plain_power_near_single_roundings`): about
    one value in a million, the same bytes by construction. A 256x256 synthesis pyramid is
    built in 14 instead of 26 ms of CPU (issue 20), plus about 3 ms for the check (16.5
    against 13.6 ms, alternated runs on the 2-core machine).
    """
    k = int(n_orientations)
    alpha = 2.0 ** (k - 1) * factorial(k - 1) / np.sqrt(k * factorial(2 * (k - 1)))
    angles = np.pi * np.arange(k) / k
    cosines = np.cos(theta[None] - angles.reshape((k,) + (1,) * theta.ndim))
    scale = (-1j) ** (k - 1) * alpha
    if not single:
        return scale * cosines ** (k - 1) * highpass[None]
    powers = np.power(np.abs(cosines), k - 1)
    if (k - 1) % 2:
        np.copysign(powers, cosines, out=powers)
    out = np.ascontiguousarray(scale * powers * highpass[None])
    _plain_power_near_single_roundings(out, cosines, highpass[None], scale, k - 1)
    return out


#: units in the last place of double precision within which :func:`oriented_windows` takes
#: a value near a single-precision rounding boundary again with the plain power (the two
#: powers differ by at most one unit; the products after them by a few)
_SINGLE_ROUNDING_MARGIN = 1 << 8


def _plain_power_near_single_roundings(
    out: np.ndarray, cosines: np.ndarray, highpass: np.ndarray, scale: complex, power: int
) -> None:
    """Recompute, as ``scale * cosines ** power * highpass``, the values of ``out`` whose
    real or imaginary part could round to another single-precision number if it were a few
    units of double precision away: those within :data:`_SINGLE_ROUNDING_MARGIN` units of
    the midpoint between two single-precision numbers (the 29 bits that rounding drops), and
    those in or near single precision's subnormal range (from ``2^-151`` to ``2^-126``).

    Parameters
    ----------
    out : ndarray of complex128, C-contiguous
        The filters computed with another power; corrected in place.
    cosines, highpass : ndarray of float64
        The factors of the plain computation, of ``out``'s shape or broadcast to it.
    scale : complex
        Its constant factor.
    power : int
        The cosines' exponent.
    """
    bits = out.reshape(-1).view(np.uint64)  # real, imaginary, real, ...
    dropped = bits & np.uint64((1 << 29) - 1)
    dropped -= np.uint64((1 << 28) - _SINGLE_ROUNDING_MARGIN)  # wraps around below the window
    near = dropped <= np.uint64(2 * _SINGLE_ROUNDING_MARGIN)
    exponents = (bits >> np.uint64(52)) & np.uint64(0x7FF)
    exponents -= np.uint64(1023 - 151)
    near |= exponents < np.uint64(151 - 126 + 1)
    if not near.any():
        return
    at = np.unravel_index(np.flatnonzero(near.reshape(-1, 2).any(axis=1)), out.shape)
    out[at] = scale * cosines[at] ** power * np.broadcast_to(highpass, out.shape)[at]


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

    def workspace(self, channels: int | None = None) -> PyramidWorkspace:
        """Scratch arrays for the transforms of ``(H, W, channels)`` images (``(H, W)`` ones
        when ``channels`` is ``None``): :class:`PyramidWorkspace`."""
        lead = () if channels is None else (int(channels),)

        def half(size: tuple[int, int]) -> np.ndarray:
            return scratch_empty(lead + (size[0], size[1] // 2 + 1), dtype=complex)

        spectra = [(half(size), half(size), half(size)) for size in self.sizes]
        conjugate = [scratch_empty(oriented[0].shape, dtype=complex) for _, oriented in self._filters]
        return PyramidWorkspace(
            channels=None if channels is None else int(channels), spectra=spectra, conjugate=conjugate
        )

    def _coefficients(self, channels: int | None) -> Pyramid:
        """A :class:`Pyramid` of uninitialised coefficients (``(h, w, C)`` views of ``(C, h, w)``
        planes, :func:`texsyn.ops.allocator.scratch_empty`), for :meth:`forward` to write into."""
        lead = () if channels is None else (channels,)
        nd = len(lead) + 2

        def band(size: tuple[int, int]) -> np.ndarray:
            return _channels_last(scratch_empty(lead + size), nd)

        bands = [[band(size) for _ in range(self.n_orientations)] for size in self.sizes[:-1]]
        return Pyramid(highpass=band(self.shape), bands=bands, lowpass=band(self.sizes[-1]))

    def _scratch(self, workspace: PyramidWorkspace | None, channels: int | None) -> PyramidWorkspace:
        """``workspace``, checked against images of ``channels`` channels, or a fresh one."""
        if workspace is None:
            return self.workspace(channels)
        if workspace.channels != channels or workspace.spectra[0][0].shape[-2:] != (
            self.shape[0],
            self.shape[1] // 2 + 1,
        ):
            raise ValueError(f"the workspace was made for other images than {self.shape + (channels,)}")
        return workspace

    def _check(self, image: np.ndarray) -> np.ndarray:
        img = np.asarray(image, dtype=np.float64)
        if img.shape[:2] != self.shape:
            raise ValueError(f"image shape {img.shape[:2]} does not match the pyramid's {self.shape}")
        return img

    def forward(
        self, image: np.ndarray, *, out: Pyramid | None = None, workspace: PyramidWorkspace | None = None
    ) -> Pyramid:
        """Analyse an image into a :class:`Pyramid`.

        ``out``, a :class:`Pyramid` that ``forward`` gave earlier for an image of the same
        shape and that is no longer needed, receives the coefficients in its arrays (an
        iterative method reuses them instead of faulting in fresh pages: arrays of 32 MiB and
        more are mapped afresh at every allocation; issue 20), and ``workspace``
        (:meth:`workspace`) holds the spectra (and, without ``out``, gives the coefficients
        their arrays, :func:`texsyn.ops.allocator.scratch_empty`). Same bytes either way.

        The channels of an ``(H, W, C)`` image are transformed as contiguous ``(C, H, W)``
        planes (the coefficients are ``(h, w, C)`` views of such planes): the transforms
        along the columns then read contiguous lines instead of lines strided by ``C``
        values, which at 2048x2048 missed the caches and grew faster than the pixel count
        (issue 20). Each line's transform is the same, so the bytes are too. The 2-D
        transforms are ``rfft2``'s and ``irfft2``'s two passes (:func:`_rfft2`,
        :func:`_irfft2`), written into the workspace.
        """
        img = self._check(image)
        channels = img.shape[2] if img.ndim == 3 else None
        ws = self._scratch(workspace, channels)
        if out is None and workspace is not None:  # the coefficients an iterative method reuses
            out = self._coefficients(channels)
        planes = np.ascontiguousarray(np.moveaxis(img, -1, 0)) if img.ndim == 3 else img
        spec, product, half = ws.spectra[0]
        _rfft2(planes, product, spec)
        nd = img.ndim
        np.multiply(spec, self._hi0, out=product)
        highpass = _irfft2(product, self.shape, half, None if out is None else out.highpass, nd)
        low = np.multiply(spec, self._lo0, out=spec)
        bands = []
        for level in range(self.n_scales):
            size = self.sizes[level]
            lo, oriented = self._filters[level]
            _, product, half = ws.spectra[level]
            previous = [None] * len(oriented) if out is None else out.bands[level]
            bands.append(
                [
                    _irfft2(np.multiply(low, g, out=product), size, half, reuse, nd)
                    for g, reuse in zip(oriented, previous)
                ]
            )
            coarse = ws.spectra[level + 1][0]
            low = self._down(np.multiply(low, lo, out=low), size, self.sizes[level + 1], product, coarse)
        _, _, half = ws.spectra[-1]
        lowpass = _irfft2(low, self.sizes[-1], half, None if out is None else out.lowpass, nd)
        return Pyramid(highpass=highpass, bands=bands, lowpass=lowpass)

    def inverse(
        self, pyramid: Pyramid, *, workspace: PyramidWorkspace | None = None, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Synthesise the image from its coefficients (adjoint of :meth:`forward`; channels as
        ``(C, H, W)`` planes, as there).

        ``workspace`` (:meth:`workspace`) holds the spectra; the image is written into
        ``out`` when given (an ``(H, W, C)`` view of ``(C, H, W)`` planes, as the images
        this method returns, that is no longer needed). Same bytes either way.
        """
        if pyramid.lowpass is None:
            raise ValueError("the pyramid has no low-pass residual")
        lowpass = np.asarray(pyramid.lowpass)
        nd = lowpass.ndim
        ws = self._scratch(workspace, lowpass.shape[2] if nd == 3 else None)
        low, rows, _ = ws.spectra[-1]
        _rfft2(_channels_first(lowpass, nd), rows, low)
        for level in reversed(range(self.n_scales)):
            size = self.sizes[level]
            lo, oriented = self._filters[level]
            fine, rows, spectrum = ws.spectra[level]
            low = self._up(low, self.sizes[level + 1], size, fine)
            low *= lo
            conjugate = ws.conjugate[level]
            for g, band in zip(oriented, pyramid.bands[level]):
                _rfft2(_channels_first(band, nd), rows, spectrum)
                low += np.multiply(spectrum, np.conjugate(g, out=conjugate), out=spectrum)
        spec = np.multiply(low, self._lo0, out=low)
        spectrum = _rfft2(_channels_first(pyramid.highpass, nd), rows, spectrum)
        spec += np.multiply(spectrum, self._hi0, out=spectrum)
        reuse = out if out is not None and _writable_planes(out, nd, self.shape) else None
        return _irfft2(spec, self.shape, rows, reuse, nd)

    @staticmethod
    def _down(
        spec: np.ndarray, fine: tuple[int, int], coarse: tuple[int, int], scratch: np.ndarray, out: np.ndarray
    ) -> np.ndarray:
        """The spectrum of size ``coarse`` cropped from ``spec``, scaled, in ``out``
        (``spec[..., rows, :][..., cols] * scale``; ``scratch``, as large as ``spec``, holds
        the rows)."""
        rows = crop_indices(fine[0], coarse[0])
        cols = np.arange(coarse[1] // 2 + 1)
        scale = (coarse[0] * coarse[1]) / (fine[0] * fine[1])
        shape = spec.shape[:-2] + (rows.size, spec.shape[-1])
        cropped = np.take(
            spec, rows, axis=-2, mode="clip", out=scratch.reshape(-1)[: math.prod(shape)].reshape(shape)
        )
        np.take(cropped, cols, axis=-1, mode="clip", out=out)  # in range: no buffered copy
        out *= scale
        return out

    @staticmethod
    def _up(spec: np.ndarray, coarse: tuple[int, int], fine: tuple[int, int], out: np.ndarray) -> np.ndarray:
        """The spectrum of size ``fine`` that zero-pads ``spec``, scaled, in ``out`` (``spec``
        is scaled in place)."""
        rows = crop_indices(fine[0], coarse[0])
        out.fill(0)
        scale = (fine[0] * fine[1]) / (coarse[0] * coarse[1])
        spec *= scale
        out[..., rows, : coarse[1] // 2 + 1] = spec
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


def _writable_planes(image: np.ndarray, ndim: int, shape: tuple[int, int]) -> bool:
    """Whether ``image`` is a float64 ``(H, W, C)`` view of C-contiguous ``(C, H, W)`` planes
    (a C-contiguous ``(H, W)`` array without channels) of size ``shape``."""
    planes = _channels_first(image, ndim)
    return planes.dtype == np.float64 and planes.flags.c_contiguous and planes.shape[-2:] == shape


def _channels_last(planes: np.ndarray, ndim: int) -> np.ndarray:
    """``(C, H, W)`` planes as an ``(H, W, C)`` view (a 2-D array as it is)."""
    return np.moveaxis(planes, 0, -1) if ndim == 3 else planes


def _channels_first(image: np.ndarray, ndim: int) -> np.ndarray:
    """An ``(H, W, C)`` array as ``(C, H, W)`` planes (a view: contiguous when the array is a
    view of such planes, as :meth:`SteerablePyramid.forward` gives them)."""
    return np.moveaxis(np.asarray(image), -1, 0) if ndim == 3 else np.asarray(image)
