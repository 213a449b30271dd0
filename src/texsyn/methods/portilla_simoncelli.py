"""Portilla–Simoncelli texture synthesis, grey or colour with cross-channel statistics.

The algorithm of J. Portilla, E. Simoncelli, "A parametric texture model based on joint
statistics of complex wavelet coefficients", IJCV 40(1), 2000, and where each step is:

1. measure the exemplar's statistics on a complex steerable pyramid (section 3): ``fit`` calls
   :func:`texsyn.models.portilla.ps_statistics` and keeps a frozen
   :class:`texsyn.models.portilla.PSStatistics`;
2. start from Gaussian noise with the exemplar's mean and variance: :meth:`PortillaSimoncelli._sample`;
3. repeat (section 4): analyse, impose the statistics coarse to fine, reconstruct, impose
   the pixel statistics: :func:`project_statistics` (the projections are in
   :mod:`texsyn.models.portilla_projections`), run by :func:`ps_synthesis` with
   :func:`texsyn.drivers.alternating.alternate_projections`.

Colour follows J. Vacher, T. Briand, "The Portilla-Simoncelli texture model: towards
understanding the early visual cortex", IPOL 2021: the statistics of the RGB channels with
every cross-channel correlation (or, with ``colour='pca'``, of the principal colour axes). ``docs/methods/portilla_simoncelli.md`` lists the
parameters and the deviations from the paper.

Why this module is long: besides the method class (fit, sample, refine, the distance
record), it holds the synthesis iteration itself, whose per-scale step works on the
regressions' rows in place for speed (issue 20; ``docs/methods/portilla_simoncelli.md``,
"Performance"), and round 1's ``ps_synthesis`` with its deprecated callback.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Annotated, cast

import numpy as np

from .._validation import OneOf, Range, as_exemplar
from ..drivers.alternating import alternate_projections
from ..models.portilla import PSStatistics, parent_rows, ps_statistics, statistics_distance
from ..models.portilla_projections import (
    adjusted_magnitudes,
    centred_magnitudes,
    highpass_shrink_factor,
    impose_lowpass_statistics,
    impose_pixel_statistics,
    magnitude_real_parts,
    parent_regression_rows,
    shrink_image_highpass,
)
from ..ops.allocator import retained_heap
from ..ops.canvas import crop_to_output, extend_to_canvas, padded_canvas
from ..ops.color import ColourSpace, colour_space
from ..ops.linalg import fixed_order
from ..ops.patches import as_channels
from ..ops.progress import Progress, Reporter
from ..transforms.complex_steerable import ComplexSteerablePyramid
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, output_bytes, shape_dims

__all__ = ["PortillaSimoncelli", "project_statistics", "projection_step", "ps_synthesis"]


def project_statistics(
    x: np.ndarray,
    target: PSStatistics,
    pyramid: ComplexSteerablePyramid,
    lags: int,
    *,
    workspace: dict | None = None,
) -> np.ndarray:
    """One Portilla–Simoncelli iteration on channels ``(C, H, W)`` (paper section 4).

    Analyse the image; impose on the low-pass residual its auto-correlation, skewness and
    kurtosis; then from the coarsest scale to the finest: the magnitude statistics of the
    scale's bands (correlations across orientations, channels and with the parent scale,
    auto-correlation, mean), the correlation of their real parts with the phase-doubled
    parents, and, after adding the scale to the partial reconstruction, that image's
    auto-correlation, skewness and kurtosis; shrink the high-pass residual to its variance;
    reconstruct; impose the pixel statistics (mean, colour covariance, skewness, kurtosis,
    range).

    ``workspace``, a dict kept from one iteration to the next (:func:`projection_step` keeps
    one), holds the largest scratch arrays, the rows of the regressions: allocating them
    anew each time costs page faults (about 5 700 per 256x256 colour iteration, 4 % of it).
    """
    n_scales = pyramid.n_scales
    pixel_var = target.pixel_moments[:, 1]
    highpass, bands, lows = pyramid.forward(x, all_lows=False, highpass_spectrum=True)
    lows[-1] = lows[-1] - lows[-1].mean(axis=(-2, -1), keepdims=True)
    # the partially reconstructed images come as half spectra (rfft2), which the low-pass
    # step's auto-correlation filter starts from
    image = impose_lowpass_statistics(
        None,
        target.low_autocorr[n_scales],
        target.low_skew_kurt[:, n_scales],
        pixel_var,
        lags,
        spectrum=pyramid.lowpass_half(lows[-1]),
        shape=pyramid.sizes[n_scales],
    )
    spectra: list = [None] * n_scales  # the bands' spectra, filled coarse to fine as parents
    for s in range(n_scales - 1, -1, -1):
        real_spectra = _real_band_spectra(bands[s], spectra, target, pyramid, s, lags, workspace)
        if s > 0:  # the parents of the next finer scale (the complex bands are not needed)
            spectra[s] = real_spectra * pyramid.half_planes[s]
        # (at the finest scale, which has no finer one, the bands' half spectra only: rfft2)
        image = impose_lowpass_statistics(
            None,
            target.low_autocorr[s],
            target.low_skew_kurt[:, s],
            pixel_var,
            lags,
            spectrum=pyramid.reconstruct_level_half(image, real_spectra, s),
            shape=pyramid.sizes[s],
        )
    shrink = highpass_shrink_factor(highpass, target.highpass_variance)
    x = pyramid.reconstruct_spectrum_half(image, highpass, shrink)
    return impose_pixel_statistics(x, target)


def _real_band_spectra(
    band: np.ndarray,
    spectra: list,
    target: PSStatistics,
    pyramid: ComplexSteerablePyramid,
    s: int,
    lags: int,
    workspace: dict | None,
) -> np.ndarray:
    """Impose the statistics of scale ``s`` on its complex bands (paper section 4); the Fourier
    transforms of their new real parts (at the finest scale, ``s = 0``, their half spectra:
    ``rfft2``).

    The magnitudes' covariance across orientations, channels and with the parent scale
    (``spectra[s + 1]``), their auto-correlation and mean; the real parts' correlation with the
    phase-doubled parents.
    """
    c, k, h, w = band.shape
    ck = c * k
    if s == pyramid.n_scales - 1:  # no parent scale: the magnitudes' own covariance, no phase regression
        current, mags = centred_magnitudes(band)
        filtered = adjusted_magnitudes(current, mags, None, target, s, lags)
        real = magnitude_real_parts(
            band, current, filtered, target.magnitude_means[s], np.empty(band.shape, dtype=np.float32)
        )
    else:
        # rows of the two regressions, filled in place: the band's centred magnitudes and its
        # parents' (double precision), the band's real parts and the phase-doubled parents
        # (single precision)
        magnitude_rows = _scratch(workspace, ("magnitude rows", s), (2 * ck, h * w), np.float32)
        real_rows = _scratch(workspace, ("real rows", s), (3 * ck, h * w), np.float32)
        parent_rows(pyramid, spectra, s, magnitude_rows[ck:], real_rows[ck:])
        current, _ = centred_magnitudes(band, magnitude_rows[:ck].reshape(band.shape))
        filtered = adjusted_magnitudes(current, None, magnitude_rows, target, s, lags)
        magnitude_real_parts(
            band, current, filtered, target.magnitude_means[s], real_rows[:ck].reshape(band.shape)
        )
        real = parent_regression_rows(real_rows, ck, target.real_parent[s]).reshape(band.shape)
    return pyramid.rfft(real) if s == 0 else pyramid.fft(real)


def _scratch(workspace: dict | None, key: tuple, shape: tuple, dtype) -> np.ndarray:
    """An uninitialised array, kept in ``workspace`` under ``key`` for the next call."""
    if workspace is None:
        return np.empty(shape, dtype=dtype)
    array = workspace.get(key)
    if array is None or array.shape != shape or array.dtype != dtype:
        array = workspace[key] = np.empty(shape, dtype=dtype)
    return array


def ps_synthesis(
    target: PSStatistics,
    initial: np.ndarray,
    n_iterations: int,
    *,
    lags: int = 3,
    pyramid: ComplexSteerablePyramid | None = None,
    reporter: Reporter | None = None,
    preview: Callable[[np.ndarray], np.ndarray] | None = None,
    callback: Callable[[int, np.ndarray], None] | None = None,
) -> np.ndarray:
    """Portilla–Simoncelli alternating projections from ``initial`` (``(C, H, W)``), paper section 4.

    Parameters
    ----------
    target : PSStatistics
        The statistics to impose.
    initial : ndarray, shape (C, H, W)
        Starting channels (any size).
    n_iterations : int
        Number of :func:`project_statistics` passes.
    lags : int
        Half-width of the auto-correlation windows the statistics were measured with.
    pyramid : ComplexSteerablePyramid, optional
        A pyramid of the channels' size (a single-precision one is built when omitted).
    reporter : Reporter, optional
        Receives one record per iteration.
    preview : callable, optional
        Turns the channels into the image shown with each record.
    callback : callable, optional
        Deprecated (round 1): ``callback(iteration, channels)`` after each iteration; use
        ``reporter`` (and ``preview``) instead.

    Returns
    -------
    ndarray, shape (C, H, W)
    """
    if callback is not None:
        warnings.warn(
            "ps_synthesis(callback=...) is deprecated; use reporter=texsyn.ops.progress.Reporter(...)",
            DeprecationWarning,
            stacklevel=2,
        )
        if reporter is not None or preview is not None:
            raise TypeError("ps_synthesis takes the deprecated callback or reporter/preview, not both")
        legacy = callback
        reporter = Reporter(
            lambda record: legacy(record.done, cast(np.ndarray, record.image)), "iteration", n_iterations
        )
        preview = _same
    x = np.asarray(initial, dtype=np.float64).copy()
    if pyramid is None:
        pyramid = ComplexSteerablePyramid(x.shape[1:], target.n_scales, target.n_orientations, single=True)
    step = projection_step(target, pyramid, lags)
    return alternate_projections(x, step, n_iterations, reporter=reporter, preview=preview)


def _same(channels: np.ndarray) -> np.ndarray:
    """The channels themselves: what round 1's ``callback(iteration, channels)`` received."""
    return channels


def projection_step(target: PSStatistics, pyramid: ComplexSteerablePyramid, lags: int):
    """The step ``step(x, iteration) -> x`` that :func:`ps_synthesis` gives the driver."""

    workspace: dict = {}

    def step(x: np.ndarray, iteration: int) -> np.ndarray:
        return project_statistics(x, target, pyramid, lags, workspace=workspace)

    return step


class PortillaSimoncelli(TextureSynthesizer):
    """Portilla-Simoncelli synthesis by alternating projections onto the joint statistics.

    Colour exemplars are described jointly, with every cross-channel correlation (not
    channel by channel). Any output size; the statistics are spatial averages, measured on
    the exemplar as it is (paper section 3; the pyramid treats it as periodic).

    Parameters
    ----------
    n_scales : int
        Scales of the complex steerable pyramid (the paper uses 4).
    n_orientations : int
        Orientations per scale (the paper uses 4).
    lags : int
        Half-width of the auto-correlation windows, ``N_a = 2 lags + 1`` (the paper: 7x7).
    n_iterations : int
        Alternating-projection iterations (the paper uses 50).
    colour : str
        'rgb' (the RGB channels with every cross-channel statistic, Vacher and Briand 2021:
        each channel's marginals are imposed as the exemplar has them), 'pca' (the
        exemplar's principal colour axes with every cross-channel statistic, the ``'pca'``
        space of :mod:`texsyn.ops.color`; 'joint' is its round-1 name; the marginals of the
        RGB channels then follow only to second order) or 'grey' (luma only, grey output).
    record_distance : bool
        Measure, after every iteration, the distance between the image's statistics and the
        exemplar's (the :func:`texsyn.metrics.ps_distance` families, in the model's
        channels) and return it with the result (``SynthesisResult.diagnostics``); it costs
        one more analysis per iteration.
    final_highpass : bool
        After the last iteration, scale the output's own high frequencies down to the
        exemplar's high-pass variance and impose the pixel statistics again
        (:func:`~texsyn.models.portilla_projections.shrink_image_highpass`; not in the paper,
        ``docs/methods/portilla_simoncelli.md``, "Deviations"). ``False`` gives the paper's
        loop alone.
    """

    name = "portilla_simoncelli"
    summary = "Portilla-Simoncelli joint statistics of a complex steerable pyramid, colour with cross-channel statistics"
    reference = (
        "J. Portilla, E. Simoncelli, A parametric texture model based on joint statistics of complex "
        "wavelet coefficients, IJCV 2000"
    )
    has_source_map = False

    def __init__(
        self,
        *,
        n_scales: Annotated[int, Range(1, 8)] = 4,
        n_orientations: Annotated[int, Range(1, 8)] = 4,
        lags: Annotated[int, Range(0, 8)] = 3,
        n_iterations: Annotated[int, Range(0, 2000)] = 50,
        colour: Annotated[str, OneOf(("rgb", "pca", "grey", "joint"))] = "rgb",
        record_distance: bool = False,
        final_highpass: bool = True,
    ):
        self.n_scales = n_scales
        self.n_orientations = n_orientations
        self.lags = lags
        self.n_iterations = n_iterations
        self.colour = colour
        self.record_distance = record_distance
        self.final_highpass = final_highpass

    def min_exemplar_size(self) -> tuple[int, str]:
        side = 2 ** (self.n_scales + 1)
        return side, f"{self.n_scales} pyramid scales need at least {side}x{side} pixels"

    # ------------------------------------------------------------------ model
    def _to_channels(self, image: np.ndarray) -> np.ndarray:
        """Image ``(H, W[, 3])`` to model channels ``(C, H, W)`` (the colour space's coordinates)."""
        return np.moveaxis(self.colour_space_.forward(image), -1, 0)

    def _to_image(self, channels: np.ndarray) -> np.ndarray:
        return self.colour_space_.inverse(np.moveaxis(channels, 0, -1))

    def _fit(self, exemplar: np.ndarray) -> None:
        self.colour_space_: ColourSpace = colour_space(self.colour, exemplar)
        coords = self._to_channels(exemplar)
        # the exemplar as it is: its periodic component would lose the low frequencies of its
        # smooth part (docs/methods/portilla_simoncelli.md, "Deviations")
        self.statistics_: PSStatistics = ps_statistics(
            np.moveaxis(coords, 0, -1),
            n_scales=self.n_scales,
            n_orientations=self.n_orientations,
            lags=self.lags,
        )

    # ------------------------------------------------------------------ memory
    memory_margin = CALIBRATED_MARGIN

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Complex pyramid, its magnitudes and parents, per channel (``docs/memory.md``).

        An empirical model of the analysis and of one iteration of the projections, fitted
        to the measured peaks (resident growth and ``tracemalloc``, 128x128 exemplars, grey
        and colour, 256x256 and 512x512 outputs, 2 to 8 orientations; ``docs/memory.md``,
        "Every method at its defaults"): ``150 + 100 n + C (40 + 95 n)`` bytes per exemplar
        pixel for the fit, and for sampling ``150`` per exemplar pixel (the statistics'
        targets) and ``90 + 45 n + C (20 + 70 n)`` per canvas pixel (``n`` the
        orientations, ``C`` the channels synthesised together): every subband of the
        pyramids is one more per orientation, grey ones included (fitted on four
        orientations only, the terms fell 15 % below the resident peaks with eight).
        """
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        channels = 3 if c == 3 and self.colour != "grey" else 1
        terms = {"exemplar": 16.0 * k * c}
        if output_shape is None:
            terms["analysis of the exemplar"] = k * (
                150.0 + 100.0 * self.n_orientations + channels * (40.0 + 95.0 * self.n_orientations)
            )
            return terms
        ch, cw = self._canvas(output_shape)
        canvas = float(ch) * float(cw)
        terms["statistics' targets"] = 150.0 * k
        terms["pyramids of one iteration"] = canvas * (
            90.0 + 45.0 * self.n_orientations + channels * (20.0 + 70.0 * self.n_orientations)
        )
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    # ------------------------------------------------------------------ synthesis
    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        """The working canvas: the output, at least ``2^(n_scales + 1)`` pixels per side."""
        return padded_canvas(shape, minimum=2 ** (self.n_scales + 1))

    def periodic_for(self, shape):
        """The pyramid is periodic (FFT) on its canvas: the output, when it is large enough."""
        return self._canvas(shape) == tuple(shape)

    def _run(self, initial: np.ndarray, iterations: int, callback) -> tuple[np.ndarray, dict | None]:
        """The projections from ``initial``; with ``record_distance``, the distance per iteration."""
        pyramid = ComplexSteerablePyramid(initial.shape[1:], self.n_scales, self.n_orientations, single=True)
        step = projection_step(self.statistics_, pyramid, self.lags)
        if self.final_highpass:
            iterate, target = step, self.statistics_

            def step(x: np.ndarray, iteration: int) -> np.ndarray:
                x = iterate(x, iteration)
                return shrink_image_highpass(x, target, pyramid) if iteration == iterations - 1 else x

        history: list[dict[str, float]] = []
        if self.record_distance:
            project = step

            def step(x: np.ndarray, iteration: int) -> np.ndarray:
                x = project(x, iteration)
                history.append(self.distance_to_exemplar(x, pyramid))
                return x

        with retained_heap():  # the iterations' temporaries reuse the memory freed by the last
            out = alternate_projections(
                np.asarray(initial, dtype=np.float64).copy(),
                step,
                iterations,
                reporter=Reporter(callback, "iteration", iterations),
                preview=self._to_image,
            )
        if not self.record_distance:
            return out, None
        families = {key: np.array([h[key] for h in history]) for key in (history[0] if history else {})}
        mean = np.mean(np.stack(list(families.values())), axis=0) if families else np.zeros(0)
        return out, {"statistics_distance": mean, "statistics_distance_by_family": families}

    def distance_to_exemplar(
        self, channels: np.ndarray, pyramid: ComplexSteerablePyramid | None = None
    ) -> dict[str, float]:
        """Distance of the statistics of model channels ``(C, H, W)`` to the exemplar's, per family.

        The families of :func:`texsyn.models.portilla.statistics_distance`; their mean is
        what :func:`texsyn.metrics.ps_distance` reports for images (which it measures on RGB
        channels rather than the model's).
        """
        target = self.statistics_
        measured = ps_statistics(
            np.moveaxis(np.asarray(channels, dtype=np.float64), 0, -1),
            n_scales=target.n_scales,
            n_orientations=target.n_orientations,
            lags=self.lags,
            pyramid=pyramid,
        )
        return statistics_distance(measured, target)

    def _sample(self, shape, rng, callback):
        h, w = self._canvas(shape)
        moments = self.statistics_.pixel_moments
        noise = rng.standard_normal((moments.shape[0], h, w))
        initial = moments[:, 0, None, None] + np.sqrt(moments[:, 1])[:, None, None] * noise
        out, diagnostics = self._run(initial, self.n_iterations, callback)
        image = crop_to_output(self._to_image(out), shape)
        return (image, None) if diagnostics is None else (image, None, diagnostics)

    @fixed_order
    def refine(
        self,
        image: np.ndarray,
        n_iterations: int | None = None,
        *,
        callback: Callable[[Progress], None] | None = None,
    ) -> np.ndarray:
        """Run the alternating projections from ``image`` instead of white noise.

        Used to post-process another method's output with the exemplar's statistics (Raad
        et al. 2016, section 5, Fig. 8: MSLG followed by Portilla-Simoncelli).

        ``image`` may be as small as an output (1x1): it is extended to the working canvas
        anyway, so an exemplar's 2x2 minimum does not apply.

        Returns
        -------
        ndarray of float32 in [0, 1], the image's size, the exemplar's channels.
        """
        exemplar = self._require_fitted()
        img = _as_refined_image(image)
        h, w = img.shape[:2]
        self._check_memory(
            exemplar.shape, (h, w), task=f"refining a {w}x{h} image", advice="use a smaller image"
        )
        ch, cw = self._canvas((h, w))
        padded = extend_to_canvas(as_channels(img), (ch, cw), mode="symmetric")
        iterations = self.n_iterations if n_iterations is None else int(n_iterations)
        out, _ = self._run(self._to_channels(padded), iterations, callback)
        return self._as_output(crop_to_output(self._to_image(out), (h, w)))


def _as_refined_image(image) -> np.ndarray:
    """``image`` checked as :func:`~texsyn._validation.as_exemplar` checks it, 1-pixel sides allowed.

    MSLG's ``post`` refines outputs of any size, down to 1x1 (as the methods sample them);
    a side of 1 is repeated to 2 for the checks and cropped back.
    """
    arr = np.asarray(image)
    h, w = arr.shape[:2] if arr.ndim >= 2 else (0, 0)
    if arr.ndim in (2, 3) and min(h, w) == 1:
        pad = [(0, 2 - min(h, 2)), (0, 2 - min(w, 2))] + [(0, 0)] * (arr.ndim - 2)
        return as_exemplar(np.pad(arr, pad, mode="edge"), name="image")[:h, :w].astype(np.float64)
    return np.asarray(as_exemplar(image, name="image"), dtype=np.float64)
