"""Histograms of steerable-pyramid subbands: what Heeger–Bergen's ``fit`` learns.

D. Heeger, J. Bergen, "Pyramid-based texture analysis/synthesis", SIGGRAPH 1995:
the texture is described by the histogram of its pixels and of every subband of its
steerable pyramid (the high-pass and low-pass residuals included). A histogram is kept as
the sorted values, per channel, which is all exact histogram matching needs
(:class:`texsyn.ops.histogram.HistogramMatcher`); see ``docs/methods/heeger_bergen.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..ops.histogram import HistogramMatcher
from ..transforms.steerable import SteerablePyramid

__all__ = ["SubbandHistograms", "subband_histograms"]


def _sorted_channels(image: np.ndarray) -> tuple[np.ndarray, ...]:
    """Read-only ascending values of every channel of an ``(H, W, C)`` array."""
    out = []
    for c in range(image.shape[-1]):
        values = np.sort(image[..., c], axis=None)
        values.flags.writeable = False
        out.append(values)
    return tuple(out)


@dataclass(frozen=True)
class SubbandHistograms:
    """Sorted pixel and subband values of an exemplar, per channel.

    Attributes
    ----------
    n_scales, n_orientations : int
        The steerable pyramid the subbands come from.
    band_keys : tuple
        Addresses of the subbands, in :meth:`texsyn.transforms.steerable.Pyramid.keys` order
        (``'highpass'``, ``(level, orientation)``..., ``'lowpass'``; levels 0-based, finest first).
    band_values : tuple of tuple of ndarray
        ``band_values[i][c]``: ascending values of subband ``band_keys[i]``, channel ``c``.
    pixel_values : tuple of ndarray
        Ascending pixel values of every channel.

    Examples
    --------
    >>> image = np.random.default_rng(0).random((16, 16, 1))
    >>> model = subband_histograms(image, image, n_scales=2, n_orientations=2)
    >>> len(model.band_keys), model.channels
    (6, 1)
    >>> pixels, bands = model.matchers(SteerablePyramid((20, 24), 2, 2))
    >>> len(bands)
    6
    """

    n_scales: int
    n_orientations: int
    band_keys: tuple
    band_values: tuple
    pixel_values: tuple

    @property
    def channels(self) -> int:
        """Number of channels described."""
        return len(self.pixel_values)

    def matchers(self, pyramid: SteerablePyramid) -> tuple[HistogramMatcher, dict]:
        """Histogram projections for images of ``pyramid``'s size.

        The targets depend on the output size (exact 1-D optimal transport when it differs
        from the exemplar's), so they are built for each synthesis; the model is not changed.

        Returns
        -------
        pixels : HistogramMatcher
            Imposes the pixel histograms on ``(H, W, C)`` images.
        bands : dict
            ``{key: HistogramMatcher}`` for every subband address.
        """
        h, w = pyramid.shape
        pixels = HistogramMatcher(self.pixel_values, h * w)
        bands = {}
        for key, values in zip(self.band_keys, self.band_values):
            bh, bw = pyramid.band_shape(key)
            bands[key] = HistogramMatcher(values, bh * bw)
        return pixels, bands


def subband_histograms(
    pixels: np.ndarray, analysed: np.ndarray, *, n_scales: int, n_orientations: int
) -> SubbandHistograms:
    """The :class:`SubbandHistograms` of an exemplar.

    Parameters
    ----------
    pixels : ndarray, shape (H, W, C)
        The values whose histograms the output's pixels get (the exemplar in the method's
        colour coordinates).
    analysed : ndarray, shape (H, W, C)
        The image whose steerable pyramid gives the subband histograms (the exemplar or its
        periodic component).
    n_scales, n_orientations : int
        Size of the steerable pyramid.
    """
    pyramid = SteerablePyramid(analysed.shape[:2], n_scales, n_orientations).forward(analysed)
    keys, values = [], []
    for key, band in pyramid.items():
        keys.append(key)
        values.append(_sorted_channels(band))
    return SubbandHistograms(
        n_scales=int(n_scales),
        n_orientations=int(n_orientations),
        band_keys=tuple(keys),
        band_values=tuple(values),
        pixel_values=_sorted_channels(pixels),
    )
