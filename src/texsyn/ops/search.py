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

import threading
from collections.abc import Callable

import numpy as np

from .jit import atomic_compare_exchange, atomic_load, atomic_store, jit, os_yield, prange
from .linalg import (
    BLOCK_COLUMNS,
    BLOCK_ROWS,
    CBLAS_NO_TRANS,
    CBLAS_ROW_MAJOR,
    cblas_sgemm,
    fixed_order,
    matmul,
    parallel_map,
    worker_count,
)
from .patches import as_channels

__all__ = [
    "knn_select",
    "BoundedNearestIndex",
    "BoundedParallelSearch",
    "FFTPatchSearch",
    "NearestPatchIndex",
    "WeightedPatchBank",
    "knn_patches",
    "nearest_both_ways",
    "bounded_index_bytes",
    "bounded_query_bytes",
    "nearest_rows",
    "nearest_rows_band",
    "nearest_rows_bounded",
    "nearest_rows_by_column_blocks",
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
        # written in place: the same values as concatenating ``bank * bank`` and ``-2 bank``,
        # without their temporaries (fresh pages cost system time)
        self._stacked = np.empty((self.size, 2 * self.dim))
        np.multiply(bank, bank, out=self._stacked[:, : self.dim])
        np.multiply(-2.0, bank, out=self._stacked[:, self.dim :])

    def distances(self, queries: np.ndarray, weights: np.ndarray, rows: slice | None = None) -> np.ndarray:
        """Distances of shape ``(Q, K)``, clamped at zero.

        Parameters
        ----------
        queries, weights : ndarray, shape (Q, D)
            Query vectors and their non-negative per-entry weights.
        rows : slice, optional
            Only these bank rows: ``(Q, len(rows))``. Starting at a multiple of
            :data:`~texsyn.ops.linalg.BLOCK_COLUMNS` and that long, the values are those of
            the full product's tiles (:func:`texsyn.ops.linalg.matmul`), the same bytes.
        """
        w = np.asarray(weights, dtype=np.float64)
        q = np.asarray(queries, dtype=np.float64)
        wq = w * q
        stacked = self._stacked if rows is None else self._stacked[rows]
        d = matmul(np.concatenate([w, wq], axis=1), stacked.T)
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
        # rows given by the caller may be views of its own arrays; gathered rows are new
        self._fresh_rows = rows is None
        if rows is None:
            exact = np.array(bank, dtype=np.float64)
            rows = exact.__getitem__
        self._rows = rows
        self.candidates = int(min(max(candidates, 1), bank.shape[0]))
        self.block = int(block)

    @classmethod
    def from_parts(
        cls,
        fill: Callable[[int, int, np.ndarray, np.ndarray | None], object],
        n_rows: int,
        dim: int,
        *,
        part_rows: int,
        rows: Callable[[np.ndarray], np.ndarray],
        candidates: int = 4,
        block: int = 1024,
    ) -> NearestPatchIndex:
        """The index of a bank given part by part: the same index as ``NearestPatchIndex(bank)``.

        ``fill(start, stop, out, offset)`` writes ``bank[start:stop] - offset`` into the
        float64 ``out`` (``offset=None``: the rows themselves). It is called twice per part:
        without an offset, for the mean, then with the mean, for the centred rows rounded
        to float32, so that neither the float64 bank nor its centred copy is ever held
        whole (the transient is one part of ``part_rows`` rows). The mean is the same sum
        as ``bank.mean(axis=0)``: NumPy adds the rows of a C-ordered array of two columns or
        more one after the other along axis 0, and each part continues the running sum from
        its first row (a single column, which NumPy sums pairwise, is taken whole). Every
        other value is computed row by row, so the index is the same, byte for byte
        (``tests/test_patch_wavelet_speed.py``).

        Parameters
        ----------
        fill : callable
            ``fill(start, stop, out, offset)``, ``out`` a float64 ``(stop - start, dim)``
            array, ``offset`` a float64 ``(dim,)`` array or None.
        n_rows, dim : int
            Shape ``(K, D)`` of the bank.
        part_rows : int
            Rows per part.
        rows : callable
            ``rows(indices) -> (n, D) float64``: the exact bank rows for the re-ranking, a
            new array on every call (the query subtracts from it in place).
        candidates, block : int
            As in the constructor.
        """
        if n_rows < 1 or dim < 1:
            raise ValueError(f"bank must be a non-empty (K, D) array, got shape {(n_rows, dim)}")
        if dim == 1:  # NumPy sums a single column pairwise, not row after row: take it whole
            column = np.empty((n_rows, 1))
            fill(0, n_rows, column, None)
            return cls(column, candidates=candidates, block=block, rows=rows)._fresh(True)
        part_rows = int(min(max(part_rows, 1), n_rows))
        # one extra row in front: the running sum, which the next part's rows are added to
        buffer = np.empty((part_rows + 1, dim))
        total = np.zeros(dim)
        for start in range(0, n_rows, part_rows):
            stop = min(n_rows, start + part_rows)
            fill(start, stop, buffer[1 : stop - start + 1], None)
            first = 1 if start == 0 else 0
            buffer[0] = total
            total = np.add.reduce(buffer[first : stop - start + 1], axis=0)
        mean = np.true_divide(total, n_rows)
        centred = np.empty((n_rows, dim), dtype=np.float32)
        for start in range(0, n_rows, part_rows):
            stop = min(n_rows, start + part_rows)
            part = buffer[: stop - start]
            fill(start, stop, part, mean)
            centred[start:stop] = part
        index = cls.__new__(cls)
        index.mean = mean
        index._bank32 = centred
        index._half_norm = 0.5 * np.einsum("kd,kd->k", centred, centred, dtype=np.float64).astype(np.float32)
        index._rows = rows
        index._fresh_rows = True
        index.candidates = int(min(max(candidates, 1), n_rows))
        index.block = int(block)
        return index

    def _fresh(self, fresh: bool) -> NearestPatchIndex:
        self._fresh_rows = fresh
        return self

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
            diff = self._rows(c.ravel()).reshape(m, self.candidates, dim)
            if getattr(self, "_fresh_rows", False):  # new arrays: the difference taken in place
                np.subtract(diff, q[:, None, :], out=diff)
            else:
                diff = diff - q[:, None, :]
            d = np.einsum("qkd,qkd->qk", diff, diff)
            best = d.min(axis=1, keepdims=True)
            pick = np.where(d == best, c, np.iinfo(np.int64).max).min(axis=1)
            index[start : start + m] = pick
            distance[start : start + m] = best[:, 0]
            # freed before the next block's products are made: one block of products at a
            # time, and the allocator hands the same memory back (no new pages per block)
            del gram, diff
        return index, distance


# ---------------------------------------------------------------------- proven nearest rows
#: unit roundoff of float64 and float32
_U64 = 2.0**-53
_U32 = 2.0**-24
#: :func:`nearest_rows_band`'s ``2 E = 2 x 2.2 gamma_{D+2} (max ||b|| + ||q||)^2`` less its gamma
_BAND_FACTOR = 2.0 * 2.2
#: (query, bank row) pairs of a block below which :class:`BoundedNearestIndex` searches its
#: bank in one part: a hand-over to another thread costs about 0.1 ms on a virtual machine
#: whose idle core must be woken, as much as half the search of 2**17 pairs saves
#: (``docs/methods/wei_levoy.md``, "Performance")
PARALLEL_PAIRS = 1 << 18


def _gamma(n: float, u: float) -> float:
    """Higham's ``gamma_n = n u / (1 - n u)``: the relative error bound of an ``n``-term sum."""
    return n * u / (1.0 - n * u)


@jit()
def _squared_distance(q, b):
    """``sum (q - b)^2`` in float64, with four partial sums (error at most ``gamma_{D+3}`` relative)."""
    n = q.shape[0]
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    t = 0
    while t + 4 <= n:
        d0 = q[t] - b[t]
        d1 = q[t + 1] - b[t + 1]
        d2 = q[t + 2] - b[t + 2]
        d3 = q[t + 3] - b[t + 3]
        a0 += d0 * d0
        a1 += d1 * d1
        a2 += d2 * d2
        a3 += d3 * d3
        t += 4
    while t < n:
        d0 = q[t] - b[t]
        a0 += d0 * d0
        t += 1
    return (a0 + a1) + (a2 + a3)


@jit(nogil=True)
def _band(coefficients, x):
    """A band around a squared distance ``x``: ``c[0] x + c[1] sqrt(x) + c[2]`` (increasing in ``x``)."""
    return coefficients[0] * x + coefficients[1] * np.sqrt(x) + coefficients[2]


@jit(nogil=True)
def _fold_max(maxima, values, n):
    """``maxima[k] = max(maxima[k], values[k])`` for ``k < n`` (a loop the compiler vectorises)."""
    for k in range(n):
        v = values[k]
        maxima[k] = v if v > maxima[k] else maxima[k]


@jit(nogil=True)
def _bounded_seeds(queries, bank, seeds, gamma_x, best_j, best_x, upper, keep_j, keep_x, kept):
    """Start a :class:`BoundedNearestIndex` search from the seeds (``-1``: none).

    Every distinct seed's exact distance bounds the smallest distance from above, and the
    seeds are the first kept rows.
    """
    m, n_seeds = seeds.shape
    for i in range(m):
        bx = np.inf
        bj = -1
        n = 0
        for t in range(n_seeds):
            j = seeds[i, t]
            seen = j < 0
            for r in range(t):
                seen = seen or seeds[i, r] == j
            if seen:
                continue
            x = _squared_distance(queries[i], bank[j])
            if x * (1.0 + gamma_x) < upper[i]:
                upper[i] = x * (1.0 + gamma_x)
            keep_j[i, n] = j
            keep_x[i, n] = x
            n += 1
            if x < bx or (x == bx and j < bj):
                bx = x
                bj = j
        best_j[i] = bj
        best_x[i] = bx
        kept[i] = n


@jit(nogil=True)
def _bounded_prepare(
    centred, full, dims, gamma_l, proj_max, err_coefficient, eps_coefficient, bands, proj32, q_ext,
    terms, band, queries, bank, seeds, gamma_x, best_j, best_x, upper, keep_j, keep_x, kept,
):  # fmt: skip
    """The query side of a :class:`BoundedNearestIndex` search, in one pass, and its seeds.

    For every query: its float32 projection extended by 1 (``proj32``), its next coordinates
    rounded through float32 (``q_ext``), ``terms`` = the squared norm of the float32
    projection, the error bound of the float32 products, and the error bound of the
    coordinates, the residual norms and their error bounds (the formulas of
    :meth:`BoundedNearestIndex._side_terms`, whose error bounds hold for any order of the
    sums), and ``band``, the largest of its bands' coefficients. Then
    :func:`_bounded_seeds` for part 0, whose bound starts every other part.
    """
    m, coords = full.shape
    n_ext = coords - dims
    for i in range(m):
        q_sq = 0.0
        head = 0.0
        for k in range(dims):
            v = np.float32(full[i, k])
            proj32[i, k] = v
            q_sq += np.float64(v) * np.float64(v)
            head += full[i, k] * full[i, k]
        proj32[i, dims] = np.float32(1.0)
        tail = 0.0
        for k in range(n_ext):
            v = full[i, dims + k]
            q_ext[i, k] = np.float64(np.float32(v))
            tail += v * v
        size_sq = 0.0
        for k in range(centred.shape[1]):
            size_sq += centred[i, k] * centred[i, k]
        root = np.sqrt(q_sq) + proj_max
        res_err = np.sqrt(eps_coefficient * size_sq) + 1e-300
        terms[0, i] = q_sq
        terms[1, i] = 2.5 * gamma_l * root * root + 1e-300
        terms[2, i] = err_coefficient * np.sqrt(size_sq)
        terms[3, i] = np.sqrt(max(size_sq - head, 0.0))
        terms[4, i] = res_err
        terms[5, i] = np.sqrt(max(size_sq - head - tail, 0.0))
        terms[6, i] = res_err
        for c in range(3):
            top = bands[i, 0, c]
            for t in range(1, bands.shape[1]):
                top = max(top, bands[i, t, c])
            band[i, c] = top
    upper[0, :] = np.inf
    _bounded_seeds(
        queries, bank, seeds, gamma_x, best_j[0], best_x[0], upper[0], keep_j[0], keep_x[0], kept[0]
    )
    for p in range(1, upper.shape[0]):
        upper[p, :] = upper[0, :]
        best_j[p, :] = -1
        best_x[p, :] = np.inf
        kept[p, :] = 0


@jit(nogil=True)
def _bounded_chunk(
    gram, lo, queries, bank, seeds, q_sq, q_err, l_err, q_res, q_res_err, q_ext, q_res2, q_res2_err,
    b_res, b_res2, b_ext, b_errors, sigma, gamma_x, gamma_e, band, best_j, best_x, upper, keep_j,
    keep_x, kept,
    overflow,
):  # fmt: skip
    """Search the bank rows ``lo, lo + 1, ...`` of one chunk (see :class:`BoundedNearestIndex`).

    ``gram[i, c]`` is the float32 product of the projections of query ``i`` and bank row
    ``lo + c``, less half the squared norm of the bank row's projection (the product of the
    projections extended by 1 and that half norm): ``-gram`` is half the projected squared
    distance less the query's own half norm. Pass 1 takes the maxima of ``gram`` over
    blocks of 16 interleaved columns (``b, b + n_blocks, ...``); while no upper bound of the
    smallest distance is known (no seeds), the row of the largest value is evaluated first.
    Pass 2 visits the blocks whose maximum may lie over the threshold of the bound ``upper`` and
    turns each value into a proven lower bound of the squared distance (projection and
    residual parts, every rounding error included); the rows that pass get a second bound
    from the next coordinates (``q_ext`` and the bank's, float32 values compared directly)
    and the residual beyond them, and the rows that pass both get their exact distance,
    which tightens the bound. Of bank row ``j`` the bounds read its residual norms
    ``b_res[j]`` (beyond the projection) and ``b_res2[j]`` (beyond the next coordinates)
    and the next coordinates ``b_ext[j]``; ``b_errors`` holds the largest error bounds of the
    bank's projections and of its two residual norms (small arrays, read from the cache).
    The state carried from chunk to chunk, per query: the best row and
    its distance, the bound, the rows kept (every row whose distance may lie within
    ``band(i, x) = band[i, 0] x + band[i, 1] sqrt(x) + band[i, 2]`` of the smallest ``x`` is
    among them) and whether more than ``keep_j.shape[1]``
    had to be kept.
    """
    m, width = gram.shape
    capacity = keep_j.shape[1]
    n_blocks = (width + 15) // 16
    n_seeds = seeds.shape[1]
    n_ext = q_ext.shape[1]
    maxima = np.empty(n_blocks, dtype=np.float32)
    for i in range(m):
        row = gram[i]
        q_extra = q_ext[i]
        maxima[:] = -np.inf
        for s in range(16):
            off = s * n_blocks
            _fold_max(maxima, row[off:], min(n_blocks, width - off))
        q = queries[i]
        bx = best_x[i]
        bj = best_j[i]
        n_kept = kept[i]
        j0 = -1
        if upper[i] == np.inf:  # no seed: start from the smallest projected distance
            first = 0
            for b in range(1, n_blocks):
                if maxima[b] > maxima[first]:
                    first = b
            v0 = np.float32(-np.inf)
            for s in range(16):
                c = s * n_blocks + first
                if c < width and row[c] > v0:
                    v0 = row[c]
                    j0 = lo + c
            x = _squared_distance(q, bank[j0])
            upper[i] = x * (1.0 + gamma_x)
            keep_j[i, n_kept] = j0
            keep_x[i, n_kept] = x
            n_kept += 1
            if x < bx or (x == bx and j0 < bj):
                bx = x
                bj = j0
        # a row can pass only if sqrt(L - l_err) - q_err - b_err_max <= sigma sqrt(upper + band)
        bound = upper[i] + _band(band[i], upper[i])
        reach = sigma * np.sqrt(bound) + q_err[i] + b_errors[0]
        limit = 0.5 * (reach * reach + l_err[i] - q_sq[i])
        floor32 = -np.float32(limit + 1e-6 * abs(limit) + 1e-30)
        full = overflow[i]
        for b in range(n_blocks):
            if maxima[b] < floor32:
                continue
            for s in range(16):
                c = s * n_blocks + b
                if c >= width:
                    break
                if row[c] < floor32:
                    continue
                v = -row[c]
                j = lo + c
                seen = j == j0
                for t in range(n_seeds):
                    seen = seen or seeds[i, t] == j
                if seen:
                    continue
                proj = q_sq[i] + 2.0 * np.float64(v) - l_err[i]
                gap = (np.sqrt(proj) if proj > 0.0 else 0.0) - q_err[i] - b_errors[0]
                lower = (gap / sigma) ** 2 if gap > 0.0 else 0.0
                res = abs(q_res[i] - b_res[j]) - q_res_err[i] - b_errors[1]
                if res > 0.0:
                    lower += res * res
                if lower > bound:
                    continue
                if n_ext > 0:  # the next coordinates and the residual beyond them
                    ext = 0.0
                    ext_j = b_ext[j]
                    for t in range(n_ext):
                        e = q_extra[t] - np.float64(ext_j[t])
                        ext += e * e
                    proj += ext * (1.0 - gamma_e)
                    gap = (np.sqrt(proj) if proj > 0.0 else 0.0) - q_err[i] - b_errors[0]
                    lower = (gap / sigma) ** 2 if gap > 0.0 else 0.0
                    res = abs(q_res2[i] - b_res2[j]) - q_res2_err[i] - b_errors[2]
                    if res > 0.0:
                        lower += res * res
                    if lower > bound:
                        continue
                x = _squared_distance(q, bank[j])
                if x < bx or (x == bx and j < bj):
                    bx = x
                    bj = j
                if x * (1.0 + gamma_x) < upper[i]:
                    upper[i] = x * (1.0 + gamma_x)
                    bound = upper[i] + _band(band[i], upper[i])
                    reach = sigma * np.sqrt(bound) + q_err[i] + b_errors[0]
                    limit = 0.5 * (reach * reach + l_err[i] - q_sq[i])
                    floor32 = -np.float32(limit + 1e-6 * abs(limit) + 1e-30)
                if n_kept == capacity:  # drop the rows that can no longer be within the band
                    cut = bx * (1.0 + 3.0 * gamma_x) + (1.0 + gamma_x) * _band(band[i], bx * (1.0 + gamma_x))
                    n = 0
                    for t in range(n_kept):
                        if keep_x[i, t] <= cut:
                            keep_j[i, n] = keep_j[i, t]
                            keep_x[i, n] = keep_x[i, t]
                            n += 1
                    n_kept = n
                if n_kept == capacity:
                    full = True
                else:
                    keep_j[i, n_kept] = j
                    keep_x[i, n_kept] = x
                    n_kept += 1
        best_j[i] = bj
        best_x[i] = bx
        kept[i] = n_kept
        overflow[i] = full


@jit(nogil=True)
def _search_part(
    sgemm, lo, hi, chunk, proj32, proj32_t, gram, queries, bank, seeds, terms, q_ext, b_res, b_res2,
    b_ext, b_errors, sigma, gamma_x, gamma_e, band, best_j, best_x, upper, keep_j, keep_x, kept, overflow,
):  # fmt: skip
    """Search the bank rows ``lo:hi`` for every query, a chunk of rows at a time, without the GIL.

    Each chunk's float32 products come from ``sgemm`` (NumPy's ``cblas_sgemm``,
    :func:`texsyn.ops.linalg.cblas_sgemm`) into ``gram`` (a flat buffer of at least
    ``len(queries) * chunk`` values), then :func:`_bounded_chunk` screens them; ``terms`` are the
    seven rows of the query side of the bounds (:meth:`BoundedNearestIndex._search_block`).
    """
    m, width_k = proj32.shape
    for c0 in range(lo, hi, chunk):
        c1 = min(hi, c0 + chunk)
        width = c1 - c0
        block = gram[: m * width].reshape((m, width))
        sgemm(
            CBLAS_ROW_MAJOR, CBLAS_NO_TRANS, CBLAS_NO_TRANS, m, width, width_k, np.float32(1.0),
            proj32.ctypes.data, width_k, proj32_t[:, c0:].ctypes.data, proj32_t.shape[1],
            np.float32(0.0), block.ctypes.data, width,
        )  # fmt: skip
        _bounded_chunk(
            block, c0, queries, bank, seeds, terms[0], terms[2], terms[1], terms[3], terms[4], q_ext,
            terms[5], terms[6], b_res, b_res2, b_ext, b_errors, sigma, gamma_x, gamma_e, band, best_j,
            best_x, upper, keep_j, keep_x, kept, overflow,
        )  # fmt: skip


#: the words of a part worker's row of the control array (:class:`BoundedParallelSearch`):
#: the job number asked, its number of queries, the job number done, stop, sleeping, and the
#: job number claimed (by the worker or, where it has not started, the caller)
_JOB, _QUERIES, _DONE, _STOP, _SLEEPING, _CLAIMED = 0, 1, 2, 3, 4, 5
#: reads of an idle part worker between two offers of its core to another thread
#: (``sched_yield``: on a busy machine the spinning takes less time from the caller)
_READS_PER_YIELD = 64
#: words per worker's row (a cache line of its own: no false sharing between workers)
_CONTROL_WORDS = 8


@jit(nogil=True)
def _part_worker(
    control, spins, pause, sgemm, part, n_parts, n_seeds, lo, hi, chunk, proj32, proj32_t, gram, queries,
    bank, seeds, terms, q_ext, b_res, b_res2, b_ext, b_errors, sigma, gamma_x, gamma_e, band, best_j,
    best_x, upper, keep_j, keep_x, kept, overflow,
):  # fmt: skip
    """The loop a part worker thread stays in (:class:`BoundedParallelSearch`), without the GIL.

    It watches its row of ``control``: a new job number (word ``_JOB``) asks for the search of
    the bank rows ``lo:hi`` (:func:`_search_part`) for ``m = control[_QUERIES]`` queries, whose
    arrays are the first values of the flat buffers (``proj32`` holds ``m x width`` values,
    ``band`` ``m x 3``, ``terms`` ``7 x m``, the parts' state ``n_parts x m``, ...), and the
    state of part ``part``. It claims the job (word ``_CLAIMED``, unless the caller, done with
    its own part first, has claimed it to search the part itself: :func:`_claim_parts`),
    searches and reports it done (word ``_DONE``). After ``spins`` reads without a job it
    raises its ``_SLEEPING`` word, looks for a job once more (the caller raises the job
    number, then reads that word: one of the two sees the other) and returns False, to sleep
    until woken; it returns True when asked to stop.
    """
    d = bank.shape[1]
    width_k = proj32_t.shape[0]
    n_ext = b_ext.shape[1]
    capacity = keep_j.shape[0] // best_j.shape[0]
    atomic_store(control, _SLEEPING, 0)
    idle = 0
    while True:
        job = atomic_load(control, _JOB)
        if job != atomic_load(control, _CLAIMED):
            idle = 0
            if not atomic_compare_exchange(control, _CLAIMED, job - 1, job):
                continue  # the caller's
            m = atomic_load(control, _QUERIES)
            state = n_parts * m
            _search_part(
                sgemm, lo, hi, chunk, proj32[: m * width_k].reshape((m, width_k)), proj32_t, gram,
                queries[: m * d].reshape((m, d)), bank, seeds[: m * n_seeds].reshape((m, n_seeds)),
                terms[: 7 * m].reshape((7, m)), q_ext[: m * n_ext].reshape((m, n_ext)), b_res, b_res2,
                b_ext, b_errors, sigma, gamma_x, gamma_e, band[: 3 * m].reshape((m, 3)),
                best_j[:state].reshape((n_parts, m))[part], best_x[:state].reshape((n_parts, m))[part],
                upper[:state].reshape((n_parts, m))[part],
                keep_j[: state * capacity].reshape((n_parts, m, capacity))[part],
                keep_x[: state * capacity].reshape((n_parts, m, capacity))[part],
                kept[:state].reshape((n_parts, m))[part], overflow[:state].reshape((n_parts, m))[part],
            )  # fmt: skip
            atomic_store(control, _DONE, job)
        elif atomic_load(control, _STOP) != 0:
            return True
        else:
            idle += 1
            if idle % _READS_PER_YIELD == 0:  # another thread may need this core
                pause()
            if idle >= spins:
                atomic_store(control, _SLEEPING, 1)
                if (
                    atomic_load(control, _JOB) == atomic_load(control, _CLAIMED)
                    and atomic_load(control, _STOP) == 0
                ):
                    return False
                atomic_store(control, _SLEEPING, 0)
                idle = 0


@jit(nogil=True)
def _post_job(control, job, m, sleeping):
    """Ask every worker (a row of ``control``) for job ``job`` on ``m`` queries;
    ``sleeping[w]``: whether worker ``w`` was asleep (to be woken)."""
    for w in range(control.shape[0]):
        row = control[w]
        atomic_store(row, _QUERIES, m)
        atomic_store(row, _JOB, job)
        sleeping[w] = atomic_load(row, _SLEEPING) != 0


@jit(nogil=True)
def _post_stop(control):
    """Ask every worker (a row of ``control``) to stop once its job in progress is done."""
    for w in range(control.shape[0]):
        atomic_store(control[w], _STOP, 1)


@jit(nogil=True)
def _claim_parts(control, job, claimed):
    """Claim job ``job`` of every worker that has not claimed it yet, reported done at once
    (the caller searches these parts itself, or drops them after an error);
    ``claimed[w]``: whether worker ``w``'s part was claimed here."""
    for w in range(control.shape[0]):
        row = control[w]
        claimed[w] = atomic_compare_exchange(row, _CLAIMED, job - 1, job)
        if claimed[w]:
            atomic_store(row, _DONE, job)


@jit(nogil=True)
def _await_job(control, job, spins):
    """Wait, spinning, until every worker reports job ``job`` done; False after ``spins``
    reads without it (the caller then checks that the workers still run)."""
    for w in range(control.shape[0]):
        row = control[w]
        count = 0
        while atomic_load(row, _DONE) != job:
            count += 1
            if count >= spins:
                return False
    return True


@jit()
def _bounded_merge(
    best_j, best_x, keep_j, keep_x, kept, overflow, gamma_x, bands, index, distance, counts, members
):  # fmt: skip
    """Join the parts of :func:`_bounded_chunk`: the best row, and the rows within each band.

    ``members[i, :counts[i, 0]]`` are the rows counted in the first band (unless the query
    overflowed).
    """
    n_parts, m = best_j.shape
    capacity = keep_x.shape[2]
    for i in range(m):
        bj = best_j[0, i]
        bx = best_x[0, i]
        full = overflow[0, i]
        for p in range(1, n_parts):
            full = full or overflow[p, i]
            if best_x[p, i] < bx or (best_x[p, i] == bx and best_j[p, i] < bj):
                bx = best_x[p, i]
                bj = best_j[p, i]
        index[i] = bj
        distance[i] = bx
        for t in range(bands.shape[1]):
            if full:
                counts[i, t] = capacity + 1
                continue
            cut = bx * (1.0 + 3.0 * gamma_x) + (1.0 + gamma_x) * _band(bands[i, t], bx * (1.0 + gamma_x))
            n = 0
            for p in range(n_parts):
                for r in range(kept[p, i]):
                    if keep_x[p, i, r] <= cut:
                        if t == 0:
                            members[i, n] = keep_j[p, i, r]
                        n += 1
            counts[i, t] = n


@jit()
def _isolation_sweep(order, keys, slack, bank, radius2, gamma_x, limit, isolated):
    """Clear ``isolated[k]`` for every row with another row within ``radius2[k]`` (squared).

    Stops, returning False, once more than ``limit`` rows are cleared.

    ``keys`` are the coordinates of the rows on a few orthonormal directions (within
    ``slack`` of the exact ones, ``radius2`` scaled for their departure from
    orthonormality), ``order`` sorts the first; two rows whose coordinates lie farther apart
    than the largest radius plus ``slack`` are farther apart than that radius, so each row
    meets only its neighbours in the order of the first coordinate, and only those near in
    every coordinate get their exact distance.
    """
    n, n_keys = keys.shape
    reach = np.sqrt(radius2.max()) + slack
    cleared = 0
    for s in range(n):
        a = order[s]
        for t in range(s + 1, n):
            j = order[t]
            if keys[j, 0] - keys[a, 0] > reach:
                break
            near = 0.0
            for c in range(1, n_keys):
                e = keys[j, c] - keys[a, c]
                near += e * e
            if near > reach * reach * (1.0 + gamma_x):
                continue
            x = _squared_distance(bank[a], bank[j])
            if x <= radius2[a] * (1.0 + gamma_x) + 1e-300 and isolated[a]:
                isolated[a] = False
                cleared += 1
            if x <= radius2[j] * (1.0 + gamma_x) + 1e-300 and isolated[j]:
                isolated[j] = False
                cleared += 1
            if cleared > limit:
                return False
    return True


class BoundedNearestIndex:
    """Exact nearest bank rows, proven: projected lower bounds screen, float64 distances decide.

    The bank is centred and projected on its ``dims`` leading principal directions; a block
    of queries is compared with every bank row through one float32 product of the
    projections (:func:`texsyn.ops.linalg.matmul`). For every pair, the projected distance
    and the distance between the residual norms (the parts outside the projection) give a
    lower bound of the squared distance in which every rounding error of the float32 and
    float64 arithmetic is accounted for (Higham's ``gamma_n`` bounds); only the rows whose
    bound is under the best exact distance found so far get their exact float64 distance
    ``sum (q - b)^2``. The answer is the row of smallest exact distance and, per query, an
    upper bound of the number of rows whose true distance may lie within given bands of
    the smallest. A caller that knows how far another arithmetic (its reference search)
    can be from the true distances uses a count of 1 as a proof that the reference would
    choose the same row, and runs the reference where the count is larger
    (:func:`nearest_rows_bounded`, ``docs/methods/wei_levoy.md``, "Performance"). Queries
    never change the index.

    Parameters
    ----------
    bank : ndarray, shape (K, D)
        The rows searched (kept as float64).
    dims : int
        Dimension of the projection (at most ``D``).
    block : int
        Queries searched together.
    chunk : int
        Bank rows per product (a multiple of 16; memory: ``block * chunk`` float32 per
        worker, meant to stay in the core's cache).
    capacity : int
        Candidate rows kept per query; a query needing more is reported with the count
        ``capacity + 1``.
    """

    def __init__(
        self,
        bank: np.ndarray,
        *,
        dims: int = 32,
        extra: int = 32,
        block: int = 256,
        chunk: int = 2048,
        capacity: int = 64,
    ):
        bank = np.ascontiguousarray(bank, dtype=np.float64)
        if bank.ndim != 2 or bank.shape[0] == 0:
            raise ValueError(f"bank must be a non-empty (K, D) array, got shape {bank.shape}")
        d = bank.shape[1]
        self.bank = bank
        self.norm_max = float(np.sqrt(np.max(np.einsum("kd,kd->k", bank, bank))))
        self.mean = bank.mean(axis=0)
        centred = bank - self.mean
        dims = int(min(max(dims, 1), d))
        total = int(min(dims + max(extra, 0), d))
        _, vectors = np.linalg.eigh(centred.T @ centred)
        self.basis = np.ascontiguousarray(vectors[:, ::-1][:, :total])
        self.dims = dims
        self._ortho = float(np.linalg.norm(self.basis.T @ self.basis - np.eye(total), 2)) + 1e-15
        self._sigma = float(np.sqrt(1.0 + self._ortho)) * (1.0 + 1e-12)
        full = centred @ self.basis
        proj = full[:, :dims]
        proj32 = proj.astype(np.float32)
        p64 = proj32.astype(np.float64)
        p_sq = np.einsum("kd,kd->k", p64, p64)
        # the products come out less half the bank rows' squared norms: [p, 1] . [b, -|b|^2 / 2]
        self._proj32_t = np.ascontiguousarray(np.vstack([proj32.T, -(0.5 * p_sq).astype(np.float32)]))
        self._proj_max = float(np.sqrt(p_sq.max()))
        err, res, res_err, res2, res2_err = self._side_terms(centred, full)
        self._b_errors = np.array([err.max(), res_err.max(), res2_err.max()])
        self._b_err_max = float(err.max())
        self._b_res, self._b_res2 = res, res2
        self._b_ext = np.ascontiguousarray(full[:, dims:].astype(np.float32))
        self.block = int(block)
        self.chunk = int(chunk)
        self.capacity = int(capacity)

    def __len__(self) -> int:
        return self.bank.shape[0]

    def isolated(self, radius2: np.ndarray, limit: int | None = None) -> np.ndarray | None:
        """Which rows are proven to have no other row within ``radius2[k]`` (squared distance).

        ``None`` when more than ``limit`` rows are not (the sweep stops there: a bank of many
        identical rows, such as a flat or binary image's, would cost it quadratic time).

        The rows are swept in the order of their coordinate on the leading principal
        direction, and compared on the next three (``||V^T (a - b)|| <= sigma ||a - b||``);
        the exact distances of the pairs these cannot separate decide, with their rounding
        error.
        """
        d = self.bank.shape[1]
        centred = self.bank - self.mean
        keys = np.ascontiguousarray(centred @ self.basis[:, : min(4, self.basis.shape[1])])
        size = np.sqrt(np.einsum("kd,kd->k", centred, centred))
        slack = 4.0 * (_gamma(d + 3, _U64) * self._sigma * float(size.max()) + 1e-300)
        radius2 = np.ascontiguousarray(radius2, dtype=np.float64) * self._sigma**2
        isolated = np.ones(len(self), dtype=np.bool_)
        order = np.argsort(keys[:, 0], kind="stable")
        limit = len(self) if limit is None else int(limit)
        gamma_x = self._distance_gammas()[0]
        if not _isolation_sweep(order, keys, slack, self.bank, radius2, gamma_x, limit, isolated):
            return None
        return isolated

    def _distance_gammas(self) -> tuple[float, float]:
        """Relative error bounds (with a 1 % margin) of a computed exact squared distance over
        all ``D`` coordinates (``gamma_{D+3}``) and over the index's coordinates
        (``gamma_{p+3}``): what every search of this index, on any thread, allows for."""
        return 1.01 * _gamma(self.bank.shape[1] + 3, _U64), 1.01 * _gamma(self.basis.shape[1] + 3, _U64)

    def _side_terms(self, centred: np.ndarray, full: np.ndarray) -> tuple[np.ndarray, ...]:
        """Projection error bound, residual norms and their error bounds of centred rows.

        ``full`` is ``centred @ basis``. ``err`` bounds the distance between the float32
        coordinates (all of them) and the exact ones ``V^T x`` of the exact centred vector.
        ``res`` and ``res2`` are the norms of the parts of ``x`` outside the first ``dims``
        and outside all coordinates, from ``||x||^2`` less the squared coordinates; the
        error of that difference is at most ``eps = 1.1 (3 sqrt(p) gamma_{D+p} + 4 omega +
        4 u) ||x||^2`` (``omega``: ``V``'s departure from orthonormality), so the norms are
        within ``res_err = sqrt(eps)`` of the exact ones.
        """
        d, p = self.basis.shape
        size_sq = np.einsum("kd,kd->k", centred, centred)
        size = np.sqrt(size_sq)
        err = 1.2 * (_U32 + np.sqrt(p) * _gamma(d + 3, _U64)) * self._sigma * size
        squares = full * full
        head = squares[:, : self.dims].sum(axis=1)
        tail = squares[:, self.dims :].sum(axis=1)
        eps = 1.1 * (3.0 * np.sqrt(p) * _gamma(d + p, _U64) + 4.0 * self._ortho + 4.0 * _U64) * size_sq
        res_err = np.sqrt(eps) + 1e-300
        res = np.sqrt(np.maximum(size_sq - head, 0.0))
        res2 = np.sqrt(np.maximum(size_sq - head - tail, 0.0))
        return err, res, res_err, res2, res_err

    def query(
        self,
        queries: np.ndarray,
        bands: np.ndarray,
        seeds: np.ndarray | None = None,
        *,
        members: bool = False,
        workers: BoundedParallelSearch | None = None,
    ) -> tuple[np.ndarray, ...]:
        """Nearest bank row of every query, and how many rows may lie within each band.

        The bank is cut into as many column parts as texsyn's thread pool has workers; each
        part is searched on its own (:func:`texsyn.ops.linalg.parallel_map`) and the parts
        are joined. The answers do not depend on the cut: the row is the one of smallest
        computed distance, and the counts are only ever compared with 1 by callers that fall
        back to their reference otherwise.

        Parameters
        ----------
        queries : ndarray, shape (Q, D)
        bands : ndarray, shape (Q, B) or (Q, B, 3)
            Non-negative margins on the squared distance, per query: constants, or the
            coefficients ``(a, b, c)`` of the band ``a x + b sqrt(x) + c`` around the smallest
            squared distance ``x`` (non-negative: the band grows with ``x``).
        seeds : ndarray of int, shape (Q, S), optional
            Rows likely to be near each query (``-1``: none), for a tight first bound.
        members : bool
            Also return the rows counted in the first band.
        workers : BoundedParallelSearch, optional
            Worker threads of this index (:meth:`parallel_search`) that search the parts of the
            bank instead of texsyn's thread pool (the same answers).

        Returns
        -------
        index : ndarray of int64, shape (Q,)
            The row of smallest computed exact distance (the lowest on a tie).
        distance : ndarray, shape (Q,)
            Its computed squared distance (relative error at most ``gamma_{D+3}``).
        counts : ndarray of int64, shape (Q, B)
            For each band, at least the number of rows ``j`` with
            ``||q - b_j||^2 <= x + band(x)``, ``x = min_k ||q - b_k||^2`` (every such row is
            among those counted); ``capacity + 1`` when the query had too many candidates.
        members : ndarray of int64, shape (Q, M), only with ``members=True``
            ``members[i, :counts[i, 0]]``: the rows counted in the first band (when that count
            is at most ``M``).
        """
        queries = np.ascontiguousarray(queries, dtype=np.float64)
        n, d = queries.shape
        bands = np.asarray(bands, dtype=np.float64)
        if bands.ndim < 3:  # constant bands
            constant = bands.reshape(n, -1)
            bands = np.zeros(constant.shape + (3,))
            bands[..., 2] = constant
        bands = np.ascontiguousarray(bands)
        if seeds is None:
            seeds = np.full((n, 0), -1, dtype=np.int64)
        seeds = np.ascontiguousarray(seeds, dtype=np.int64).reshape(n, -1)
        index = np.empty(n, dtype=np.int64)
        distance = np.empty(n)
        counts = np.empty((n, bands.shape[1]), dtype=np.int64)
        gamma_x, gamma_e = self._distance_gammas()
        if workers is not None and workers.index is not self:
            raise ValueError("workers of another index (BoundedNearestIndex.parallel_search)")
        if workers is not None and workers.serves(min(n, self.block), seeds.shape[1]):
            n_parts = workers.n_parts
        else:
            n_parts = self._parts(min(n, self.block))  # (bounded_query_bytes counts this buffer)
        found = np.empty((n, n_parts * self.capacity), dtype=np.int64)
        for start in range(0, n, self.block):
            stop = min(n, start + self.block)
            self._search_block(
                queries[start:stop], seeds[start:stop], bands[start:stop], gamma_x, gamma_e,
                index[start:stop], distance[start:stop], counts[start:stop], found[start:stop], n_parts,
                workers,
            )  # fmt: skip
        if members:
            return index, distance, counts, found
        return index, distance, counts

    def _parts(self, queries: int) -> int:
        """Parts of the bank searched in parallel: one per worker, of at least 1024 rows, when a
        block of ``queries`` makes at least :data:`PARALLEL_PAIRS` (query, row) pairs."""
        return _bank_parts(queries, len(self))

    def _search_block(
        self,
        q: np.ndarray,
        seeds: np.ndarray,
        bands: np.ndarray,
        gamma_x: float,
        gamma_e: float,
        index: np.ndarray,
        distance: np.ndarray,
        counts: np.ndarray,
        members: np.ndarray,
        n_parts: int,
        workers: BoundedParallelSearch | None = None,
    ) -> None:
        """:meth:`query` of one block of queries, the bank cut into ``n_parts`` parts searched in
        parallel (by ``workers`` when they serve this many parts, else by
        :func:`~texsyn.ops.linalg.parallel_map`)."""
        k, m = len(self), q.shape[0]
        edges = _part_edges(k, n_parts)
        centred = q - self.mean
        full = centred @ self.basis
        dim, coords = self.basis.shape
        served = workers is not None and n_parts == workers.n_parts and workers.serves(m, seeds.shape[1])
        buffers = (
            workers.buffers  # type: ignore[union-attr]
            if served
            else _SearchBuffers(
                m, n_parts, self.dims + 1, coords - self.dims, 0, 0, self.capacity, self.chunk
            )
        )
        (proj32, q_ext, band, terms, best_j, best_x, upper, keep_j, keep_x, kept, overflow) = buffers.views(m)
        overflow[...] = False
        if served:  # the workers read the queries and seeds from their buffers
            q, seeds = buffers.copy_in(q, seeds)
        # the query's side of the bounds (:meth:`_side_terms`, the same formulas; rows of
        # terms: q_sq, l_err, q_err, q_res, q_res_err, q_res2, q_res2_err), and the seeds,
        # once: their rows are kept by part 0, their bound starts every part
        _bounded_prepare(
            centred, full, self.dims, _gamma(self.dims + 4, _U32), self._proj_max,
            1.2 * (_U32 + np.sqrt(coords) * _gamma(dim + 3, _U64)) * self._sigma,
            1.1 * (3.0 * np.sqrt(coords) * _gamma(dim + coords, _U64) + 4.0 * self._ortho + 4.0 * _U64),
            bands, proj32, q_ext, terms, band,
            q, self.bank, seeds, gamma_x, best_j, best_x, upper, keep_j, keep_x, kept,
        )  # fmt: skip
        sgemm = cblas_sgemm()

        def search_part(p: int) -> None:
            lo, hi = edges[p], edges[p + 1]
            if sgemm is not None:  # one compiled call, the products included
                _search_part(
                    sgemm, lo, hi, self.chunk, proj32, self._proj32_t, buffers.gram[p], q, self.bank,
                    seeds, terms, q_ext, self._b_res, self._b_res2, self._b_ext, self._b_errors,
                    self._sigma, gamma_x, gamma_e, band, best_j[p], best_x[p], upper[p], keep_j[p],
                    keep_x[p], kept[p], overflow[p],
                )  # fmt: skip
                return
            q_sq, l_err, q_err, q_res, q_res_err, q_res2, q_res2_err = terms
            for c0 in range(lo, hi, self.chunk):
                c1 = min(hi, c0 + self.chunk)
                _bounded_chunk(
                    proj32 @ self._proj32_t[:, c0:c1], c0, q, self.bank, seeds, q_sq, q_err, l_err,
                    q_res, q_res_err, q_ext, q_res2, q_res2_err, self._b_res, self._b_res2, self._b_ext,
                    self._b_errors,
                    self._sigma, gamma_x, gamma_e, band, best_j[p], best_x[p], upper[p], keep_j[p],
                    keep_x[p], kept[p], overflow[p],
                )  # fmt: skip

        if served:
            workers.run(m, search_part)  # type: ignore[union-attr]
        else:
            parallel_map(search_part, range(n_parts))
        _bounded_merge(
            best_j, best_x, keep_j, keep_x, kept, overflow, gamma_x, bands, index, distance, counts, members
        )  # fmt: skip

    def parallel_search(self, queries: int, seeds: int) -> BoundedParallelSearch:
        """Workers for many :meth:`query` calls of up to ``queries`` queries with ``seeds`` seeds
        each (a context manager, passed as ``query(..., workers=...)``;
        :class:`BoundedParallelSearch`)."""
        return BoundedParallelSearch(self, queries, seeds)


def _part_edges(rows: int, n_parts: int) -> list[int]:
    """The first bank row of every part (multiples of 16), then ``rows``."""
    return [16 * (rows * p // (16 * n_parts)) for p in range(n_parts)] + [rows]


class _SearchBuffers:
    """The arrays of a :class:`BoundedNearestIndex` search of at most ``queries`` queries, the
    bank cut in ``n_parts`` parts, each a flat buffer whose first values hold the arrays of a
    block of ``m`` queries (:meth:`views`): the same buffers serve blocks of every size, so
    that a part worker can stay in one compiled call (:class:`BoundedParallelSearch`).
    ``width``: values of a projected query (the projection and 1), ``n_ext``: its next
    coordinates; ``n_seeds`` and ``dim`` size the copies of the seeds and queries (0: none).
    """

    def __init__(
        self,
        queries: int,
        n_parts: int,
        width: int,
        n_ext: int,
        n_seeds: int,
        dim: int,
        capacity: int,
        chunk: int,
    ) -> None:
        self.n_parts, self.width, self.n_ext, self.n_seeds, self.dim = n_parts, width, n_ext, n_seeds, dim
        self.capacity = capacity
        self.proj32 = np.empty(queries * width, dtype=np.float32)
        self.q_ext = np.empty(queries * n_ext)
        self.band = np.empty(queries * 3)
        self.terms = np.empty(7 * queries)
        self.best_j = np.empty(n_parts * queries, dtype=np.int64)
        self.best_x = np.empty(n_parts * queries)
        self.upper = np.empty(n_parts * queries)
        self.keep_j = np.empty(n_parts * queries * capacity, dtype=np.int64)
        self.keep_x = np.empty(n_parts * queries * capacity)
        self.kept = np.empty(n_parts * queries, dtype=np.int64)
        self.overflow = np.empty(n_parts * queries, dtype=np.bool_)
        self.gram = np.empty((n_parts, queries * chunk), dtype=np.float32)  # each part's products
        self.queries = np.empty(queries * dim)
        self.seeds = np.empty(queries * n_seeds, dtype=np.int64)

    def views(self, m: int) -> tuple[np.ndarray, ...]:
        """``proj32 (m, width)``, ``q_ext (m, n_ext)``, ``band (m, 3)``, ``terms (7, m)``, and the
        parts' state: ``best_j, best_x, upper (P, m)``, ``keep_j, keep_x (P, m, capacity)``,
        ``kept, overflow (P, m)``."""
        p, c = self.n_parts, self.capacity
        return (
            self.proj32[: m * self.width].reshape(m, self.width),
            self.q_ext[: m * self.n_ext].reshape(m, self.n_ext),
            self.band[: 3 * m].reshape(m, 3),
            self.terms[: 7 * m].reshape(7, m),
            self.best_j[: p * m].reshape(p, m),
            self.best_x[: p * m].reshape(p, m),
            self.upper[: p * m].reshape(p, m),
            self.keep_j[: p * m * c].reshape(p, m, c),
            self.keep_x[: p * m * c].reshape(p, m, c),
            self.kept[: p * m].reshape(p, m),
            self.overflow[: p * m].reshape(p, m),
        )

    def copy_in(self, queries: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The queries and seeds copied to the buffers, as ``(m, dim)`` and ``(m, n_seeds)`` views."""
        m = queries.shape[0]
        q = self.queries[: m * self.dim].reshape(m, self.dim)
        q[...] = queries
        s = self.seeds[: m * self.n_seeds].reshape(m, self.n_seeds)
        s[...] = seeds
        return q, s


#: (query, row) pairs of a block from which :class:`BoundedParallelSearch`'s workers take
#: parts of the bank: their hand-over costs a few microseconds, not the 0.1 ms of a woken
#: thread (:data:`PARALLEL_PAIRS`); level 1 of Wei and Levoy's default 128x128 exemplar (26
#: queries against 4096 rows) is cut in two
WORKER_PAIRS = 1 << 15
#: reads of its control word a part worker makes without a job before it sleeps, offering
#: its core to other threads every :data:`_READS_PER_YIELD` reads (0.85 ms on the benchmark
#: machine: longer than the caller's work between two wavefronts, 0.1-0.2 ms). Measured
#: there (``docs/methods/wei_levoy.md``, "Part workers"): without the offers, workers
#: spinning as long took 10 % more time from a command beside a busy process than the
#: thread pool did; with them, none
SPIN_READS = 1 << 18


class BoundedParallelSearch:
    """Worker threads that search parts of a :class:`BoundedNearestIndex`'s bank for a caller
    making many small queries (Wei and Levoy's wavefronts: one query of about 50 rows every
    millisecond), handed their jobs through memory rather than woken each time.

    Handing a part to a sleeping thread costs about 0.1 ms on a virtual machine (its core is
    woken, then the GIL changes hands), as much as a tenth of the search it runs. Here each
    worker (one per part beyond the first, which the caller's thread searches) stays in a
    compiled loop without the GIL (:func:`_part_worker`): it reads its control word until a
    job is posted, searches its rows (the float32 products through NumPy's ``cblas_sgemm``,
    :func:`_search_part`) in buffers shared with the caller (:class:`_SearchBuffers`), and
    posts the job done; after :data:`SPIN_READS` reads without a job (about a millisecond,
    offering its core to other threads every few reads: ``sched_yield``) it sleeps until the next one. A part whose worker has not claimed it when the caller is
    done with part 0 is searched by the caller (:meth:`run`): where other processes keep the
    cores busy, a worker the system does not run costs no wait. The answers are the same rows
    as without the workers (the parts are the same, and every part's answer is proven;
    ``tests/test_ops_bounded_search.py``).

    A context manager: the threads start on entry and are stopped and joined on exit (also on
    an error, after the job in progress); it may be entered again after an exit, and one
    thread at a time queries through it. Blocks of another number of parts (too few pairs:
    :data:`WORKER_PAIRS`), of more queries than ``queries`` or of another number of seeds
    are searched as without workers. Where NumPy's ``cblas_sgemm`` is not found
    (:func:`texsyn.ops.linalg.cblas_sgemm`) or one part would do, there are no workers.

    Parameters
    ----------
    index : BoundedNearestIndex
    queries : int
        The most queries of a block that the workers serve (at most the index's ``block``).
    seeds : int
        Seeds per query of the blocks they serve.
    """

    def __init__(self, index: BoundedNearestIndex, queries: int, seeds: int) -> None:
        self.index = index
        self.queries = max(1, min(int(queries), index.block))
        self.n_seeds = int(seeds)
        self.n_parts = _bank_parts(self.queries, len(index), WORKER_PAIRS)
        self.sgemm = cblas_sgemm()
        self.pause = os_yield()
        self.active = self.n_parts > 1 and self.sgemm is not None and self.pause is not None
        self._threads: list[threading.Thread] = []
        self._wake: list[threading.Event] = []
        self._errors: list[BaseException] = []
        self._job = 0
        if not self.active:
            return
        dim, coords = index.basis.shape
        self.buffers = _SearchBuffers(
            self.queries, self.n_parts, index.dims + 1, coords - index.dims, self.n_seeds, dim,
            index.capacity, index.chunk,
        )  # fmt: skip
        self._control = np.zeros((self.n_parts - 1, _CONTROL_WORDS), dtype=np.int64)
        self._sleeping = np.zeros(self.n_parts - 1, dtype=np.bool_)
        self._claimed = np.zeros(self.n_parts - 1, dtype=np.bool_)

    def serves(self, m: int, n_seeds: int) -> bool:
        """Whether the workers search blocks of ``m`` queries with ``n_seeds`` seeds (in
        :attr:`n_parts` parts): not too many queries, enough (query, row) pairs
        (:data:`WORKER_PAIRS`), the seeds they were made for."""
        return (
            self.active
            and bool(self._threads)
            and m <= self.queries
            and m * len(self.index) >= WORKER_PAIRS
            and n_seeds == self.n_seeds
        )

    def __enter__(self) -> BoundedParallelSearch:
        if self.active:
            if self._threads:
                raise RuntimeError("the search workers are running already")
            self._control[...] = 0  # (entered again after an exit: its stop words were set)
            self._wake, self._errors, self._job = [], [], 0
            try:
                for w in range(self.n_parts - 1):
                    self._wake.append(threading.Event())
                    thread = threading.Thread(target=self._serve, args=(w,), name="texsyn-part", daemon=True)
                    thread.start()
                    self._threads.append(thread)
            except BaseException:  # (no thread for the next one: stop those started)
                self.__exit__(None, None, None)
                raise
        return self

    def __exit__(self, *exc_info) -> None:
        if self._threads:
            _post_stop(self._control)
        for w in range(len(self._threads)):
            self._wake[w].set()
        for thread in self._threads:
            thread.join()
        self._threads = []

    def _serve(self, w: int) -> None:
        """A worker thread: the compiled loop, and sleeps between its runs."""
        index = self.index
        b = self.buffers
        gamma_x, gamma_e = index._distance_gammas()
        part = w + 1
        edges = _part_edges(len(index), self.n_parts)
        control = self._control[w]
        try:
            while not _part_worker(
                control, SPIN_READS, self.pause, self.sgemm, part, self.n_parts, self.n_seeds, edges[part],
                edges[part + 1], index.chunk, b.proj32, index._proj32_t, b.gram[part], b.queries,
                index.bank, b.seeds, b.terms, b.q_ext, index._b_res, index._b_res2, index._b_ext,
                index._b_errors, index._sigma, gamma_x, gamma_e, b.band, b.best_j, b.best_x, b.upper,
                b.keep_j, b.keep_x, b.kept, b.overflow,
            ):  # fmt: skip
                self._wake[w].wait()
                self._wake[w].clear()
        except BaseException as error:  # reported to the caller by run()
            self._errors.append(error)

    def run(self, m: int, search_part: Callable[[int], None]) -> None:
        """Post a job of ``m`` queries to the workers, search part 0 with ``search_part(0)`` on
        this thread, then the parts no worker has started yet (a worker that the system has
        not run since the job was posted: another process on its core), and wait for the
        workers' parts. On an error the parts not started are dropped and the ones started
        awaited: no worker writes into the buffers after this returns or raises."""
        self._job += 1
        job = self._job
        _post_job(self._control, job, m, self._sleeping)
        for w in np.flatnonzero(self._sleeping):
            self._wake[w].set()
        try:
            search_part(0)
            _claim_parts(self._control, job, self._claimed)
            for w in np.flatnonzero(self._claimed):
                search_part(int(w) + 1)
        finally:
            _claim_parts(self._control, job, self._claimed)  # (after an error: none searches them)
            while not _await_job(self._control, job, SPIN_READS * 16):
                if self._errors:
                    raise RuntimeError("a search worker failed") from self._errors[0]
                if not all(thread.is_alive() for thread in self._threads):  # pragma: no cover
                    raise RuntimeError("a search worker stopped")
        if self._errors:  # (its parts were searched here)
            raise RuntimeError("a search worker failed") from self._errors[0]


def _bank_parts(queries: float, rows: float, pairs: int = PARALLEL_PAIRS) -> int:
    """:meth:`BoundedNearestIndex._parts`: one part per worker, of at least 1024 rows, when a
    block of ``queries`` makes at least ``pairs`` (query, row) pairs (:data:`PARALLEL_PAIRS`)."""
    if queries * rows < pairs:
        return 1
    return max(1, min(worker_count(), int(rows) // 1024))


def bounded_query_bytes(queries: float, rows: float, *, block: int = 256, capacity: int = 64) -> float:
    """Bytes of the candidates a :class:`BoundedNearestIndex` of ``rows`` rows holds while it
    answers ``queries`` queries at once: ``capacity`` int64 rows per query and bank part
    (``found``), and each part's kept rows and distances for one block (``docs/memory.md``).

    The parts are one per worker for large blocks, so the bytes grow with the workers.
    """
    parts = _bank_parts(min(queries, block), rows)
    return 8.0 * capacity * parts * queries + 16.0 * capacity * parts * min(queries, block)


def bounded_index_bytes(rows: float, dim: int, *, dims: int = 32, extra: int = 32) -> tuple[float, float]:
    """``(kept, building)`` bytes of a :class:`BoundedNearestIndex` of ``rows`` rows of ``dim`` values.

    ``kept``: the float32 projections and next coordinates, the residual norms and the
    basis (the bank itself is the caller's and not counted); ``building``: a centred copy of
    the bank (the index's, freed before :meth:`~BoundedNearestIndex.isolated` makes its
    own), its coordinates and their squares (``docs/memory.md``). A query of ``m`` rows adds a few ``m x dim``
    arrays and, per worker, ``m x chunk`` float32 products.
    """
    p = min(dims, dim)
    t = min(p + max(extra, 0), dim)
    kept = rows * (4.0 * (p + 1) + 4.0 * (t - p) + 16.0) + 8.0 * dim * (t + 1)
    building = rows * (8.0 * dim + 24.0 * t + 12.0 * p + 48.0) + 8.0 * dim * dim
    return kept, building


@jit()
def _searched_bands(queries, best, factor, bank_norm_max, rest, bands):
    """The queries still to search (``best[i] < 0``) into ``rest``, and their
    :func:`nearest_rows_band` as constant bands ``(0, 0, E)`` into ``bands``; returns their number."""
    n = 0
    for i in range(queries.shape[0]):
        if best[i] >= 0:
            continue
        size = 0.0
        for t in range(queries.shape[1]):
            size += queries[i, t] * queries[i, t]
        reach = bank_norm_max + np.sqrt(size)
        rest[n] = i
        bands[n, 0, 0] = 0.0
        bands[n, 0, 1] = 0.0
        bands[n, 0, 2] = factor * (reach * reach)
        n += 1
    return n


def nearest_rows_band(queries: np.ndarray, bank_norm_max: float) -> np.ndarray:
    """How far from the smallest distance the row :func:`nearest_rows` picks can be (squared).

    :func:`nearest_rows` picks the smallest computed ``||b||^2 - 2 q . b``; whatever order its
    products sum in, each value is within ``E = 2.2 gamma_{D+2} (max ||b|| + ||q||)^2`` of
    the true ``||q - b||^2 - ||q||^2``, so the row it picks has a true squared distance within
    ``2 E`` of the smallest.
    """
    queries = np.asarray(queries, dtype=np.float64)
    q_norm = np.sqrt(np.einsum("kd,kd->k", queries, queries))
    return _BAND_FACTOR * _gamma(queries.shape[1] + 2, _U64) * (bank_norm_max + q_norm) ** 2


@jit()
def _isolated_seeds(queries, bank, seeds, isolated, best):
    """``best[i] = seeds[i, s]`` for the first seed ``s`` whose row equals query ``i`` and is
    ``isolated`` (queries with ``best[i] >= 0`` and seeds ``-1`` are passed over)."""
    m, n_seeds = seeds.shape
    for s in range(n_seeds):
        for i in range(m):
            j = seeds[i, s]
            if j < 0 or best[i] >= 0 or not isolated[j]:
                continue
            equal = True
            for t in range(queries.shape[1]):
                if bank[j, t] != queries[i, t]:
                    equal = False
                    break
            if equal:
                best[i] = j


def nearest_rows_bounded(
    queries: np.ndarray,
    bank: np.ndarray,
    bank_norm: np.ndarray,
    index: BoundedNearestIndex,
    seeds: np.ndarray | None = None,
    isolated: np.ndarray | None = None,
    workers: BoundedParallelSearch | None = None,
) -> np.ndarray:
    """:func:`nearest_rows`, the same rows, through a :class:`BoundedNearestIndex` of ``bank``.

    The row :func:`nearest_rows` picks has a true squared distance within
        :func:`nearest_rows_band` of the smallest. Where the index proves that a single row
        lies within that band, that row is :func:`nearest_rows`'s answer; a block of queries with
        any other count (exact ties between identical rows) is answered by :func:`nearest_rows`
        itself, on the whole block, so that its products are the ones it would have computed.
        A query equal to one of its seeds whose row is ``isolated`` (no other row within the
        band: :meth:`BoundedNearestIndex.isolated` of :func:`nearest_rows_band` of the bank
        itself) needs no search.

        Parameters
        ----------
        queries : ndarray, shape (Q, D)
        bank : ndarray, shape (K, D)
            The rows ``index`` was built on.
        bank_norm : ndarray, shape (K,)
            ``np.sum(bank * bank, axis=1)``, as :func:`nearest_rows` takes it.
        index : BoundedNearestIndex
        seeds : ndarray of int, shape (Q, S), optional
            Likely rows, passed to :meth:`BoundedNearestIndex.query`.
        isolated : ndarray of bool, shape (K,), optional
            The bank rows with no other row within their band.
        workers : BoundedParallelSearch, optional
            The index's part workers (:meth:`BoundedNearestIndex.parallel_search`), for a
            caller that makes many small searches.
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    n = queries.shape[0]
    best = np.full(n, -1, dtype=np.int64)
    if seeds is not None and isolated is not None:
        seeds = np.asarray(seeds, dtype=np.int64).reshape(n, -1)
        _isolated_seeds(queries, bank, np.ascontiguousarray(seeds), isolated, best)
    rest, bands = np.empty(n, dtype=np.int64), np.empty((n, 1, 3))
    count = _searched_bands(
        queries, best, _BAND_FACTOR * _gamma(queries.shape[1] + 2, _U64), index.norm_max, rest, bands
    )
    if count:
        every = count == n  # no copies when every query is searched
        rest = rest[:count]
        sub = queries if every else queries[rest]
        sub_seeds = None if seeds is None else seeds if every else seeds[rest]
        found, _, counts, members = index.query(sub, bands[:count], sub_seeds, members=True, workers=workers)
        best[rest] = found
        tied = np.flatnonzero(counts[:, 0] != 1)
        if tied.size:
            # more than one part's capacity: an overflow (capacity + 1), whatever the parts
            if np.any(counts[tied, 0] > index.capacity):
                return nearest_rows_by_column_blocks(queries, bank, bank_norm)
            best[rest[tied]] = _nearest_rows_among(
                queries, bank, bank_norm, rest[tied], [members[t, : counts[t, 0]] for t in tied]
            )
    return best


def _nearest_rows_among(
    queries: np.ndarray, bank: np.ndarray, bank_norm: np.ndarray, rows: np.ndarray, among: list[np.ndarray]
) -> np.ndarray:
    """:func:`nearest_rows`'s answer for the queries ``rows``, known to be one of ``among[i]``.

    The values ``||b||^2 - 2 q . b`` of those bank rows are computed by the very products
    :func:`nearest_rows` makes (:func:`texsyn.ops.linalg.matmul`'s tiles of the whole block
    of queries, only the tiles that hold a candidate, one column of tiles at a time), so the
    smallest one, the lowest row on a tie, is its answer: the columns are visited in
    ascending order and a later one wins only with a smaller value.
    """
    m, n = queries.shape[0], bank.shape[0]
    b = bank.T
    candidates = [np.sort(c) for c in among]
    columns = sorted({int(c) // BLOCK_COLUMNS for rows_ in candidates for c in rows_})
    tile_rows = sorted({int(i) // BLOCK_ROWS for i in rows})
    out = np.full(len(rows), -1, dtype=np.int64)
    best = np.full(len(rows), np.inf)
    with fixed_order():
        for c in columns:
            start = c * BLOCK_COLUMNS
            cols = slice(start, start + BLOCK_COLUMNS)
            if m <= BLOCK_ROWS and n <= BLOCK_COLUMNS:  # one tile: matmul makes one product
                products = queries @ b
            else:
                products = np.empty((m, min(n, start + BLOCK_COLUMNS) - start))
                for t in tile_rows:
                    r = t * BLOCK_ROWS
                    np.matmul(queries[r : r + BLOCK_ROWS], b[:, cols], out=products[r : r + BLOCK_ROWS])
            for k, (i, cand) in enumerate(zip(rows, candidates, strict=True)):
                cand = cand[(cand >= start) & (cand < start + BLOCK_COLUMNS)]
                if cand.size:
                    values = bank_norm[cand] - 2.0 * products[i, cand - start]
                    j = int(np.argmin(values))
                    if out[k] < 0 or values[j] < best[k]:
                        out[k], best[k] = cand[j], values[j]
    return out


def nearest_rows_by_column_blocks(queries: np.ndarray, bank: np.ndarray, bank_norm: np.ndarray) -> np.ndarray:
    """:func:`nearest_rows`, the same rows, holding the values of :data:`BLOCK_COLUMNS` bank
    rows at a time instead of all of them.

    Each block's values ``||b||^2 - 2 q . b`` come from the tiles :func:`nearest_rows`'s
    product makes (:func:`texsyn.ops.linalg.matmul`: one single-thread product per tile of
    :data:`BLOCK_ROWS` queries and :data:`BLOCK_COLUMNS` bank rows), so they are the same
    numbers; a later block wins only with a strictly smaller value, so a tie goes to the
    lowest row as :func:`numpy.argmin`'s does. One block at a time, on this thread (the
    fallback of :func:`nearest_rows_bounded`, rare: exact ties beyond the index's members):
    three ``(Q, BLOCK_COLUMNS)`` arrays, not ``(Q, K)`` (``docs/memory.md``, "Second round").
    """
    m, n = queries.shape[0], bank.shape[0]
    if n <= BLOCK_COLUMNS:
        return nearest_rows(queries, bank, bank_norm)

    def block_minimum(start: int) -> tuple[np.ndarray, np.ndarray]:
        stop = min(n, start + BLOCK_COLUMNS)
        b = bank[start:stop].T
        products = np.empty((m, stop - start))
        for r in range(0, m, BLOCK_ROWS):  # matmul's tiles, on this worker
            np.matmul(queries[r : r + BLOCK_ROWS], b, out=products[r : r + BLOCK_ROWS])
        values = bank_norm[None, start:stop] - 2.0 * products
        local = np.argmin(values, axis=1)
        return local + start, values[np.arange(len(local)), local]

    with fixed_order():
        best, value = block_minimum(0)
        for start in range(BLOCK_COLUMNS, n, BLOCK_COLUMNS):
            rows_, values_ = block_minimum(start)
            smaller = values_ < value
            best = np.where(smaller, rows_, best)
            value = np.where(smaller, values_, value)
    return best
