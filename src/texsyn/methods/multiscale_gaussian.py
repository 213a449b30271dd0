"""Multiscale locally Gaussian synthesis, MSLG (Raad, Desolneux & Morel 2016, section 4).

Algorithm 3 of the paper, as :class:`MSLG` runs it:

1. ``fit``: zoom the exemplar out ``K - 1`` times (Gaussian blur 1.4, sub-sampling by 2,
   eq. 9); for every scale but the coarsest, split it into low and high frequencies and
   build the search of the joint distance of eq. (14) (:class:`~texsyn.models.gaussian.PatchSource`);
2. ``sample``: the coarse-to-fine walk (:func:`texsyn.drivers.coarse_to_fine.coarse_to_fine`)

   - coarsest scale (line 3): LG with half-patch overlaps joined by a boundary cut
     (``coarse_seam='quilt'``) or averaged as eq. 15 does (``'average'``), with
     :func:`texsyn.methods.single_scale_gaussian.single_scale`; with ``histogram='match'``
     it then gets the coarsest exemplar scale's histogram;
   - each finer scale (:meth:`MSLG._fine_scale`, lines 5-17): zoom the coarser result in
     (eq. 12) and keep it as the low frequencies; in raster order, sample the high
     frequencies of each patch from the local Gaussian of the ``m`` exemplar patches
     nearest for eq. (14) (overlap term plus low-resolution term);
3. with ``histogram='match'``, the exemplar's histogram per channel; with ``highpass='match'``
   too, the high-pass residual of a steerable pyramid gets the exemplar's histogram and the
   pixels their histogram again (:meth:`MSLG._match_highpass`);
4. optionally, a short Portilla–Simoncelli synthesis started from the result (section 5,
   Fig. 8).

See ``docs/methods/local_gaussian.md``.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import OneOf, Range
from ..drivers.coarse_to_fine import coarse_to_fine
from ..drivers.raster import (
    Block,
    block_window,
    fill_blocks,
    raster_positions,
    torus_fits,
    torus_positions,
)
from ..errors import InputError
from ..models.gaussian import PatchSource
from ..models.histograms import SubbandHistograms, subband_histograms
from ..ops.canvas import crop_to_output, extend_to_canvas, padded_canvas
from ..ops.fourier import periodic_smooth_decomposition
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ..transforms.pyramids import crop_to_multiple, gaussian_blur, zoom_in, zoom_out
from ..transforms.steerable import SteerablePyramid, max_scales
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, fft_search_bytes, output_bytes, shape_dims
from .heeger_bergen import HeegerBergen
from .portilla_simoncelli import PortillaSimoncelli
from .single_scale_gaussian import (
    PASTE,
    clamp_neighbours,
    draw,
    local_gaussian_bytes,
    match_exemplar_marginals,
    single_scale,
    torus_free,
)

__all__ = ["MSLG", "ZOOM_SIGMA"]

#: Gaussian blur of the zoom-out and of the low/high split (paper, eq. 9 and Table 1)
ZOOM_SIGMA = 1.4


class MSLG(TextureSynthesizer):
    """Multiscale locally Gaussian (MSLG) synthesis (Raad et al. 2016, Algorithm 3).

    The exemplar is zoomed out ``n_scales - 1`` times (Gaussian blur 1.4, sub-sampling by
    2). The coarsest scale is synthesised by LG with half-patch overlaps (joined as
    ``coarse_seam`` says);
    each finer scale zooms the previous result in (Fourier zero-padding, eq. 12) and keeps
    it as the low frequencies of every patch, sampling only the high frequencies from the
    local Gaussian of the ``m`` exemplar patches nearest for the joint distance of eq. (14)
    (overlap term plus low-resolution term). Small patches then reproduce the global
    arrangement of macro-textures.

    Parameters
    ----------
    patch_size : int
        Even patch side ``n`` (the step is ``n / 2``).
    n_neighbors : int
        Number ``m`` of nearest exemplar patches per Gaussian.
    n_scales : int
        Number of scales ``K`` (1 is LG with half-patch overlaps joined by ``coarse_seam``).
    mode : str
        ``'sample'`` or ``'mean'``.
    seed_patch : str
        First patch at the coarsest scale: ``'gaussian'`` or ``'copy'``.
    zoom_boundary : str
        Boundary handling of the Fourier zoom-in: ``'symmetric'`` (mirror extension, no
        border ringing) or ``'periodic'`` (the paper's literal formula).
    coarse_seam : str
        How the coarsest scale's patches join: ``'quilt'`` (boundary cut) or ``'average'``
        (eq. 15, the paper's; averaging two draws in every overlap removes up to half of the
        coarse scale's variance: ``docs/methods/local_gaussian.md``, "Deviations").
    histogram : str
        ``'match'`` gives the coarsest scale the histogram of the coarsest exemplar scale
        (it is zoomed in as the low frequencies of the next), and the output the exemplar's
        histogram per channel at the end (``docs/methods/local_gaussian.md``, "Marginals"),
        before ``post``; ``'none'`` skips both.
    highpass : str
        With ``histogram='match'``: ``'match'`` gives the output's high-pass residual (the
        frequencies above the finest band of a steerable pyramid) the histogram of the
        exemplar's and then the pixels their histogram again, so that matching the pixels does
        not leave the finest details up to twice as strong as the exemplar's
        (``docs/methods/local_gaussian.md``, "Marginals"); ``'none'`` matches the pixels only.
    post : str
        ``'portilla_simoncelli'`` uses the MSLG result as the initial image of a short
        Portilla-Simoncelli synthesis (Raad et al. 2016, section 5, Fig. 8); ``'none'`` skips it.
    post_iterations : int
        Portilla-Simoncelli iterations of the post-processing.

    References
    ----------
    Raad, Desolneux, Morel, JMIV 2016, section 4, Algorithm 3, eqs. (9)-(15).
    """

    name = "mslg"
    memory_margin = CALIBRATED_MARGIN
    summary = "Multiscale locally Gaussian patch sampling"
    reference = "Raad, Desolneux, Morel, JMIV 2016 (MSLG)"
    has_source_map = False
    #: channels are synthesised jointly: a material stack or an RGBA exemplar (docs/materials.md)
    max_channels = 16

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 256)] = 20,
        n_neighbors: Annotated[int, Range(2, 10000)] = 20,
        n_scales: Annotated[int, Range(1, 6)] = 2,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        zoom_boundary: Annotated[str, OneOf(("symmetric", "periodic"))] = "symmetric",
        coarse_seam: Annotated[str, OneOf(("quilt", "average"))] = "quilt",
        histogram: Annotated[str, OneOf(("match", "none"))] = "match",
        highpass: Annotated[str, OneOf(("match", "none"))] = "match",
        post: Annotated[str, OneOf(("none", "portilla_simoncelli"))] = "none",
        post_iterations: Annotated[int, Range(1, 500)] = 10,
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.n_scales = n_scales
        self.mode = mode
        self.seed_patch = seed_patch
        self.zoom_boundary = zoom_boundary
        self.coarse_seam = coarse_seam
        self.histogram = histogram
        self.highpass = highpass
        self.post = post
        self.post_iterations = post_iterations

    def _check_params(self) -> None:
        super()._check_params()
        if self.patch_size % 2:
            raise InputError(
                f"parameter 'patch_size' of method 'mslg' must be even (the step is n/2), got {self.patch_size}"
            )

    def min_exemplar_size(self):
        side = 2 ** (self.n_scales - 1) * (self.patch_size + 1)
        return side, (
            f"with n_scales={self.n_scales} the coarsest scale is 1/{2 ** (self.n_scales - 1)} of the "
            f"exemplar and patch_size={self.patch_size} needs at least {self.patch_size + 1} pixels there"
        )

    def _post_method(self, exemplar_shape: tuple[int, ...]) -> PortillaSimoncelli:
        """The (unfitted) Portilla–Simoncelli method of the final pass (section 5)."""
        rows, cols = exemplar_shape[:2]
        return PortillaSimoncelli(n_scales=max_scales((rows, cols)), n_iterations=self.post_iterations)

    def _canvas(self, shape: tuple[int, int]) -> tuple[int, int]:
        """Finest-scale canvas: a multiple of ``2^(K-1)``, at least a patch at the coarsest scale."""
        big = 2 ** (self.n_scales - 1)
        return padded_canvas(shape, minimum=big * self.patch_size, multiple=big)

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """FFT searches of every scale; the Fourier zoom-in of the finest scale (``docs/memory.md``).

        The zoom-in transforms the mirror extension of each scale, a complex image four times
        the size of the next one, so it dominates the sampling of large outputs.
        """
        h, w, c = shape_dims(exemplar_shape)
        big = 2 ** (self.n_scales - 1)
        hc, wc = (h // big) * big, (w // big) * big
        kept_total, build_max = 8.0 * h * w * c, 0.0
        for k in range(self.n_scales):
            sh, sw = hc >> k, wc >> k
            coarse = k == self.n_scales - 1
            kept, build, _ = fft_search_bytes(sh, sw, c if coarse else 2 * c)
            kept_total += kept + 8.0 * sh * sw * c * (1 if coarse else 2)
            build_max = max(build_max, build + 24.0 * sh * sw * c)
        terms = {"exemplar scales and their spectra": kept_total}
        post = None
        if self.post == "portilla_simoncelli":
            post = self._post_method((h, w))
            terms["Portilla-Simoncelli statistics"] = sum(post.memory_terms(exemplar_shape).values())
        highpass_build = 0.0
        if self._matches_highpass():
            # the exemplar's high-pass histograms: a one-scale, one-orientation Heeger-Bergen
            # model of the whole exemplar (missed until a 4000x3000 exemplar's fit measured
            # 5.4 GiB against an estimate of 4.4: benchmarks/results.md)
            highpass = HeegerBergen(n_scales=1, n_orientations=1).memory_terms(exemplar_shape)
            terms["high-pass histograms"] = highpass["exemplar and its sorted subbands"]
            highpass_build = highpass["pyramid of the exemplar"]
        if output_shape is None:
            terms["spectra construction"] = max(build_max, highpass_build)
            return terms
        n = self.patch_size
        rows, cols = self._canvas(output_shape[:2])
        canvas = float(rows) * float(cols)
        m = min(
            self.n_neighbors,
            max(1, ((hc >> (self.n_scales - 1)) - n + 1) * ((wc >> (self.n_scales - 1)) - n + 1)),
        )
        _, _, query = fft_search_bytes(hc, wc, 2 * c if self.n_scales > 1 else c, masks=9)
        search = max(query, local_gaussian_bytes(m, n * n * c))
        # the zoom-in (symmetric: the mirror extension's spectrum, the zero-padded spectrum of
        # four times its size, its shifted copy and the inverse transform's two passes;
        # tracemalloc counts the whole zero-padded spectrum, the resident set only its written
        # quarter: 280 and 68 bytes a value traced, docs/memory.md, "Every method at its
        # defaults") is over before the finest scale is synthesised
        zoom = (280.0 if self.zoom_boundary == "symmetric" else 68.0) * c * canvas
        synthesis = canvas * (16.0 * c + 1.0) + output_bytes(c, output_shape)
        if self._matches_highpass():
            synthesis += 64.0 * c * canvas  # the high-pass residual and its histogram
        terms["one search or one local Gaussian"] = search
        if self.n_scales > 1:
            synthesis += 32.0 * c * canvas  # the zoomed low-pass (a view of the zoom's result)
            terms["finest scale: the Fourier zoom-in, then the synthesis"] = max(zoom, synthesis)
        else:
            terms["canvas, mask, high-pass residual and output"] = synthesis
        if post is not None:
            terms["Portilla-Simoncelli refinement"] = sum(
                post.memory_terms(exemplar_shape, output_shape).values()
            )
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = crop_to_multiple(as_channels(exemplar), 2 ** (self.n_scales - 1))
        scales = [ex]
        for _ in range(self.n_scales - 1):
            scales.append(zoom_out(scales[-1], ZOOM_SIGMA))
        self.scales_ = scales
        n = self.patch_size
        self.coarse_source_ = PatchSource.build(scales[-1], scales[-1], n)
        self.fine_sources_ = []
        for k in range(self.n_scales - 1):
            low = gaussian_blur(scales[k], ZOOM_SIGMA)
            high = scales[k] - low
            stacked = np.concatenate([scales[k], low], axis=2)
            self.fine_sources_.append(PatchSource.build(stacked, high, n))
        self.highpass_model_: SubbandHistograms | None = None
        if self._matches_highpass():
            channels = as_channels(exemplar)
            self.highpass_model_ = subband_histograms(
                channels, periodic_smooth_decomposition(channels)[0], n_scales=1, n_orientations=1
            )
        self.post_ = None
        if self.post == "portilla_simoncelli":
            self.post_ = self._post_method(exemplar.shape).fit(exemplar)

    def _matches_highpass(self) -> bool:
        return self.histogram == "match" and self.highpass == "match"

    def _match_highpass(self, image: np.ndarray) -> np.ndarray:
        """The exemplar's high-pass histogram, then its pixel histogram, per channel.

        Matching the pixel histogram of a blend that lost mid-frequency contrast stretches
        every frequency, the finest too: measured as Portilla and Simoncelli's high-pass
        variance, MSLG's outputs had 1.2-2.3 times the exemplar's. Imposing the histogram of
        the exemplar's high-pass residual (one Heeger-Bergen step restricted to that band,
        computed on the exemplar's periodic component so its borders add no edge) and then
        the pixel histogram brings it back (``docs/methods/local_gaussian.md``, "Marginals").
        """
        model = self.highpass_model_
        assert model is not None
        pyramid = SteerablePyramid(padded_canvas(image.shape[:2], minimum=2), 1, 1)
        canvas = extend_to_canvas(image, pyramid.shape, mode="symmetric")
        _, match_band = model.matchers(pyramid)
        coeffs = pyramid.forward(canvas)
        coeffs["highpass"] = match_band["highpass"](coeffs["highpass"])
        out = crop_to_output(pyramid.inverse(coeffs), image.shape[:2])
        return match_exemplar_marginals(out, self.exemplar_, patch_size=self.patch_size)

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """True where MSLG can run on the output's torus (``docs/tiling.md``, "On a torus"):
        no Portilla–Simoncelli pass, sides that are multiples of ``2^(n_scales - 1)`` (every
        scale is the output's torus, halved), and blocks that fit the torus at every scale
        (:func:`~texsyn.drivers.raster.torus_fits`)."""
        n, big = self.patch_size, 2 ** (self.n_scales - 1)
        if self.post != "none" or any(side % big for side in shape):
            return False
        free = torus_free(n)
        return all(
            torus_fits(side // 2**level, n, step, free=free)
            for side in shape
            for level in range(self.n_scales)
            for step in (n - n // 2, n // 2)
        )

    def _sample_torus(self, shape, rng, callback):
        """Algorithm 3 on the output's torus: the coarsest scale's LG and every finer scale's
        blocks wrap across the edges (:func:`~texsyn.drivers.raster.fill_blocks` with
        ``torus=True``), and the zoom-in between scales is periodic (eq. 12 as the paper
        writes it), so that every scale wraps."""
        return self._sample(shape, rng, callback, torus=True)

    def _sample(self, shape, rng, callback, torus: bool = False):
        n, big, n_scales = self.patch_size, 2 ** (self.n_scales - 1), self.n_scales
        canvas_h, canvas_w = tuple(shape) if torus else self._canvas(shape)
        sources = [self.coarse_source_] + self.fine_sources_
        m = min(clamp_neighbours(self.n_neighbors, s, self.name) for s in sources)

        def scale(level: int, coarser: np.ndarray | None) -> np.ndarray:
            reporter = Reporter(callback, f"scale {n_scales - level}/{n_scales}")
            if coarser is None:  # the coarsest scale: LG, patches joined by `coarse_seam`
                coarse = single_scale(
                    self.scales_[-1],
                    self.coarse_source_,
                    (canvas_h // big, canvas_w // big),
                    overlap=n // 2,
                    m=m,
                    model="lg",
                    seam=self.coarse_seam,
                    mode=self.mode,
                    sigma=0.0,
                    theta=0.0,
                    seed_patch=self.seed_patch,
                    rng=rng,
                    reporter=reporter,
                    torus=torus,
                )
                if self.histogram == "match":  # the coarse scale's contrast, before it is zoomed in
                    coarse = match_exemplar_marginals(coarse, self.scales_[-1])
                return coarse
            low = zoom_in(coarser, boundary="periodic" if torus else self.zoom_boundary)
            return self._fine_scale(low, self.fine_sources_[level], m, rng, reporter, torus=torus)

        out = crop_to_output(coarse_to_fine(scale, n_scales)[0], shape)
        if self.histogram == "match":
            out = match_exemplar_marginals(out, self.exemplar_, patch_size=self.patch_size)
            if self.highpass_model_ is not None and out.shape[0] * out.shape[1] >= self.patch_size**2:
                out = self._match_highpass(out)
        if self.post_ is not None:
            report = Reporter(callback, "portilla_simoncelli")
            out = self.post_.refine(np.clip(out, 0.0, 1.0), callback=report.relabel(report.stage))
        return out, None

    def _fine_scale(
        self, low: np.ndarray, source: PatchSource, m: int, rng, reporter: Reporter, torus: bool = False
    ) -> np.ndarray:
        """Alg. 3 lines 6-17: high frequencies sampled on top of the zoomed-in result ``low``.

        ``source`` holds this scale's joint search and its high frequencies (lines 9-11); the
        search's energy terms are cached for this call only, so the fitted source is never
        changed. ``torus``: the blocks, and the part of ``low`` under each, wrap across the
        edges (:func:`~texsyn.drivers.raster.torus_positions`).
        """
        n = self.patch_size
        channels = low.shape[2]
        low_weight = np.full((n, n, channels), 1.0 / (channels * n * n))
        energies: dict = {}  # this call's cache of the search's energy terms

        height, width = low.shape[:2]

        def choose(block: Block) -> np.ndarray:
            # the joint distance of eq. (14): overlap term and low-resolution term, as channels
            x, y, mask = block.row, block.col, block.known
            under = low[block_window(x, y, n, (height, width), torus=torus)]
            k = int(mask.sum()) * channels
            over = np.broadcast_to(mask[..., None] / max(k, 1), (n, n, channels))
            weights = np.concatenate([over, low_weight], axis=2)
            query = np.concatenate([block.values, under], axis=2)
            gauss = source.neighbour_gaussian(query, weights, m, energies=energies)  # lines 9-12
            return under + draw(gauss, self.mode, rng).reshape(n, n, channels)  # 13-14

        out = np.zeros_like(low)
        if torus:  # the last block keeps a quarter free, as at the coarsest scale
            rows, cols = (torus_positions(side, n, n // 2, free=torus_free(n)) for side in (height, width))
        else:
            rows, cols = raster_positions(height, n, n // 2), raster_positions(width, n, n // 2)
        fill_blocks(out, rows, cols, n, choose, PASTE["none"], reporter=reporter, torus=torus)
        return out
