"""Efros-Leung non-parametric pixel sampling (Efros and Leung 1999)."""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import Range
from ..ops.nonparametric import NonParametricSampler
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, nonparametric_bytes, output_bytes
from ..errors import InputError

__all__ = ["EfrosLeung"]


class EfrosLeung(TextureSynthesizer):
    """Efros-Leung synthesis: grow the texture pixel by pixel from a central seed.

    Every pixel is drawn from the exemplar pixels whose neighbourhood best matches its
    already synthesised neighbourhood (Gaussian-weighted SSD, exhaustive exact search).
    The search is batched into matrix products without changing the sequential result
    (see :mod:`texsyn.ops.nonparametric`).

    Parameters
    ----------
    window_size : int
        Odd side of the square neighbourhood window.
    epsilon : float
        Candidates are the windows within ``(1 + epsilon)`` of the best distance.
    max_error : float
        Largest accepted distance per unit weight; it grows by 10 % after a pass that
        fills nothing.
    seed_size : int
        Side of the random exemplar seed placed at the centre of the output.

    References
    ----------
    A. Efros, T. Leung, "Texture synthesis by non-parametric sampling", ICCV 1999.
    C. Aguerrebere, Y. Gousseau, G. Tartavel, "Exemplar-based texture synthesis: the
    Efros-Leung algorithm", Image Processing On Line 3 (2013).

    Notes
    -----
    Limitations (paper, section 4): slow, since every pixel searches the whole exemplar;
    it may grow "garbage" or verbatim copies on some textures.
    """

    name = "efros_leung"
    summary = "Efros-Leung pixel-by-pixel non-parametric sampling"
    reference = "Efros, Leung, ICCV 1999"
    has_source_map = True

    def __init__(
        self,
        *,
        window_size: Annotated[int, Range(3, 101)] = 11,
        epsilon: Annotated[float, Range(0.0, 10.0)] = 0.1,
        max_error: Annotated[float, Range(0.0, None, low_open=True)] = 0.3,
        seed_size: Annotated[int, Range(1, 64)] = 3,
    ):
        self.window_size = window_size
        self.epsilon = epsilon
        self.max_error = max_error
        self.seed_size = seed_size

    def _check_params(self) -> None:
        super()._check_params()
        if self.window_size % 2 == 0:
            raise InputError(
                f"parameter 'window_size' of method 'efros_leung' must be odd, got {self.window_size}"
            )

    def min_exemplar_size(self):
        side = max(self.window_size, self.seed_size)
        return side, f"window_size={self.window_size} needs at least {side}x{side} pixels"

    def _fit(self, exemplar: np.ndarray) -> None:
        self.sampler_ = NonParametricSampler(exemplar, self.window_size)

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Every exemplar window (squared and scaled, ``16 K w^2 C`` bytes); the canvas and one
        batch of searches against all windows (``docs/memory.md``)."""
        h, w, c = shape_dims(exemplar_shape)
        kept, transient = nonparametric_bytes(h, w, c, self.window_size, output_shape)
        terms = {"exemplar windows": 8.0 * h * w * c + kept}
        if output_shape is None:
            terms["window extraction"] = transient
            return terms
        terms["canvas and one batch of searches"] = transient
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _sample(self, shape, rng, callback):
        report = None
        if callback is not None:

            def report(done: int, total: int) -> None:
                callback(Progress("pixels", done, total))

        values, source = self.sampler_.grow(
            shape,
            epsilon=self.epsilon,
            max_error=self.max_error,
            seed_size=self.seed_size,
            rng=rng,
            callback=report,
        )
        return values, source
