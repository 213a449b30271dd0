"""Efros–Leung non-parametric pixel sampling (Efros and Leung 1999); ``docs/methods/efros_leung.md``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

import numpy as np

from .._validation import OneOf, Range, as_exemplar, normalize_rng
from ..drivers.raster import grow_pixels
from ..errors import InputError
from ..ops.kcoherence import CoherentWindows
from ..ops.linalg import fixed_order
from ..ops.nonparametric import NonParametricSampler
from ..ops.patches import as_channels
from ..ops.progress import Progress, Reporter
from ._base import SynthesisResult, TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, nonparametric_bytes, output_bytes, shape_dims

__all__ = ["EfrosLeung"]


class EfrosLeung(TextureSynthesizer):
    """Efros-Leung synthesis: grow the texture pixel by pixel from a central seed.

    The algorithm of the paper (section 2), as :meth:`fit` and :meth:`_sample` run it:

    1. ``fit``: every exemplar window of side ``w`` (:class:`~texsyn.ops.nonparametric.NonParametricSampler`);
    2. ``sample``: a random ``seed_size`` square of the exemplar at the centre of the output;
       then, pass after pass over the unfilled pixels that touch the filled region, each
       pixel takes the centre of an exemplar window whose Gaussian-weighted distance to its
       known neighbourhood is within ``(1 + tolerance)`` of the best, if at most
       ``max_error`` (:func:`texsyn.drivers.raster.grow_pixels`).

    The search is exhaustive and exact: float32 lower bounds in matrix products, then exact
    distances of the windows that could be candidates, with the bytes of the plain float64
    search (``docs/methods/efros_leung.md``, "Performance"). ``search='approximate'`` compares
    each pixel with a few dozen k-coherent windows only ("Approximate search" there).

    Parameters
    ----------
    window_size : int
        Odd side of the square neighbourhood window.
    tolerance : float
        Candidates are the windows within ``(1 + tolerance)`` of the best distance (the
        paper's ``epsilon``; ``epsilon=`` is accepted with a DeprecationWarning).
    max_error : float
        Largest accepted distance per unit weight; it grows by 10 % after a pass that
        fills nothing.
    seed_size : int
        Side of the random exemplar seed placed at the centre of the output.
    search : {'exact', 'approximate'}
        ``'exact'``: every exemplar window is compared (the paper). ``'approximate'``: only
        the windows continuing the sources of the pixel's filled 8-neighbours (Ashikhmin
        2001) and their ``k_coherence`` most similar windows (Tong et al. 2002), with exact
        distances: 0.24 s instead of about 3.5 s of CPU for 128 -> 256 colour; about four
        choices in five are ones the exact search could make (measured in the docs).
    k_coherence : int
        Similar windows per continuation in the approximate search (ranked on the
        exemplar's 8 principal axes of Gaussian-weighted windows); unused by ``'exact'``.

    References
    ----------
    A. Efros, T. Leung, "Texture synthesis by non-parametric sampling", ICCV 1999.
    C. Aguerrebere, Y. Gousseau, G. Tartavel, "Exemplar-based texture synthesis: the
    Efros-Leung algorithm", Image Processing On Line 3 (2013).
    M. Ashikhmin, "Synthesizing natural textures", I3D 2001; X. Tong et al., "Synthesis of
    bidirectional texture functions on arbitrary surfaces", SIGGRAPH 2002 (k-coherence).

    Notes
    -----
    Limitations (paper, section 4): slow, since every pixel searches the whole exemplar;
    it may grow "garbage" or verbatim copies on some textures.
    """

    name = "efros_leung"
    #: the exact search's terms are calibrated (docs/memory.md); the approximate search's are
    #: not, and keep the default 1.25 (:meth:`_approximate_memory`)
    memory_margin = CALIBRATED_MARGIN
    summary = "Efros-Leung pixel-by-pixel non-parametric sampling"
    reference = "Efros, Leung, ICCV 1999"
    has_source_map = True
    deprecated_params = {"epsilon": "tolerance"}

    def __init__(
        self,
        *,
        window_size: Annotated[int, Range(3, 101)] = 11,
        tolerance: Annotated[float, Range(0.0, 10.0)] = 0.1,
        max_error: Annotated[float, Range(0.0, None, low_open=True)] = 0.3,
        seed_size: Annotated[int, Range(1, 64)] = 3,
        search: Annotated[str, OneOf(("exact", "approximate"))] = "exact",
        k_coherence: Annotated[int, Range(0, 64)] = 4,
    ):
        self.window_size = window_size
        self.tolerance = tolerance
        self.max_error = max_error
        self.seed_size = seed_size
        self.search = search
        self.k_coherence = k_coherence

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
        if self.search == "approximate":
            self.sampler_: NonParametricSampler | CoherentWindows = CoherentWindows(
                exemplar, self.window_size, k=self.k_coherence
            )
        else:
            self.sampler_ = NonParametricSampler(exemplar, self.window_size)

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Every exemplar window (squared and scaled, ``16 K w^2 C`` bytes); the canvas and one
        batch of searches against all windows (``docs/memory.md``)."""
        h, w, c = shape_dims(exemplar_shape)
        if self.search == "approximate":  # uncalibrated: the default margin of 1.25
            terms = self._approximate_memory(h, w, c, output_shape)
            return {key: value * 1.25 / CALIBRATED_MARGIN for key, value in terms.items()}
        kept, transient = nonparametric_bytes(h, w, c, self.window_size, output_shape, screened=True)
        terms = {"exemplar windows": 8.0 * h * w * c + kept}
        if output_shape is None:
            terms["window extraction"] = transient
            return terms
        terms["canvas and one batch of searches"] = transient
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _approximate_memory(self, h: int, w: int, c: int, output_shape) -> dict[str, float]:
        """The approximate search keeps the exemplar twice and ``k`` similar windows per window;
        its fit holds every window once in float32 (``docs/memory.md``)."""
        k = float(max(1, (h - self.window_size + 1) * (w - self.window_size + 1)))
        dim = float(self.window_size**2 * c)
        terms = {"exemplar and similar windows": 24.0 * h * w * c + 8.0 * k * (self.k_coherence + 2)}
        if output_shape is None:
            terms["windows in float32"] = 8.0 * k * dim + 16.0 * dim * dim
            return terms
        oh, ow = output_shape[:2]
        r = self.window_size // 2
        terms["canvas"] = float(oh + 2 * r) * float(ow + 2 * r) * (8.0 * c + 33.0) + 24.0 * oh * ow + 8.0 * k
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _sample(self, shape, rng, callback, *, torus: bool = False):
        values, source = grow_pixels(
            self.sampler_,
            shape,
            tolerance=self.tolerance,
            max_error=self.max_error,
            seed_size=self.seed_size,
            rng=rng,
            reporter=Reporter(callback, "pixels"),
            torus=torus,
        )
        return values, source

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """An output at least a window a side grows on a torus (``docs/tiling.md``, "On a torus")."""
        return min(shape) >= self.window_size

    def _sample_torus(self, shape, rng, callback):
        """The growth of :meth:`_sample` on a torus: windows, neighbours and batches wrap
        around the output's edges, so the region grows across them and the output tiles
        (:func:`texsyn.drivers.raster.grow_pixels` ``torus``); exact and approximate search."""
        return self._sample(shape, rng, callback, torus=True)

    @fixed_order
    def fill(
        self,
        image: np.ndarray,
        known: np.ndarray,
        *,
        exemplar_mask: np.ndarray | None = None,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> SynthesisResult:
        """Constrained synthesis (section 2): fill the unknown pixels of ``image``.

        The known pixels stay as they are; the unknown ones grow inwards from them by the
        passes of synthesis (:func:`texsyn.drivers.raster.grow_pixels`): "onion peel", each
        pass taking the unknown pixels that touch known ones, those with the most known
        pixels in their window first, each the centre of an exemplar window within
        ``(1 + tolerance)`` of the best distance on its known pixels (``docs/editing.md``).
        The search is the exact one (``search='approximate'`` is not used here).

        Parameters
        ----------
        image : ndarray, shape (H, W) or (H, W, C)
            Values in [0, 1], the exemplar's channels; unknown pixels may hold anything.
        known : ndarray of bool, shape (H, W)
            The pixels to keep.
        exemplar_mask : ndarray of bool, optional
            The exemplar pixels that may be used: only the windows lying wholly in it are
            candidates (filling from the rest of the image itself). All by default.
        rng, callback
            As in :meth:`sample`; progress stage ``"pixels"``.

        Returns
        -------
        SynthesisResult
            The filled image (float32) and the exemplar position of every pixel (``-1``
            for the known pixels).
        """
        ex = as_channels(self._require_fitted())
        img = as_channels(as_exemplar(image, name="image"))
        mask = np.asarray(known, dtype=bool)
        if mask.shape != img.shape[:2] or img.shape[2] != ex.shape[2]:
            raise InputError(
                f"image {img.shape} and mask {mask.shape} must have one size, and the exemplar's "
                f"{ex.shape[2]} channel(s)"
            )
        if exemplar_mask is not None:
            try:
                sampler = NonParametricSampler(ex, self.window_size, allowed=exemplar_mask)
            except ValueError:
                raise InputError(
                    f"no {self.window_size}x{self.window_size} window of the exemplar lies wholly in its "
                    "known pixels; give a smaller window_size or an exemplar"
                ) from None
        elif isinstance(self.sampler_, NonParametricSampler):
            sampler = self.sampler_
        else:
            sampler = NonParametricSampler(ex, self.window_size)
        start_source = np.full(mask.shape + (2,), -1, dtype=np.int64)
        values, source = grow_pixels(
            sampler,
            mask.shape,
            tolerance=self.tolerance,
            max_error=self.max_error,
            rng=normalize_rng(rng),
            reporter=Reporter(callback, "pixels"),
            known=(img, mask, start_source),
        )
        values = np.where(mask[..., None], img, values)
        return SynthesisResult(self._as_output(values), np.asarray(source, dtype=np.int32))

    @fixed_order
    def sample_guided(
        self,
        guide_source: np.ndarray,
        guide_target: np.ndarray,
        *,
        weight: float = 1.0,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> SynthesisResult:
        """Guided synthesis: grow a texture whose guide map follows ``guide_target``.

        The growth of :meth:`sample` (section 2), each pixel's distance adding ``weight``
        times the Gaussian-weighted mean squared difference between the exemplar window's
        guide (``guide_source``, the exemplar's size) and the output's guide around the
        pixel (``guide_target``, the output's size, which the output takes), over the whole
        window, the pixel itself included (``docs/editing.md``). The search is the exact
        float64 matrix product (the float32 screen of synthesis knows nothing of guides).
        """
        ex = as_channels(self._require_fitted())
        source = as_channels(np.asarray(guide_source, dtype=np.float64))
        target = as_channels(np.asarray(guide_target, dtype=np.float64))
        if source.shape[:2] != ex.shape[:2] or source.shape[2] != target.shape[2]:
            raise InputError(
                f"the exemplar's guide ({source.shape[1]}x{source.shape[0]}) must have the exemplar's size "
                f"({ex.shape[1]}x{ex.shape[0]}) and the channels of the output's guide"
            )
        sampler = NonParametricSampler(ex, self.window_size, guide=source, guide_weight=weight)
        values, source_map = grow_pixels(
            sampler,
            target.shape[:2],
            tolerance=self.tolerance,
            max_error=self.max_error,
            seed_size=self.seed_size,
            rng=normalize_rng(rng),
            reporter=Reporter(callback, "pixels"),
            guide=target,
        )
        return SynthesisResult(self._as_output(values), np.asarray(source_map, dtype=np.int32))
