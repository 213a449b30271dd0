"""Exact nearest-patch search: FFT correlation for single masked queries, BLAS for batches.

The weighted squared distance between a query window ``q`` with weights ``w`` and the
exemplar window anchored at ``t`` (top-left) is

    d(t) = sum_x w(x) ||E(t + x) - q(x)||^2
         = (E^2 * w)(t) - 2 sum_c (E_c * (w q_c))(t) + sum_x w(x) ||q(x)||^2

where ``*`` denotes correlation. All three terms are exact in float64 and the result is
clamped at zero (the terms nearly cancel for good matches).

Queries never change these objects (``docs/architecture.md``, "Fitted state"); what one
synthesis reuses between its queries (the energy term of a repeated mask) is in a cache that
the caller passes in.

Why this module is long: it is the one place where texsyn finds nearest patches exactly:
FFT correlation for single masked queries, BLAS products for batches (weighted, ``k``
nearest, nearest row), compiled folds for the both-way and the float32-screened searches.
The expansion of the squared distance, its clamping at zero and the tie rules are written
once here and read side by side. The approximate tree search of Wei and Levoy is
:mod:`texsyn.ops.tsvq`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .jit import jit, prange
from .linalg import matmul
from .patches import as_channels

__all__ = [
    "knn_select",
    "FFTPatchSearch",
    "NearestPatchIndex",
    "WeightedPatchBank",
    "knn_patches",
    "nearest_both_ways",
    "nearest_rows",
]


def knn_select(distances: np.ndarray, k: int) -> np.ndarray:
    """Flat indices of the ``k`` smallest distances, ordered by (distance, index).

    Tie-safe: equal distances are ordered by their flat index, so the selection does not
    depend on how the partition orders them; ``k`` is clamped to the number of candidates.
    """
    d = np.asarray(distances).ravel()
    k = int(min(max(k, 1), d.size))
    kth = np.partition(d, k - 1)[k - 1]
    cand = np.flatnonzero(d <= kth)
    return cand[np.argsort(d[cand], kind="stable")][:k]


class FFTPatchSearch:
    """Exact (optionally weighted) SSD of one query window against every exemplar position.

    Everything that depends only on the exemplar (channel spectra, spectrum of the summed
    squares) is computed once here, and queries never change the object. The mask-dependent
    energy term can be kept in a cache that the caller owns (``energies``, one dict per
    synthesis), so that repeated queries with the same overlap shape cost ``C`` forward and
    one inverse real FFT.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, C)
        Any stack of real channels (colour, wavelet subbands, ...).
    window : (int, int)
        Height and width of the query window.
    mode : {'valid', 'periodic'}
        ``'valid'`` returns distances for the ``(H-h+1, W-w+1)`` anchors whose window lies
        inside the exemplar; ``'periodic'`` wraps around and returns ``(H, W)`` distances.
    """

    def __init__(self, exemplar: np.ndarray, window: tuple[int, int], *, mode: str = "valid"):
        ex = as_channels(np.asarray(exemplar, dtype=np.float64))
        self.shape = ex.shape[:2]
        self.window = (int(window[0]), int(window[1]))
        if mode not in ("valid", "periodic"):
            raise ValueError(f"mode must be 'valid' or 'periodic', got {mode!r}")
        if mode == "valid" and (self.window[0] > self.shape[0] or self.window[1] > self.shape[1]):
            raise ValueError(
                f"search window {self.window[1]}x{self.window[0]} is larger than the exemplar "
                f"({self.shape[1]}x{self.shape[0]})"
            )
        self.mode = mode
        self._spectra = np.fft.rfft2(ex, axes=(0, 1))
        self._sq_spectrum = np.fft.rfft2(np.sum(ex * ex, axis=2))
        self._sq_spectra = np.fft.rfft2(ex * ex, axes=(0, 1)) if ex.shape[2] > 1 else None
        self.channels = ex.shape[2]

    @property
    def anchor_shape(self) -> tuple[int, int]:
        """Shape of the distance map returned by :meth:`distances`."""
        if self.mode == "periodic":
            return self.shape
        return (self.shape[0] - self.window[0] + 1, self.shape[1] - self.window[1] + 1)

    def _correlate(self, spectrum: np.ndarray) -> np.ndarray:
        out = np.fft.irfft2(spectrum, s=self.shape)
        a, b = self.anchor_shape
        return out[:a, :b]

    def _energy(self, weights: np.ndarray, energies: dict | None) -> np.ndarray:
        """The weight-dependent term ``(E^2 * w)(t)``, read from or stored in ``energies``."""
        key = (weights.shape, weights.tobytes())
        hit = None if energies is None else energies.get(key)
        if hit is None:
            if weights.ndim == 2:
                kern = np.fft.rfft2(weights, s=self.shape)
                hit = self._correlate(self._sq_spectrum * np.conj(kern))
            else:
                kern = np.fft.rfft2(weights, s=self.shape, axes=(0, 1))
                hit = self._correlate(np.sum(self._sq_spectra * np.conj(kern), axis=2))
            if energies is not None:
                if len(energies) > 64:
                    energies.clear()
                energies[key] = hit
        return hit

    def distances(
        self, query: np.ndarray, weights: np.ndarray | None = None, *, energies: dict | None = None
    ) -> np.ndarray:
        """Weighted SSD map between ``query`` and every exemplar window.

        Parameters
        ----------
        query : ndarray, shape (h, w) or (h, w, C)
            Values outside the weight support are ignored.
        weights : ndarray, shape (h, w) or (h, w, C), optional
            Non-negative pixel weights (a 0/1 mask, a Gaussian, ...), shared by the channels
            or one per channel (e.g. two terms of different weight stacked as channels,
            Raad et al. 2016 eq. 14); all ones by default.
        energies : dict, optional
            The caller's cache of this search's energy terms, keyed by the weights: one dict
            (empty at first) per synthesis, for this search only. Without it every query
            computes the term; the result is the same.

        Returns
        -------
        ndarray, shape :attr:`anchor_shape`
            ``d[t]`` for top-left anchors ``t``, clamped at zero.

        Examples
        --------
        >>> search = FFTPatchSearch(np.arange(16.0).reshape(4, 4), (2, 2))
        >>> cache = {}
        >>> d = search.distances(np.array([[5.0, 6.0], [9.0, 10.0]]), energies=cache)
        >>> d.shape, float(d[1, 1]), len(cache)
        ((3, 3), 0.0, 1)
        """
        q = as_channels(np.asarray(query, dtype=np.float64))
        if q.shape[:2] != self.window:
            raise ValueError(f"query window must be {self.window}, got {q.shape[:2]}")
        w = np.ones(self.window) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.ndim == 3 and self.channels == 1:
            w = w[..., 0]
        wc = w[..., None] if w.ndim == 2 else w
        q = np.where(wc > 0, q, 0.0)  # unknown values outside the weights may be anything
        wq = wc * q
        cross = np.fft.rfft2(wq, s=self.shape, axes=(0, 1))
        cross_term = self._correlate(np.sum(self._spectra * np.conj(cross), axis=2))
        const = float(np.sum(wq * q))
        d = self._energy(w, energies) - 2.0 * cross_term + const
        return np.maximum(d, 0.0, out=d)

    def knn(
        self, query: np.ndarray, weights: np.ndarray | None = None, k: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` best anchors as ``(k, 2)`` ``(row, col)`` and their distances (tie-safe)."""
        d = self.distances(query, weights)
        idx = knn_select(d, k)
        rows, cols = np.unravel_index(idx, d.shape)
        return np.stack([rows, cols], axis=1), d.ravel()[idx]


class WeightedPatchBank:
    """Exact weighted SSD between many queries, each with its own weights, and a patch bank.

    ``d[q, k] = sum_x weights[q, x] (bank[k, x] - queries[q, x])^2`` is computed as one
    matrix product of ``[w, w q]`` with the stacked bank ``[bank^2, -2 bank]``, which is built
    once here (queries never change it).

    Parameters
    ----------
    bank : ndarray, shape (K, D)
        Patch vectors (any channel stack, flattened consistently with the queries).
    """

    def __init__(self, bank: np.ndarray):
        bank = np.asarray(bank, dtype=np.float64)
        self.size, self.dim = bank.shape
        self._stacked = np.ascontiguousarray(np.concatenate([bank * bank, -2.0 * bank], axis=1))

    def distances(self, queries: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Distances of shape ``(Q, K)``, clamped at zero.

        Parameters
        ----------
        queries, weights : ndarray, shape (Q, D)
            Query vectors and their non-negative per-entry weights.
        """
        w = np.asarray(weights, dtype=np.float64)
        q = np.asarray(queries, dtype=np.float64)
        wq = w * q
        d = matmul(np.concatenate([w, wq], axis=1), self._stacked.T)
        d += np.sum(wq * q, axis=1)[:, None]
        return np.maximum(d, 0.0, out=d)


def _norm_less_products(queries: np.ndarray, bank: np.ndarray, bank_norm: np.ndarray) -> np.ndarray:
    """``||b||^2 - 2 q . b`` for every query row ``q`` and bank row ``b``: ``(Q, K)``, by BLAS."""
    return bank_norm[None, :] - 2.0 * matmul(queries, bank.T)


def nearest_rows(queries: np.ndarray, bank: np.ndarray, bank_norm: np.ndarray | None = None) -> np.ndarray:
    """Exact nearest bank row of every query row (unweighted SSD), in one matrix product.

    The row minimising ``||b||^2 - 2 q . b``: the squared distance ``||q - b||^2`` less the
    query's own ``||q||^2``, which is the same for every bank row and so is never computed.
    Ties go to the lowest row.

    Parameters
    ----------
    queries : ndarray, shape (Q, D)
    bank : ndarray, shape (K, D)
    bank_norm : ndarray, shape (K,), optional
        ``np.sum(bank * bank, axis=1)``, for a caller that searches one bank many times.

    Examples
    --------
    >>> nearest_rows(np.array([[0.9, 0.0], [0.0, 2.0]]), np.eye(2)).tolist()
    [0, 1]
    """
    norm = np.sum(bank * bank, axis=1) if bank_norm is None else bank_norm
    return np.argmin(_norm_less_products(queries, bank, norm), axis=1)


def knn_patches(
    queries: np.ndarray, bank: np.ndarray, k: int = 1, *, block: int = 1024
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``k`` nearest bank rows of every query row (unweighted SSD), by blocked BLAS.

    Returns
    -------
    indices : ndarray, shape (Q, k)
        Bank rows ordered by (distance, index).
    distances : ndarray, shape (Q, k)
    """
    bank = np.asarray(bank, dtype=np.float64)
    queries = np.asarray(queries, dtype=np.float64)
    k = int(min(max(k, 1), bank.shape[0]))
    bank_norm = np.sum(bank * bank, axis=1)
    idx = np.empty((queries.shape[0], k), dtype=np.intp)
    dist = np.empty((queries.shape[0], k))
    for start in range(0, queries.shape[0], block):
        q = queries[start : start + block]
        d = _norm_less_products(q, bank, bank_norm)
        d += np.sum(q * q, axis=1)[:, None]  # the full squared distance
        np.maximum(d, 0.0, out=d)
        order = np.argsort(d, axis=1, kind="stable")[:, :k]
        idx[start : start + len(q)] = order
        dist[start : start + len(q)] = np.take_along_axis(d, order, axis=1)
    return idx, dist


@jit()
def _fold_minima(gram, query_norm, bank_norm, offset, q_idx, q_dist, b_idx, b_dist):
    """One pass over a block of ``q . x`` products: row and column minima of the distances."""
    n_rows, n_cols = gram.shape
    for i in range(n_rows):
        best = np.inf
        arg = 0
        qn = query_norm[i]
        for j in range(n_cols):
            d = qn + bank_norm[j] - 2.0 * gram[i, j]
            if d < 0.0:
                d = 0.0
            if d < best:
                best = d
                arg = j
            if d < b_dist[j]:
                b_dist[j] = d
                b_idx[j] = offset + i
        q_idx[offset + i] = arg
        q_dist[offset + i] = best


def nearest_both_ways(
    queries: np.ndarray, bank: np.ndarray, *, block: int = 512
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact nearest neighbours in both directions between two patch sets, in one pass.

    The products ``Q X^T`` come from BLAS in blocks of queries; a compiled loop folds each
    block into the row minima (nearest bank row of every query) and the running column
    minima (nearest query of every bank row). Ties go to the lowest index.

    Parameters
    ----------
    queries : ndarray, shape (Q, D)
    bank : ndarray, shape (K, D)

    Returns
    -------
    query_nearest : ndarray of intp, shape (Q,)
    query_distance : ndarray, shape (Q,)
        Squared distance from each query to its nearest bank row.
    bank_nearest : ndarray of intp, shape (K,)
    bank_distance : ndarray, shape (K,)
    """
    bank = np.ascontiguousarray(bank, dtype=np.float64)
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    bank_norm = np.sum(bank * bank, axis=1)
    query_norm = np.sum(queries * queries, axis=1)
    q_idx = np.empty(queries.shape[0], dtype=np.int64)
    q_dist = np.empty(queries.shape[0])
    b_idx = np.zeros(bank.shape[0], dtype=np.int64)
    b_dist = np.full(bank.shape[0], np.inf)
    for start in range(0, queries.shape[0], block):
        q = queries[start : start + block]
        _fold_minima(
            matmul(q, bank.T),
            query_norm[start : start + block],
            bank_norm,
            start,
            q_idx,
            q_dist,
            b_idx,
            b_dist,
        )
    return q_idx, q_dist, b_idx, b_dist


@jit(parallel=True)
def _best_columns(gram, half_norm, k, out):
    """Per row, the ``k`` columns with the smallest ``half_norm[j] - gram[i, j]`` (ties: lower j)."""
    n_rows, n_cols = gram.shape
    for i in prange(n_rows):
        values = np.full(k, np.inf)
        index = np.zeros(k, dtype=np.int64)
        for j in range(n_cols):
            v = half_norm[j] - gram[i, j]
            if v < values[k - 1]:
                p = k - 1
                while p > 0 and values[p - 1] > v:
                    values[p] = values[p - 1]
                    index[p] = index[p - 1]
                    p -= 1
                values[p] = v
                index[p] = j
        out[i, :] = index


class NearestPatchIndex:
    """Nearest bank row of many query rows: a float32 BLAS screen, then an exact re-rank.

    The bank is centred on its mean (which keeps the float32 products accurate), the
    ``candidates`` best rows of every query are found from the products ``Q X^T`` in float32
    blocks by a compiled selection loop, and these candidates are re-ranked by their exact
    float64 squared distance (ties: lowest row). The result is the exact nearest row unless
    several rows are within float32 rounding of the best (relative 1e-6), where any of them
    may be returned, deterministically. Everything is built here; queries never change the
    index.

    Parameters
    ----------
    bank : ndarray, shape (K, D)
    candidates : int
        Rows re-ranked exactly per query.
    block : int
        Queries per matrix product (memory: ``block * K`` float32).
    rows : callable, optional
        ``rows(indices) -> (n, D) float64``: the exact bank rows, for banks that are cheaper to
        recompute than to keep in float64. By default a float64 copy of ``bank`` is kept.
    """

    def __init__(
        self,
        bank: np.ndarray,
        *,
        candidates: int = 4,
        block: int = 1024,
        rows: Callable[[np.ndarray], np.ndarray] | None = None,
    ):
        bank = np.asarray(bank)
        if bank.ndim != 2 or bank.shape[0] == 0:
            raise ValueError(f"bank must be a non-empty (K, D) array, got shape {bank.shape}")
        self.mean = bank.mean(axis=0, dtype=np.float64)
        centred = np.ascontiguousarray((bank - self.mean).astype(np.float32))
        self._bank32 = centred
        self._half_norm = 0.5 * np.einsum("kd,kd->k", centred, centred, dtype=np.float64).astype(np.float32)
        if rows is None:
            exact = np.array(bank, dtype=np.float64)
            rows = exact.__getitem__
        self._rows = rows
        self.candidates = int(min(max(candidates, 1), bank.shape[0]))
        self.block = int(block)

    def __len__(self) -> int:
        return self._bank32.shape[0]

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest bank row of every query.

        Returns
        -------
        index : ndarray of int64, shape (Q,)
        distance : ndarray of float64, shape (Q,)
            Exact squared Euclidean distance to that row.
        """
        queries = np.asarray(queries, dtype=np.float64)
        dim = self._bank32.shape[1]
        if queries.ndim != 2 or queries.shape[1] != dim:
            raise ValueError(f"queries must have shape (Q, {dim}), got {queries.shape}")
        n = queries.shape[0]
        index = np.empty(n, dtype=np.int64)
        distance = np.empty(n)
        cand = np.empty((min(n, self.block), self.candidates), dtype=np.int64)
        for start in range(0, n, self.block):
            q = queries[start : start + self.block]
            m = q.shape[0]
            gram = matmul((q - self.mean).astype(np.float32), self._bank32.T)
            _best_columns(gram, self._half_norm, self.candidates, cand[:m])
            c = cand[:m]
            diff = self._rows(c.ravel()).reshape(m, self.candidates, dim) - q[:, None, :]
            d = np.einsum("qkd,qkd->qk", diff, diff)
            best = d.min(axis=1, keepdims=True)
            pick = np.where(d == best, c, np.iinfo(np.int64).max).min(axis=1)
            index[start : start + m] = pick
            distance[start : start + m] = best[:, 0]
        return index, distance
