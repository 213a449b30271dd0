"""Gaussian filtering, Gaussian zoom-out, Fourier zoom-in, Gaussian pyramids and the
Laplacian tight frame.

The zooms follow Raad, Desolneux and Morel (2016, section 3: eq. 9-12); the tight frame is
the undecimated Laplacian pyramid of Peyré's grouplets (2008, section 2.3). Levels are
0-based, the finest (the image itself) first.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..ops.linalg import parallel_map, worker_count
from .steerable import radial_lowpass

__all__ = [
    "SPECTRUM_VALUES",
    "LaplacianTightFrame",
    "crop_to_multiple",
    "gaussian_blur",
    "gaussian_pyramid",
    "zoom_in",
    "zoom_out",
]


#: complex values of the filtered spectra one FFT call of :class:`LaplacianTightFrame` holds:
#: 16 MB, so that a large stack's temporaries are reused by the allocator instead of being
#: new pages faulted in at every call (glibc maps blocks above 32 MB afresh each time;
#: ``docs/methods/grouplets.md``, "Performance")
SPECTRUM_VALUES = 1 << 20


def gaussian_blur(image: np.ndarray, sigma: float, *, mode: str = "symmetric") -> np.ndarray:
    """Gaussian filter of standard deviation ``sigma`` pixels on the spatial axes only.

    ``mode='symmetric'`` mirrors with the edge sample repeated (SciPy ``'reflect'``);
    ``mode='periodic'`` multiplies the spectrum by ``exp(-2 pi^2 sigma^2 |k|^2)`` (exact for
    periodic images).
    """
    img = np.asarray(image, dtype=np.float64)
    if mode == "symmetric":
        if sigma <= 1e-15:  # SciPy skips the axes of a zero sigma
            return img.copy()
        return _correlate_reflect(_correlate_reflect(img, sigma, 0), sigma, 1)
    if mode == "periodic":
        ky = np.fft.fftfreq(img.shape[0])[:, None]
        kx = np.fft.rfftfreq(img.shape[1])[None, :]
        mult = np.exp(-2.0 * np.pi**2 * sigma**2 * (kx**2 + ky**2))
        if img.ndim == 3:
            mult = mult[..., None]
        spec = np.fft.rfft2(img, axes=(0, 1)) * mult
        return np.fft.irfft2(spec, s=img.shape[:2], axes=(0, 1))
    raise ValueError(f"mode must be 'symmetric' or 'periodic', got {mode!r}")


def _correlate_reflect(x: np.ndarray, sigma: float, axis: int) -> np.ndarray:
    """``scipy.ndimage.gaussian_filter1d(x, sigma, axis, mode="reflect", truncate=4.0)``, same bytes.

    SciPy's weights (``_gaussian_kernel1d``: radius ``int(4 sigma + 0.5)``, ``exp(-x^2 / 2
    sigma^2)`` normalised by its sum) and the arithmetic of its symmetric 1-D correlation
    (``x[i] w_0``, then ``(x[i - j] + x[i + j]) w_j`` added from the outermost tap in) on the
    half-sample mirror extension, in NumPy: without importing ``scipy.ndimage`` (0.15 s of
    start-up for ``texsyn synth -m wei_levoy``, ``docs/performance.md``).
    """
    radius = int(4.0 * float(sigma) + 0.5)
    taps = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sigma * sigma) * taps**2)
    weights = (phi / phi.sum())[::-1]
    n = x.shape[axis]
    period = np.arange(-radius, n + radius) % (2 * n)  # d c b a | a b c d | d c b a
    ext = np.take(np.moveaxis(x, axis, 0), np.where(period < n, period, 2 * n - 1 - period), axis=0)
    out = ext[radius : radius + n] * weights[radius]
    for j in range(-radius, 0):
        out += (ext[radius + j : radius + j + n] + ext[radius - j : radius - j + n]) * weights[radius + j]
    return np.ascontiguousarray(np.moveaxis(out, 0, axis))  # C order, as SciPy's output


def zoom_out(image: np.ndarray, sigma: float = 1.4, *, mode: str = "symmetric") -> np.ndarray:
    """Gaussian zoom-out ``S_2(u * G_sigma)``: blur, then keep even rows and columns.

    References
    ----------
    Raad, Desolneux, Morel (2016), eq. (9)-(11), sigma = 1.4.
    """
    return gaussian_blur(image, sigma, mode=mode)[::2, ::2]


def zoom_in(image: np.ndarray, *, boundary: str = "symmetric") -> np.ndarray:
    """Fourier zoom-in by 2 (Raad et al. 2016, eq. 12).

    Keeps the frequencies ``|xi_1| <= (M-1)//2``, ``|xi_2| <= (N-1)//2`` of the ``M x N``
    image in a ``2M x 2N`` spectrum. With ``boundary='symmetric'`` (default) the zoom is
    applied to the half-sample mirror extension and the top-left quarter is kept, which avoids
    ringing along the borders; ``boundary='periodic'`` follows the paper literally.
    """
    u = np.asarray(image, dtype=np.float64)
    if boundary == "symmetric":
        ext = np.concatenate([u, u[::-1]], axis=0)
        ext = np.concatenate([ext, ext[:, ::-1]], axis=1)
        big = zoom_in(ext, boundary="periodic")
        return big[: 2 * u.shape[0], : 2 * u.shape[1]]
    if boundary != "periodic":
        raise ValueError(f"boundary must be 'symmetric' or 'periodic', got {boundary!r}")
    m, n = u.shape[:2]
    h1, h2 = (m - 1) // 2, (n - 1) // 2
    spec = np.fft.fftshift(np.fft.fft2(u, axes=(0, 1)), axes=(0, 1))
    big = np.zeros((2 * m, 2 * n) + u.shape[2:], dtype=complex)
    big[m - h1 : m + h1 + 1, n - h2 : n + h2 + 1] = spec[
        m // 2 - h1 : m // 2 + h1 + 1, n // 2 - h2 : n // 2 + h2 + 1
    ]
    return 4.0 * np.real(np.fft.ifft2(np.fft.ifftshift(big, axes=(0, 1)), axes=(0, 1)))


def crop_to_multiple(image: np.ndarray, q: int) -> np.ndarray:
    """Crop an exemplar to the largest size whose sides are multiples of ``q``."""
    h = (image.shape[0] // q) * q
    w = (image.shape[1] // q) * q
    if h == 0 or w == 0:
        raise ValueError(
            f"image of {image.shape[1]}x{image.shape[0]} pixels is too small for {q}-divisible sizes"
        )
    return image[:h, :w]


def gaussian_pyramid(
    image: np.ndarray, levels: int, *, sigma: float = 1.0, mode: str = "symmetric"
) -> list[np.ndarray]:
    """Gaussian pyramid ``[u, zoom_out(u), zoom_out^2(u), ...]`` with ``levels`` images."""
    if levels < 1:
        raise ValueError(f"levels must be at least 1, got {levels}")
    out = [np.asarray(image, dtype=np.float64)]
    for _ in range(levels - 1):
        if min(out[-1].shape[:2]) < 2:
            raise ValueError(
                f"image of {image.shape[1]}x{image.shape[0]} pixels is too small for {levels} levels"
            )
        out.append(zoom_out(out[-1], sigma, mode=mode))
    return out


def _on_workers(transform, lines: int) -> None:
    """``transform(slice)`` of ``lines`` lines, split into one contiguous run per worker thread
    (NumPy's FFTs release the GIL; each line is computed alone, so the bytes do not depend on
    the split)."""
    workers = max(1, min(worker_count(), lines))
    bounds = [lines * i // workers for i in range(workers + 1)]
    parallel_map(transform, [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])])


def _filtered(
    x: np.ndarray,
    spectral: Callable[[np.ndarray, slice], object],
    columns: np.ndarray,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """``irfft2(spectral(rfft2(x)))`` over the last two axes, with the bytes of ``scipy.fft``'s
    transforms, on texsyn's worker threads.

    NumPy's FFT is the same pocketfft (``rfft2``: rows, then columns; ``irfft2``: columns,
    then rows, scaled by ``1 / (H W)`` once at the end, which is NumPy's unscaled inverse times
    that factor), so the grouplet method does not import ``scipy.fft``
    (``docs/methods/grouplets.md``, "Performance"). The work is split in runs of rows, then of
    columns, then of rows: each worker filters its columns between their forward and inverse
    transforms (``spectral(columns of the spectra, slice)`` writes the filtered columns into
    that slice of ``columns``, complex, of shape ``(..., H, W // 2 + 1)``), so the filtering
    runs on the threads with no pass of its own. Every line is computed alone, so the bytes
    do not depend on the split. ``out``: where to write the images.
    """
    h, w = x.shape[-2:]
    spectrum = np.empty(x.shape[:-1] + (w // 2 + 1,), dtype=np.complex128)
    image = np.empty(columns.shape[:-1] + (w,)) if out is None else out

    def forward_rows(rows: slice) -> None:
        np.fft.rfft(x[..., rows, :], axis=-1, out=spectrum[..., rows, :])

    def filter_columns(cols: slice) -> None:
        np.fft.fft(spectrum[..., cols], axis=-2, out=spectrum[..., cols])
        spectral(spectrum[..., cols], cols)
        np.fft.ifft(columns[..., cols], axis=-2, norm="forward", out=columns[..., cols])

    def inverse_rows(rows: slice) -> None:
        np.fft.irfft(columns[..., rows, :], n=w, axis=-1, norm="forward", out=image[..., rows, :])
        image[..., rows, :] *= 1.0 / (h * w)

    _on_workers(forward_rows, h)
    _on_workers(filter_columns, w // 2 + 1)
    _on_workers(inverse_rows, h)
    return image


class LaplacianTightFrame:
    """Translation-invariant Laplacian pyramid as a Parseval tight frame.

    Radial Fourier filters ``Psi_j`` (``j < J``) and ``Phi_J`` with ``sum Psi_j^2 + Phi_J^2 = 1``:
    undecimated, non-oriented bands of the full image size, exact reconstruction and
    ``sum_j ||f_j||^2 = ||f||^2``. Periodic. Used by the wavelet-grouplet transform (Peyré
    2008, section 2.3; the paper's weights ``kappa_j`` are absorbed in the filters).

    Parameters
    ----------
    shape : (int, int)
        Image size ``(H, W)``.
    levels : int
        Number ``J`` of detail bands; the transform returns ``J + 1`` bands.
    """

    def __init__(self, shape: tuple[int, int], levels: int = 3):
        h, w = shape
        self.shape = (int(h), int(w))
        self.levels = int(levels)
        kr = np.fft.fftfreq(h)[:, None]
        kc = np.fft.rfftfreq(w)[None, :]
        radius = 2 * np.pi * np.sqrt(kr**2 + kc**2)

        phis = [np.ones_like(radius)] + [
            radial_lowpass(2 ** (j - 1) * radius) for j in range(1, self.levels + 1)
        ]
        self.filters = np.stack(
            [np.sqrt(np.maximum(phis[j] ** 2 - phis[j + 1] ** 2, 0.0)) for j in range(self.levels)]
            + [phis[-1]]
        )

    def forward(self, image: np.ndarray) -> np.ndarray:
        """Bands ``(J+1, H, W[, C])`` of an image ``(H, W[, C])``; band ``J`` is the low-pass."""
        x = np.asarray(image, dtype=np.float64)
        if x.shape[:2] != self.shape:
            raise ValueError(f"image has size {x.shape[:2]}, the frame was built for {self.shape}")
        spectrum = np.fft.rfft2(x, axes=(0, 1))
        filt = self.filters if x.ndim == 2 else self.filters[..., None]
        return np.fft.irfft2(filt * spectrum[None], s=self.shape, axes=(1, 2))

    def inverse(self, bands: np.ndarray) -> np.ndarray:
        """Image from its bands (the adjoint, which is the exact inverse of a tight frame)."""
        b = np.asarray(bands, dtype=np.float64)
        spectra = np.fft.rfft2(b, axes=(1, 2))
        filt = self.filters if b.ndim == 3 else self.filters[..., None]
        return np.fft.irfft2(np.sum(filt * spectra, axis=0), s=self.shape, axes=(0, 1))

    def forward_planes(self, planes: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
        """Bands ``(J+1, B, H, W)`` of a stack of images ``(B, H, W)``, contiguous.

        The same transform as :meth:`forward` with the images first, as the grouplet frame
        reads them; the 2-D FFTs of the stack run on texsyn's worker threads (each one is
        computed the same way on any thread, so the result does not depend on their number).
        The images are transformed a few at a time (:data:`SPECTRUM_VALUES`), so the
        temporaries of a large stack stay small; ``out`` (C-contiguous, ``(J+1, B, H, W)``)
        receives the bands, a buffer an iterative method reuses.
        """
        x = np.asarray(planes, dtype=np.float64)
        if x.ndim != 3 or x.shape[1:] != self.shape:
            raise ValueError(f"planes must have shape (B, {self.shape[0]}, {self.shape[1]}), got {x.shape}")
        shape = (self.filters.shape[0],) + x.shape
        if out is not None and (out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous):
            raise ValueError(f"out must be a C-contiguous float64 array of shape {shape}")
        step = self._chunk(x.shape[0])
        if out is None and step >= x.shape[0]:
            return self._forward_chunk(x, None)
        result = np.empty(shape) if out is None else out
        product: np.ndarray | None = None
        for b0 in range(0, x.shape[0], step):
            chunk = x[b0 : b0 + step]
            if product is None or len(product[0]) != len(chunk):
                product = np.empty(
                    (len(self.filters), len(chunk)) + self.filters[0].shape, dtype=np.complex128
                )
            self._forward_chunk(chunk, product, result[:, b0 : b0 + step])
        return result

    def _forward_chunk(
        self, x: np.ndarray, product: np.ndarray | None, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Bands ``(J+1, b, H, W)`` of ``b`` images; ``product``: where to filter their spectra,
        ``out``: where to write the bands."""
        bands = (len(self.filters),) + x.shape[:-1] + self.filters[0].shape[-1:]
        product = np.empty(bands, dtype=np.complex128) if product is None else product
        filters = self.filters[:, None]

        def band_spectra(spectra: np.ndarray, cols: slice) -> None:
            np.multiply(filters[..., cols], spectra[None], out=product[..., cols])

        return _filtered(x, band_spectra, product, out)

    def inverse_planes(self, bands: np.ndarray) -> np.ndarray:
        """Images ``(B, H, W)`` from bands ``(J+1, B, H, W)`` (the adjoint of :meth:`forward_planes`).

        The images are computed a few at a time, as in :meth:`forward_planes`.
        """
        b = np.asarray(bands, dtype=np.float64)
        step = self._chunk(b.shape[1])
        images = []
        for b0 in range(0, b.shape[1], step):
            chunk = b[:, b0 : b0 + step]
            total = np.empty(chunk.shape[1:-1] + self.filters[0].shape[-1:], dtype=np.complex128)

            def band_sum(spectra: np.ndarray, cols: slice, total: np.ndarray = total) -> None:
                # sum_j filter_j spectrum_j of these columns (the spectra are overwritten)
                np.sum(
                    np.multiply(self.filters[:, None, :, cols], spectra, out=spectra),
                    axis=0,
                    out=total[..., cols],
                )

            images.append(_filtered(chunk, band_sum, total))
        return images[0] if len(images) == 1 else np.concatenate(images)

    def _chunk(self, planes: int) -> int:
        """Images per FFT call: the filtered spectra of all ``J+1`` bands within :data:`SPECTRUM_VALUES`."""
        per_image = self.filters.shape[0] * self.filters.shape[1] * self.filters.shape[2]
        return max(1, min(planes, SPECTRUM_VALUES // per_image))
