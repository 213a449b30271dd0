"""The Efros–Leung candidate sampler: window distances and the tolerance rule, on any channels.

The building block of the ``efros_leung`` method and of the coarsest level of the ``cwt``
method (Gallagher and Kokaram), which runs it on stacks of complex wavelet subbands. The
growing loop that calls it is :func:`texsyn.drivers.raster.grow_pixels`
(``docs/methods/efros_leung.md``).

The distance of a partly known window to an exemplar window (Efros and Leung 1999, section
2.1, and the reference MATLAB code): SSD over the known pixels only, weighted by a Gaussian
of ``sigma = w / 6.4``, divided by the total weight. The candidates are every window whose
distance is at most ``(1 + tolerance)`` times the smallest; one is picked uniformly.
:func:`schedule_batches` splits a pass of the growing loop into batches of pixels that do
not interact, so that a batch can be searched with one matrix product.
"""

from __future__ import annotations

import numba
import numpy as np

from .patches import as_channels, extract_patches
from .search import WeightedPatchBank

__all__ = ["NonParametricSampler", "schedule_batches"]


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


class NonParametricSampler:
    """Everything region growing needs from an exemplar, built once (in a method's ``fit``).

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, C)
        Any stack of real channels; distances sum over channels.
    window : int
        Odd side ``w`` of the square neighbourhood.

    Examples
    --------
    >>> sampler = NonParametricSampler(np.arange(25.0).reshape(5, 5), 3)
    >>> windows = sampler.exemplar[None, :3, :3]          # one window, fully known
    >>> src, err = sampler.match(windows, np.ones((1, 3, 3), bool), 0.0, np.array([0.5]))
    >>> src.tolist(), bool(err[0] < 1e-9)
    ([[1, 1]], True)
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
        k, channels = windows.shape[0], self.exemplar.shape[2]
        weights = known * self.gauss
        norm = weights.sum(axis=(1, 2))
        full_w = np.broadcast_to(weights[..., None], weights.shape + (channels,))
        d = self.bank.distances(windows.reshape(k, -1), full_w.reshape(k, -1))
        d /= norm[:, None]
        choice, error = _pick_candidates(d, float(tolerance), uniforms)
        return self.centres[choice], error
