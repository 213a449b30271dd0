"""The Efros–Leung candidate sampler: window distances and the tolerance rule, on any channels.

The building block of the ``efros_leung`` method and of the coarsest level of the ``cwt``
method (Gallagher and Kokaram), which runs it on stacks of complex wavelet subbands. The
growing loop that calls it is :func:`texsyn.drivers.raster.grow_pixels`
(``docs/methods/efros_leung.md``); round 1's :func:`grow_texture` and
:meth:`NonParametricSampler.grow` call it, deprecated.

The distance of a partly known window to an exemplar window (Efros and Leung 1999, section
2.1, and the reference MATLAB code): SSD over the known pixels only, weighted by a Gaussian
of ``sigma = w / 6.4``, divided by the total weight. The candidates are every window whose
distance is at most ``(1 + tolerance)`` times the smallest; one is picked uniformly.
:func:`schedule_batches` splits a pass of the growing loop into batches of pixels that do
not interact, so that a batch can be searched with one matrix product.

Why this module is long: the sampler keeps, beside the paper's search, the forms that
editing needs (candidates restricted to the known part of an image, a guide term;
``docs/editing.md``) next to the rule they share, and the two deprecated round-1 forms of
the growing loop.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from .jit import jit
from .linalg import BLOCK_COLUMNS
from .patches import as_channels, extract_patches
from .progress import Reporter
from .search import WeightedPatchBank
from .window_screen import ScreenBank, WindowScreen

__all__ = ["NonParametricSampler", "grow_texture", "schedule_batches"]


@jit()
def schedule_batches(rows, cols, radius, height, width, max_batch, wrap=False):
    """Split an ordered pixel list into batches that can be processed at once.

    A pixel joins the current batch only if no pixel of the batch and no earlier pixel not
    yet scheduled lies within Chebyshev distance ``radius``; processing the batches in order
    then gives exactly the result of processing the pixels one by one in list order. With
    ``wrap``, the distance is measured on the torus of ``height x width`` (the output wraps
    around its edges, ``docs/tiling.md``).

    Returns
    -------
    batch_of : ndarray of int64
        Batch index of every pixel.
    n_batches : int
    """
    n = rows.size
    batch_of = np.full(n, -1, np.int64)
    stamp = np.zeros((height + 2 * radius + 1, width + 2 * radius + 1), np.int64)
    remaining = np.arange(n)
    n_left = n
    batch = 0
    while n_left > 0:
        batch += 1
        taken = 0
        kept = 0
        for idx in range(n_left):
            p = remaining[idx]
            r0 = rows[p]
            c0 = cols[p]
            if taken < max_batch and stamp[r0 + radius, c0 + radius] != batch:
                batch_of[p] = batch - 1
                taken += 1
            else:
                remaining[kept] = p
                kept += 1
            if (
                wrap
            ):  # the pixels within radius around the torus (pixel (y, x) is stamp[y + radius, x + radius])
                for a in range(r0 - radius, r0 + radius + 1):
                    for b in range(c0 - radius, c0 + radius + 1):
                        stamp[(a % height) + radius, (b % width) + radius] = batch
                continue
            for a in range(r0, r0 + 2 * radius + 1):
                for b in range(c0, c0 + 2 * radius + 1):
                    stamp[a, b] = batch
        n_left = kept
    return batch_of, batch


@jit()
def _pick_candidates(d, tolerance, uniforms):
    """For every row: a uniformly chosen index among ``d <= (1 + tolerance) min d``."""
    n_rows, n_cols = d.shape
    choice = np.empty(n_rows, np.int64)
    error = np.empty(n_rows)
    for i in range(n_rows):
        best = np.inf
        for k in range(n_cols):
            if d[i, k] < best:
                best = d[i, k]
        threshold = best * (1.0 + tolerance) + 1e-10
        count = 0
        for k in range(n_cols):
            if d[i, k] <= threshold:
                count += 1
        target = min(int(uniforms[i] * count), count - 1)
        seen = 0
        for k in range(n_cols):
            if d[i, k] <= threshold:
                if seen == target:
                    choice[i] = k
                    error[i] = d[i, k]
                    break
                seen += 1
    return choice, error


def candidate_threshold(best: np.ndarray, tolerance: float) -> np.ndarray:
    """Efros and Leung's candidates of a window: distances at most this, ``(1 + tolerance)``
    times the smallest plus ``1e-10`` (so that exact copies tie), for each row's ``best``
    (``docs/methods/efros_leung.md``). The compiled pickers write the same rule inline."""
    return best * (1.0 + float(tolerance)) + 1e-10


class NonParametricSampler:
    """Everything region growing needs from an exemplar, built once (in a method's ``fit``).

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, C)
        Any stack of real channels; distances sum over channels.
    window : int
        Odd side ``w`` of the square neighbourhood.
    allowed : ndarray of bool, shape (H0, W0), optional
        Exemplar pixels that may be used (hole filling from the rest of the image,
        ``docs/editing.md``): only the windows lying wholly in it are candidates. By
        default every window is. With it, :meth:`match` (the float64 matrix product) is the
        search, not the float32 screen.
    guide : ndarray, shape (H0, W0) or (H0, W0, G), optional
        The exemplar's guide map (guided synthesis, ``docs/editing.md``): :meth:`match` then
        takes the output's guide windows too and adds ``guide_weight`` times their
        Gaussian-weighted mean squared difference (over the whole window) to the distance.
        The search is :meth:`match` then.
    guide_weight : float
        Weight of the guide term.

    Examples
    --------
    >>> sampler = NonParametricSampler(np.arange(25.0).reshape(5, 5), 3)
    >>> windows = sampler.exemplar[None, :3, :3]          # one window, fully known
    >>> src, err = sampler.match(windows, np.ones((1, 3, 3), bool), 0.0, np.array([0.5]))
    >>> src.tolist(), bool(err[0] < 1e-9)
    ([[1, 1]], True)
    """

    def __init__(
        self,
        exemplar: np.ndarray,
        window: int = 11,
        allowed: np.ndarray | None = None,
        guide: np.ndarray | None = None,
        guide_weight: float = 1.0,
    ):
        self.exemplar = as_channels(np.asarray(exemplar, dtype=np.float64))
        self.window = int(window)
        radius = self.window // 2
        patches, anchors = extract_patches(self.exemplar, self.window)
        self.guide_weight = float(guide_weight)
        self.guide_channels = 0
        if guide is not None:
            guide = as_channels(np.asarray(guide, dtype=np.float64))
            self.guide_channels = guide.shape[2]
            patches = np.concatenate([patches, extract_patches(guide, self.window)[0]], axis=1)
        self.centres = anchors + radius
        grid = np.arange(self.window) - radius
        sigma = self.window / 6.4
        self.gauss = np.exp(-(grid[:, None] ** 2 + grid[None, :] ** 2) / (2.0 * sigma**2))
        self.allowed_windows: np.ndarray | None = None
        if allowed is not None:
            inside = np.lib.stride_tricks.sliding_window_view(
                np.asarray(allowed, dtype=bool), (window, window)
            )
            whole: np.ndarray = np.all(inside, axis=(2, 3))
            keep = whole[anchors[:, 0], anchors[:, 1]]
            if not keep.any():
                raise ValueError(f"no {window}x{window} window lies wholly in the allowed pixels")
            patches, self.centres = patches[keep], self.centres[keep]
            self.allowed_windows = keep
        self.bank = WeightedPatchBank(patches)
        plain = allowed is None and guide is None
        self._screen = ScreenBank(self.exemplar, patches, self.gauss) if plain else None

    @property
    def n_windows(self) -> int:
        """Number of exemplar windows (candidates of every search)."""
        return self.bank.size

    def match(
        self, windows: np.ndarray, known: np.ndarray, tolerance: float, uniforms: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Choose an exemplar pixel for each of ``k`` partly known windows.

        Parameters
        ----------
        windows : ndarray, shape (k, w, w, C)
            Current values around each pixel (unknown values are ignored).
        known : ndarray of bool, shape (k, w, w)
            Which of them are known.
        tolerance : float
            Candidates are the windows within ``(1 + tolerance)`` of the best distance.
        uniforms : ndarray, shape (k,)
            One uniform draw in [0, 1) per pixel: which candidate is taken.

        Returns
        -------
        source : ndarray of int64, shape (k, 2)
            Exemplar ``(row, col)`` of the chosen window's centre.
        error : ndarray, shape (k,)
            Its distance (Gaussian-weighted SSD per unit weight).
        """
        if self.guide_channels:
            raise ValueError("a sampler with a guide is searched by match_guided")
        k, channels = windows.shape[0], self.exemplar.shape[2]
        weights = known * self.gauss
        norm = weights.sum(axis=(1, 2))
        full_w = np.broadcast_to(weights[..., None], weights.shape + (channels,))
        d = self.bank.distances(windows.reshape(k, -1), full_w.reshape(k, -1))
        d /= norm[:, None]
        choice, error = _pick_candidates(d, float(tolerance), uniforms)
        return self.centres[choice], error

    def match_in_blocks(
        self, windows: np.ndarray, known: np.ndarray, tolerance: float, uniforms: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`match`'s choice and error, with the distances of
        :data:`~texsyn.ops.linalg.BLOCK_COLUMNS` exemplar windows at a time instead of all.

        The blocks' distances are the same numbers as :meth:`match`'s
        (:meth:`~texsyn.ops.search.WeightedPatchBank.distances` of whole tiles); a first pass
        finds every window's smallest, a second counts the candidates within the threshold,
        a third takes the one the uniform draw picks, in window order, as :meth:`match` does.
        Three products instead of one, for the rare batch whose float32 screen is not sure
        (:meth:`match_screened`); ``(k, BLOCK_COLUMNS)`` distances instead of ``(k, K)``
        (``docs/memory.md``, "Second round").
        """
        n = self.n_windows
        if self.guide_channels or n <= BLOCK_COLUMNS:
            return self.match(windows, known, tolerance, uniforms)
        k, channels = windows.shape[0], self.exemplar.shape[2]
        weights = known * self.gauss
        norm = weights.sum(axis=(1, 2))
        full_w = np.broadcast_to(weights[..., None], weights.shape + (channels,)).reshape(k, -1)
        queries = windows.reshape(k, -1)
        starts = range(0, n, BLOCK_COLUMNS)

        def block(start: int) -> np.ndarray:
            d = self.bank.distances(queries, full_w, slice(start, start + BLOCK_COLUMNS))
            d /= norm[:, None]
            return d

        best = np.full(k, np.inf)
        for start in starts:
            np.minimum(best, block(start).min(axis=1), out=best)
        threshold = candidate_threshold(best, tolerance)[:, None]
        counts = np.zeros(k, dtype=np.int64)
        for start in starts:
            counts += np.count_nonzero(block(start) <= threshold, axis=1)
        target = np.minimum((uniforms * counts).astype(np.int64), counts - 1)
        choice = np.full(k, -1, dtype=np.int64)
        error = np.empty(k)
        seen = np.zeros(k, dtype=np.int64)
        for start in starts:
            d = block(start)
            inside = d <= threshold
            here = np.count_nonzero(inside, axis=1)
            rows = np.flatnonzero((choice < 0) & (seen + here > target))
            if rows.size:  # the (target - seen)-th candidate of this block, in window order
                j = np.argmax(np.cumsum(inside[rows], axis=1) > (target - seen)[rows, None], axis=1)
                choice[rows], error[rows] = start + j, d[rows, j]
            seen += here
            if np.all(choice >= 0):
                break
        return self.centres[choice], error

    def match_guided(
        self,
        windows: np.ndarray,
        known: np.ndarray,
        tolerance: float,
        uniforms: np.ndarray,
        guides: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`match` for a sampler built with a ``guide`` (guided synthesis, ``docs/editing.md``).

        The distance is the known pixels' Gaussian-weighted SSD per unit weight (as in
        :meth:`match`) plus ``guide_weight`` times the Gaussian-weighted SSD per unit weight
        of the guides over the whole window, its centre included: one matrix product.

        Parameters
        ----------
        windows, known, tolerance, uniforms
            As for :meth:`match`.
        guides : ndarray, shape (k, w, w, G)
            The output's guide around each pixel.
        """
        k, channels, g = windows.shape[0], self.exemplar.shape[2], self.guide_channels
        if not g:
            raise ValueError("match_guided needs a sampler built with a guide")
        weights = known * self.gauss
        weights = weights / weights.sum(axis=(1, 2))[:, None, None]
        colour_w = np.broadcast_to(weights[..., None], weights.shape + (channels,))
        guide_w = np.broadcast_to(
            (self.guide_weight / self.gauss.sum()) * self.gauss[None, :, :, None],
            (k,) + self.gauss.shape + (g,),
        )
        queries = np.concatenate([windows.reshape(k, -1), guides.reshape(k, -1)], axis=1)
        all_w = np.concatenate([colour_w.reshape(k, -1), guide_w.reshape(k, -1)], axis=1)
        choice, error = _pick_candidates(self.bank.distances(queries, all_w), float(tolerance), uniforms)
        return self.centres[choice], error

    @property
    def screens(self) -> bool:
        """Whether :meth:`screen` and :meth:`match_screened` stand for :meth:`match`.

        False for a subclass with its own :meth:`match` (its rule is not the screened one).
        """
        return type(self).match is NonParametricSampler.match and self._screen is not None

    def screen(
        self, windows: np.ndarray, known: np.ndarray, out: tuple[np.ndarray, np.ndarray] | None = None
    ) -> WindowScreen:
        """Float32 lower bounds of the distances of ``k`` windows, for :meth:`match_screened`
        (:meth:`texsyn.ops.window_screen.ScreenBank.screen`).

        Parameters
        ----------
        windows : ndarray, shape (k, w, w, C)
        known : ndarray of bool, shape (k, w, w)
            What is known of them now; it must stay known until they are matched.
        out : (ndarray, ndarray), optional
            :meth:`screen_buffers` of at least ``k`` rows, used by the result.
        """
        assert self._screen is not None, "a sampler with allowed windows does not screen"
        return self._screen.screen(windows, known, out)

    def screen_buffers(self, rows: int) -> tuple[np.ndarray, np.ndarray]:
        """Room for the bounds of up to ``rows`` windows (:meth:`screen`'s ``out``)."""
        assert self._screen is not None, "a sampler with allowed windows does not screen"
        return self._screen.buffers(rows)

    def match_screened(
        self,
        windows: np.ndarray,
        known: np.ndarray,
        tolerance: float,
        uniforms: np.ndarray,
        screen: WindowScreen,
        rows: slice,
        accept: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`match` and its acceptance ``error <= accept``, from the lower bounds of ``screen``.

        The same choice as :meth:`match` (``docs/methods/efros_leung.md``, "Performance"): every
        window that could be a candidate of :meth:`match` survives the float32 screen and
        gets its exact float64 distance; where the rounding of :meth:`match`'s matrix
        product could put a survivor on the other side of the threshold (a distance within
        about ``1e-12`` of it, relatively), the whole batch is searched by :meth:`match`.

        Parameters
        ----------
        windows, known, tolerance, uniforms
            As for :meth:`match`; ``known`` must contain what ``screen`` was built with.
        screen : WindowScreen
        rows : slice
            The rows of ``screen`` that belong to these windows.
        accept : float
            Largest accepted error.

        Returns
        -------
        source : ndarray of int64, shape (k, 2)
        error : ndarray, shape (k,)
        accepted : ndarray of bool, shape (k,)
        """
        assert self._screen is not None, "a sampler with allowed windows does not screen"
        choice, error, sure = self._screen.choose(windows, known, tolerance, uniforms, screen, rows, accept)
        if not sure:
            source, error = self.match_in_blocks(windows, known, tolerance, uniforms)
            return source, error, error <= accept
        return self.centres[choice], error, error <= accept

    def fill_screened(
        self,
        canvas: np.ndarray,
        filled: np.ndarray,
        source: np.ndarray,
        pixels: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        batches: tuple[int, int],
        screen: WindowScreen,
        chunk_start: int,
        tolerance: float,
        accept: float,
        wrap: bool = False,
    ) -> tuple[int, int]:
        """:meth:`match_screened` for consecutive batches of a pass, writing the output.

        Each batch is chosen as :meth:`match_screened` chooses it and its accepted pixels
        written (values, mask, source map), in one compiled loop
        (:meth:`texsyn.ops.window_screen.ScreenBank.fill`, which gives the arguments);
        it stops before a batch whose choice the rounding of :meth:`match` could change,
        which the caller then searches with :meth:`match`. With ``wrap`` the output is a
        torus, and each pixel written is copied across the wraps into the canvas's padding
        (:func:`texsyn.ops.window_screen.wrap_pixel`).

        Returns
        -------
        next : int
            The batch to search with :meth:`match` (``batches[1]`` when none).
        written : int
            Pixels filled.
        """
        assert self._screen is not None, "a sampler with allowed windows does not screen"
        return self._screen.fill(
            canvas,
            filled,
            source,
            pixels,
            batches,
            screen,
            chunk_start,
            self.centres,
            tolerance,
            accept,
            wrap,
        )

    def grow(
        self,
        shape: tuple[int, int],
        *,
        epsilon: float = 0.1,
        max_error: float = 0.3,
        seed_size: int = 3,
        seed_block: tuple[int, int, int, int] | None = None,
        rng: np.random.Generator,
        callback: Callable[[int, int], None] | None = None,
        max_batch: int = 256,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Deprecated: use :func:`texsyn.drivers.raster.grow_pixels` with this sampler.

        The round-1 form of the Efros–Leung growing loop, kept with a
        :class:`DeprecationWarning`; ``epsilon`` is now ``tolerance`` and ``callback(filled,
        total)`` a :class:`~texsyn.ops.progress.Reporter`. The result is the same.
        """
        warnings.warn(
            "NonParametricSampler.grow is deprecated; use texsyn.drivers.raster.grow_pixels(sampler, "
            "shape, tolerance=..., reporter=...)",
            DeprecationWarning,
            stacklevel=2,
        )
        return _grow(self, shape, epsilon, max_error, seed_size, seed_block, rng, callback, max_batch)


def grow_texture(
    exemplar: np.ndarray,
    shape: tuple[int, int],
    *,
    window: int = 11,
    epsilon: float = 0.1,
    max_error: float = 0.3,
    seed_size: int = 3,
    rng: np.random.Generator,
    callback: Callable[[int, int], None] | None = None,
    max_batch: int = 256,
) -> tuple[np.ndarray, np.ndarray]:
    """Deprecated: use ``grow_pixels(NonParametricSampler(exemplar, window), shape, ...)``.

    The round-1 one-call form of Efros and Leung's growth (section 2), kept with a
    :class:`DeprecationWarning`: :func:`texsyn.drivers.raster.grow_pixels` with
    ``tolerance=epsilon`` and a :class:`~texsyn.ops.progress.Reporter` that passes
    ``(filled, total)`` to ``callback`` after every pass. The result is the same.

    Returns
    -------
    values : ndarray, shape (H, W, C), float64
    source : ndarray of int64, shape (H, W, 2)
    """
    warnings.warn(
        "texsyn.ops.nonparametric.grow_texture is deprecated; use texsyn.drivers.raster.grow_pixels("
        "NonParametricSampler(exemplar, window), shape, tolerance=..., reporter=...)",
        DeprecationWarning,
        stacklevel=2,
    )
    sampler = NonParametricSampler(exemplar, window)
    return _grow(sampler, shape, epsilon, max_error, seed_size, None, rng, callback, max_batch)


def _grow(
    sampler: NonParametricSampler,
    shape: tuple[int, int],
    epsilon: float,
    max_error: float,
    seed_size: int,
    seed_block: tuple[int, int, int, int] | None,
    rng: np.random.Generator,
    callback: Callable[[int, int], None] | None,
    max_batch: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Deprecated forms' body: the drivers layer's growing loop, with the round-1 callback.

    ``grow_pixels`` is imported when a deprecated form is called, never when ``texsyn.ops``
    is imported: the layers below the drivers do not depend on them.
    """
    from ..drivers.raster import grow_pixels

    reporter = None
    if callback is not None:
        legacy = callback
        reporter = Reporter(lambda record: legacy(record.done, record.total), "pixels", shape[0] * shape[1])
    return grow_pixels(
        sampler,
        shape,
        tolerance=epsilon,
        max_error=max_error,
        seed_size=seed_size,
        seed_block=seed_block,
        rng=rng,
        reporter=reporter,
        max_batch=max_batch,
    )
