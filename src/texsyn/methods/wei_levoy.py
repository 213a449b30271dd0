"""Wei-Levoy multiresolution pixel synthesis with causal neighbourhoods (Wei and Levoy 2000).

The algorithm of the paper's sections 2-3, step by step (``docs/methods/wei_levoy.md``):

1. Build the exemplar's Gaussian pyramid and, for every level and exemplar pixel, its
   neighbourhood vector: the causal L-shaped half of a ``window x window`` square at that
   level (the pixels before it in raster order) and the full ``parent_window`` square at the
   next coarser level; optionally a tree-structured vector quantiser over them
   (:meth:`WeiLevoy._fit`, :class:`texsyn.ops.tsvq.TSVQ`).
2. Start every level of the output pyramid as noise with the exemplar's histogram (random
   exemplar pixels) and synthesise the levels coarse to fine
   (:func:`texsyn.drivers.coarse_to_fine.coarse_to_fine`), each in raster order: every pixel
   takes the value of the exemplar pixel whose neighbourhood is nearest to its own
   (:meth:`WeiLevoy._synthesise_level`, :func:`texsyn.ops.search.nearest_rows` or the tree).

Both images are treated toroidally, as in the paper. The search is exact, or approximate
with the paper's tree-structured vector quantisation (``search='tsvq'``).

Vectorisation: pixels are visited along wavefronts ``x + (r + 1) y = t`` (``r = window // 2``)
and each wavefront is searched with one matrix product. A pixel's causal neighbourhood only
reaches ``r`` columns to the right in the rows above and ``r`` to the left in its own row, so
every pixel sees exactly what raster order would show it -- except the few pixels of the
first ``r`` columns, whose toroidally wrapped neighbours at the end of the previous row are
not synthesised yet (they hold the initial noise, as the wrapped rows of the first line do in
the paper).

Tileable outputs (``tileable=True``, ``docs/tiling.md``) are synthesised on a torus: the same
pass, then at every level a second pass with the full, non-causal neighbourhood over the rows
and columns around the wraps, whose first pass read the initial noise across them
(:meth:`WeiLevoy._wrap_pass`).

Levels are 0-based, the finest (the full-size image) first.

Why this module is long: the paper's algorithm is one class whose steps share the fitted
banks and the wavefront order -- the fit, the raster pass, its memory estimate and the
torus's second pass -- and reads best in one place.

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000, sections 2-3.
"""

from __future__ import annotations

from contextlib import nullcontext
from typing import Annotated

import numpy as np

from .._validation import OneOf, Range
from ..drivers.coarse_to_fine import coarse_to_fine
from ..errors import InputError
from ..ops.jit import jit
from ..ops.linalg import BLOCK_COLUMNS
from ..ops.patches import as_channels, gather_wrapped, gather_wrapped_kernel
from ..ops.progress import Reporter
from ..ops.search import (
    BoundedNearestIndex,
    bounded_index_bytes,
    nearest_rows,
    nearest_rows_band,
    nearest_rows_bounded,
)
from ..ops.tsvq import TSVQ
from ..transforms.pyramids import gaussian_pyramid
from ..transforms.steerable import pyramid_sizes
from ._base import TextureSynthesizer
from ._memory import CALIBRATED_MARGIN, output_bytes, pixel_count, shape_dims

__all__ = ["WeiLevoy", "causal_offsets", "TSVQ"]  # TSVQ: from texsyn.ops.tsvq, kept here for 0.1 users

#: levels whose bank has at least this many rows are searched through a
#: :class:`~texsyn.ops.search.BoundedNearestIndex` (the same rows as the plain product, proven)
BOUNDED_SEARCH_ROWS = 1024
#: ... unless more than this share of its rows have another row at the same place (ties)
TWINNED_ROWS = 0.01
#: on a torus, the rows and columns around each wrap synthesised again with the full
#: neighbourhood: this many times ``window // 2``, centred on the wrap
WRAP_BAND = 2


def causal_offsets(window: int) -> np.ndarray:
    """Offsets ``(dy, dx)`` of the pixels before the centre, in raster order, in a square window."""
    r = window // 2
    return np.array([(dy, dx) for dy in range(-r, 1) for dx in range(-r, r + 1) if dy < 0 or dx < 0])


def square_offsets(window: int) -> np.ndarray:
    r = window // 2
    return np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])


def _gather(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Toroidal neighbourhood vectors ``(n, len(offsets) * C)`` at the given pixels."""
    h, w = image.shape[:2]
    rr = (rows[:, None] + offsets[None, :, 0]) % h
    cc = (cols[:, None] + offsets[None, :, 1]) % w
    flat = image.reshape(h * w, -1)
    return np.take(flat, rr * w + cc, axis=0).reshape(len(rows), -1)


@jit()
def _wavefront_queries(out, parent, ys, xs, causal, parent_offsets, src, ew, eh, queries, seeds):
    """One wavefront's queries and seeds in one compiled call (:meth:`WeiLevoy._synthesise_level`).

    ``queries[i]``: the causal neighbourhood of pixel ``(ys[i], xs[i])`` in ``out``, then the
    parent square around ``(ys[i] // 2, xs[i] // 2)`` in ``parent`` (none when ``parent`` has
    no pixel), both wrapped (:func:`texsyn.ops.patches.gather_wrapped_kernel`);
    ``seeds[i]``: the continuations of the left and upper pixels' sources ``src`` in the
    ``eh x ew`` exemplar (the next pixel of the left source's row, the pixel under the upper
    source, both wrapped).
    """
    h, w, channels = out.shape
    gather_wrapped_kernel(out, ys, xs, causal, queries, 0)
    if parent.shape[0] > 0:
        gather_wrapped_kernel(parent, ys // 2, xs // 2, parent_offsets, queries, causal.shape[0] * channels)
    for i in range(ys.shape[0]):
        y, x = ys[i], xs[i]
        left = src[y, (x - 1) % w]
        up = src[(y - 1) % h, x]
        seeds[i, 0] = left - left % ew + (left + 1) % ew
        seeds[i, 1] = (up + ew) % (eh * ew)


def _squared_norms(bank: np.ndarray, rows: int = 1024) -> np.ndarray:
    """``np.sum(bank * bank, axis=1)``, the same sums, a block of rows at a time (no temporary
    as large as the bank: its fresh pages cost system time)."""
    out = np.empty(len(bank))
    for start in range(0, len(bank), rows):
        block = bank[start : start + rows]
        np.sum(block * block, axis=1, out=out[start : start + rows])
    return out


class WeiLevoy(TextureSynthesizer):
    """Wei-Levoy synthesis: multiresolution raster-order pixel sampling.

    Parameters
    ----------
    levels : int
        Number of Gaussian pyramid levels.
    window : int
        Odd side of the neighbourhood square at the current level (its causal half is used).
    parent_window : int
        Odd side of the full square neighbourhood at the next coarser level.
    search : str
        'exact' nearest neighbourhood, or 'tsvq' (the original tree-structured vector
        quantisation, approximate and faster on large exemplars).
    leaf_size : int
        Vectors per leaf of the TSVQ tree.
    fit_rng : int
        Seed of the random choices of fit (the TSVQ construction); ``sample`` takes its own.

    References
    ----------
    L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
    SIGGRAPH 2000.

    Notes
    -----
    ``random_state`` is the deprecated name of ``fit_rng`` (``docs/methods/wei_levoy.md``).
    """

    name = "wei_levoy"
    summary = "Wei-Levoy multiresolution synthesis with causal neighbourhoods"
    reference = "Wei, Levoy, SIGGRAPH 2000"
    has_source_map = True
    #: the exact search's terms were checked against the measured peaks (``docs/memory.md``,
    #: "Second round"); the TSVQ's were not and keep the default 1.25 (:meth:`memory_terms`)
    memory_margin = CALIBRATED_MARGIN
    deprecated_params = {"random_state": "fit_rng"}

    def __init__(
        self,
        *,
        levels: Annotated[int, Range(1, 6)] = 4,
        window: Annotated[int, Range(3, 21)] = 9,
        parent_window: Annotated[int, Range(1, 21)] = 5,
        search: Annotated[str, OneOf(("exact", "tsvq"))] = "exact",
        leaf_size: Annotated[int, Range(1, 4096)] = 32,
        fit_rng: Annotated[int, Range(0, 2**32 - 1)] = 0,
    ):
        self.levels = levels
        self.window = window
        self.parent_window = parent_window
        self.search = search
        self.leaf_size = leaf_size
        self.fit_rng = fit_rng

    def _check_params(self) -> None:
        super()._check_params()
        for name in ("window", "parent_window"):
            if getattr(self, name) % 2 == 0:
                raise InputError(
                    f"parameter {name!r} of method 'wei_levoy' must be odd, got {getattr(self, name)}"
                )

    def min_exemplar_size(self):
        side = max(2 ** (self.levels - 1) * 2, self.window // 2 + 1)
        return side, f"levels={self.levels} needs at least {side}x{side} pixels"

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Neighbourhood banks of every exemplar pixel and level; one wavefront of searches.

        An exact search compares a whole wavefront (about ``width / (window // 2 + 1)``
        pixels) with every exemplar pixel at once (``docs/memory.md``).
        """
        h, w, c = shape_dims(exemplar_shape)
        causal = (self.window**2 - 1) // 2
        parent = self.parent_window**2
        sizes = pyramid_sizes((h, w), self.levels - 1)
        kept, peak, dims = 8.0 * h * w * c * 7 / 3, 0.0, []
        for level, (sh, sw) in enumerate(sizes):  # the finest (largest) level is built first
            k = float(sh * sw)
            dim = (causal + (parent if level + 1 < self.levels else 0)) * c
            dims.append(dim)
            # the gathered parts, the bank and its squares (for the norms) coexist
            widest = max(causal, parent)
            build = max(20.0 * k * dim, 24.0 * k * widest + 8.0 * k * widest * c)
            if self.search == "tsvq":
                build = max(build, 40.0 * k * dim)
            bounded = self.search == "exact" and k >= BOUNDED_SEARCH_ROWS
            if bounded:  # the proven search's index, built next to the bank
                index_kept, index_build = bounded_index_bytes(k, dim)
                build = max(build, index_build)
            peak = max(peak, kept + 8.0 * k * dim + build)
            kept += 8.0 * k * dim + 8.0 * k
            if bounded:
                kept += index_kept + k
            if self.search == "tsvq":
                kept += 16.0 * k * dim / max(1, self.leaf_size) + 16.0 * k
        terms = {"exemplar pyramid and neighbourhood banks": kept}
        if output_shape is None:
            terms["bank construction"] = max(0.0, peak - kept)
            if self.search != "exact":  # uncalibrated: the default margin of 1.25
                return {key: value * 1.25 / CALIBRATED_MARGIN for key, value in terms.items()}
            return terms
        oh, ow = output_shape[:2]
        slope = self.window // 2 + 1
        front = 0.0
        out_sizes = pyramid_sizes((oh, ow), self.levels - 1)
        for level, (sh, sw) in enumerate(out_sizes):
            n = float(min(sh, -(-sw // slope)))
            k = float(sizes[level][0] * sizes[level][1])
            search = 24.0 * n * k if self.search == "exact" else 0.0
            if self.search == "exact" and k >= BOUNDED_SEARCH_ROWS:
                # the proven search: two parts' candidates and float32 products a query, then
                # at most the exact fallback, one block of bank rows at a time
                # (texsyn.ops.search.nearest_rows_by_column_blocks)
                search = n * (24.0 * min(k, BLOCK_COLUMNS) + 2.0 * (24.0 * 64 + 4.0 * 2048))
            front = max(front, 24.0 * n * dims[level] + 16.0 * n * max(causal, parent) + search)
        pixels = pixel_count(output_shape)
        terms["one wavefront of searches"] = front
        # the finest level's noise and its copy, its source, the coarser levels (a third of
        # the pixels); then the image, its source and the source map (divmod, stacked)
        terms["output pyramid and source maps"] = pixels * max((56.0 * c + 32.0) / 3, 8.0 * c + 40.0)
        terms["output image"] = output_bytes(c, output_shape)
        if self.search != "exact":  # uncalibrated: the default margin of 1.25
            return {key: value * 1.25 / CALIBRATED_MARGIN for key, value in terms.items()}
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        """Step 1: the exemplar pyramid and every pixel's neighbourhood vector, level by level."""
        ex = as_channels(exemplar)
        self.pyramid_ = gaussian_pyramid(ex, self.levels, sigma=1.0)
        self.causal_ = causal_offsets(self.window)
        self.parent_ = square_offsets(self.parent_window)
        rng = np.random.default_rng(self.fit_rng)
        self.banks_, self.norms_, self.trees_, self.indexes_, self.isolated_ = [], [], [], [], []
        for level, image in enumerate(self.pyramid_):
            rows, cols = np.divmod(np.arange(image.shape[0] * image.shape[1]), image.shape[1])
            # the causal part, then the parent square, gathered in place (as the queries are)
            causal = len(self.causal_) * image.shape[2]
            parent = len(self.parent_) * image.shape[2] if level + 1 < self.levels else 0
            bank = np.empty((len(rows), causal + parent))
            gather_wrapped(np.ascontiguousarray(image), rows, cols, self.causal_, bank)
            if parent:
                coarser = np.ascontiguousarray(self.pyramid_[level + 1])
                gather_wrapped(coarser, rows // 2, cols // 2, self.parent_, bank, causal)
            self.banks_.append(bank)
            self.norms_.append(_squared_norms(bank))
            self.trees_.append(TSVQ(bank, self.leaf_size, rng) if self.search == "tsvq" else None)
            index = isolated = None
            if self.search == "exact" and len(bank) >= BOUNDED_SEARCH_ROWS:
                index = BoundedNearestIndex(bank)
                # rows that no other row comes near: a query equal to one needs no search;
                # a bank with many rows that have a twin (a flat or binary exemplar) would send
                # most queries to the plain search anyway, so it keeps the plain search
                isolated = index.isolated(
                    nearest_rows_band(bank, index.norm_max), limit=int(TWINNED_ROWS * len(bank))
                )
                if isolated is None:
                    index = None
                else:
                    isolated.setflags(write=False)
            self.indexes_.append(index)
            self.isolated_.append(isolated)

    def _sample(self, shape, rng, callback):
        """Step 2: the output pyramid, coarse to fine; the finest level and its sources."""
        return self._sample_levels(shape, rng, callback, torus=False)

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """Whether a tileable output of ``shape`` is synthesised on a torus (``docs/tiling.md``).

        Every level but the coarsest must halve exactly (a side divisible by
        ``2 ** (levels - 1)``), so that a pixel's parent wraps with it, and the coarsest level
        must hold a whole window and parent window (no pixel twice in one neighbourhood).
        """
        step = 2 ** (self.levels - 1)
        coarsest = pyramid_sizes(shape, self.levels - 1)[-1]
        return (
            shape[0] % step == 0
            and shape[1] % step == 0
            and min(coarsest) >= max(self.window, self.parent_window)
        )

    def _sample_torus(self, shape, rng, callback):
        """:meth:`_sample` on a torus: every level gets a second, non-causal pass across its wraps.

        The raster pass already wraps every neighbourhood (section 2 of the paper), but the
        first ``window // 2`` rows and columns of a level read, across the wrap, pixels that
        still hold the initial noise. After that pass, those rows and columns are synthesised
        again with the full ``window x window`` square at the level (and the parent square),
        which now reads synthesised pixels on both sides of each wrap
        (:meth:`_wrap_pass`; ``docs/methods/wei_levoy.md``, "Tileable outputs").
        """
        return self._sample_levels(shape, rng, callback, torus=True)

    def _sample_levels(self, shape, rng, callback, *, torus: bool):
        """The output pyramid, coarse to fine (the seam pass at each level on a torus)."""
        sizes = pyramid_sizes(shape, self.levels - 1)  # the output halved (rounded up) L - 1 times
        total = sum(h * w for h, w in sizes)

        def level_step(
            level: int, coarser: tuple[np.ndarray, np.ndarray] | None
        ) -> tuple[np.ndarray, np.ndarray]:
            reporter = Reporter(callback, f"level {self.levels - level}/{self.levels}", total)
            done = sum(h * w for h, w in sizes[level + 1 :])  # pixels of the coarser levels
            parent = None if coarser is None else coarser[0]
            image, source = self._synthesise_level(level, sizes[level], parent, rng, reporter, done)
            if torus:
                self._wrap_pass(level, image, source, parent)
            return image, source

        out, source = coarse_to_fine(level_step, self.levels)[0]
        ex_w = self.pyramid_[0].shape[1]
        source_map = np.stack(np.divmod(source, ex_w), axis=-1)
        return out, source_map

    def _synthesise_level(
        self,
        level: int,
        size: tuple[int, int],
        parent: np.ndarray | None,
        rng: np.random.Generator,
        reporter: Reporter,
        done: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One output level in raster order (paper, section 2), given the coarser level.

        The level starts as random exemplar pixels; wavefront by wavefront, every pixel takes
        the exemplar pixel whose neighbourhood vector (causal half at this level, full square
        in ``parent``) is nearest, exactly or through the level's TSVQ.

        Parameters
        ----------
        level : int
            0-based level, the finest first.
        size : (int, int)
            Height and width of the level.
        parent : ndarray or None
            The synthesised coarser level; ``None`` at the coarsest.
        rng : numpy.random.Generator
            Source of the initial noise.
        reporter : Reporter
            Receives the pixels done so far over all levels, every 64 wavefronts.
        done : int
            Pixels of the levels synthesised before this one.

        Returns
        -------
        image : ndarray, shape size + (C,)
        source : ndarray of int, shape size
            Flat index of each pixel's exemplar pixel at this level.
        """
        ex = self.pyramid_[level]
        h, w = size
        flat_ex = ex.reshape(-1, ex.shape[2])
        start = rng.integers(len(flat_ex), size=h * w)
        out = flat_ex[start].reshape(h, w, ex.shape[2]).copy()
        src = start.reshape(h, w)  # every pixel's source is overwritten when it is synthesised
        eh, ew = ex.shape[:2]
        bank, norms, tree = self.banks_[level], self.norms_[level], self.trees_[level]
        index, isolated = self.indexes_[level], self.isolated_[level]
        slope = self.window // 2 + 1
        ys_all = np.arange(h)
        # the index's wavefronts gather their queries and seeds in one compiled pass, and its
        # part workers stay ready between wavefronts
        no_parent = np.empty((0, 0, ex.shape[2]))
        workers = None if index is None else index.parallel_search(min(h, -(-w // slope)), 2)
        with workers or nullcontext():
            for t in range(w + slope * (h - 1)):
                first, last = max(0, -(-(t - w + 1) // slope)), min(h - 1, t // slope)
                if first > last:
                    continue
                ys = ys_all[first : last + 1]
                xs = t - slope * ys
                q = np.empty((ys.size, bank.shape[1]))  # the causal part, then the parent square
                if index is not None:
                    seeds = np.empty((ys.size, 2), dtype=np.int64)
                    _wavefront_queries(
                        out, no_parent if parent is None else parent, ys, xs, self.causal_, self.parent_,
                        src, ew, eh, q, seeds,
                    )  # fmt: skip
                    best = nearest_rows_bounded(q, bank, norms, index, seeds, isolated, workers)
                else:
                    gather_wrapped(out, ys, xs, self.causal_, q)
                    if parent is not None:
                        gather_wrapped(
                            parent, ys // 2, xs // 2, self.parent_, q, len(self.causal_) * out.shape[2]
                        )
                    best = tree.nearest(q) if tree is not None else nearest_rows(q, bank, norms)
                out[ys, xs] = flat_ex[best]
                src[ys, xs] = best
                done += len(ys)
                if t % 64 == 0:
                    reporter(done)
        return out, src

    def _full_bank(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """Every exemplar pixel's full neighbourhood vector at ``level`` and its squared norm:
        the whole ``window x window`` square at the level, then the parent square."""
        image = self.pyramid_[level]
        rows, cols = np.divmod(np.arange(image.shape[0] * image.shape[1]), image.shape[1])
        parts = [_gather(image, rows, cols, square_offsets(self.window))]
        if level + 1 < self.levels:
            parts.append(_gather(self.pyramid_[level + 1], rows // 2, cols // 2, self.parent_))
        bank = np.ascontiguousarray(np.concatenate(parts, axis=1))
        return bank, np.sum(bank * bank, axis=1)

    def _wrap_pass(self, level: int, out: np.ndarray, src: np.ndarray, parent: np.ndarray | None) -> None:
        """Synthesise again, in place, the pixels whose causal neighbourhoods met the noise
        across a wrap: the first ``r = window // 2`` rows, then the first ``r`` columns.

        Each pixel takes the exemplar pixel whose full neighbourhood (the ``window x window``
        square at the level, all of it synthesised by now, and the parent square) is nearest,
        on the torus. The rows go in raster order and the columns in column order, along
        wavefronts ``x + (r + 1) y`` (``y + (r + 1) x`` for the columns): two pixels of one
        wavefront are more than ``r`` apart in the other direction, so every pixel sees the
        pixels revisited before it in that order, as a one-by-one pass would show it -- on a
        level at least ``(r + 1)(2r - 1) + r + 1`` pixels along the band. On a narrower level
        (the coarse levels: 16 pixels at 128x128 with the defaults) two pixels of one
        wavefront can be within ``r`` of each other across the wrap along the band, and each
        reads the other's value from before the wavefront (still the same bytes on any
        thread count).
        """
        ex = self.pyramid_[level]
        flat_ex = ex.reshape(-1, ex.shape[2])
        bank, norms = self._full_bank(level)
        tree = (
            TSVQ(bank, self.leaf_size, np.random.default_rng(self.fit_rng)) if self.search == "tsvq" else None
        )
        index = None  # the same rows as the plain product, proven (see _fit)
        if tree is None and len(bank) >= BOUNDED_SEARCH_ROWS:
            index = BoundedNearestIndex(bank)
        square = square_offsets(self.window)
        h, w = out.shape[:2]
        r = self.window // 2
        slope = r + 1
        n = WRAP_BAND * r  # the band's width, centred on each wrap
        strip = np.arange(n)
        # (k, j): k across the band, j along it; wavefront t = j + slope k
        bands = [  # the rows around the horizontal wrap, then the columns around the vertical one
            (lambda k, j: ((k - n // 2) % h, j), w),
            (lambda k, j: ((j + n - n // 2) % h, (k - n // 2) % w), h - n),
        ]
        for place, length in bands:
            for t in range(length + slope * (n - 1)):
                along = t - slope * strip
                ok = (along >= 0) & (along < length)
                if not ok.any():
                    continue
                ys, xs = place(strip[ok], along[ok])
                q = np.empty((ys.size, bank.shape[1]))
                gather_wrapped(out, ys, xs, square, q)
                if parent is not None:
                    gather_wrapped(parent, ys // 2, xs // 2, self.parent_, q, len(square) * out.shape[2])
                if tree is not None:
                    best = tree.nearest(q)
                elif index is not None:
                    best = nearest_rows_bounded(q, bank, norms, index)
                else:
                    best = nearest_rows(q, bank, norms)
                out[ys, xs] = flat_ex[best]
                src[ys, xs] = best
