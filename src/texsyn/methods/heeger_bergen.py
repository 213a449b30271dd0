"""Heeger-Bergen pyramid-based texture synthesis (Heeger and Bergen 1995)."""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import Range
from ..ops import (
    ColorPCA,
    SteerablePyramid,
    HistogramMatcher,
    as_channels,
    periodic_smooth_decomposition,
)
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, output_bytes

__all__ = ["HeegerBergen"]


class HeegerBergen(TextureSynthesizer):
    """Heeger-Bergen synthesis: match the histograms of every steerable-pyramid subband.

    Starting from white noise, each iteration analyses the current image with a steerable
    pyramid, imposes on every subband (the high-pass and low-pass residuals included) the
    histogram of the exemplar's corresponding subband, reconstructs, and imposes the
    exemplar's pixel histogram. Colour images are processed along the exemplar's principal
    colour axes (decorrelated channels), as in the IPOL description of Briand et al. 2014.
    Output sizes that differ from the exemplar's use the exact 1-D optimal-transport
    histogram target (spec 00, 5.2), so any output size works.

    Parameters
    ----------
    n_scales : int
        Number of pyramid scales.
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
        """Sorted subbands of the exemplar; pyramid filters, two sets of subbands and targets.

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
        side = 2**self.n_scales
        canvas = float(max(output_shape[0], side)) * float(max(output_shape[1], side))
        filters, coefficients = self._pyramid_bytes(canvas, c)
        terms["pyramid filters"] = filters
        terms["histogram targets"] = coefficients + 8.0 * c * canvas
        terms["subbands (two iterations)"] = 2.0 * coefficients
        terms["image and spectra"] = 40.0 * c * canvas
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        self.pca_ = ColorPCA(ex) if ex.shape[2] > 1 else None
        coords = self.pca_.forward(ex) if self.pca_ is not None else ex
        base = periodic_smooth_decomposition(coords)[0] if self.periodic_component else coords
        pyramid = SteerablePyramid(ex.shape[:2], self.n_scales, self.n_orientations).forward(base)
        channels = ex.shape[2]
        self.band_values_ = {
            key: [np.sort(band[..., c], axis=None) for c in range(channels)]
            for key, band in pyramid.items()
        }
        self.pixel_values_ = [np.sort(coords[..., c], axis=None) for c in range(channels)]

    def _sample(self, shape, rng, callback):
        side = 2**self.n_scales
        canvas = (max(shape[0], side), max(shape[1], side))
        channels = len(self.pixel_values_)
        pyr = SteerablePyramid(canvas, self.n_scales, self.n_orientations)
        match_pixels = HistogramMatcher(self.pixel_values_, canvas[0] * canvas[1])
        match_band = {
            key: HistogramMatcher(values, _band_size(pyr, key)) for key, values in self.band_values_.items()
        }

        image = match_pixels(rng.standard_normal(canvas + (channels,)))
        for it in range(self.n_iterations):
            coeffs = pyr.forward(image)
            for key, band in coeffs.items():
                coeffs[key] = match_band[key](band)
            image = match_pixels(pyr.inverse(coeffs))
            if callback is not None:
                callback(Progress("iteration", it + 1, self.n_iterations))
        if self.pca_ is not None:
            image = self.pca_.inverse(image)
        return image[: shape[0], : shape[1]], None


def _band_size(pyr: SteerablePyramid, key) -> int:
    if key == "highpass":
        h, w = pyr.sizes[0]
    elif key == "lowpass":
        h, w = pyr.sizes[-1]
    else:
        h, w = pyr.sizes[key[0]]
    return h * w
