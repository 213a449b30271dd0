"""Efros-Freeman image quilting (Efros and Freeman 2001)."""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import Range
from ..ops import FFTPatchSearch, as_channels, boundary_cut_mask, overlap_error
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, fft_search_bytes, output_bytes
from ..errors import InputError

__all__ = ["Quilting"]


class Quilting(TextureSynthesizer):
    """Image quilting: paste exemplar blocks in raster order, joined by minimum-error cuts.

    Each block is chosen at random among the exemplar blocks whose squared error on the
    overlap with what is already synthesised is within ``(1 + tolerance)`` of the best
    (exact FFT search over every exemplar position); it is then pasted along the
    minimum-error boundary cut of the vertical, horizontal or L-shaped overlap.

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
    summary = "Efros-Freeman image quilting with minimum-error boundary cuts"
    reference = "Efros, Freeman, SIGGRAPH 2001"
    has_source_map = True

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
        h, w, c = shape_dims(exemplar_shape)
        kept, build, query = fft_search_bytes(h, w, c, masks=3)
        terms = {"exemplar and its spectra": 8.0 * h * w * c + kept}
        if output_shape is None:
            terms["spectra construction"] = build
            return terms
        step, o = self.patch_size - self._overlap(), self._overlap()
        rows = max(1, -(-(output_shape[0] - o) // step)) * step + o
        cols = max(1, -(-(output_shape[1] - o) // step)) * step + o
        terms["one block search"] = query
        terms["canvas and source map"] = float(rows) * cols * (8.0 * c + 8.0)
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _sample(self, shape, rng, callback):
        ex = as_channels(self.exemplar_)
        b, o = self.patch_size, self._overlap()
        step = b - o
        n_rows = max(1, -(-(shape[0] - o) // step))
        n_cols = max(1, -(-(shape[1] - o) // step))
        canvas = np.zeros((n_rows * step + o, n_cols * step + o, ex.shape[2]))
        source = np.zeros(canvas.shape[:2] + (2,), dtype=np.int32)
        offsets = np.stack(np.meshgrid(np.arange(b), np.arange(b), indexing="ij"), axis=-1)
        anchor_rows, anchor_cols = self.search_.anchor_shape
        masks = {}
        total = n_rows * n_cols
        for bi in range(n_rows):
            for bj in range(n_cols):
                y, x = bi * step, bj * step
                left = o if bj > 0 else 0
                top = o if bi > 0 else 0
                old = canvas[y : y + b, x : x + b]
                if left == 0 and top == 0:
                    ti = int(rng.integers(anchor_rows))
                    tj = int(rng.integers(anchor_cols))
                else:
                    key = (left, top)
                    if key not in masks:
                        m = np.zeros((b, b))
                        m[:, :left] = 1.0
                        m[:top, :] = 1.0
                        masks[key] = m
                    d = self.search_.distances(old, masks[key])
                    best = d.min()
                    cand = np.flatnonzero(d.ravel() <= best * (1.0 + self.tolerance) + 1e-9)
                    ti, tj = divmod(int(cand[rng.integers(cand.size)]), anchor_cols)
                new = ex[ti : ti + b, tj : tj + b]
                if self.boundary_cut:
                    take = boundary_cut_mask(overlap_error(old, new), left, top)
                else:
                    take = np.ones((b, b), dtype=bool)
                canvas[y : y + b, x : x + b] = np.where(take[..., None], new, old)
                src_block = source[y : y + b, x : x + b]
                source[y : y + b, x : x + b] = np.where(take[..., None], offsets + (ti, tj), src_block)
                if callback is not None:
                    callback(Progress("blocks", bi * n_cols + bj + 1, total))
        return canvas[: shape[0], : shape[1]], source[: shape[0], : shape[1]]
