"""Non-parametric sampling on the dual-tree complex wavelet transform (Gallagher and Kokaram).

The algorithm of the paper's section 3.1, step by step (``docs/methods/cwt.md``):

1. Analyse the exemplar with an ``L``-level DT-CWT, each of Y, U, V for colour
   (:meth:`ComplexWaveletSampling._fit`, :class:`texsyn.transforms.dtcwt.DTCWT`).
2. Walk the coefficient tree from the coarsest level to the finest
   (:func:`texsyn.drivers.coarse_to_fine.coarse_to_fine`), one source map per level:

   - at the coarsest level ``L - 1``, grow the output by Efros-Leung sampling on the six
     complex subbands searched jointly, seeded with the exemplar at the centre
     (:meth:`ComplexWaveletSampling._grow_coarsest`, with
     :func:`texsyn.drivers.raster.grow_pixels`); one position there summarises a
     ``2^L x 2^L`` pixel area, so a small window sees large structures (whole words of a
     text). Beyond the paper, a candidate that continues an already placed neighbour
     (Ashikhmin's coherent candidate, the paper's reference [1]) is preferred when it is
     within ``(1 + coherence)`` of the best
     (:class:`~texsyn.ops.coherence.CoherentSampler`), so that neighbouring blocks
     continue each other instead of coming from unrelated places;
   - every finer level copies the ``2 x 2`` children of its parent's source
     (:func:`block_indices`, the paper's Fig. 4); with ``refine=True`` (the direction of
     the paper's section 4, not in the paper) every finer level then re-chooses each
     position among its neighbours' continued sources, with its full neighbourhood
     (:meth:`ComplexWaveletSampling._refine_level`), which moves the seams between copied
     blocks to where the two sources agree.

3. Gather every subband and the low-pass image of every channel along these maps
   (:func:`propagate`) and invert the transform.

Levels are 0-based, the finest first, as everywhere in texsyn; the paper's "level ``n``"
is our level ``L - 1``.

References
----------
C. Gallagher, A. Kokaram, "Wavelet based texture synthesis", sections 2-3.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import OneOf, Range
from ..drivers.coarse_to_fine import coarse_to_fine
from ..drivers.raster import grow_pixels
from ..errors import InputError
from ..ops.canvas import crop_to_output, padded_canvas
from ..ops.coherence import CoherentSampler, independent_groups, refine_group, window_offsets
from ..ops.color import ColourSpace, colour_space
from ..ops.nonparametric import NonParametricSampler
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ..transforms.dtcwt import DTCWT, DTCWTPyramid
from ..transforms.pyramids import crop_to_multiple
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, nonparametric_bytes, output_bytes, shape_dims

__all__ = ["ComplexWaveletSampling", "propagate", "block_indices"]

#: most passes of the refinement over a level (it stops earlier when a pass changes nothing)
REFINE_SWEEPS = 3


def block_indices(grid: np.ndarray, block: int) -> np.ndarray:
    """Expand a per-cell index map to a per-sample map of ``block x block`` children.

    ``grid[i, j] = a`` (one coordinate) becomes ``out[b i + u, b j + v] = b a + u`` (rows)
    for the coefficient tree of the paper's Fig. 4 (section 3.1, third step): the child
    ``(u, v)`` of cell ``(i, j)`` at a level ``log2(b)`` finer comes from the same child of
    the source cell.

    Examples
    --------
    >>> block_indices(np.array([[[5, 7]]]), 2)[..., 0]
    array([[10, 10],
           [11, 11]])
    """
    rows = block * np.repeat(np.repeat(grid[..., 0], block, axis=0), block, axis=1)
    cols = block * np.repeat(np.repeat(grid[..., 1], block, axis=0), block, axis=1)
    offs = np.arange(rows.shape[0]) % block
    offc = np.arange(rows.shape[1]) % block
    return np.stack([rows + offs[:, None], cols + offc[None, :]], axis=-1)


def propagate(pyramid: DTCWTPyramid, maps: list[np.ndarray], lowpass_map: np.ndarray) -> DTCWTPyramid:
    """Gather coefficients of ``pyramid`` along per-level source maps.

    Parameters
    ----------
    pyramid : DTCWTPyramid
        The exemplar's coefficients (one channel).
    maps : list of ndarray of int
        ``maps[level]`` of shape ``(h_level, w_level, 2)``, 0-based with the finest first:
        the exemplar position of every output coefficient of that level.
    lowpass_map : ndarray of int
        Exemplar position of every output low-pass sample.

    Returns
    -------
    DTCWTPyramid
        The output's coefficients, ready for :meth:`DTCWT.inverse`.
    """
    highs = [hp[m[..., 0], m[..., 1]] for hp, m in zip(pyramid.highpasses, maps)]
    low = pyramid.lowpass[lowpass_map[..., 0], lowpass_map[..., 1]]
    return DTCWTPyramid(lowpass=low, highpasses=highs)


class ComplexWaveletSampling(TextureSynthesizer):
    """DT-CWT domain non-parametric sampling (Gallagher and Kokaram).

    Efros-Leung growth (Gaussian-weighted window, candidates within ``tolerance`` of the best)
    on the six complex subbands of the coarsest level, seeded with the whole exemplar at the
    centre, preferring the continuation of an already placed neighbour (``coherence``); the
    chosen source positions drive the copy of every finer level and of the low-pass image
    through the coefficient tree; colour is synthesised on Y and the same coordinates carry U
    and V (``docs/methods/cwt.md``).

    Parameters
    ----------
    levels : int
        Number ``L`` of DT-CWT levels; the search runs on the coarsest, where each position
        covers ``2^L x 2^L`` pixels.
    window : int
        Odd neighbourhood width ``w1`` at the coarsest level.
    tolerance : float
        Candidates are within ``(1 + tolerance)`` of the best distance (the paper's epsilon,
        0.1).
    seed : str
        'exemplar' (the whole exemplar grid at the centre, the paper's Fig. 1) or 'random'
        (a random 3x3 block).
    candidates : str
        'all' exemplar positions (windows reach into the zero padding, the paper's reading)
        or only 'valid' ones whose window lies inside.
    filters : str
        'a' (near_sym_a + qshift_a) or 'b' (near_sym_b + qshift_b) Kingsbury filters.
    coherence : float
        Beyond the paper (Ashikhmin's coherent candidates, the paper's reference [1]): at the
        coarsest level, the best continuation of an already placed neighbour (its source
        shifted by the offset between them) is taken when its distance is within
        ``(1 + coherence)`` of the best; 0 gives the paper's rule alone. Neighbouring blocks
        then continue each other (mortar lines, text lines) instead of coming from unrelated
        places.
    refine : bool
        Beyond the paper (its section 4 names the direction): re-choose every position of
        every finer level, with its full (non-causal) neighbourhood, among its propagated
        source and the continuations of its neighbours' sources, which moves the seams
        between copied blocks to where the sources agree.
    refine_radius : int
        Also consider, at the finer levels, the sources within this many positions of the
        propagated one (0: only the neighbours' continuations).

    References
    ----------
    C. Gallagher, A. Kokaram, "Wavelet based texture synthesis", sections 2-3, Figs. 1 and 4.
    M. Ashikhmin, "Synthesizing natural textures", I3D 2001, section 3.

    Notes
    -----
    Limitations (paper, section 4): mild blur, more visible on sharp textures, because the
    copied blocks' filter supports overlap. Continuations are whole ``2^L x 2^L`` blocks, so
    where no continuation exists (beyond the exemplar's border) a structure still breaks at
    a block border; ``refine`` moves such seams but cannot create the missing content.
    ``epsilon`` is the deprecated name of ``tolerance``.
    """

    name = "cwt"
    summary = "Efros-Leung sampling on the coarsest DT-CWT level, propagated down the coefficient tree"
    reference = "Gallagher, Kokaram, Wavelet based texture synthesis"
    has_source_map = True
    source_map_exact = False
    deprecated_params = {"epsilon": "tolerance"}
    memory_margin = CALIBRATED_MARGIN

    def __init__(
        self,
        *,
        levels: Annotated[int, Range(1, 5)] = 3,
        window: Annotated[int, Range(3, 31)] = 5,
        tolerance: Annotated[float, Range(0.0, 10.0)] = 0.1,
        seed: Annotated[str, OneOf(("exemplar", "random"))] = "exemplar",
        candidates: Annotated[str, OneOf(("all", "valid"))] = "all",
        filters: Annotated[str, OneOf(("a", "b"))] = "a",
        coherence: Annotated[float, Range(0.0, 10.0)] = 2.0,
        refine: bool = False,
        refine_radius: Annotated[int, Range(0, 4)] = 0,
    ):
        self.levels = levels
        self.window = window
        self.tolerance = tolerance
        self.seed = seed
        self.candidates = candidates
        self.filters = filters
        self.coherence = coherence
        self.refine = refine
        self.refine_radius = refine_radius

    def _check_params(self) -> None:
        super()._check_params()
        if self.window % 2 == 0:
            raise InputError(f"parameter 'window' of method 'cwt' must be odd, got {self.window}")

    def min_exemplar_size(self):
        cells = self.window if self.candidates == "valid" else 3
        side = 2**self.levels * cells
        return (
            side,
            f"levels={self.levels} needs at least {side}x{side} pixels ({cells} positions at the coarsest level)",
        )

    def _transform(self) -> DTCWT:
        return DTCWT(self.levels, biort=f"near_sym_{self.filters}", qshift=f"qshift_{self.filters}")

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """DT-CWT pyramids and the windows of the coarsest level; the output's pyramid and maps.

        The filters of length ``m`` gather ``m`` shifted copies of the rows of an image in
        blocks of at most 2 MiB (:mod:`texsyn.transforms.dtcwt`), after a contiguous copy of
        the image; ``refine`` holds a zero-padded copy of one exemplar level and a copy of one output
        source map (``docs/memory.md``).
        """
        h, w, c = shape_dims(exemplar_shape)
        q = 2**self.levels
        hc, wc = (h // q) * q, (w // q) * q  # the exemplar as _fit crops it (crop_to_multiple)
        k = float(hc * wc)
        taps = 19 if self.filters == "b" else 7
        pyramid = 32.0 * k + 8.0 * k / 4 ** (self.levels - 1)
        pad = self.window // 2 if self.candidates == "all" else 0
        top_h, top_w = hc // q + 2 * pad, wc // q + 2 * pad
        grid = None if output_shape is None else self._grid(output_shape)
        kept, transient = nonparametric_bytes(top_h, top_w, 12, self.window, grid)
        terms = {"exemplar pyramids and coarsest windows": 16.0 * k * c + c * pyramid + kept}
        if output_shape is None:
            terms["pyramid construction"] = max(8.0 * taps * k + 80.0 * k, transient)
            return terms
        assert grid is not None
        full = float(grid[0] * q) * float(grid[1] * q)
        terms["growth at the coarsest level"] = transient
        if self.coherence > 0:  # CoherentSampler: the windows' values carry their sources
            terms["growth at the coarsest level"] += 16.0 * (top_h * top_w + grid[0] * grid[1])
        terms["coefficient maps"] = 16.0 * full * (1.0 / 3 + 4.0 / 4**self.levels + 1.5)
        side = float(max(grid) * q)  # the longest row a filter gathers
        gathered = min(8.0 * taps * full, max(8.0 * 2**18, 8.0 * taps * side))
        terms["one output pyramid and its inverse"] = pyramid / k * full + 16.0 * full + gathered
        terms["output planes"] = 8.0 * c * full + output_bytes(c, output_shape)
        if self.refine:  # the padded level-0 subbands of the exemplar, one level-0 source map
            terms["refinement"] = 24.0 * k + 4.0 * full
        return terms

    def _grid(self, shape: tuple[int, int]) -> tuple[int, int]:
        """Positions of the coarsest level: the canvas (a multiple of ``2^levels``) over ``2^levels``."""
        q = 2**self.levels
        rows, cols = padded_canvas(shape, multiple=q)
        return (rows // q, cols // q)

    def _fit(self, exemplar: np.ndarray) -> None:
        """Step 1: the DT-CWT of every channel; the coarsest subbands of Y become the search bank."""
        ex = crop_to_multiple(as_channels(exemplar), 2**self.levels)
        self.colour_space_: ColourSpace = colour_space("yuv", ex)  # the paper works on Y, U, V
        channels = self.colour_space_.forward(ex)
        transform = self._transform()
        self.pyramids_ = [transform.forward(channels[..., c]) for c in range(channels.shape[2])]
        top = self.pyramids_[0].highpasses[-1]
        stack = np.concatenate([top.real, top.imag], axis=2)  # coherent 6-vector as 12 reals
        self.pad_ = self.window // 2 if self.candidates == "all" else 0
        padded = np.pad(stack, ((self.pad_, self.pad_), (self.pad_, self.pad_), (0, 0)))
        self.sampler_ = NonParametricSampler(padded, self.window)
        self.cropped_shape_ = ex.shape[:2]

    def _sample(self, shape, rng, callback):
        """Steps 2 and 3: source maps coarse to fine, then the gathered coefficients inverted."""
        grid = self._grid(shape)

        def level_step(level: int, coarser: np.ndarray | None) -> np.ndarray:
            if coarser is None:  # the coarsest level: Efros-Leung growth
                return self._grow_coarsest(grid, rng, Reporter(callback, "positions"))
            children = block_indices(coarser, 2)  # the coefficient tree (paper, Fig. 4)
            return self._refine_level(level, children) if self.refine else children

        maps = coarse_to_fine(level_step, self.levels)
        cells = maps[-1]
        lowpass_map = block_indices(cells, 2)
        info = {"cells": cells, "level_maps": maps, "lowpass_map": lowpass_map}
        Reporter(callback, "propagation", 1)(1, info=info)
        transform = self._transform()
        planes = [transform.inverse(propagate(p, maps, lowpass_map)) for p in self.pyramids_]
        image = self.colour_space_.inverse(np.stack(planes, axis=-1))
        # pixel source: the level-0 position of each pixel's coefficients, two pixels per position
        pixel = block_indices(maps[0], 2)
        pixel[..., 0] = np.minimum(pixel[..., 0], self.cropped_shape_[0] - 1)
        pixel[..., 1] = np.minimum(pixel[..., 1], self.cropped_shape_[1] - 1)
        return crop_to_output(image, shape), crop_to_output(pixel, shape)

    def _grow_coarsest(
        self, grid: tuple[int, int], rng: np.random.Generator, reporter: Reporter
    ) -> np.ndarray:
        """Efros-Leung growth of the coarsest level's source map (paper, sections 2 and 3.1).

        The seed (the whole exemplar grid, or a random ``3 x 3`` block) is placed at the
        centre; every other position takes a random one of the exemplar positions whose
        Gaussian-weighted window distance over the six complex subbands is within
        ``(1 + tolerance)`` of the best, unless the best continuation of a known neighbour is
        within ``(1 + coherence)`` of the best
        (:class:`~texsyn.ops.coherence.CoherentSampler`; not with ``coherence=0``, the
        paper's rule). No error threshold: the candidate set is always accepted,
        coefficients have no fixed scale.

        Returns
        -------
        ndarray of int, shape grid + (2,)
            The exemplar position (at the coarsest level) of every output position.
        """
        top = self.pyramids_[0].highpasses[-1]
        h, w = top.shape[:2]
        if self.seed == "exemplar":
            seed_block = (self.pad_, self.pad_, h, w)
        else:
            s = min(3, h, w)
            seed_block = (
                self.pad_ + int(rng.integers(h - s + 1)),
                self.pad_ + int(rng.integers(w - s + 1)),
                s,
                s,
            )
        sampler = CoherentSampler(self.sampler_, self.coherence) if self.coherence > 0 else self.sampler_
        _, source = grow_pixels(
            sampler,
            grid,
            tolerance=self.tolerance,
            max_error=np.inf,
            seed_block=seed_block,
            rng=rng,
            reporter=reporter if reporter.active else None,
        )
        return source - self.pad_

    def _refine(self, maps: list[np.ndarray]) -> list[np.ndarray]:
        """:meth:`_refine_level` on given source maps, levels ``L - 2`` down to 0.

        Each refined level is handed down to every finer level (its children's blocks)
        before that level is refined in turn; ``maps[level]`` is 0-based, the finest first.
        :meth:`_sample` does the same level by level inside its coarse-to-fine walk; this
        form refines maps built by hand (a test of the refinement alone).
        """
        refined = list(maps)
        for level in range(self.levels - 2, -1, -1):
            refined[level] = self._refine_level(level, refined[level])
            for finer in range(level - 1, -1, -1):
                refined[finer] = block_indices(refined[level], 2 ** (level - finer))
        return refined

    def _refine_level(self, level: int, current: np.ndarray) -> np.ndarray:
        """Re-choose every position of a finer level among its neighbours' continuations (``refine``).

        Not in the paper; its section 4 asks for the finer levels to be refined instead of
        only copied. Each position compares the Gaussian-weighted window (``window`` wide, the
        position itself left out) of the level's six subbands assembled by ``current`` with
        the exemplar's window around each candidate: its propagated source, the sources
        within ``refine_radius`` positions of it, and the continuation of each of its eight
        neighbours (the neighbour's source shifted by the offset between them); it keeps the
        closest, the propagated source winning ties. Where two copied blocks meet, the
        positions along the border so take the side whose continuation agrees with the other,
        and the seam moves to where the sources agree (along a mortar line rather than across
        it). Exemplar windows are zero-padded, as the paper pads; groups of positions that lie
        in no other's window are updated together, in a fixed order, and passes repeat until
        one changes nothing (at most :data:`REFINE_SWEEPS`).

        Parameters
        ----------
        level : int
            0-based level, below the coarsest.
        current : ndarray of int
            The level's source map as propagated from the level above.

        Returns
        -------
        ndarray of int
            The refined source map, same shape.
        """
        half, rad = self.window // 2, self.refine_radius
        local = [(a, b) for a in range(-rad, rad + 1) for b in range(-rad, rad + 1) if (a, b) != (0, 0)]
        local.sort(key=lambda o: (abs(o[0]) + abs(o[1]), o))
        offsets = np.array(local, dtype=np.int64).reshape(-1, 2)
        oy, ox = window_offsets(self.window)
        gauss = np.exp(-(oy**2 + ox**2) / (2.0 * (self.window / 6.4) ** 2))
        gauss[half, half] = 0.0  # the position itself is what is chosen again
        band = self.pyramids_[0].highpasses[level]
        padded = np.pad(band, ((half, half), (half, half), (0, 0)))  # the paper's zero padding
        choice = np.ascontiguousarray(current, dtype=np.int64).copy()
        for _ in range(REFINE_SWEEPS):
            changed = 0
            for rows, cols in independent_groups(choice.shape[:2], half + 1):
                changed += refine_group(rows, cols, choice, padded, gauss, offsets, half)
            if changed == 0:
                break
        return choice
