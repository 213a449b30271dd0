"""Efros–Freeman image quilting (Efros and Freeman 2001); ``docs/methods/quilting.md``."""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import Range
from ..drivers.raster import Block, block_canvas, block_positions, fill_block_rows
from ..errors import InputError
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ..ops.seams import cut_mask
from ..ops.search import FFTPatchSearch
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, fft_search_terms, output_bytes, shape_dims

__all__ = ["Quilting"]


class Quilting(TextureSynthesizer):
    """Image quilting: paste exemplar blocks in raster order, joined by minimum-error cuts.

    The algorithm of the paper (section 2.1), as :meth:`_sample` runs it through the raster
    block loop :func:`texsyn.drivers.raster.fill_blocks`:

    1. go through the output in raster order, in steps of ``patch_size - overlap``;
    2. choose the block (:meth:`_choose`): the first at random; the others at random among
       the exemplar blocks whose squared error on the overlap with what is already
       synthesised is within ``(1 + tolerance)`` of the best (exact FFT search over every
       exemplar position);
    3. paste it (:meth:`_paste`) along the minimum-error boundary cut of the vertical,
       horizontal or L-shaped overlap (:func:`texsyn.ops.seams.cut_mask`).

    Parameters
    ----------
    patch_size : int
        Side of the square blocks, in pixels.
    overlap : int or None
        Overlap between neighbouring blocks; ``None`` means ``patch_size // 6`` (at least 1).
    tolerance : float
        Candidates are the blocks whose overlap error is at most ``(1 + tolerance)`` times the
        smallest one.
    boundary_cut : bool
        Join blocks along the minimum-error boundary cut; ``False`` overwrites the overlap
        (the paper's "neighbouring blocks constrained by overlap" variant, Fig. 2b).

    References
    ----------
    A. Efros, W. Freeman, "Image quilting for texture synthesis and transfer", SIGGRAPH 2001.
    L. Raad, B. Galerne, "Efros and Freeman image quilting algorithm for texture synthesis",
    Image Processing On Line 7 (2017).
    """

    name = "quilting"
    memory_margin = CALIBRATED_MARGIN
    summary = "Efros-Freeman image quilting with minimum-error boundary cuts"
    reference = "Efros, Freeman, SIGGRAPH 2001"
    has_source_map = True
    streams_rows = True

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 1024)] = 32,
        overlap: Annotated[int | None, Range(1, 512)] = None,
        tolerance: Annotated[float, Range(0.0, 10.0)] = 0.1,
        boundary_cut: bool = True,
    ):
        self.patch_size = patch_size
        self.overlap = overlap
        self.tolerance = tolerance
        self.boundary_cut = boundary_cut

    def _overlap(self) -> int:
        return max(1, self.patch_size // 6) if self.overlap is None else self.overlap

    def min_exemplar_size(self):
        return self.patch_size, f"patch_size={self.patch_size} needs at least that many pixels per side"

    def _check_params(self) -> None:
        super()._check_params()
        if self._overlap() >= self.patch_size:
            raise InputError(
                f"parameter 'overlap' of method 'quilting' must be smaller than patch_size="
                f"{self.patch_size}, got {self.overlap}"
            )

    def _fit(self, exemplar: np.ndarray) -> None:
        self.search_ = FFTPatchSearch(exemplar, (self.patch_size, self.patch_size))

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Exemplar spectra of the FFT search; the block canvas, its source map and one search.

        See ``docs/memory.md``.
        """
        terms, query = fft_search_terms(exemplar_shape, masks=3, fitting=output_shape is None)
        if output_shape is None:
            return terms
        c = shape_dims(exemplar_shape)[2]
        rows, cols = block_canvas(output_shape, self.patch_size, self.patch_size - self._overlap())
        terms["one block search"] = query
        terms["canvas and source map"] = float(rows) * cols * (8.0 * c + 8.0)
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def streaming_memory_terms(self, exemplar_shape, output_shape) -> dict[str, float]:
        """Exemplar spectra and one block search; a band of one row of blocks, not the canvas.

        :meth:`sample_rows` holds ``patch_size`` rows of the canvas (colours and source map,
        float64) and the finished rows it yields, as floats, as 8- or 16-bit samples and as
        filtered PNG scanlines (about 32 bytes a sample): none grows with the output's height
        (``docs/performance.md``, "Any size in bounded memory").
        """
        terms, query = fft_search_terms(exemplar_shape, masks=3, fitting=False)
        c = shape_dims(exemplar_shape)[2]
        b = self.patch_size
        width = float(block_canvas(output_shape, b, b - self._overlap())[1])
        terms["one block search"] = query
        terms["band of one row of blocks"] = b * width * (8.0 * (c + 2) + 1.0)
        terms["finished rows and their encoding"] = b * width * (8.0 * (c + 2) + 32.0 * c)
        return terms

    # ------------------------------------------------------------------ the paper's steps
    def _choose(
        self, block: Block, rng: np.random.Generator, energies: dict | None = None
    ) -> tuple[int, int]:
        """Exemplar corner of the next block (section 2.1, step 2).

        ``energies`` is the sampling call's cache of the search's energy terms (one per
        overlap shape); the fitted search itself is never changed.
        """
        anchor_rows, anchor_cols = self.search_.anchor_shape
        if not block.known.any():
            return int(rng.integers(anchor_rows)), int(rng.integers(anchor_cols))
        d = self.search_.distances(block.values, block.known.astype(np.float64), energies=energies)
        best = d.min()
        cand = np.flatnonzero(d.ravel() <= best * (1.0 + self.tolerance) + 1e-9)
        ti, tj = divmod(int(cand[rng.integers(cand.size)]), anchor_cols)
        return ti, tj

    def _paste(
        self, block: Block, corner: tuple[int, int], exemplar: np.ndarray, offsets: np.ndarray
    ) -> np.ndarray:
        """The block joined along the boundary cut (section 2.1, step 3).

        The canvas carries the exemplar position of every pixel as two extra channels
        after the colour ones (exact in float64), so that the cut places both at once.
        """
        b, c = self.patch_size, exemplar.shape[2]
        ti, tj = corner
        old = block.values
        new = np.concatenate([exemplar[ti : ti + b, tj : tj + b], offsets + (ti, tj)], axis=-1)
        if self.boundary_cut:
            take = cut_mask(old[..., :c], new[..., :c], block.known)
        else:
            take = np.ones((b, b), dtype=bool)
        return np.where(take[..., None], new, old)

    def _sample_rows(self, shape, rng, callback):
        ex = as_channels(self.exemplar_)
        c = ex.shape[2]
        b, o = self.patch_size, self._overlap()
        energies: dict = {}  # this call's cache of the search's energy terms
        offsets = np.stack(np.meshgrid(np.arange(b), np.arange(b), indexing="ij"), axis=-1).astype(np.float64)

        def choose(block: Block) -> tuple[int, int]:
            return self._choose(
                Block(block.row, block.col, block.values[..., :c], block.known), rng, energies
            )

        for rows in fill_block_rows(
            shape,
            c + 2,
            block_positions(shape[0], b, b - o),
            block_positions(shape[1], b, b - o),
            b,
            choose,
            lambda block, corner: self._paste(block, corner, ex, offsets),
            reporter=Reporter(callback, "blocks"),
        ):
            yield rows[..., :c], rows[..., c:].astype(np.int32)

    def _sample(self, shape, rng, callback):
        c = as_channels(self.exemplar_).shape[2]
        image = np.empty(tuple(shape) + (c,))
        source = np.empty(tuple(shape) + (2,), dtype=np.int32)
        top = 0
        for rows, rows_source in self._sample_rows(shape, rng, callback):
            image[top : top + rows.shape[0]] = rows
            source[top : top + rows.shape[0]] = rows_source
            top += rows.shape[0]
        return image, source
