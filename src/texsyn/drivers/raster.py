"""Patch loops that synthesise a texture piece by piece from what is already there.

The methods of this family differ in one step only: given the part of a window that is
already synthesised, choose what goes into it, and join it to what is there. The loops that
walk the output are written here once; the method passes its step in
(``docs/architecture.md``, "Drivers").

Two loop shapes, hence two functions:

- :func:`fill_blocks` visits square blocks in raster order, row by row: image quilting
  (Efros & Freeman 2001, section 2.1), LG, CLG and RCLG (Raad, Desolneux & Morel 2016,
  Algorithm 2), every scale of MSLG (Algorithm 3) and the Gaussian resampling experiment
  (Algorithm 1). The method gives ``choose(block)`` (the new patch, from the block's known
  pixels) and ``paste(block, patch)`` (the block's new content: boundary cut, average or
  overwrite, :mod:`texsyn.ops.seams`).
- :func:`grow_pixels` grows single pixels outwards from a seed, in "onion-peel" passes
  over the pixels that touch the synthesised region, with an acceptance threshold that
  relaxes when a pass fills nothing: Efros & Leung (1999, section 2) and the coarsest level
  of Gallagher & Kokaram's complex-wavelet method. The order is not raster, the unit is a
  pixel, and pixels are searched in exact batches, so it does not fit the block loop; its
  step is a :class:`~texsyn.ops.nonparametric.NonParametricSampler` (window distances and
  the tolerance rule).

See ``docs/methods/efros_leung.md``, ``docs/methods/quilting.md`` and
``docs/methods/local_gaussian.md``.

Why this module is long: both loops of the family are here, each written once for all the
methods that walk the output that way; the pixel growth has two kinds of pass (the exact
search in batches, with its chunks of lower bounds computed in the background, and the
approximate one), which share everything else.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..ops.canvas import padded_canvas
from ..ops.kcoherence import CoherentWindows
from ..ops.nonparametric import NonParametricSampler, schedule_batches
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ..ops.window_screen import gather_windows

__all__ = [
    "Block",
    "block_canvas",
    "block_positions",
    "block_window",
    "fill_block_rows",
    "fill_blocks",
    "grow_pixels",
    "join_bands",
    "raster_positions",
    "torus_fits",
    "torus_positions",
]


# ---------------------------------------------------------------------------- block loop
@dataclass(frozen=True)
class Block:
    """One block of the raster loop, as the method's step sees it.

    Attributes
    ----------
    row, col : int
        Top-left corner in the canvas.
    values : ndarray, shape (n, n, C)
        The canvas under the block (a view: do not write to it; on a torus, a copy
        gathered across the wraps).
    known : ndarray of bool, shape (n, n)
        Which of its pixels are already synthesised (a view; a copy on a torus).
    """

    row: int
    col: int
    values: np.ndarray
    known: np.ndarray


def block_positions(length: int, size: int, step: int) -> np.ndarray:
    """Corners ``0, step, 2 step, ...`` of the fewest blocks of ``size`` that cover ``length``.

    At least one block; the canvas they cover is :func:`block_canvas`.

    Examples
    --------
    >>> block_positions(25, 10, 6).tolist()
    [0, 6, 12, 18]
    """
    count = (block_canvas((length, length), size, step)[0] - size) // step + 1
    return np.arange(count) * step


def block_canvas(shape: tuple[int, int], size: int, step: int) -> tuple[int, int]:
    """The smallest canvas ``size + k step`` (``k >= 0``) on each side that covers ``shape``.

    A grid of blocks of side ``size`` every ``step`` pixels (overlap ``size - step``), as
    image quilting and LG use; the output is its top-left corner
    (:func:`texsyn.ops.canvas.crop_to_output`).

    Examples
    --------
    >>> block_canvas((25, 10), 10, 6)
    (28, 10)
    """
    overlap = size - step
    rows, cols = padded_canvas(shape, minimum=step, multiple=step, extra=-overlap)
    return rows + overlap, cols + overlap


def raster_positions(size: int, n: int, step: int) -> np.ndarray:
    """Corners ``0, step, 2 step, ...`` up to ``size - n``, plus ``size - n``.

    The block positions when the canvas is the image itself (Raad et al. 2016, Algorithms 1
    and 3): the last block is moved back so that it ends on the border.

    Examples
    --------
    >>> raster_positions(27, 10, 5).tolist()
    [0, 5, 10, 15, 17]
    """
    pos = list(range(0, size - n + 1, step))
    if pos[-1] != size - n:
        pos.append(size - n)
    return np.asarray(pos)


def torus_positions(length: int, size: int, step: int, *, free: int = 1) -> np.ndarray:
    """Corners of the blocks that cover a torus of circumference ``length``, in visiting order.

    ``k`` blocks, their corners spread evenly, ``floor(i length / k)``, so that every step is
    ``floor(length / k)`` or one more and every overlap, the wrapped one (the last block
    over the first) included, is the same all round to a pixel. ``k = ceil(length / step)``,
    the fewest blocks whose steps are at most ``step`` (overlaps at least ``size - step``;
    when ``step`` divides ``length``, corners ``0, step, 2 step, ...`` and exactly that
    overlap), but at least 2 and no more than leave every step at least ``(size + free) / 2``:
    the last block of a row (column), which overlaps blocks on both its sides, keeps
    ``free`` pixels of its own between them. An overlap of half a block or more (the LG
    family's default) is then smaller on a torus (``docs/tiling.md``, "On a torus").

    Examples
    --------
    >>> torus_positions(100, 32, 27).tolist()
    [0, 25, 50, 75]
    >>> torus_positions(81, 32, 27).tolist()
    [0, 27, 54]
    >>> torus_positions(128, 40, 20).tolist()  # steps of 21 or 22, not 20
    [0, 21, 42, 64, 85, 106]
    >>> torus_positions(128, 40, 20, free=10).tolist()  # steps of 25 or 26
    [0, 25, 51, 76, 102]
    """
    least = -(-(int(size) + max(1, int(free))) // 2)
    count = max(2, min(-(-int(length) // int(step)), int(length) // least))
    return (np.arange(count) * int(length)) // count


def torus_fits(length: int, size: int, step: int, *, free: int = 1) -> bool:
    """Whether :func:`torus_positions` lays blocks of ``size`` on a torus of ``length``:
    every step at least ``(size + free) / 2`` (a block's overlaps on its two sides leave
    ``free`` pixels between them, and a block never overlaps itself) and less than a block
    (neighbours overlap).

    Examples
    --------
    >>> torus_fits(128, 32, 27), torus_fits(30, 32, 27), torus_fits(128, 40, 20)
    (True, False, True)
    """
    steps = np.diff(np.append(torus_positions(length, size, step, free=free), length))
    return bool(2 * steps.min() >= size + max(1, int(free)) and steps.max() < size)


def block_window(row: int, col: int, size: int, shape: tuple[int, int], *, torus: bool = False) -> Any:
    """Index of the ``size`` x ``size`` block at ``(row, col)`` of a canvas of ``shape``: slices
    (a view), or on a torus its rows and columns wrapped across the edges (``np.ix_``: a copy).

    Examples
    --------
    >>> canvas = np.arange(16).reshape(4, 4)
    >>> canvas[block_window(3, 3, 2, (4, 4), torus=True)].tolist()
    [[15, 12], [3, 0]]
    """
    if torus:
        return np.ix_((row + np.arange(size)) % shape[0], (col + np.arange(size)) % shape[1])
    return slice(row, row + size), slice(col, col + size)


def fill_blocks(
    canvas: np.ndarray,
    rows: Sequence[int] | np.ndarray,
    cols: Sequence[int] | np.ndarray,
    size: int,
    choose: Callable[[Block], Any],
    paste: Callable[[Block, Any], np.ndarray],
    *,
    seed: np.ndarray | None = None,
    reporter: Reporter | None = None,
    known: np.ndarray | None = None,
    torus: bool = False,
) -> np.ndarray:
    """Fill ``canvas`` block by block in raster order (rows, then columns within a row).

    For every corner ``(x, y)`` of ``rows x cols``: ``patch = choose(block)``, then the
    block becomes ``paste(block, patch)`` and all its pixels are known.

    Parameters
    ----------
    canvas : ndarray, shape (H, W, C)
        Written in place.
    rows, cols : sequence of int
        Block corners along each axis, in visiting order.
    size : int
        Block side ``n``.
    choose : callable
        ``choose(block) -> patch``: the method's choice for a :class:`Block` (what it
        returns is passed on to ``paste`` as it is).
    paste : callable
        ``paste(block, patch) -> ndarray (n, n, C)``: the block's new content.
    seed : ndarray, shape (n, n, C), optional
        Content of the first block, placed without ``choose``/``paste``; it counts as done
        but is not reported (Raad et al. 2016, Algorithm 2, line 1).
    reporter : Reporter, optional
        Receives ``(done, total)`` after every block, ``total = len(rows) * len(cols)``.
    known : ndarray of bool, shape (H, W), optional
        Canvas pixels known before the loop (hole filling, ``docs/editing.md``): the blocks
        see them as known, and a block whose pixels are all known is skipped (counted as
        done). By default nothing is known.
    torus : bool
        The canvas is a torus (tileable outputs, ``docs/tiling.md``, "On a torus"): a block
        that crosses the right (bottom) edge goes on at the left (top), so the last block
        of a row overlaps the row's first block and the last row the first row; the
        block's ``values`` and ``known`` are then copies gathered across the wraps, its
        known pixels on every side are those already placed, and its content is written
        back across the wraps. ``rows`` and ``cols`` come from :func:`torus_positions`.

    Returns
    -------
    ndarray of bool, shape (H, W)
        Which canvas pixels were written (or known from the start).
    """
    skip_known = known is not None
    known = np.zeros(canvas.shape[:2], dtype=bool) if known is None else np.array(known, dtype=bool)
    total = len(rows) * len(cols)
    done = 0
    height, width = known.shape
    for x in rows:
        for y in cols:
            at = block_window(x, y, size, (height, width), torus=torus)  # on a torus: copies, written back
            window, mask = canvas[at], known[at]
            if skip_known and mask.all():
                done += 1
                if reporter is not None:
                    reporter(done, total)
                continue
            if done == 0 and seed is not None:
                window[...] = seed
                mask[...] = True
                if torus:
                    canvas[at], known[at] = window, mask
                done = 1
                continue
            block = Block(int(x), int(y), window, mask)
            window[...] = paste(block, choose(block))
            mask[...] = True
            if torus:
                canvas[at], known[at] = window, mask
            done += 1
            if reporter is not None:
                reporter(done, total)
    return known


def fill_block_rows(
    shape: tuple[int, int],
    channels: int,
    rows: Sequence[int] | np.ndarray,
    cols: Sequence[int] | np.ndarray,
    size: int,
    choose: Callable[[Block], Any],
    paste: Callable[[Block, Any], np.ndarray],
    *,
    seed: np.ndarray | None = None,
    reporter: Reporter | None = None,
) -> Iterator[np.ndarray]:
    """:func:`fill_blocks` holding one row of blocks at a time; yields finished output rows.

    The blocks are visited and filled exactly as :func:`fill_blocks` fills a canvas of
    zeros (same calls of ``choose`` and ``paste``, same content), but the canvas is a band
    of ``size`` rows: when a row of blocks is done, the rows that the next one does not
    overlap are final and are yielded, and the overlap moves to the top of the band. The
    memory is ``size`` rows of the canvas whatever its height (``docs/performance.md``,
    "Any size in bounded memory").

    Parameters
    ----------
    shape : (int, int)
        The output ``(height, width)``: the yielded rows are cropped to it.
    channels : int
        Channels of the canvas (the method may carry extra ones, e.g. its source map).
    rows, cols : sequence of int
        Block corners along each axis (ascending, evenly spaced rows), covering ``shape``.
    size : int
        Block side ``n``.
    choose, paste : callable
        As in :func:`fill_blocks`; a :class:`Block`'s ``row`` is its canvas row, and its
        ``values`` and ``known`` are views of the band.
    seed : ndarray, shape (n, n, channels), optional
        Content of the first block, as in :func:`fill_blocks` (placed without
        ``choose``/``paste``, counted as done, not reported).
    reporter : Reporter, optional
        Receives ``(done, total)`` after every block (but the seed).

    Yields
    ------
    ndarray, shape (k, width, channels)
        The next ``k`` finished rows of the output, top to bottom (float64).
    """
    height, width = shape
    canvas_width = int(cols[-1]) + size
    band = np.zeros((size, canvas_width, channels))
    known = np.zeros((size, canvas_width), dtype=bool)
    total = len(rows) * len(cols)
    done = 0
    emitted = 0
    for k, x in enumerate(rows):
        x = int(x)
        for y in cols:
            window = band[:, y : y + size]
            mask = known[:, y : y + size]
            if done == 0 and seed is not None:
                window[...] = seed
                mask[...] = True
                done = 1
                continue
            block = Block(x, int(y), window, mask)
            window[...] = paste(block, choose(block))
            mask[...] = True
            done += 1
            if reporter is not None:
                reporter(done, total)
        last = k == len(rows) - 1
        step = size if last else int(rows[k + 1]) - x
        end = min(x + step, height)
        if end > emitted:
            yield band[emitted - x : end - x, :width].copy()
            emitted = end
        if not last:
            kept = size - step  # the overlap with the next row of blocks
            band[:kept] = band[step:]
            band[kept:] = 0.0
            known[:kept] = known[step:]
            known[kept:] = False


# ---------------------------------------------------------------------------- pixel growth
class _Chunks:
    """The lower bounds of one pass of :func:`grow_pixels`, chunk by chunk of whole batches.

    A chunk is a run of batches with about ``rows`` pixels in all. The bounds of chunk
    ``c + 1`` are computed by ``background`` (one thread, itself using the matrix-product
    pool) while chunk ``c`` is matched, from what is known when chunk ``c`` starts: the
    pixels filled in between enter the exact distances, and those of large weight the
    bound too (:meth:`~texsyn.ops.nonparametric.NonParametricSampler.match_screened`).
    The bounds depend only on what is known when they are computed, never on timing.

    Parameters
    ----------
    sampler : NonParametricSampler
    background : ThreadPoolExecutor
    bounds : ndarray of int
        Batch ``b`` is pixels ``bounds[b]:bounds[b + 1]`` of ``rows, cols``.
    rows, cols : ndarray of int
        The pass's pixels in batch order.
    size : int
        Pixels per chunk, about.
    buffers : list
        Two places for bounds (``sampler.screen_buffers``, or None until needed), used by
        the even and the odd chunks: a chunk's bounds are computed while the previous
        chunk's are in use, and the pages are reused from pass to pass.
    """

    def __init__(self, sampler, background, bounds, rows, cols, size, buffers):
        self.sampler, self.background, self.bounds = sampler, background, bounds
        self.buffers, self.size = buffers, size
        self.rows, self.cols = rows, cols
        n_batches = bounds.size - 1
        firsts = [0]
        while firsts[-1] < n_batches:
            reach = int(np.searchsorted(bounds, bounds[firsts[-1]] + size, "right")) - 1
            firsts.append(min(n_batches, max(firsts[-1] + 1, reach)))
        self.firsts = firsts
        self.upcoming: Any = None

    def _submit(self, chunk: int, canvas: _Canvas) -> Any:
        if chunk >= len(self.firsts) - 1:
            return None
        span = slice(self.bounds[self.firsts[chunk]], self.bounds[self.firsts[chunk + 1]])
        rows, cols = self.rows[span], self.cols[span]
        windows, known = gather_windows(canvas.values, canvas.filled, rows, cols, 2 * canvas.r + 1)
        room = self.buffers[chunk % 2]
        if room is None or room[0].shape[0] < rows.size:
            room = self.buffers[chunk % 2] = self.sampler.screen_buffers(max(rows.size, self.size))
        return self.background.submit(self.sampler.screen, windows, known, room)

    def screen(self, chunk: int, canvas: _Canvas) -> Any:
        """The bounds of chunk ``chunk`` (the chunks are asked for in order); the next
        chunk's are started in the background."""
        current = self.upcoming if self.upcoming is not None else self._submit(chunk, canvas)
        self.upcoming = self._submit(chunk + 1, canvas)
        return current.result()


def grow_pixels(
    sampler: NonParametricSampler | CoherentWindows,
    shape: tuple[int, int],
    *,
    tolerance: float = 0.1,
    max_error: float = 0.3,
    seed_size: int = 3,
    seed_block: tuple[int, int, int, int] | None = None,
    rng: np.random.Generator,
    reporter: Reporter | None = None,
    max_batch: int = 256,
    known: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    guide: np.ndarray | None = None,
    torus: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Grow a texture pixel by pixel from a seed (Efros and Leung 1999, section 2).

    * A small seed copied from a random place of the exemplar sits at the centre of the
      output, on a torus across its corner (``seed_block=(row, col, height, width)`` names
      it instead; cropped, centred, when larger than the output).
    * Each pass collects the unfilled pixels with a filled 8-neighbour, shuffles them and
      sorts them (stably) by decreasing number of filled pixels in their window.
    * Each pixel, in that order, takes the centre of an exemplar window chosen by
      :meth:`NonParametricSampler.match` (within ``(1 + tolerance)`` of the best distance),
      provided that its distance is at most ``max_error``; a pass that fills nothing raises
      ``max_error`` by 10 %.

    Vectorised without changing the result: a pixel's template depends only on pixels
    within ``r = w // 2`` of it, so each pass is split into batches of pixels that do not
    interact (:func:`~texsyn.ops.nonparametric.schedule_batches`), searched together: this is
    exactly the sequential order of the pass (``docs/methods/efros_leung.md``, "Performance"). A
    :class:`~texsyn.ops.kcoherence.CoherentWindows` sampler (the approximate search) fills
    the pixels one by one in a compiled loop instead.

    Parameters
    ----------
    sampler : NonParametricSampler or CoherentWindows
        The exemplar's windows and the candidate rule (built once, in ``fit``).
    shape : (int, int)
        Output size.
    tolerance : float
        Candidates are the windows within ``(1 + tolerance)`` of the best distance.
    max_error : float
        Largest accepted distance per unit weight, at the start.
    seed_size : int
        Side of the random seed square.
    seed_block : (int, int, int, int), optional
        Exemplar block used as the seed.
    rng : numpy.random.Generator
    reporter : Reporter, optional
        Receives ``(filled, total)`` after every pass.
    max_batch : int
        Most pixels searched in one matrix product (the result does not depend on it).
    known : (ndarray, ndarray, ndarray), optional
        Constrained synthesis (hole filling, the paper's section 2 and ``docs/editing.md``):
        ``(values (H, W, C), mask (H, W) of bool, source (H, W, 2))``, the pixels known
        from the start, their values and their source (``-1`` for none). No seed is placed
        then; the unknown pixels grow inwards from the known ones, by the same passes, and
        the known pixels are returned unchanged.
    guide : ndarray, shape (H, W) or (H, W, G), optional
        The output's guide map, for a sampler built with the exemplar's
        (:class:`~texsyn.ops.nonparametric.NonParametricSampler` ``guide``; guided
        synthesis, ``docs/editing.md``): every search gets the guide around its pixel
        (the borders repeated). The search is then the matrix product.
    torus : bool
        Grow the output on a torus, so that it tiles (``docs/tiling.md``, "On a torus"):
        every window wraps around the output's edges (its values and known pixels across an
        edge are those of the other side), a pixel's 8-neighbours and the pixels that
        interact in a batch wrap too, so the filled region grows across the wraps. Then the
        bands where the growing fronts met (the middle row and column) are sampled again
        with every pixel around them known, in two sweeps (:func:`join_bands`; one draw
        per pixel of each sweep, after the growth's). The output must be at least
        ``window // 2`` a side; not with ``known`` or ``guide``.

    Returns
    -------
    values : ndarray, shape (H, W, C), float64
        The synthesised channels (every synthesised pixel equals the exemplar pixel its
        source names).
    source : ndarray of int64, shape (H, W, 2)
        Exemplar ``(row, col)`` of every output pixel.
    """
    ex = sampler.exemplar
    channels = ex.shape[2]
    height, width = shape
    window = sampler.window
    r = window // 2
    if torus and (known is not None or guide is not None or min(height, width) < r):
        raise ValueError(f"a torus needs an output of at least {r} a side, without known pixels or a guide")
    canvas = _Canvas(
        np.zeros((height + 2 * r, width + 2 * r, channels)),
        np.zeros((height + 2 * r, width + 2 * r), dtype=bool),
        np.full((height, width, 2), -1, dtype=np.int64),
        r,
        torus,
    )
    values, filled, source = canvas.values, canvas.filled, canvas.source
    if guide is not None:
        if not isinstance(sampler, NonParametricSampler) or not sampler.guide_channels:
            raise ValueError("a guide needs a NonParametricSampler built with the exemplar's guide")
        canvas.guide_windows = np.lib.stride_tricks.sliding_window_view(
            np.pad(as_channels(np.asarray(guide, dtype=np.float64)), ((r, r), (r, r), (0, 0)), mode="edge"),
            (window, window),
            axis=(0, 1),
        )

    if known is None:
        n_filled = _place_seed(canvas, ex, seed_size, seed_block, rng)
    else:
        start_values, start_mask, start_source = known
        values[r : r + height, r : r + width] = start_values
        filled[r : r + height, r : r + width] = start_mask
        source[...] = start_source
        n_filled = int(np.count_nonzero(start_mask))
    total = height * width
    threshold = float(max_error)
    near = np.zeros((height + 2, width + 2), dtype=bool)  # filled pixels, dilated by one
    # one thread computes the next chunk's lower bounds while this one is matched
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="texsyn-screen") as background:
        if isinstance(sampler, CoherentWindows):
            fill: _ApproximatePass | _ExactPass = _ApproximatePass(sampler, canvas)
        else:
            fill = _ExactPass(sampler, canvas, background, max_batch)
        while n_filled < total:
            # the pass: frontier pixels (unfilled, with a filled 8-neighbour), shuffled, then
            # those with the most filled pixels in their window first
            inner = filled[r : r + height, r : r + width]
            near[:] = False
            for dy in range(3):
                for dx in range(3):
                    if torus:  # the padding holds the other side of each wrap
                        near[1:-1, 1:-1] |= filled[
                            r - 1 + dy : r - 1 + dy + height, r - 1 + dx : r - 1 + dx + width
                        ]
                    else:
                        near[dy : dy + height, dx : dx + width] |= inner
            rows, cols = np.nonzero(near[1:-1, 1:-1] & ~inner)
            perm = rng.permutation(rows.size)
            rows, cols = rows[perm], cols[perm]
            counts = np.count_nonzero(canvas.known_windows[rows, cols], axis=(1, 2))
            order = np.argsort(-counts, kind="stable")
            rows, cols = rows[order], cols[order]
            uniforms = rng.random(rows.size)  # one draw per pixel, in list order
            filled_now = fill(rows, cols, uniforms, tolerance, threshold)
            n_filled += filled_now
            if filled_now == 0:
                threshold *= 1.1
            if reporter is not None:
                reporter(n_filled, total)
        if torus:
            for sweep in range(JOIN_SWEEPS):
                _resample_joins(fill, canvas, rng, tolerance, max_batch, backward=sweep % 2 == 1)
    return values[r : r + height, r : r + width], source


#: sweeps of :func:`_resample_joins` over the bands where the fronts of a torus growth meet,
#: forwards then backwards, so that the join is sampled again from each side (one sweep left
#: the approximate search's middle lines up to 2.3x their neighbours, two 1.1-1.7x;
#: ``docs/tiling.md``, "On a torus (``efros_leung``)")
JOIN_SWEEPS = 2


def join_bands(height: int, width: int, radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels around the lines where the fronts of a torus growth meet, in sweep order.

    The seed sits across the output's corner (:func:`grow_pixels` ``torus``), so the fronts
    meet last along the middle row and the middle column. The bands are the ``2 radius + 1``
    rows centred on the middle row, then the ``2 radius + 1`` columns centred on the middle
    column (the square where they cross is in both). Each is cut along its length into
    segments of at least ``(radius + 1)(2 radius + 1)`` pixels, swept side by side along
    wavefronts ``j + (radius + 1) k`` (``j`` along the segment, ``k`` across the band): the
    pixels of one wavefront are more than ``radius`` apart along the band, so none is in
    another's window (``docs/tiling.md``, "On a torus (``efros_leung``)").

    Returns
    -------
    rows, cols : ndarray of int64
        The pixels, wavefront after wavefront.
    fronts : ndarray of int64
        Wavefront ``f`` is pixels ``fronts[f]:fronts[f + 1]``.

    Examples
    --------
    >>> rows, cols, fronts = join_bands(8, 6, 1)
    >>> [list(zip(rows[a:b].tolist(), cols[a:b].tolist())) for a, b in zip(fronts[:4], fronts[1:5])]
    [[(3, 0)], [(3, 1)], [(3, 2), (4, 0)], [(3, 3), (4, 1)]]
    >>> rows, cols, fronts = join_bands(6, 12, 1)  # two segments of the rows' band
    >>> list(zip(rows[:4].tolist(), cols[:4].tolist()))
    [(2, 0), (2, 6), (2, 1), (2, 7)]
    """
    side, slope = 2 * int(radius) + 1, int(radius) + 1
    rows, cols, fronts = [], [], [0]
    for length, circumference, down in ((width, height, False), (height, width, True)):
        k, j = np.meshgrid(np.arange(side), np.arange(length), indexing="ij")
        n_segments = max(1, length // (slope * side))
        starts = (np.arange(n_segments) * length) // n_segments
        wave = (j - starts[np.searchsorted(starts, j, "right") - 1] + slope * k).ravel()
        order = np.argsort(wave, kind="stable")
        band = (k.ravel()[order] + circumference // 2 - int(radius)) % circumference
        along = j.ravel()[order]
        rows.append(along if down else band)
        cols.append(band if down else along)
        starts = np.flatnonzero(np.diff(wave[order])) + 1
        fronts.extend((starts + fronts[-1]).tolist() + [fronts[-1] + wave.size])
    return np.concatenate(rows), np.concatenate(cols), np.asarray(fronts, dtype=np.int64)


def _resample_joins(
    fill,
    canvas: _Canvas,
    rng: np.random.Generator,
    tolerance: float,
    max_batch: int,
    *,
    backward: bool = False,
) -> None:
    """Sample again, by the growth's own rule, every pixel of the bands where the fronts of a
    torus growth met (:func:`join_bands`), now that every pixel around them is known.

    Pixel after pixel in sweep order, each is forgotten and takes the centre of an exemplar
    window within ``(1 + tolerance)`` of the best distance to its whole window (every pixel
    but itself; the approximate search's candidates continue its 8 neighbours' sources),
    always accepted: a non-causal second pass of pixel-based synthesis (as Wei–Levoy's
    across its wraps), on the lines where the growth filled a gap from both sides
    (``docs/tiling.md``, "On a torus (``efros_leung``)"). A wavefront is searched at once
    (split by :func:`~texsyn.ops.nonparametric.schedule_batches` on the torus where a small
    output brings two of its pixels within a window): exactly the one-by-one order. One
    uniform draw per pixel, in :func:`join_bands`'s order; ``backward`` visits the
    wavefronts last to first.
    """
    r = canvas.r
    height, width = canvas.source.shape[:2]
    rows, cols, fronts = join_bands(height, width, r)
    uniforms = rng.random(rows.size)
    spans = list(zip(fronts[:-1].tolist(), fronts[1:].tolist(), strict=True))
    for start, stop in reversed(spans) if backward else spans:
        front_rows, front_cols, front_uniforms = rows[start:stop], cols[start:stop], uniforms[start:stop]
        batch_of, n_batches = schedule_batches(front_rows, front_cols, r, height, width, max_batch, True)
        for batch in range(n_batches):
            members = batch_of == batch
            canvas.forget(front_rows[members], front_cols[members])
            fill(front_rows[members], front_cols[members], front_uniforms[members], tolerance, np.inf)


def _place_seed(canvas, ex, seed_size, seed_block, rng) -> int:
    """The seed of :func:`grow_pixels` at the centre of the canvas (on a torus, across its
    corner); pixels placed."""
    ex_h, ex_w = ex.shape[:2]
    height, width = canvas.source.shape[:2]
    r = canvas.r
    if seed_block is None:
        sh = sw = int(min(seed_size, height, width, ex_h, ex_w))
        si, sj = int(rng.integers(ex_h - sh + 1)), int(rng.integers(ex_w - sw + 1))
    else:
        si, sj, sh, sw = (int(v) for v in seed_block)
        if sh > height:
            si, sh = si + (sh - height) // 2, height
        if sw > width:
            sj, sw = sj + (sw - width) // 2, width
    seed_rows, seed_cols = np.meshgrid(np.arange(sh), np.arange(sw), indexing="ij")
    if canvas.wrap:
        # on a torus, centred on the corner where the output's edges cross: the fronts then
        # meet last half a tile away, inside the tile, not along its edges
        rows, cols = (seed_rows - sh // 2) % height, (seed_cols - sw // 2) % width
        canvas.write(rows.ravel(), cols.ravel(), ex[si : si + sh, sj : sj + sw].reshape(sh * sw, -1))
        canvas.source[rows, cols, 0] = seed_rows + si
        canvas.source[rows, cols, 1] = seed_cols + sj
        return sh * sw
    top, left = (height - sh) // 2, (width - sw) // 2
    canvas.values[top + r : top + r + sh, left + r : left + r + sw] = ex[si : si + sh, sj : sj + sw]
    canvas.filled[top + r : top + r + sh, left + r : left + r + sw] = True
    canvas.source[top : top + sh, left : left + sw, 0] = seed_rows + si
    canvas.source[top : top + sh, left : left + sw, 1] = seed_cols + sj
    return sh * sw


@dataclass
class _Canvas:
    """What :func:`grow_pixels` grows: the padded values and mask, and the source map.

    On a torus (``wrap``) the padding is the other side of each wrap of the output, kept up
    to date as pixels are written, so that every window reads across the edges.
    """

    values: np.ndarray
    filled: np.ndarray
    source: np.ndarray
    r: int
    wrap: bool = False

    def __post_init__(self) -> None:
        # the window around every output pixel, as views: indexing them copies whole windows
        window = 2 * self.r + 1
        self.value_windows = np.lib.stride_tricks.sliding_window_view(
            self.values, (window, window), axis=(0, 1)
        )
        self.known_windows = np.lib.stride_tricks.sliding_window_view(self.filled, (window, window))
        self.guide_windows: np.ndarray | None = None  # the output's guide, for guided synthesis
        # the samplers' compiled loops are told of a torus only when there is one (a sampler
        # subclass written before the torus need not take the argument)
        self.wrap_argument = {"wrap": True} if self.wrap else {}

    def write(self, rows: np.ndarray, cols: np.ndarray, values: np.ndarray) -> None:
        """Output pixels ``(rows, cols)`` take ``values`` and become known (and, on a torus,
        their copies in the padding)."""
        for at_rows, at_cols, inside in self._places(rows, cols):
            self.values[at_rows, at_cols] = values[inside]
            self.filled[at_rows, at_cols] = True

    def forget(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Output pixels ``(rows, cols)`` become unknown again (their copies too), to be
        sampled again (:func:`_resample_joins`); values and sources stay until then."""
        for at_rows, at_cols, _ in self._places(rows, cols):
            self.filled[at_rows, at_cols] = False

    def _places(self, rows: np.ndarray, cols: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, Any]]:
        """Where output pixels ``(rows, cols)`` stand in the padded canvas: themselves, and on a
        torus their copies across the wraps (which of the pixels each copy is of)."""
        r = self.r
        yield rows + r, cols + r, slice(None)
        if not self.wrap:
            return
        height, width = self.source.shape[:2]
        for i in (-1, 0, 1):
            for j in (-1, 0, 1):
                if i == j == 0:
                    continue
                at_rows, at_cols = rows + r + i * height, cols + r + j * width
                inside = (
                    (at_rows >= 0) & (at_rows < height + 2 * r) & (at_cols >= 0) & (at_cols < width + 2 * r)
                )
                yield at_rows[inside], at_cols[inside], inside


class _ExactPass:
    """One pass of the exact search, in batches of pixels that do not interact.

    A pixel's template depends only on pixels within ``r = w // 2`` of it, so the pass is
    split into batches (:func:`~texsyn.ops.nonparametric.schedule_batches`), searched in
    order: exactly the sequential order of the pass. With a sampler that
    :attr:`~texsyn.ops.nonparametric.NonParametricSampler.screens`, a batch is matched from
    the float32 lower bounds of its chunk (:class:`_Chunks`), otherwise by
    :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`.
    """

    def __init__(self, sampler: NonParametricSampler, canvas: _Canvas, background, max_batch: int):
        self.sampler, self.canvas, self.background = sampler, canvas, background
        self.batch_cap = int(max(8, min(max_batch, (1 << 23) // max(sampler.n_windows, 1))))
        # chunks of about 300 rows (colour 128 x 128 exemplar): the matching waits only for
        # a pass's first one, later ones are computed from a recent state (tight bounds),
        # and each group of a chunk's product has rows enough to amortise the packing of
        # the bank (measured: 150 rows 4.1 s of CPU, 300 rows 3.6 s, the main thread 1.0
        # and 1.3 s; docs/methods/efros_leung.md, "Performance")
        # and never more rows than the canvas has pixels: the two buffers of bounds have room
        # for a chunk (a 12x12 exemplar's 4 windows of 11x11 asked for 2^20 rows, 8 GB)
        height, width = canvas.source.shape[:2]
        self.screen_rows = min(max(128, (1 << 22) // max(sampler.n_windows, 1)), height * width)
        self.screened = sampler.screens
        self.buffers: list = [None, None]

    def __call__(self, rows, cols, uniforms, tolerance: float, threshold: float) -> int:
        sampler, canvas, r = self.sampler, self.canvas, self.canvas.r
        height, width = canvas.source.shape[:2]
        batch_of, n_batches = schedule_batches(rows, cols, r, height, width, self.batch_cap, canvas.wrap)
        by_batch = np.argsort(batch_of, kind="stable")
        bounds = np.searchsorted(batch_of[by_batch], np.arange(n_batches + 1))
        rows, cols, uniforms = rows[by_batch], cols[by_batch], uniforms[by_batch]
        if not self.screened:
            return sum(
                self._match(rows, cols, uniforms, bounds, b, tolerance, threshold) for b in range(n_batches)
            )
        chunks = _Chunks(sampler, self.background, bounds, rows, cols, self.screen_rows, self.buffers)
        pixels = (rows, cols, uniforms, bounds)
        filled_now = 0
        for chunk in range(len(chunks.firsts) - 1):
            screen = chunks.screen(chunk, canvas)
            batch, stop = chunks.firsts[chunk], chunks.firsts[chunk + 1]
            while batch < stop:
                batch, written = sampler.fill_screened(
                    canvas.values,
                    canvas.filled,
                    canvas.source,
                    pixels,
                    (batch, stop),
                    screen,
                    int(bounds[chunks.firsts[chunk]]),
                    tolerance,
                    threshold,
                    **canvas.wrap_argument,
                )
                filled_now += written
                if batch < stop:  # rounding could matter: the matrix-product search
                    filled_now += self._match(rows, cols, uniforms, bounds, batch, tolerance, threshold)
                    batch += 1
        return filled_now

    def _match(self, rows, cols, uniforms, bounds, batch: int, tolerance: float, threshold: float) -> int:
        """Batch ``batch`` by :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`; pixels filled."""
        sampler, canvas = self.sampler, self.canvas
        members = slice(int(bounds[batch]), int(bounds[batch + 1]))
        pr, pc = rows[members], cols[members]
        windows, known = np.moveaxis(canvas.value_windows[pr, pc], 1, 3), canvas.known_windows[pr, pc]
        if canvas.guide_windows is None:  # screened: the rare batch, in blocks of windows
            match = sampler.match_in_blocks if self.screened else sampler.match
            src, err = match(windows, known, tolerance, uniforms[members])
        else:
            guides = np.moveaxis(canvas.guide_windows[pr, pc], 1, 3)
            src, err = sampler.match_guided(windows, known, tolerance, uniforms[members], guides)
        ok = err <= threshold
        pr, pc, src = pr[ok], pc[ok], src[ok]
        canvas.write(pr, pc, sampler.exemplar[src[:, 0], src[:, 1]])
        canvas.source[pr, pc] = src
        return int(ok.sum())


class _ApproximatePass:
    """One pass of the approximate search: pixel by pixel in list order, in one compiled
    loop (:meth:`~texsyn.ops.kcoherence.CoherentWindows.grow_pass`)."""

    def __init__(self, sampler: CoherentWindows, canvas: _Canvas):
        self.sampler, self.canvas = sampler, canvas
        self.stamp = np.full(sampler.n_windows, -1, dtype=np.int64)
        self.n_stamped = 0

    def __call__(self, rows, cols, uniforms, tolerance: float, threshold: float) -> int:
        canvas = self.canvas
        chosen = self.sampler.grow_pass(
            rows,
            cols,
            uniforms,
            canvas.values,
            canvas.filled,
            canvas.source,
            tolerance,
            threshold,
            self.stamp,
            self.n_stamped,
            **canvas.wrap_argument,
        )
        self.n_stamped += rows.size
        return int(np.count_nonzero(chosen >= 0))
