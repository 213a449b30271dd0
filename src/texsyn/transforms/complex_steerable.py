"""The complex (analytic) steerable pyramid of Portilla and Simoncelli.

J. Portilla, E. Simoncelli, "A parametric texture model based on joint statistics of complex
wavelet coefficients", IJCV 40(1), 2000 (their pyramid). The windows are those of
:mod:`texsyn.transforms.steerable`; every oriented band keeps only the half of the spectrum its
orientation points to, doubled, so that its real part is the real steerable band and its
magnitude is a local energy. The pyramid works for any image size (spectra are cropped, which
is exact for odd sizes too) and is batched over channels: images are ``(C, H, W)``.

Besides the plain analysis (:meth:`ComplexSteerablePyramid.forward`) it offers the pieces of
the coarse-to-fine reconstruction that the Portilla–Simoncelli projections need: the
partially reconstructed low-pass images (:meth:`~ComplexSteerablePyramid.lowpass_image`,
:meth:`~ComplexSteerablePyramid.reconstruct_level`), the re-creation of complex bands from
their real parts (:meth:`~ComplexSteerablePyramid.analytic`) and the interpolation of a level
to the next finer size (:meth:`~ComplexSteerablePyramid.expand`). Levels are 0-based, the
finest first (``docs/methods/portilla_simoncelli.md``).

Why this module is long: besides the plain analysis and reconstruction, the synthesis loop
needs forms of them that skip the zero lines of their inputs (:meth:`upsampled_ifft`) or
work on half spectra (:meth:`~ComplexSteerablePyramid.reconstruct_level_half` and the
others of ``rfft2``, with the Nyquist frequencies of zero-padding); they are kept next to
the full forms they must match (``tests/test_portilla_fast_paths.py``).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable

import numpy as np

from ..ops import fft as pocketfft
from ..ops.fft import inverse_norm as inverse_norm  # re-exported (its home before issue 20's eighth round)
from ..ops.linalg import parallel_map, worker_count
from .steerable import crop_indices, oriented_windows, pyramid_sizes, radial_lowpass

__all__ = ["ComplexSteerablePyramid", "fft_workers", "for_each_band", "inverse_norm", "shared_stack"]


@functools.cache
def _crop_runs(n_fine: int, n_coarse: int) -> list[tuple[slice, slice]]:
    """:func:`_runs` of ``crop_indices(n_fine, n_coarse)`` (cached)."""
    return _runs(crop_indices(n_fine, n_coarse))


def _runs(indices: np.ndarray) -> list[tuple[slice, slice]]:
    """The contiguous runs of an index array: ``(slice of the indexed axis, slice of indices)``.

    :func:`~texsyn.transforms.steerable.crop_indices` gives two runs (the non-negative and the
    negative frequencies): copying them as slices moves the same values as fancy indexing,
    without its gather.

    Examples
    --------
    >>> _runs(np.array([0, 1, 6, 7]))
    [(slice(0, 2, None), slice(0, 2, None)), (slice(6, 8, None), slice(2, 4, None))]
    """
    cuts = np.flatnonzero(np.diff(indices) != 1) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [len(indices)]])
    return [
        (slice(int(indices[a]), int(indices[b - 1]) + 1), slice(int(a), int(b)))
        for a, b in zip(starts, stops)
    ]


#: bands of this many pixels or more are processed one at a time, or, in a stack of
#: :data:`_SHARED_VALUES` values or more, half of them on a second thread (:func:`shared_stack`)
_BAND_BY_BAND = 1 << 14
#: a stack's values from which its halves go to two threads: a 256x256 level's four grey or
#: twelve colour bands, a 512x512 image's three channels; not a 128x128 level's twelve
#: colour bands, nor a 256x256 image's three channels (their hand-overs cost what they save)
_SHARED_VALUES = 1 << 18
#: FFTs of this many values or more use every CPU of the process (a 512x512 level's
#: twelve colour bands; a 256x256 level's are transformed on one thread) ...
_THREADED_FFT = 1 << 21
#: ... or, in a thread with a real-time scheduling policy, this many (:func:`fft_workers`: a
#: 256x256 level's twelve colour bands, not its four grey ones)
_THREADED_FFT_REALTIME = 1 << 19
#: frequencies per block of rows in which :class:`ComplexSteerablePyramid` computes its
#: filters (the blocks' temporaries stay small and in the cache; they share texsyn's threads)
_FILTER_BLOCK = 1 << 13


def fft_workers(size: int) -> int:
    """Threads for an FFT of ``size`` values: every CPU of the process from :data:`_THREADED_FFT`
    values (:data:`_THREADED_FFT_REALTIME` under a real-time scheduling policy), else one.

    pocketfft transforms each line on one thread, the same way whichever, so the bytes do not
    depend on the number of threads (``docs/determinism.md``). Its second thread sleeps
    between two transforms of the synthesis loop (NumPy's work on the bands runs between
    them) and has to be woken for each. Measured on the 2-core benchmark machine, 20
    iterations of a 256x256 Portilla-Simoncelli synthesis: under the default policy the loop
    ran 6-8 % faster with a 256x256 level's transforms on one thread (grey 0.48 -> 0.45 s,
    colour 1.46 -> 1.35 s; 512x512 and 1024x1024 also faster with 2^21 than with 2^17 or
    2^23), but in a process run by ``chrt -f 50`` (a real-time policy, whose woken threads
    start at once on the idle core) two threads took 8 % off the same transforms. Since the
    loop's single-thread transforms were made faster (issue 20, eighth round: in place,
    band by band), a real-time thread gains from a second one on a 256x256 level's twelve
    colour bands only (20 iterations, colour 1.13-1.15 s with 2^17, 1.11-1.12 s with 2^19,
    1.12-1.14 s with 2^21; grey 0.41, 0.39 and 0.38 s)
    (``docs/methods/portilla_simoncelli.md``, "Performance").
    """
    if size < _THREADED_FFT_REALTIME:  # one thread under either policy: no system call
        return 1
    threshold = _THREADED_FFT_REALTIME if _realtime_thread() else _THREADED_FFT
    return worker_count() if size >= threshold else 1


def _realtime_thread() -> bool:
    """Whether the calling thread runs under a real-time scheduling policy (FIFO or round robin)."""
    try:
        return os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR)
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return False


def _row_blocks(size: tuple[int, int]) -> list[slice]:
    """Blocks of about :data:`_FILTER_BLOCK` values of a ``size`` grid, whole rows."""
    h, w = size
    rows = max(1, _FILTER_BLOCK // max(w, 1))
    return [slice(start, min(start + rows, h)) for start in range(0, h, rows)]


def shared_stack(count: int, size: int) -> bool:
    """Whether a stack of ``count`` bands (or channels) of ``size`` pixels is shared between two
    threads (:func:`for_each_band`): two bands or more, of :data:`_BAND_BY_BAND` pixels or
    more, :data:`_SHARED_VALUES` values or more in all, and more than one CPU for texsyn's
    threads (:func:`~texsyn.ops.linalg.worker_count`).

    Measured on the 2-core machine, Portilla-Simoncelli's loop, 20 iterations in process
    (issue 20, ninth round): 256x256 colour 1.24 -> 1.07 s, grey 0.41 -> 0.39 s; 512x512 (5
    iterations) colour 1.37 -> 1.10 s, grey 0.49 -> 0.42 s. Sharing the 128x128 colour
    level's twelve bands, or a 256x256 image's three channels (whose skewness and kurtosis
    steps are mostly Python, which holds the GIL), gained nothing or lost
    (``docs/methods/portilla_simoncelli.md``, "Performance").
    """
    return size >= _BAND_BY_BAND and count * size >= _SHARED_VALUES and count > 1 and worker_count() > 1


def for_each_band(function: Callable[[slice], None], count: int, size: int) -> None:
    """Call ``function(bands)`` on slices ``bands`` that cover ``range(count)``.

    - A stack that :func:`shared_stack` shares (a 256x256 level's bands) goes as two halves,
      the second on one of texsyn's threads (:func:`~texsyn.ops.linalg.parallel_map`), each
      half's operations on its bands at once: the GIL is released for each operation's
      work, and few operations leave few hand-overs of it.
    - Otherwise bands of ``size`` pixels or more go one at a time: a chain of NumPy
      operations on one band stays in the processor's cache, which a whole pyramid level
      does not fit (measured: the phase doubling of twelve 256x256 bands takes half the time
      band by band).
    - Smaller bands go all at once (fewer Python and FFT call overheads).

    ``function`` must compute each band the same way whatever the slice and whichever the
    thread, so that the bytes depend on neither.
    """
    if shared_stack(count, size):
        half = (count + 1) // 2
        parallel_map(function, [slice(0, half), slice(half, count)])
    elif size < _BAND_BY_BAND:
        function(slice(0, count))
    else:
        for i in range(count):
            function(slice(i, i + 1))


def _stack_transform(transform: Callable, x: np.ndarray, columns: int) -> np.ndarray:
    """``transform(x)`` (:func:`texsyn.ops.fft.fft2` or ``rfft2``; ``columns`` of output),
    half of a :func:`shared_stack` on a second thread (each line is transformed the same way:
    the same bytes), else on :func:`fft_workers` threads."""
    h, w = x.shape[-2:]
    count = x.size // max(h * w, 1)
    if not (x.flags.c_contiguous and shared_stack(count, h * w)):
        return transform(x, workers=fft_workers(x.size))
    flat = x.reshape(count, h, w)
    out = np.empty((count, h, columns), dtype=np.result_type(x.dtype, np.complex64))

    def run(bands: slice) -> None:
        transform(flat[bands], out=out[bands])

    for_each_band(run, count, h * w)
    return out.reshape(x.shape[:-2] + (h, columns))


class ComplexSteerablePyramid:
    """Complex (analytic) steerable pyramid of a fixed size, batched over channels.

    The real part of every band is the real steerable band of
    :class:`texsyn.transforms.steerable.SteerablePyramid`; the complex band keeps only the half of the spectrum
    that the orientation points to, doubled (Portilla and Simoncelli 2000).

    Parameters
    ----------
    shape : (int, int)
    n_scales, n_orientations : int
    single : bool
        Compute the Fourier transforms in single precision (twice as fast; reconstruction
        error ~1e-6 instead of ~1e-15). The synthesis loop uses it; statistics do not.

    Examples
    --------
    >>> pyramid = ComplexSteerablePyramid((32, 30), n_scales=2, n_orientations=4)
    >>> highpass, bands, lows = pyramid.forward(np.zeros((1, 32, 30)))
    >>> [band.shape for band in bands], lows[-1].shape
    ([(1, 4, 32, 30), (1, 4, 16, 15)], (1, 8, 8))
    """

    def __init__(
        self, shape: tuple[int, int], n_scales: int = 4, n_orientations: int = 4, *, single: bool = False
    ):
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
        self.lo0 = np.empty(self.shape)  # radial_lowpass(r / 2) on the finest grid, filled below
        self.hi0 = np.empty(self.shape)
        self.lo: list[np.ndarray] = []
        self.real_filters: list[np.ndarray] = []
        self.conj_real_filters: list[np.ndarray] = []  # np.conj(real_filters[s]), for reconstruct_level
        self.analytic_filters: list[np.ndarray] = []
        self.half_planes: list[np.ndarray] = []
        rd, cd = self.real_dtype, np.result_type(self.real_dtype, np.complex64)
        for level, size in enumerate(self.sizes[: self.n_scales]):
            freqs = (
                2 * np.pi * np.fft.fftfreq(size[0])[:, None],
                2 * np.pi * np.fft.fftfreq(size[1])[None, :],
            )
            filters = (
                np.empty(size, dtype=rd),  # lo
                np.empty((k,) + size, dtype=cd),  # real_filters
                np.empty((k,) + size, dtype=cd),  # conj_real_filters
                np.empty((k,) + size, dtype=cd),  # analytic_filters
                np.empty((k,) + size, dtype=rd),  # half_planes
            )

            def fill(rows: slice, level=level, freqs=freqs, filters=filters) -> None:
                lo_out, reals_out, conj_out, analytic_out, halves_out = filters
                fy, fx = freqs[0][rows], freqs[1]
                r, theta = np.hypot(fx, fy), np.arctan2(fy, fx)  # _polar's, on these rows
                if level == 0:
                    self.lo0[rows] = lo0 = radial_lowpass(r / 2.0)
                    self.hi0[rows] = np.sqrt(np.maximum(1.0 - lo0**2, 0.0))
                lo = radial_lowpass(r)
                reals = oriented_windows(theta, np.sqrt(np.maximum(1.0 - lo**2, 0.0)), k, single=single)
                # analytic bands: the half plane each orientation points to, doubled
                c = np.cos(theta[None] - (np.pi * np.arange(k) / k)[:, None, None])
                halves = np.where(c > 1e-12, 2.0, np.where(c < -1e-12, 0.0, 1.0))
                if rows.start == 0:
                    halves[:, 0, 0] = 1.0
                lo_out[rows] = lo
                reals_out[:, rows] = reals
                np.conj(reals_out[:, rows], out=conj_out[:, rows])
                analytic_out[:, rows] = reals * halves
                halves_out[:, rows] = halves

            # pointwise functions of the frequency, so blocks of rows give the numbers of the
            # whole grid; the blocks' powers and cosines are long NumPy calls that release the
            # GIL, shared among texsyn's threads (issue 20: 256x256, 33 -> 21 ms on two cores;
            # 2048x2048, whose whole-grid temporaries page-faulted, 3.4-6.1 -> 1.2-1.5 s)
            parallel_map(fill, _row_blocks(size))
            for filter_list, values in zip(
                (self.lo, self.real_filters, self.conj_real_filters, self.analytic_filters, self.half_planes),
                filters,
            ):
                filter_list.append(values)
        if not self.n_scales:  # no level filled them
            r0, _ = self._polar(self.shape)
            self.lo0 = radial_lowpass(r0 / 2.0)
            self.hi0 = np.sqrt(np.maximum(1.0 - self.lo0**2, 0.0))
        self.lo0 = self.lo0.astype(self.real_dtype)
        self.hi0 = self.hi0.astype(self.real_dtype)
        # L(r/2) at every level's resolution: the low-pass that the partially reconstructed
        # images of Portilla-Simoncelli carry (paper section 3; the reference code's lo0 mask).
        # Level s + 1 takes level s's low-pass window at the same frequency indices, which keeps
        # the reconstruction exact for odd sizes too (where the grids are not exactly 2x apart).
        self.mid = [self.lo0]
        for level in range(self.n_scales):
            rows = crop_indices(self.sizes[level][0], self.sizes[level + 1][0])
            cols = crop_indices(self.sizes[level][1], self.sizes[level + 1][1])
            self.mid.append(self.lo[level][rows[:, None], cols[None, :]])
        # the non-negative column frequencies of the filters, for the half spectra of rfft2
        # (lowpass_half, reconstruct_level_half, reconstruct_spectrum_half)
        self.conj_real_filters_half = [
            np.ascontiguousarray(f[..., : f.shape[-1] // 2 + 1]) for f in self.conj_real_filters
        ]
        self.mid_half = [np.ascontiguousarray(m[..., : m.shape[-1] // 2 + 1]) for m in self.mid]
        self.hi0_half = np.ascontiguousarray(self.hi0[..., : self.shape[1] // 2 + 1])

    def fft(self, x: np.ndarray) -> np.ndarray:
        """2-D FFT over the last two axes, in the pyramid's precision (``single`` or double).

        Large transforms use several threads (:func:`fft_workers`; same bytes).
        """
        x = np.asarray(x)
        dtype = np.result_type(self.real_dtype, np.complex64) if np.iscomplexobj(x) else self.real_dtype
        return _stack_transform(pocketfft.fft2, x.astype(dtype, copy=False), x.shape[-1])

    def rfft(self, x: np.ndarray) -> np.ndarray:
        """``rfft2`` of real arrays in the pyramid's precision: the columns ``0 .. w // 2`` of
        :meth:`fft` (pocketfft computes the full transform of real data as this half, then
        mirrors it: the same bytes), in half the time."""
        x = np.asarray(x)
        return _stack_transform(pocketfft.rfft2, x.astype(self.real_dtype, copy=False), x.shape[-1] // 2 + 1)

    def irfft(self, half: np.ndarray, level: int = 0, *, overwrite: bool = False) -> np.ndarray:
        """The real image of the size of ``level`` from its half spectrum (``irfft2``;
        ``overwrite``: ``half`` may be overwritten, which saves memory traffic, same bytes)."""
        workers = fft_workers(2 * half.size)
        return pocketfft.irfft2(half, s=self.sizes[level], workers=workers, overwrite_x=overwrite)

    def ifft(self, x: np.ndarray) -> np.ndarray:
        """Inverse 2-D FFT over the last two axes (complex result; threads as :meth:`fft`)."""
        return pocketfft.ifft2(x, workers=fft_workers(x.size))

    @staticmethod
    def _polar(shape):
        fy = 2 * np.pi * np.fft.fftfreq(shape[0])[:, None]
        fx = 2 * np.pi * np.fft.fftfreq(shape[1])[None, :]
        return np.hypot(fx, fy), np.arctan2(fy, fx)

    @staticmethod
    def resize_spectrum(spec: np.ndarray, size_from, size_to) -> np.ndarray:
        """Crop or zero-pad a full 2-D spectrum (last two axes), keeping amplitudes, in its
        precision (complex64 stays single precision since issue 20's single-precision step; before,
        it was widened)."""
        scale = (size_to[0] * size_to[1]) / (size_from[0] * size_from[1])
        shape = spec.shape[:-2] + tuple(size_to)
        if size_to[0] <= size_from[0]:
            rows = _crop_runs(size_from[0], size_to[0])
            cols = _crop_runs(size_from[1], size_to[1])
            out = np.empty(shape, dtype=np.result_type(spec.dtype, scale))
            for fine_r, coarse_r in rows:
                for fine_c, coarse_c in cols:
                    np.multiply(spec[..., fine_r, fine_c], scale, out=out[..., coarse_r, coarse_c])
            return out
        rows = _crop_runs(size_to[0], size_from[0])
        cols = _crop_runs(size_to[1], size_from[1])
        out = np.zeros(shape, dtype=np.result_type(spec.dtype, np.complex64))  # the spectrum's precision
        for fine_r, coarse_r in rows:
            for fine_c, coarse_c in cols:
                np.multiply(spec[..., coarse_r, coarse_c], scale, out=out[..., fine_r, fine_c])
        return out

    def upsampled_ifft(self, spec: np.ndarray, level: int) -> np.ndarray:
        """``ifft(resize_spectrum(spec, sizes[level + 1], sizes[level]))``, the same bytes, faster.

        The zero-padded spectrum's columns outside the coarse frequencies are zero, so the
        first pass of the 2-D inverse transform (along the columns, scaled by ``1 / (h w)``
        as pocketfft scales it: a product after the transform) runs on the coarse columns
        only; a zero column's transform (zeros whose signs pocketfft's arithmetic sets) is
        computed once and copied. The second pass (along the rows) is the 2-D transform's own.
        """
        (hc, wc), (h, w) = self.sizes[level + 1], self.sizes[level]
        scale = (h * w) / (hc * wc)
        workers = fft_workers(spec.size * (h * w) // (hc * wc))
        batch = spec.shape[:-2]
        dtype = np.result_type(spec.dtype, np.complex64)
        columns = np.empty(batch + (h, wc + 1), dtype=dtype)  # the coarse columns, then a zero one
        columns[..., wc] = 0.0
        rows = _crop_runs(h, hc)
        for (fine_r, coarse_r), (next_r, _) in zip(rows, rows[1:] + [(slice(h, h), None)]):
            np.multiply(spec[..., coarse_r, :], scale, out=columns[..., fine_r, :wc])
            columns[..., fine_r.stop : next_r.start, :wc] = 0.0  # the zero padding between the runs
        columns[..., : rows[0][0].start, :wc] = 0.0
        columns = pocketfft.ifft(columns, axis=-2, norm="forward", overwrite_x=True, workers=workers)
        # scale by 1 / (h w) as pocketfft does (real and imaginary parts by a real factor) while
        # copying into the full array, whose other columns are the zero column's transform
        real = columns.real.dtype
        norm = inverse_norm(h * w, real)
        out = np.empty(batch + (h, w), dtype=dtype)
        source, target = columns.view(real), out.view(real)
        previous = 0
        for fine_c, coarse_c in _crop_runs(w, wc):
            out[..., previous : fine_c.start] = columns[..., wc : wc + 1]
            np.multiply(
                source[..., 2 * coarse_c.start : 2 * coarse_c.stop],
                norm,
                out=target[..., 2 * fine_c.start : 2 * fine_c.stop],
            )
            previous = fine_c.stop
        out[..., previous:] = columns[..., wc : wc + 1]
        return pocketfft.ifft(out, axis=-1, norm="forward", overwrite_x=True, workers=workers)

    def expand(self, image: np.ndarray, level: int) -> np.ndarray:
        """Interpolate ``(..., h, w)`` arrays of level ``level + 1`` to the size of ``level``."""
        spec = self.fft(image)
        out = self.ifft(self.resize_spectrum(spec, self.sizes[level + 1], self.sizes[level]))
        return out if np.iscomplexobj(image) else out.real

    def forward(
        self,
        image: np.ndarray,
        *,
        spectra: bool = False,
        all_lows: bool = True,
        highpass_spectrum: bool = False,
    ):
        """``(highpass, bands, lows)`` of ``(C, H, W)`` images (and the bands' spectra).

        ``bands[s]`` is complex ``(C, K, h_s, w_s)``; ``lows[s]`` the real low-pass image that
        enters level ``s`` (``lows[0]`` is the image low-passed once, ``lows[-1]`` the residual).
        With ``spectra=True`` a fourth item lists the Fourier transforms of the bands; with
        ``all_lows=False`` only the residual ``lows[-1]`` is computed (the others are None);
        with ``highpass_spectrum=True`` the first item is the high-pass residual's Fourier
        transform instead of the residual (:meth:`reconstruct_spectrum` takes it back).
        """
        x = np.asarray(image, dtype=np.float64)
        spec = self.fft(x)
        highpass = spec * self.hi0 if highpass_spectrum else self.ifft(spec * self.hi0).real
        low = spec * self.lo0
        bands, lows, band_spectra = [], [], []
        for s in range(self.n_scales):
            lows.append(self.ifft(low).real if all_lows else None)
            if spectra:
                band_spectra.append(low[:, None] * self.analytic_filters[s])
                bands.append(self.ifft(band_spectra[-1]))
            else:
                bands.append(self._bands(low, s))
            low = self.resize_spectrum(low * self.lo[s], self.sizes[s], self.sizes[s + 1])
        lows.append(self.ifft(low).real)
        return (highpass, bands, lows, band_spectra) if spectra else (highpass, bands, lows)

    def _bands(self, low: np.ndarray, level: int) -> np.ndarray:
        """``ifft(low[:, None] * analytic_filters[level])``: each line is transformed the same
        way whichever the batch, so these are the bytes of band-by-band transforms.

        A level that :func:`shared_stack` shares goes in two halves on two threads, each
        half's products then one transform of its bands (a 256x256 colour level: 4.4 -> 2.8
        ms on the 2-core machine, in the synthesis loop). Otherwise bands of
        :data:`_BAND_BY_BAND` pixels or more go one at a time, product then transform, while
        the band is in the cache (5.0 -> 4.2 ms); a level whose transform is threaded
        (:func:`fft_workers`) goes at once, products then one transform of all the bands.
        """
        filters = self.analytic_filters[level]
        c, k = low.shape[0], filters.shape[0]
        out = np.empty((c, k) + low.shape[1:], dtype=np.result_type(low.dtype, filters.dtype))
        size = low.shape[-1] * low.shape[-2]
        workers = fft_workers(out.size)
        if not shared_stack(c * k, size) and (workers > 1 or size < _BAND_BY_BAND):
            np.multiply(low[:, None], filters, out=out)
            return pocketfft.ifft2(out, overwrite_x=True, workers=workers)  # in place
        flat = out.reshape((c * k,) + low.shape[1:])

        def run(bands: slice) -> None:
            for i in range(bands.start, bands.stop):
                np.multiply(low[i // k], filters[i % k], out=flat[i])
            pocketfft.ifft2(flat[bands], overwrite_x=True)  # in place

        for_each_band(run, c * k, size)
        return out

    def lowpass_image(self, residual: np.ndarray) -> np.ndarray:
        """The coarsest partially reconstructed image: the low-pass residual filtered by ``L(r/2)``."""
        return self.ifft(self.fft(residual) * self.mid[-1]).real

    def reconstruct_level(
        self, coarser: np.ndarray, real_bands: np.ndarray | None, level: int, *, real_spectra=None
    ) -> np.ndarray:
        """Partially reconstructed image of ``level`` from the one of the level below and the
        level's real bands (or their Fourier transforms ``real_spectra``).

        Both images carry the low-pass ``L(r/2)`` of their own resolution (Portilla and
        Simoncelli's partially reconstructed low-pass images), so the finest one is the
        image's low-pass part and :meth:`reconstruct` only adds the high-pass residual.
        """
        spec = self.resize_spectrum(self.fft(coarser), self.sizes[level + 1], self.sizes[level])
        if real_spectra is None:
            if real_bands is None:
                raise ValueError("reconstruct_level needs the real bands or their spectra")
            real_spectra = self.fft(real_bands)
        # np.sum over the orientations, in its order: ((b0 + b1) + b2) + ...
        filters = self.conj_real_filters[level]
        total = real_spectra[..., 0, :, :] * filters[0]
        for b in range(1, filters.shape[0]):
            total += real_spectra[..., b, :, :] * filters[b]
        spec += total
        spec *= self.mid[level]
        return self.ifft(spec).real

    def upsampled_half(self, half: np.ndarray, level: int) -> np.ndarray:
        """The half spectrum (``rfft2``) at the size of ``level`` of a real image of level
        ``level + 1`` given by its half spectrum: the same image as
        ``ifft(resize_spectrum(fft(image), ...)).real`` up to rounding.

        Zero-padding puts an even size's Nyquist frequency (``-n / 2``) on the fine grid's
        negative side only; the real part of the inverse transform sees its Hermitian part,
        half at ``-n / 2`` and half at ``+n / 2``, which is what this half spectrum holds.
        """
        (hc, wc), (h, w) = self.sizes[level + 1], self.sizes[level]
        scale = (h * w) / (hc * wc)
        out = np.zeros(half.shape[:-2] + (h, w // 2 + 1), dtype=np.result_type(half.dtype, np.complex64))
        cols = (wc + 1) // 2  # the non-negative frequencies below the Nyquist one
        runs = _crop_runs(h, hc)
        for fine_r, coarse_r in runs:
            np.multiply(half[..., coarse_r, :cols], scale, out=out[..., fine_r, :cols])
        if wc % 2 == 0:  # the Nyquist column, half of it at +wc/2 (-wc/2 is its mirror)
            for fine_r, coarse_r in runs:
                np.multiply(half[..., coarse_r, cols], scale / 2, out=out[..., fine_r, cols])
        if hc % 2 == 0:  # the Nyquist row: half at -hc/2, half at +hc/2
            negative, positive = h - hc // 2, hc // 2
            out[..., negative, :cols] *= 0.5
            out[..., positive, :cols] = out[..., negative, :cols]
            if wc % 2 == 0:  # the corner (-hc/2, -wc/2): half there, half at (hc/2, wc/2)
                out[..., positive, cols] = out[..., negative, cols]
                out[..., negative, cols] = 0.0
        return out

    def lowpass_half(self, residual: np.ndarray) -> np.ndarray:
        """:meth:`lowpass_image`'s half spectrum (``rfft2``; the image is :meth:`irfft` of it
        at level ``n_scales``)."""
        spec = self.rfft(residual)
        spec *= self.mid_half[-1]
        return spec

    def reconstruct_level_half(
        self, coarser: np.ndarray, real_half_spectra: np.ndarray, level: int = 0
    ) -> np.ndarray:
        """:meth:`reconstruct_level` from the real bands' half spectra (``rfft2``: :meth:`rfft`,
        or the columns ``0 .. w // 2`` of :meth:`fft`), with half the products: the half
        spectrum of the partially reconstructed image (the same image up to rounding:
        :meth:`irfft` of it)."""
        spec = self.upsampled_half(self.rfft(coarser), level)
        filters = self.conj_real_filters_half[level]  # np.sum over the orientations, in its order
        half = filters.shape[-1]
        total = real_half_spectra[..., 0, :, :half] * filters[0]
        for b in range(1, filters.shape[0]):
            total += real_half_spectra[..., b, :, :half] * filters[b]
        spec += total
        spec *= self.mid_half[level]
        return spec

    def reconstruct(self, low0: np.ndarray, highpass: np.ndarray) -> np.ndarray:
        """The image from the finest partially reconstructed image and the high-pass residual."""
        return self.ifft(self.fft(low0) + self.fft(highpass) * self.hi0).real

    def reconstruct_spectrum(self, low0: np.ndarray, highpass_spectrum: np.ndarray, gain) -> np.ndarray:
        """:meth:`reconstruct` with the high-pass residual given by its Fourier transform
        (:meth:`forward` with ``highpass_spectrum=True``), scaled by ``gain`` per channel.

        The residual's transform is used as it is instead of being transformed back and
        forth (the same numbers up to rounding).
        """
        gain = np.asarray(gain, dtype=self.real_dtype)[..., None, None]
        spec = self.fft(low0)
        spec += highpass_spectrum * (gain * self.hi0)
        return self.ifft(spec).real

    def reconstruct_spectrum_half(self, low0: np.ndarray, highpass_spectrum: np.ndarray, gain) -> np.ndarray:
        """:meth:`reconstruct_spectrum` with half spectra (``rfft2``; the columns ``0 .. w // 2``
        of the residual's transform) and a real inverse transform: the same image up to
        rounding."""
        half = self.shape[1] // 2 + 1
        gain = np.asarray(gain, dtype=self.real_dtype)[..., None, None]
        spec = self.rfft(low0)
        spec += highpass_spectrum[..., :half] * (gain * self.hi0_half)
        return self.irfft(spec, overwrite=True)

    def analytic(self, real_bands: np.ndarray, level: int, *, real_spectra=None):
        """Re-create the complex bands ``(..., K, h, w)`` from their real parts; returns
        ``(bands, their spectra)``."""
        if real_spectra is None:
            real_spectra = self.fft(real_bands)
        spectra = real_spectra * self.half_planes[level]
        return self.ifft(spectra), spectra
