"""Portilla-Simoncelli texture synthesis, grey or colour with cross-channel statistics.

The exemplar is summarised by the joint statistics of its complex steerable pyramid
(:func:`texsyn.ops.portilla.ps_statistics`: marginal moments, auto-correlations of the
partially reconstructed low-passes, magnitude auto- and cross-correlations across
orientations, scales and channels, cross-scale phase statistics); synthesis imposes them on
white noise by alternating projections (:func:`texsyn.ops.portilla.ps_synthesis`).

References
----------
J. Portilla, E. Simoncelli, "A parametric texture model based on joint statistics of complex
wavelet coefficients", IJCV 40(1), 2000, sections 3-4. Colour: J. Vacher, T. Briand, "The
Portilla-Simoncelli texture model: towards understanding the early visual cortex", IPOL 2021.
"""

from __future__ import annotations

from typing import Annotated, Callable

import numpy as np

from .._validation import OneOf, Range, as_exemplar
from ..ops import ColorPCA, as_channels, luma, periodic_smooth_decomposition
from ..ops.portilla import ComplexSteerablePyramid, PSStatistics, pixel_statistics, ps_statistics, ps_synthesis
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, output_bytes
from ..ops.linalg import fixed_order

__all__ = ["PortillaSimoncelli"]

class PortillaSimoncelli(TextureSynthesizer):
    """Portilla-Simoncelli synthesis by alternating projections onto the joint statistics.

    Colour exemplars are described in their principal colour axes with every cross-channel
    correlation (not channel by channel). Any output size; the statistics are spatial
    averages. The exemplar is replaced by its periodic component before analysis.

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
        'joint' (colour with cross-channel statistics) or 'grey' (luma only).
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
        colour: Annotated[str, OneOf(("joint", "grey"))] = "joint",
    ):
        self.n_scales = n_scales
        self.n_orientations = n_orientations
        self.lags = lags
        self.n_iterations = n_iterations
        self.colour = colour

    def min_exemplar_size(self) -> tuple[int, str]:
        side = 2 ** (self.n_scales + 1)
        return side, f"{self.n_scales} pyramid scales need at least {side}x{side} pixels"

    # ------------------------------------------------------------------ model
    def _to_channels(self, image: np.ndarray) -> np.ndarray:
        """Image ``(H, W[, 3])`` to model channels ``(C, H, W)`` (principal colour axes)."""
        img = as_channels(np.asarray(image, dtype=np.float64))
        if self.pca_ is not None:
            if img.shape[2] == 1:
                img = np.repeat(img, 3, axis=2)
            return np.moveaxis(self.pca_.forward(img), -1, 0)
        if img.shape[2] == 3:
            img = luma(img)[..., None]
        return np.moveaxis(img, -1, 0)

    def _to_image(self, channels: np.ndarray) -> np.ndarray:
        img = np.moveaxis(channels, 0, -1)
        return self.pca_.inverse(img) if self.pca_ is not None else img[..., 0]

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        self.pca_ = ColorPCA(ex) if ex.shape[2] == 3 and self.colour == "joint" else None
        coords = self._to_channels(exemplar)
        periodic = periodic_smooth_decomposition(np.moveaxis(coords, 0, -1))[0]
        stats = ps_statistics(periodic, n_scales=self.n_scales, n_orientations=self.n_orientations, lags=self.lags)
        # pixel statistics of the exemplar itself; everything spatial from its periodic part
        stats.pixel_moments, stats.pixel_range, stats.colour_covariance = pixel_statistics(coords)
        self.statistics_: PSStatistics = stats

    # ------------------------------------------------------------------ memory
    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Complex pyramid, its magnitudes and parents, per channel (``docs/memory.md``).

        An empirical model of the analysis and of one iteration of the projections: about
        ``110 + 150 n_orientations`` bytes per pixel and channel, nearly independent of
        ``n_scales`` (the coarser scales add a third), measured with ``tracemalloc``.
        """
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        channels = 3 if c == 3 and self.colour == "joint" else 1
        terms = {"exemplar": 16.0 * k * c}
        if output_shape is None:
            terms["analysis of the exemplar"] = k * (150.0 + channels * (100.0 + 140.0 * self.n_orientations))
            return terms
        ch, cw = self._canvas(output_shape)
        canvas = float(ch) * float(cw)
        terms["pyramids of one iteration"] = canvas * (100.0 + channels * (110.0 + 150.0 * self.n_orientations))
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    # ------------------------------------------------------------------ synthesis
    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        side = 2 ** (self.n_scales + 1)
        return max(shape[0], side), max(shape[1], side)

    def _run(self, initial: np.ndarray, iterations: int, callback) -> np.ndarray:
        pyramid = ComplexSteerablePyramid(initial.shape[1:], self.n_scales, self.n_orientations, single=True)
        def report(k, x):
            if callback is not None:
                callback(Progress("iteration", k, iterations, image=self._to_image(x)))

        return ps_synthesis(self.statistics_, initial, iterations, lags=self.lags, pyramid=pyramid, callback=report)

    def _sample(self, shape, rng, callback):
        h, w = self._canvas(shape)
        moments = self.statistics_.pixel_moments
        noise = rng.standard_normal((moments.shape[0], h, w))
        initial = moments[:, 0, None, None] + np.sqrt(moments[:, 1])[:, None, None] * noise
        out = self._run(initial, self.n_iterations, callback)
        return self._to_image(out)[: shape[0], : shape[1]], None

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

        Returns
        -------
        ndarray of float32 in [0, 1], the image's size, the exemplar's channels.
        """
        exemplar = self._require_fitted()
        img = np.asarray(as_exemplar(image, name="image"), dtype=np.float64)
        h, w = img.shape[:2]
        self._check_memory(exemplar.shape, (h, w), task=f"refining a {w}x{h} image", advice="use a smaller image")
        ch, cw = self._canvas((h, w))
        padded = np.pad(as_channels(img), ((0, ch - h), (0, cw - w), (0, 0)), mode="symmetric")
        iterations = self.n_iterations if n_iterations is None else int(n_iterations)
        return self._as_output(self._to_image(self._run(self._to_channels(padded), iterations, callback))[:h, :w])

