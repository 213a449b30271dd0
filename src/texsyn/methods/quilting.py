"""Efros–Freeman image quilting (Efros and Freeman 2001); ``docs/methods/quilting.md``.

Why this module is long: the paper's three uses of the block loop are here, side by side,
on one set of parameters and the same two steps (the candidate rule and the boundary-cut
paste): synthesis (section 2.1), texture transfer and guided synthesis (section 3, one pass
with a correspondence term), and hole filling (``docs/editing.md``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Annotated

import numpy as np

from .._validation import Range, as_exemplar, normalize_rng
from ..drivers.raster import (
    Block,
    block_canvas,
    block_positions,
    fill_block_rows,
    fill_blocks,
    raster_positions,
    torus_fits,
    torus_positions,
)
from ..errors import InputError
from ..ops.linalg import fixed_order
from ..ops.patches import as_channels
from ..ops.progress import Progress, Reporter
from ..ops.seams import cut_mask
from ..ops.search import FFTPatchSearch
from ._base import SynthesisResult, TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, fft_search_terms, output_bytes, shape_dims

__all__ = ["Quilting"]


@functools.cache
def block_offsets(size: int) -> np.ndarray:
    """``(row, col)`` of every pixel of a ``size`` x ``size`` block, float64 (read-only, shared):
    added to a block's exemplar corner, the exemplar positions the canvas carries."""
    offsets = np.stack(np.meshgrid(np.arange(size), np.arange(size), indexing="ij"), axis=-1).astype(
        np.float64
    )
    offsets.flags.writeable = False
    return offsets


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
        return self._pick(d, rng)

    def _pick(self, d: np.ndarray, rng: np.random.Generator) -> tuple[int, int]:
        """One anchor at random among those within ``(1 + tolerance)`` of the smallest error
        ``d`` (section 2.1; infinite errors are never candidates)."""
        best = d.min()
        cand = np.flatnonzero(d.ravel() <= best * (1.0 + self.tolerance) + 1e-9)
        ti, tj = divmod(int(cand[rng.integers(cand.size)]), d.shape[1])
        return ti, tj

    def _chooser(self, channels: int, rng: np.random.Generator) -> Callable[[Block], tuple[int, int]]:
        """:meth:`_choose` for blocks of a canvas that carries the exemplar positions after its
        ``channels`` colour channels, with one run's cache of the search's energy terms."""
        energies: dict = {}

        def choose(block: Block) -> tuple[int, int]:
            return self._choose(
                Block(block.row, block.col, block.values[..., :channels], block.known), rng, energies
            )

        return choose

    def _paste(
        self,
        block: Block,
        corner: tuple[int, int],
        exemplar: np.ndarray,
        every_side: bool = False,
    ) -> np.ndarray:
        """The block joined along the boundary cut (section 2.1, step 3).

        The canvas carries the exemplar position of every pixel as two extra channels
        after the colour ones (exact in float64), so that the cut places both at once.
        ``every_side``: the cut also runs through known strips on the right and at the
        bottom (on a torus, :func:`texsyn.ops.seams.cut_mask`).
        """
        b, c = block.values.shape[0], exemplar.shape[2]  # a transfer pass's blocks are smaller
        offsets = block_offsets(b)
        ti, tj = corner
        old = block.values
        new = np.concatenate([exemplar[ti : ti + b, tj : tj + b], offsets + (ti, tj)], axis=-1)
        if self.boundary_cut:
            take = cut_mask(old[..., :c], new[..., :c], block.known, every_side=every_side)
        else:
            take = np.ones((b, b), dtype=bool)
        return np.where(take[..., None], new, old)

    def _sample_rows(self, shape, rng, callback):
        ex = as_channels(self.exemplar_)
        c = ex.shape[2]
        b, o = self.patch_size, self._overlap()
        choose = self._chooser(c, rng)
        for rows in fill_block_rows(
            shape,
            c + 2,
            block_positions(shape[0], b, b - o),
            block_positions(shape[1], b, b - o),
            b,
            choose,
            lambda block, corner: self._paste(block, corner, ex),
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

    # ------------------------------------------------------------------ tileable (docs/tiling.md)
    def _torus_steps(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray] | None:
        """Block corners on the output's torus, rows and columns, or None where the
        blocks do not fit (:func:`texsyn.drivers.raster.torus_fits`)."""
        b, step = self.patch_size, self.patch_size - self._overlap()
        if not all(torus_fits(length, b, step) for length in shape):
            return None
        return torus_positions(shape[0], b, step), torus_positions(shape[1], b, step)

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """True where every step between blocks on the torus is more than half a block
        (with the default overlap, every output side at least ``patch_size + 2`` pixels,
        ``patch_size + 1`` for an odd ``patch_size``, which must be 5 or at least 7)."""
        return self._torus_steps(shape) is not None

    def _sample_torus(self, shape, rng, callback):
        """Section 2.1 on the output's torus (``docs/tiling.md``, "On a torus").

        The blocks go in raster order over the torus (:func:`texsyn.drivers.raster.fill_blocks`
        with ``torus=True``): the last block of each row overlaps the row's first across the
        right edge and the last row the first row across the bottom edge. Each block is
        chosen for its squared error on every known pixel of the block, the wrapped ones
        included (the search :meth:`fill` runs on holes), and joined along the
        minimum-error cut through every known strip: left and top, and on the last column
        and row right and bottom too (:func:`texsyn.ops.seams.cut_mask`, ``every_side``).
        """
        ex = as_channels(self.exemplar_)
        c = ex.shape[2]
        b = self.patch_size
        steps = self._torus_steps(shape)
        assert steps is not None  # torus_for(shape) holds
        canvas = np.zeros(tuple(shape) + (c + 2,))
        choose = self._chooser(c, rng)
        fill_blocks(
            canvas,
            steps[0],
            steps[1],
            b,
            choose,
            lambda block, corner: self._paste(block, corner, ex, every_side=True),
            reporter=Reporter(callback, "blocks"),
            torus=True,
        )
        return canvas[..., :c], canvas[..., c:].astype(np.int32)

    # ------------------------------------------------------------------ editing (docs/editing.md)
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
        """Fill the unknown pixels of ``image`` with blocks of the fitted exemplar.

        Blocks of ``patch_size`` cover the hole's bounding box (grown by the overlap) in
        raster order, every ``patch_size - overlap`` pixels (the last one moved back to end
        on the box); a block whose pixels are all known is skipped. Each block is chosen as
        in synthesis (section 2.1), its error being the squared error on all the pixels of
        the block already known (the image's known pixels, whatever their shape, and the
        blocks placed before it), and joined by the minimum-error boundary cut through the
        leading overlap with earlier blocks; the image's known pixels are then put back, so
        they are kept exactly (``docs/editing.md``).

        Parameters
        ----------
        image : ndarray, shape (H, W) or (H, W, C)
            Values in [0, 1], the exemplar's channels; unknown pixels may hold anything.
        known : ndarray of bool, shape (H, W)
            The pixels to keep.
        exemplar_mask : ndarray of bool, optional
            The exemplar pixels that may be copied: only the blocks lying wholly in it are
            candidates (filling from the rest of the image itself). All by default.
        rng, callback
            As in :meth:`sample`; progress stage ``"blocks"``.

        Returns
        -------
        SynthesisResult
            The filled image (float32) and the exemplar position of every pixel (``-1``
            for the known pixels).
        """
        ex = as_channels(self._require_fitted())
        img, known = _editing_input(image, known, ex.shape[2])
        generator = normalize_rng(rng)
        b, o = self.patch_size, self._overlap()
        height, width = known.shape
        if min(height, width) < b:
            raise InputError(f"image of {width}x{height} pixels is smaller than patch_size={b}")
        allowed = None if exemplar_mask is None else _blocks_inside(exemplar_mask, b)
        if allowed is not None and not allowed.any():
            raise InputError(
                f"no {b}x{b} block of the exemplar lies wholly in its known pixels; "
                "give a smaller patch_size or an exemplar"
            )
        c = ex.shape[2]
        canvas = np.concatenate([img, np.full((height, width, 2), -1.0)], axis=-1)
        hole_rows, hole_cols = np.nonzero(~known)
        rows = _covering_blocks(int(hole_rows.min()), int(hole_rows.max()) + 1, height, b, o)
        cols = _covering_blocks(int(hole_cols.min()), int(hole_cols.max()) + 1, width, b, o)
        energies: dict = {}

        def choose(block: Block) -> tuple[int, int]:
            if not block.known.any():
                if allowed is None:
                    anchor_rows, anchor_cols = self.search_.anchor_shape
                    return int(generator.integers(anchor_rows)), int(generator.integers(anchor_cols))
                free = np.flatnonzero(allowed)
                ti, tj = divmod(int(free[generator.integers(free.size)]), allowed.shape[1])
                return ti, tj
            values = block.values[..., :c]
            d = self.search_.distances(values, block.known.astype(np.float64), energies=energies)
            if allowed is not None:
                d = np.where(allowed, d, np.inf)
            return self._pick(d, generator)

        def paste(block: Block, corner: tuple[int, int]) -> np.ndarray:
            new = self._paste(block, corner, ex)
            kept = known[block.row : block.row + b, block.col : block.col + b]
            return np.where(kept[..., None], block.values, new)

        fill_blocks(canvas, rows, cols, b, choose, paste, known=known, reporter=Reporter(callback, "blocks"))
        canvas[..., :c] = np.where(known[..., None], img, canvas[..., :c])
        return SynthesisResult(self._as_output(canvas[..., :c]), canvas[..., c:].astype(np.int32))

    @fixed_order
    def transfer(
        self,
        texture_map: np.ndarray,
        target_map: np.ndarray,
        *,
        alpha: float = 0.1,
        iterations: int = 1,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> SynthesisResult:
        """Texture transfer (section 3): quilt the exemplar so that it follows ``target_map``.

        Every block's error is ``alpha_i`` times its mean squared error on the overlap with
        the blocks already placed (from the second iteration on, on the whole block, against
        the previous iteration's result where nothing is placed yet) plus ``1 - alpha_i``
        times the mean squared error between the correspondence maps of the exemplar block
        and of the output block; the candidates and the cut are those of synthesis. The
        iterations shrink the block by a third each time, and ``alpha_i = alpha + (0.9 -
        alpha) (i - 1) / (N - 1)``: the paper's ``0.8 (i - 1) / (N - 1) + 0.1`` for the
        default ``alpha = 0.1`` (``docs/editing.md``).

        Parameters
        ----------
        texture_map : ndarray, shape (H0, W0) or (H0, W0, G)
            The exemplar's correspondence map (its blurred luminance, in the paper).
        target_map : ndarray, shape (H, W) or (H, W, G)
            The output's correspondence map (the target's blurred luminance); the output
            takes its size.
        alpha : float
            Weight of the overlap error in the first iteration, in [0, 1].
        iterations : int
            Number of passes ``N``.
        rng, callback
            As in :meth:`sample`; progress stages ``"iteration i/N"``.

        Returns
        -------
        SynthesisResult
            The output and its source map (exemplar position of every pixel).
        """
        ex = as_channels(self._require_fitted())
        texture_map, target_map = _map_pair(texture_map, target_map, ex.shape[:2])
        generator = normalize_rng(rng)
        sizes = [int(round(self.patch_size * (2.0 / 3.0) ** i)) for i in range(int(iterations))]
        if sizes[-1] < 3:
            raise InputError(
                f"{iterations} iterations shrink patch_size={self.patch_size} to blocks of {sizes[-1]} "
                "pixels; give fewer iterations or a larger patch_size (the last block needs at least 3)"
            )
        previous = None
        image = source = np.empty(0)
        for i, b in enumerate(sizes):
            weight = alpha if len(sizes) == 1 else alpha + (0.9 - alpha) * i / (len(sizes) - 1)
            overlap = (
                max(1, b // 6)
                if self.overlap is None
                else max(1, min(b - 1, self.overlap * b // self.patch_size))
            )
            reporter = Reporter(callback, f"iteration {i + 1}/{len(sizes)}")
            image, source = self._quilt_matching(
                ex, texture_map, target_map, b, overlap, weight, 1.0 - weight, previous, generator, reporter
            )
            previous = image
        return SynthesisResult(self._as_output(image), source.astype(np.int32))

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
        """Guided synthesis: a texture whose guide map follows ``guide_target``.

        Each block's error is its mean squared error on the overlap (as in :meth:`sample`)
        plus ``weight`` times the mean squared difference between the guide of the exemplar
        block (``guide_source``, the exemplar's size) and the output's guide under the
        block (``guide_target``, the output's size): a user paints which material goes
        where (``docs/editing.md``).
        """
        ex = as_channels(self._require_fitted())
        guide_source, guide_target = _map_pair(guide_source, guide_target, ex.shape[:2])
        b, o = self.patch_size, self._overlap()
        image, source = self._quilt_matching(
            ex,
            guide_source,
            guide_target,
            b,
            o,
            1.0,
            float(weight),
            None,
            normalize_rng(rng),
            Reporter(callback, "blocks"),
        )
        return SynthesisResult(self._as_output(image), source.astype(np.int32))

    def _quilt_matching(
        self, ex, texture_map, target_map, b, o, local_weight, map_weight, previous, rng, reporter
    ) -> tuple[np.ndarray, np.ndarray]:
        """One raster pass of blocks of side ``b`` whose error adds a map term (section 3).

        The exemplar and its map are searched together (one FFT search of ``C + G``
        channels, each with its own weights): ``local_weight`` over the ``C`` colour
        channels of the known pixels (or, with ``previous``, of every pixel: the overlap
        and the previous result), ``map_weight`` over the ``G`` map channels of every
        pixel, each as a mean per pixel and channel.
        """
        shape = target_map.shape[:2]
        c, g = ex.shape[2], texture_map.shape[2]
        search = FFTPatchSearch(np.concatenate([ex, texture_map], axis=-1), (b, b))
        rows, cols = block_canvas(shape, b, b - o)
        pad = ((0, rows - shape[0]), (0, cols - shape[1]), (0, 0))
        target = np.pad(target_map, pad, mode="edge")
        before = None if previous is None else np.pad(as_channels(previous), pad, mode="edge")
        canvas = np.zeros((rows, cols, c + 2))
        energies: dict = {}
        map_weights = np.full((b, b, g), map_weight / (b * b * g))

        def choose(block: Block) -> tuple[int, int]:
            x, y = block.row, block.col
            values, local = block.values[..., :c], block.known.astype(np.float64)
            if before is not None:
                values = np.where(block.known[..., None], values, before[x : x + b, y : y + b])
                local = np.ones((b, b))
            count = local.sum()
            scale = local_weight / (count * c) if count > 0 else 0.0
            weights = np.concatenate([np.repeat((local * scale)[..., None], c, axis=2), map_weights], axis=2)
            query = np.concatenate([values, target[x : x + b, y : y + b]], axis=-1)
            return self._pick(search.distances(query, weights, energies=energies), rng)

        fill_blocks(
            canvas,
            block_positions(shape[0], b, b - o),
            block_positions(shape[1], b, b - o),
            b,
            choose,
            lambda block, corner: self._paste(block, corner, ex),
            reporter=reporter,
        )
        return canvas[: shape[0], : shape[1], :c], canvas[: shape[0], : shape[1], c:]


def _editing_input(image: np.ndarray, known: np.ndarray, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """An image to fill as ``(H, W, C)`` float64 and its mask of known pixels, checked."""
    img = as_channels(as_exemplar(image, name="image", max_channels=max(3, channels)))
    mask = np.asarray(known, dtype=bool)
    if mask.shape != img.shape[:2]:
        raise InputError(f"mask of shape {mask.shape} does not match the image's {img.shape[:2]}")
    if img.shape[2] != channels:
        raise InputError(
            f"image has {img.shape[2]} channels and the exemplar {channels}; give both grey or both colour"
        )
    return img, mask


def _map_pair(source: np.ndarray, target: np.ndarray, exemplar_shape) -> tuple[np.ndarray, np.ndarray]:
    """Two correspondence (or guide) maps as ``(H, W, G)`` float64 arrays, checked."""
    first = as_channels(np.asarray(source, dtype=np.float64))
    second = as_channels(np.asarray(target, dtype=np.float64))
    if first.shape[:2] != tuple(exemplar_shape):
        raise InputError(
            f"the exemplar's map is {first.shape[1]}x{first.shape[0]} pixels; it must have the "
            f"exemplar's size, {exemplar_shape[1]}x{exemplar_shape[0]}"
        )
    if first.shape[2] != second.shape[2]:
        raise InputError(
            f"the two maps have {first.shape[2]} and {second.shape[2]} channels; they must match"
        )
    if not (np.all(np.isfinite(first)) and np.all(np.isfinite(second))):
        raise InputError("the maps must hold finite values")
    return first, second


def _blocks_inside(mask: np.ndarray, b: int) -> np.ndarray:
    """Which ``b x b`` blocks (by top-left anchor) lie wholly in ``mask``: a box sum."""
    inside = np.pad(np.asarray(mask, dtype=np.int64), ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    total = inside[b:, b:] - inside[:-b, b:] - inside[b:, :-b] + inside[:-b, :-b]
    return total == b * b


def _covering_blocks(start: int, stop: int, length: int, b: int, o: int) -> np.ndarray:
    """Corners of blocks of side ``b`` (overlap ``o``) covering ``[start - o, stop + o)``
    within ``[0, length)``, the last one moved back to end on the range."""
    low, high = max(0, start - o), min(length, stop + o)
    if high - low < b:
        high = min(length, low + b)
        low = high - b
    return low + raster_positions(high - low, b, b - o)
