"""Heeger–Bergen pyramid-based texture synthesis (Heeger and Bergen 1995).

The paper's algorithm (its ``match-texture`` procedure), and where each step is:

1. analyse the exemplar with a steerable pyramid and keep the histogram of its pixels and of
   every subband: ``fit`` builds a :class:`texsyn.models.histograms.SubbandHistograms`;
2. start from white noise with the exemplar's pixel histogram: :meth:`HeegerBergen._sample`;
3. repeat: analyse, match every subband's histogram, reconstruct, match the pixel histogram:
   :meth:`HeegerBergen._step`, run by :func:`texsyn.drivers.alternating.alternate_projections`.

``docs/methods/heeger_bergen.md`` lists the parameters and the deviations from the paper.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import Range
from ..drivers.alternating import alternate_projections
from ..models.histograms import SubbandHistograms, subband_histograms
from ..ops.allocator import LARGE_SCRATCH_BYTES, scratch_empty
from ..ops.canvas import crop_to_output, padded_canvas
from ..ops.color import ColourSpace, colour_space
from ..ops.fourier import periodic_smooth_decomposition
from ..ops.histogram import HistogramMatcher
from ..ops.progress import Reporter
from ..ops.ranks import expect_ranks
from ..transforms.steerable import SteerablePyramid
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, output_bytes, shape_dims

__all__ = ["HeegerBergen"]


class HeegerBergen(TextureSynthesizer):
    """Heeger-Bergen synthesis: match the histograms of every steerable-pyramid subband.

    Starting from white noise, each iteration analyses the current image with a steerable
    pyramid, imposes on every subband (the high-pass and low-pass residuals included) the
    histogram of the exemplar's corresponding subband, reconstructs, and imposes the
    exemplar's pixel histogram. Colour images are processed along the exemplar's principal
    colour axes (decorrelated channels, the ``'pca'`` space of :mod:`texsyn.ops.color`), as
    in the IPOL description of Briand et al. 2014. Output sizes that differ from the
    exemplar's use the exact 1-D optimal-transport histogram target
    (:func:`texsyn.ops.histogram.hist_target`), so any output size works.

    Parameters
    ----------
    n_scales : int
        Number of pyramid scales (levels 0-based, the finest first).
    n_orientations : int
        Number of oriented subbands per scale.
    n_iterations : int
        Number of analysis / matching / synthesis rounds.
    periodic_component : bool
        Compute the subband statistics on the exemplar's periodic component, so that its
        borders do not add spurious oriented energy. The pixel histogram is always the
        exemplar's own.

    References
    ----------
    D. Heeger, J. Bergen, "Pyramid-based texture analysis/synthesis", SIGGRAPH 1995.
    T. Briand, J. Vacher, B. Galerne, J. Rabin, "The Heeger & Bergen pyramid based texture
    synthesis algorithm", Image Processing On Line 4 (2014).
    """

    name = "heeger_bergen"
    #: channels are synthesised jointly: a material stack or an RGBA exemplar (docs/materials.md)
    max_channels = 16
    memory_margin = CALIBRATED_MARGIN
    summary = "Heeger-Bergen steerable-pyramid histogram matching"
    reference = "Heeger, Bergen, SIGGRAPH 1995; Briand et al., IPOL 2014"

    def __init__(
        self,
        *,
        n_scales: Annotated[int, Range(1, 8)] = 4,
        n_orientations: Annotated[int, Range(1, 8)] = 4,
        n_iterations: Annotated[int, Range(1, 100)] = 5,
        periodic_component: bool = True,
    ):
        self.n_scales = n_scales
        self.n_orientations = n_orientations
        self.n_iterations = n_iterations
        self.periodic_component = periodic_component

    def min_exemplar_size(self):
        side = 2**self.n_scales
        return side, f"n_scales={self.n_scales} needs at least {side}x{side} pixels"

    def _pyramid_bytes(self, pixels: float, channels: int) -> tuple[float, float]:
        """``(filters, coefficients)`` bytes of a steerable pyramid of ``pixels`` pixels."""
        scales = sum(4.0**-j for j in range(self.n_scales))
        coefficients = 8.0 * channels * pixels * (1.0 + self.n_orientations * scales + 4.0**-self.n_scales)
        filters = pixels * ((4.0 + 8.0 * self.n_orientations) * scales + 16.0)
        return filters, coefficients

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Sorted subbands of the exemplar; pyramid filters, subbands, workspace and targets.

        See ``docs/memory.md``.
        """
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        _, coefficients = self._pyramid_bytes(k, c)
        terms = {"exemplar and its sorted subbands": 16.0 * k * c + coefficients}
        if output_shape is None:
            filters, _ = self._pyramid_bytes(k, c)
            terms["pyramid of the exemplar"] = filters + coefficients + 24.0 * k * c
            return terms
        ch, cw = self._canvas(output_shape)
        canvas = float(ch) * float(cw)
        filters, coefficients = self._pyramid_bytes(canvas, c)
        terms["pyramid filters"] = filters
        terms["histogram targets"] = coefficients + 8.0 * c * canvas
        # one set of subbands, reused from step to step, and the pyramid's workspace: three half
        # spectra of every level and one filter-sized conjugate per band level (issue 20)
        scales = sum(4.0**-j for j in range(self.n_scales))
        terms["subbands"] = coefficients
        terms["spectra workspace"] = canvas * (24.0 * c * (scales + 4.0**-self.n_scales) + 8.0 * scales)
        # below the workspace's size the reconstruction is a new image, made while the last
        # one is still referenced (:meth:`_step`)
        large = 16.0 * c * ch * (cw // 2 + 1) >= LARGE_SCRATCH_BYTES
        terms["images and sort keys"] = (16.0 if large else 24.0) * c * canvas
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        """The working canvas: the output, at least ``2^n_scales`` pixels per side."""
        return padded_canvas(shape, minimum=2**self.n_scales)

    def periodic_for(self, shape):
        """The pyramid is periodic (FFT) on its canvas: the output, when it is large enough."""
        return self._canvas(shape) == tuple(shape)

    def _fit(self, exemplar: np.ndarray) -> None:
        self.colour_space_: ColourSpace = colour_space("pca", exemplar)
        coords = self.colour_space_.forward(exemplar)
        base = periodic_smooth_decomposition(coords)[0] if self.periodic_component else coords
        self.model_: SubbandHistograms = subband_histograms(
            coords, base, n_scales=self.n_scales, n_orientations=self.n_orientations
        )

    def _step(self, pyramid: SteerablePyramid, match_pixels: HistogramMatcher, match_band: dict):
        """One iteration of the paper's loop: analyse, match every subband, reconstruct, match pixels.

        Nothing large is allocated in an iteration (issue 20; the same bytes,
        ``docs/methods/heeger_bergen.md``, "Performance"): the subbands and the reconstruction
        are matched in place, with one scratch array for the sort keys of every call; the
        transforms' spectra live in one workspace of the pyramid; the next step's analysis
        writes its subbands into this step's, and the reconstruction is written over the
        image the step was given. These arrays are made once, in ordinary pages
        (:func:`texsyn.ops.allocator.scratch_empty`).
        """
        channels = self.model_.channels
        scratch = scratch_empty((channels * pyramid.shape[0] * pyramid.shape[1],), dtype=np.uint64)
        height, width = pyramid.shape
        # a workspace where glibc would map each spectrum afresh (32 MiB and more); below,
        # its heap recycles the transforms' temporaries while they are hot in the caches,
        # which measured faster (256x256 colour: 0.40 against 0.45 s a synthesis)
        large = 16 * channels * height * (width // 2 + 1) >= LARGE_SCRATCH_BYTES
        workspace = pyramid.workspace(channels) if large else None

        def keys(values: int) -> np.ndarray:
            return scratch[: channels * values].reshape(channels, values)

        previous: list = [None]  # the last step's coefficients, whose arrays the next one reuses

        def step(image: np.ndarray, iteration: int) -> np.ndarray:
            coeffs = pyramid.forward(image, out=previous[0], workspace=workspace)
            for key, band in coeffs.items():
                coeffs[key] = match_band[key](band, overwrite=True, keys=keys(band.shape[0] * band.shape[1]))
            image = pyramid.inverse(coeffs, workspace=workspace, out=image if large else None)
            previous[0] = coeffs
            return match_pixels(image, overwrite=True, keys=keys(image.shape[0] * image.shape[1]))

        return step

    def _sample(self, shape, rng, callback):
        canvas = self._canvas(shape)
        pyramid = SteerablePyramid(canvas, self.n_scales, self.n_orientations)
        match_pixels, match_band = self.model_.matchers(pyramid)
        # every iteration ranks every subband and the pixels, the noise once more
        bands = sum(h * w for h, w in map(pyramid.band_shape, self.model_.band_keys))
        pixels = canvas[0] * canvas[1]
        expect_ranks(self.model_.channels * (self.n_iterations * (bands + pixels) + pixels))
        noise = match_pixels(rng.standard_normal(canvas + (self.model_.channels,)))
        image = alternate_projections(
            noise,
            self._step(pyramid, match_pixels, match_band),
            self.n_iterations,
            reporter=Reporter(callback, "iteration", self.n_iterations),
        )
        return crop_to_output(self.colour_space_.inverse(image), shape), None
