"""Non-parametric pixel sampling by region growing (Efros and Leung 1999), on any channel stack.

This is the engine of the ``efros_leung`` method and of the coarsest level of the ``cwt``
method (Gallagher and Kokaram), which runs it on stacks of complex wavelet subbands.

Algorithm (Efros and Leung 1999, section 2; details of the reference MATLAB code):

* a small seed copied from a random place of the exemplar sits at the centre of the output;
* each pass collects the unfilled pixels that have a filled 8-neighbour, shuffles them and
  sorts them (stably) by decreasing number of filled pixels in their window;
* each pixel, in that order, compares its window (filled pixels only, Gaussian weights
  ``sigma = w / 6.4``, SSD divided by the total weight) with every exemplar window, picks
  at random one of the windows whose distance is at most ``(1 + epsilon)`` times the
  smallest, and takes its centre value, provided that the distance is below
  ``max_error``; if a whole pass fills nothing, ``max_error`` grows by 10 %.

Vectorisation without changing the result: a pixel's template only depends on pixels
within ``r = w // 2`` of it (Chebyshev distance). The pixels of a pass are split greedily
into batches such that no pixel of a batch lies within ``r`` of another pixel of the batch
or of any earlier pixel still waiting; every batch is then searched with one matrix product
against all exemplar windows. This is exactly the sequential order of the pass.
"""

from __future__ import annotations

from typing import Callable

import numba
import numpy as np
from scipy import ndimage

from .patches import as_channels, extract_patches
from .search import WeightedPatchBank

__all__ = ["NonParametricSampler", "grow_texture", "schedule_batches"]


@numba.njit(cache=True)
def schedule_batches(rows, cols, radius, height, width, max_batch):
    """Split an ordered pixel list into batches that can be processed at once.

    A pixel joins the current batch only if no pixel of the batch and no earlier pixel not
    yet scheduled lies within Chebyshev distance ``radius``; processing the batches in order
    then gives exactly the result of processing the pixels one by one in list order.

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
            for a in range(r0, r0 + 2 * radius + 1):
                for b in range(c0, c0 + 2 * radius + 1):
                    stamp[a, b] = batch
        n_left = kept
    return batch_of, batch


@numba.njit(cache=True)
def _pick_candidates(d, epsilon, uniforms):
    """For every row: a uniformly chosen index among ``d <= (1 + epsilon) min d``."""
    n_rows, n_cols = d.shape
    choice = np.empty(n_rows, np.int64)
    error = np.empty(n_rows)
    for i in range(n_rows):
        best = np.inf
        for k in range(n_cols):
            if d[i, k] < best:
                best = d[i, k]
        threshold = best * (1.0 + epsilon) + 1e-10
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


class NonParametricSampler:
    """Everything region growing needs from an exemplar, built once (in a method's ``fit``).

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, C)
        Any stack of real channels; distances sum over channels.
    window : int
        Odd side ``w`` of the square neighbourhood.
    """

    def __init__(self, exemplar: np.ndarray, window: int = 11):
        self.exemplar = as_channels(np.asarray(exemplar, dtype=np.float64))
        self.window = int(window)
        radius = self.window // 2
        patches, anchors = extract_patches(self.exemplar, self.window)
        self.centres = anchors + radius
        self.bank = WeightedPatchBank(patches)
        grid = np.arange(self.window) - radius
        sigma = self.window / 6.4
        self.gauss = np.exp(-(grid[:, None] ** 2 + grid[None, :] ** 2) / (2.0 * sigma**2))

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
        """Grow a texture pixel by pixel (Efros and Leung 1999); see :func:`grow_texture`.

        ``seed_block=(row, col, height, width)`` seeds the growth with that block of the
        exemplar (cropped, centred, when larger than the output) instead of a random
        ``seed_size`` square.
        """
        ex = self.exemplar
        ex_h, ex_w, channels = ex.shape
        height, width = shape
        window = self.window
        r = window // 2
        bank, centres, gauss = self.bank, self.centres, self.gauss
        batch_cap = int(max(8, min(max_batch, (1 << 23) // max(bank.size, 1))))
        dy, dx = np.meshgrid(np.arange(window), np.arange(window), indexing="ij")

        values = np.zeros((height + 2 * r, width + 2 * r, channels))
        filled = np.zeros((height + 2 * r, width + 2 * r), dtype=bool)
        source = np.full((height, width, 2), -1, dtype=np.int64)

        if seed_block is None:
            sh = sw = int(min(seed_size, height, width, ex_h, ex_w))
            si, sj = int(rng.integers(ex_h - sh + 1)), int(rng.integers(ex_w - sw + 1))
        else:
            si, sj, sh, sw = (int(v) for v in seed_block)
            if sh > height:
                si, sh = si + (sh - height) // 2, height
            if sw > width:
                sj, sw = sj + (sw - width) // 2, width
        top, left = (height - sh) // 2, (width - sw) // 2
        values[top + r : top + r + sh, left + r : left + r + sw] = ex[si : si + sh, sj : sj + sw]
        filled[top + r : top + r + sh, left + r : left + r + sw] = True
        seed_rows, seed_cols = np.meshgrid(np.arange(sh), np.arange(sw), indexing="ij")
        source[top : top + sh, left : left + sw, 0] = seed_rows + si
        source[top : top + sh, left : left + sw, 1] = seed_cols + sj

        n_filled, total = sh * sw, height * width
        threshold = float(max_error)
        ring = np.ones((3, 3), dtype=bool)
        while n_filled < total:
            inner = filled[r : r + height, r : r + width]
            frontier = ndimage.binary_dilation(inner, structure=ring) & ~inner
            rows, cols = np.nonzero(frontier)
            known = ndimage.uniform_filter(filled.astype(np.float64), size=window, mode="constant")
            perm = rng.permutation(rows.size)
            rows, cols = rows[perm], cols[perm]
            order = np.argsort(-np.rint(known[rows + r, cols + r] * window * window), kind="stable")
            rows, cols = rows[order], cols[order]
            batch_of, n_batches = schedule_batches(rows, cols, r, height, width, batch_cap)
            uniforms = rng.random(rows.size)  # one draw per pixel, in list order
            by_batch = np.argsort(batch_of, kind="stable")
            bounds = np.searchsorted(batch_of[by_batch], np.arange(n_batches + 1))
            filled_now = 0
            for b in range(n_batches):
                members = by_batch[bounds[b] : bounds[b + 1]]
                pr, pc = rows[members], cols[members]
                win_r = pr[:, None, None] + dy
                win_c = pc[:, None, None] + dx
                weights = filled[win_r, win_c] * gauss
                norm = weights.sum(axis=(1, 2))
                full_w = np.broadcast_to(weights[..., None], weights.shape + (channels,))
                d = bank.distances(
                    values[win_r, win_c].reshape(len(members), -1),
                    full_w.reshape(len(members), -1),
                )
                d /= norm[:, None]
                choice, err = _pick_candidates(d, float(epsilon), uniforms[members])
                ok = err <= threshold
                if not np.any(ok):
                    continue
                pr, pc, choice = pr[ok], pc[ok], choice[ok]
                src = centres[choice]
                values[pr + r, pc + r] = ex[src[:, 0], src[:, 1]]
                filled[pr + r, pc + r] = True
                source[pr, pc] = src
                filled_now += int(ok.sum())
            n_filled += filled_now
            if filled_now == 0:
                threshold *= 1.1
            if callback is not None:
                callback(n_filled, total)
        return values[r : r + height, r : r + width], source


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
    """Grow a texture pixel by pixel from an exemplar (Efros and Leung 1999).

    One-call form of :class:`NonParametricSampler` (build it once when sampling many times).

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, C)
        Any stack of real channels; distances sum over channels.
    shape : (int, int)
        Output size.
    window : int
        Odd side ``w`` of the square neighbourhood.
    epsilon : float
        Candidate tolerance: windows within ``(1 + epsilon)`` of the best distance.
    max_error : float
        Largest accepted distance (per unit weight); grows by 10 % after a pass that fills
        nothing.
    seed_size : int
        Side of the seed copied at the centre of the output.
    rng : numpy.random.Generator
    callback : callable, optional
        Called as ``callback(filled, total)`` after every pass.
    max_batch : int
        Most pixels searched in one matrix product (the result does not depend on it).

    Returns
    -------
    values : ndarray, shape (H, W, C), float64
        The synthesised channels (every pixel equals the exemplar pixel its source names).
    source : ndarray of int64, shape (H, W, 2)
        Exemplar ``(row, col)`` of every output pixel.

    References
    ----------
    A. Efros, T. Leung, "Texture synthesis by non-parametric sampling", ICCV 1999.
    """
    return NonParametricSampler(exemplar, window).grow(
        shape,
        epsilon=epsilon,
        max_error=max_error,
        seed_size=seed_size,
        rng=rng,
        callback=callback,
        max_batch=max_batch,
    )
