"""Histogram matching and 1-D optimal transport.

Matching the histogram of ``n`` values to a reference of ``N_y`` values is the 1-D optimal
transport between their empirical measures: the sorted values are mapped monotonically
(Peyré 2008, eq. 4; Tartavel et al. 2013, section 3). When the sizes differ the
target of each rank is the barycentre of the reference mass the monotone plan sends to it
(:func:`hist_target`), so any output size works (``docs/methods/heeger_bergen.md``).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from .allocator import scratch_empty
from .color import ColorPCA
from .jit import jit
from .linalg import parallel_map, worker_count
from .ranks import compiled_ranks, order_by_key, scatter_by_key, sorted_keys

__all__ = [
    "HistogramMatcher",
    "hist_target",
    "hist_target_rows",
    "match_sorted",
    "match_sorted_rows",
    "match_histogram",
    "match_histogram_pca",
    "transport_energy",
]


def hist_target(n: int, reference: np.ndarray, *, method: str = "ot", presorted: bool = False) -> np.ndarray:
    """The ``n`` sorted target values that impose the distribution of ``reference``.

    Parameters
    ----------
    n : int
        Number of values to produce (the size of the vector being matched).
    reference : ndarray
        Reference values (any shape, flattened), of any length ``N_y``.
    method : {'ot', 'interp'}
        ``'ot'``: exact 1-D optimal transport target, the barycentric projection of the
        monotone plan between the uniform measures on ``n`` and ``N_y`` points;
        for ``n == N_y`` it is ``sort(reference)``. ``'interp'``: quantile interpolation.
    presorted : bool
        Whether ``reference`` is already sorted ascending (skips a sort).

    Returns
    -------
    ndarray, shape (n,), ascending.
    """
    ys = np.asarray(reference, dtype=np.float64).ravel()
    if not presorted:
        ys = np.sort(ys)
    ny = ys.size
    if ny == 0:
        raise ValueError("reference must contain at least one value")
    if n == ny:
        return ys.copy()
    if method == "interp":
        return np.interp((np.arange(n) + 0.5) / n, (np.arange(ny) + 0.5) / ny, ys)
    if method != "ot":
        raise ValueError(f"method must be 'ot' or 'interp', got {method!r}")
    cums = np.concatenate([[0.0], np.cumsum(ys)]) / ny

    def integral(t: np.ndarray) -> np.ndarray:
        k = np.minimum(np.floor(t * ny).astype(np.int64), ny - 1)
        return cums[k] + (t - k / ny) * ys[k]

    edges = integral(np.arange(n + 1) / n)
    return n * np.diff(edges)


def hist_target_rows(n: int, references_sorted: np.ndarray) -> np.ndarray:
    """:func:`hist_target` (``method='ot'``, ``presorted=True``) of every row of ``references_sorted``.

    ``(R, N_y)`` ascending rows give ``(R, n)`` ascending targets, each row the bytes of
    :func:`hist_target` of that row. Once numba is loaded (``docs/performance.md``,
    "Start-up") the rows are computed by a compiled kernel, without NumPy's temporaries:
    about ten times faster at 256x256 and more for larger outputs, whose temporaries no
    longer fit the caches (the same expressions in the same order, so the same bytes).
    """
    ys = np.ascontiguousarray(np.atleast_2d(references_sorted), dtype=np.float64)
    rows, ny = ys.shape
    if ny == 0:
        raise ValueError("reference must contain at least one value")
    if n == ny or "numba" not in sys.modules:
        return np.stack([hist_target(n, row, presorted=True) for row in ys]) if rows else np.empty((0, n))
    cums = np.empty((rows, ny + 1))
    cums[:, 0] = 0.0
    np.cumsum(ys, axis=1, out=cums[:, 1:])  # each row's sequential sum, as np.cumsum of the row
    cums /= ny
    out = scratch_empty((rows, n))  # kept by an iterative method: ordinary pages (ops.allocator)
    chunks = (
        np.array_split(np.arange(rows), min(rows, worker_count()))
        if rows * n >= 1 << 20
        else [np.arange(rows)]
    )
    parallel_map(lambda r: _ot_targets(ys, cums, n, out, r[0], r[-1] + 1), [c for c in chunks if c.size])
    return out


@jit(nogil=True)
def _ot_targets(ys, cums, n, out, start, stop):
    """Rows ``start .. stop - 1`` of :func:`hist_target_rows`: ``hist_target``'s ``integral``
    at ``t = j / n`` and its differences, scaled by ``n``, in the same floating-point order.
    The index ``k`` and the offset ``t - k / N_y`` of each ``t`` are the same for every row:
    computed once."""
    ny = ys.shape[1]
    index = np.empty(n + 1, dtype=np.int64)
    offset = np.empty(n + 1)
    for j in range(n + 1):
        t = j / n
        k = min(np.int64(math.floor(t * ny)), ny - 1)
        index[j] = k
        offset[j] = t - k / ny
    for i in range(start, stop):
        previous = 0.0
        for j in range(n + 1):
            k = index[j]
            edge = cums[i, k] + offset[j] * ys[i, k]
            if j > 0:
                out[i, j - 1] = n * (edge - previous)
            previous = edge


def match_sorted(
    values: np.ndarray, target_sorted: np.ndarray, *, rng: np.random.Generator | None = None
) -> np.ndarray:
    """Give ``values`` the sorted ``target_sorted`` values in the order of their ranks.

    The result is the orthogonal projection of ``values`` onto the permutations of the target
    (Peyre 2008, eq. 4). Ties are broken by position, or at random when ``rng``
    is given.
    """
    x = np.asarray(values)
    flat = x.ravel()
    if flat.size != target_sorted.size:
        raise ValueError(f"need {flat.size} target values, got {target_sorted.size}")
    if rng is None:
        return match_sorted_rows(flat[None], np.asarray(target_sorted)[None])[0].reshape(x.shape)
    order = _rank_with_random_ties(flat, rng.random(flat.size))
    out = np.empty(flat.size, dtype=np.float64)
    out[order] = target_sorted
    return out.reshape(x.shape)


def _rank_with_random_ties(values: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """``np.lexsort((keys, values))``: the order of ``values``, equal values ordered by ``keys``
    and then by position, computed with one sort and a ``lexsort`` of the ties only.

    The permutation is fully determined (equal values sort by ``keys``, equal keys by
    position), so it is the same permutation ``lexsort`` gives, five to ten times faster on
    continuous data where ties are rare. NaNs sort last and tie with each other, as in
    NumPy's sorts. ``values`` and ``keys`` may also be ``(B, N)`` rows, each ranked alone.
    """
    rows = np.ascontiguousarray(np.atleast_2d(values), dtype=np.float64)
    tie_keys = np.atleast_2d(keys)
    if compiled_ranks(rows.size):  # by value, then position; the rows without ties are done
        keys_sorted, shift = sorted_keys(rows)
        order, tied = order_by_key(rows, keys_sorted, shift)
    else:  # equal values in any order: the ties are sorted below anyway
        order, tied = np.argsort(rows, axis=-1), np.ones(rows.shape[0], dtype=bool)
    for i in np.flatnonzero(tied):
        _sort_ties(rows[i], tie_keys[i], order[i])
    return order.reshape(np.shape(values))


def _sort_ties(values: np.ndarray, keys: np.ndarray, order: np.ndarray) -> None:
    """Reorder, in place, each run of equal values of ``order`` by ``keys``, then position."""
    ranked = values[order]
    equal_next = ranked[1:] == ranked[:-1]
    nan = np.isnan(ranked)
    if nan[-1:].any():  # NumPy's sorts put NaNs last and treat them as equal
        equal_next |= nan[1:] & nan[:-1]
    if not equal_next.any():
        return
    tied = np.zeros(values.size, dtype=bool)
    tied[1:] |= equal_next
    tied[:-1] |= equal_next
    k = np.flatnonzero(tied)  # each run of equal values is a run of consecutive ranks
    starts = np.ones(k.size, dtype=bool)
    starts[1:] = ~equal_next[k[1:] - 1]
    positions = order[k]
    order[k] = positions[np.lexsort((positions, keys[positions], np.cumsum(starts)))]


def match_sorted_rows(
    values: np.ndarray,
    targets_sorted: np.ndarray,
    *,
    rows: np.ndarray | None = None,
    out: np.ndarray | None = None,
    keys: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`match_sorted` for many rows at once: row ``i`` of ``values`` gets the values of
    row ``i`` of ``targets_sorted`` in the order of its ranks (ties broken by position).

    The ranks come from NumPy's vectorised ``argsort`` (rows split over the worker threads),
    whose order among equal values is then made canonical by position, so the result is
    that of a stable sort on every machine and for any thread count.

    Parameters
    ----------
    values : ndarray, shape (B, N)
    targets_sorted : ndarray, shape (T, N)
        ``T = B`` without ``rows``.
    rows : ndarray of int, shape (B,), optional
        Row ``i`` of ``values`` takes the targets of row ``rows[i]`` (no reordered copy of
        the targets is made).
    out : ndarray of float64, shape (B, N), C-contiguous, optional
        Where to write the result; it may be ``values`` itself (matched in place).
    keys : ndarray of uint64, shape (B, N), C-contiguous, optional
        Scratch space for the sort keys. An iterative method passes the same ``out`` and
        ``keys`` at every step: reused pages, instead of fresh ones the kernel has to fault
        in (``docs/performance.md``, "Memory reuse"); the result is the same.
    """
    x = np.ascontiguousarray(values, dtype=np.float64)
    t = np.ascontiguousarray(targets_sorted, dtype=np.float64)
    index = np.arange(x.shape[0]) if rows is None else np.asarray(rows, dtype=np.int64)
    if x.ndim != 2 or t.ndim != 2 or x.shape[1] != t.shape[1] or index.shape != (x.shape[0],):
        raise ValueError(
            f"values {x.shape} and targets {t.shape} must be (B, N) and (T, N) arrays, one row each"
        )
    if rows is None and t.shape[0] != x.shape[0]:
        raise ValueError(f"values {x.shape} and targets {t.shape} must be equal (B, N) arrays")
    if index.size and (index.min() < 0 or index.max() >= t.shape[0]):
        raise ValueError(f"rows must index the {t.shape[0]} target rows")
    if out is not None and (out.shape != x.shape or out.dtype != np.float64 or not out.flags.c_contiguous):
        raise ValueError(f"out must be a C-contiguous float64 array of shape {x.shape}")
    if compiled_ranks(x.size):
        sorted_rows, shift = sorted_keys(x, keys)
        return scatter_by_key(x, sorted_rows, shift, t, index, out)
    order = _argsort_rows(x)
    return _scatter_by_rank_numpy(x, order, t, index, out)


def _argsort_rows(x: np.ndarray) -> np.ndarray:
    """``argsort`` of every row, the rows split over texsyn's worker threads (NumPy releases
    the GIL while sorting). The order among equal values is arbitrary."""
    workers = min(worker_count(), x.shape[0])
    if workers <= 1 or x.size < 1 << 15:
        return np.argsort(x, axis=-1)
    chunks = np.array_split(np.arange(x.shape[0]), workers)
    return np.concatenate(parallel_map(lambda rows: np.argsort(x[rows], axis=-1), chunks))


def _scatter_by_rank_numpy(
    x: np.ndarray, order: np.ndarray, targets: np.ndarray, rows: np.ndarray, out: np.ndarray | None = None
) -> np.ndarray:
    """``out[i, order[i, k]] = targets[rows[i], k]`` after the runs of equal values (rare in
    continuous data) are put in position order by one ``lexsort`` over their elements only:
    :func:`texsyn.ops.ranks.scatter_by_key`'s result with NumPy (until numba is loaded)."""
    ranked = np.take_along_axis(x, order, axis=1)
    equal_next = ranked[:, 1:] == ranked[:, :-1]
    if equal_next.any():
        tied = np.zeros(x.shape, dtype=bool)
        tied[:, 1:] |= equal_next
        tied[:, :-1] |= equal_next
        r, k = np.nonzero(tied)  # row-major: each run's elements are consecutive
        starts = np.ones(r.size, dtype=bool)
        starts[1:] = (r[1:] != r[:-1]) | ~equal_next[r[1:], k[1:] - 1]
        positions = order[r, k]
        order = order.copy()
        order[r, k] = positions[np.lexsort((positions, np.cumsum(starts)))]
    out = np.empty_like(x) if out is None else out
    np.put_along_axis(out, order, targets[rows], axis=1)
    return out


def match_histogram(
    values: np.ndarray,
    reference: np.ndarray,
    *,
    method: str = "ot",
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Impose the histogram of ``reference`` on ``values`` (any sizes, see :func:`hist_target`).

    For equal sizes the result holds exactly the reference values, rearranged.
    """
    x = np.asarray(values, dtype=np.float64)
    return match_sorted(x, hist_target(x.size, reference, method=method), rng=rng)


class HistogramMatcher:
    """Impose fixed per-channel histograms, optionally along principal colour axes.

    The targets for ``n_values`` samples per channel are computed once (:func:`hist_target`;
    :func:`hist_target_rows`, the same bytes, when the channels' references are alike), so an
    iterative method can project at every step at the cost of one sort per channel; the
    channels are ranked together, as the rows of one :func:`match_sorted_rows` call (split
    over the worker threads; each row is ranked alone, so the bytes are those of
    :func:`match_sorted` channel by channel).

    Parameters
    ----------
    sorted_values : list of ndarray
        Ascending reference values of every channel (PCA coordinates when ``pca`` is given).
    n_values : int
        Number of samples per channel of the images to be matched.
    pca : ColorPCA, optional
        Match along these axes (:class:`texsyn.ops.color.ColorPCA`) instead of the channels themselves.
    method : {'ot', 'interp'}
    """

    def __init__(self, sorted_values, n_values: int, *, pca: ColorPCA | None = None, method: str = "ot"):
        self.pca = pca
        sizes = {np.size(values) for values in sorted_values}
        if method == "ot" and len(sizes) == 1 and 0 not in sizes:  # one row per channel, compiled
            self._stacked = hist_target_rows(n_values, np.stack([np.ravel(v) for v in sorted_values]))
        else:
            self._stacked = scratch_empty((len(sorted_values), n_values))
            for c, values in enumerate(sorted_values):
                self._stacked[c] = hist_target(n_values, values, method=method, presorted=True)
        self.targets = list(self._stacked)

    def __call__(
        self,
        image: np.ndarray,
        rng: np.random.Generator | None = None,
        *,
        overwrite: bool = False,
        keys: np.ndarray | None = None,
    ) -> np.ndarray:
        """Matched copy of ``image`` (shape ``(..., C)``); ties broken at random with ``rng``.

        ``overwrite=True`` lets the result be written into ``image`` itself (when its channels
        are contiguous rows, as the ``(C, H, W)`` planes of
        :class:`texsyn.transforms.steerable.SteerablePyramid`, no PCA and no ``rng``), and
        ``keys``, a C-contiguous ``(C, N)`` uint64 array, is scratch for the sort keys: an
        iterative method passes them at every step instead of faulting in fresh pages (issue
        20: 46 -> 30 ns a value on rows of 4M values). Same bytes either way
        (:func:`match_sorted_rows`).
        """
        coords = self.pca.forward(image) if self.pca is not None else np.asarray(image, dtype=np.float64)
        flat = coords.reshape(-1, coords.shape[-1])
        if rng is None:  # match_sorted of every channel, the channels ranked as rows together
            if flat.shape[0] != self._stacked.shape[1]:
                raise ValueError(f"need {flat.shape[0]} target values, got {self._stacked.shape[1]}")
            rows = flat.T
            in_place = overwrite and self.pca is None and rows.flags.c_contiguous and rows.flags.writeable
            out = match_sorted_rows(rows, self._stacked, out=rows if in_place else None, keys=keys)
            out = out.T.reshape(coords.shape)
            return self.pca.inverse(out) if self.pca is not None else out
        # match_sorted(..., rng) of every channel, ranked together
        if any(target.size != flat.shape[0] for target in self.targets):
            raise ValueError(f"need {flat.shape[0]} target values per channel")
        ties = np.stack([rng.random(flat.shape[0]) for _ in self.targets])
        order = _rank_with_random_ties(flat.T, ties)
        out = np.empty_like(flat)
        for c, target in enumerate(self.targets):
            out[order[c], c] = target
        out = out.reshape(coords.shape)
        return self.pca.inverse(out) if self.pca is not None else out


def match_histogram_pca(
    image: np.ndarray,
    reference: np.ndarray,
    *,
    pca: ColorPCA | None = None,
    method: str = "ot",
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Colour histogram matching along the reference's principal colour axes.

    Parameters
    ----------
    image, reference : ndarray, shape (..., C)
    pca : ColorPCA, optional
        Axes computed once from the reference (recomputed when omitted).
    """
    pca = ColorPCA(reference) if pca is None else pca
    ref = pca.forward(reference).reshape(-1, np.shape(reference)[-1])
    n_values = int(np.prod(np.shape(image)[:-1]))
    matcher = HistogramMatcher(
        [np.sort(ref[:, c]) for c in range(ref.shape[1])], n_values, pca=pca, method=method
    )
    return matcher(image, rng)


def transport_energy(x: np.ndarray, y: np.ndarray) -> float:
    """``N W_2^2`` between the empirical measures of ``x`` (N values) and ``y``
    (the cost of the monotone plan of :func:`hist_target`).

    For equal sizes this is ``sum((sort(x) - sort(y))^2)``.
    """
    xs = np.sort(np.asarray(x, dtype=np.float64).ravel())
    ys = np.sort(np.asarray(y, dtype=np.float64).ravel())
    n, ny = xs.size, ys.size
    b = np.unique(np.concatenate([np.arange(n + 1) / n, np.arange(ny + 1) / ny]))
    mid = 0.5 * (b[1:] + b[:-1])
    qx = xs[np.minimum((mid * n).astype(np.int64), n - 1)]
    qy = ys[np.minimum((mid * ny).astype(np.int64), ny - 1)]
    return float(n * np.sum(np.diff(b) * (qx - qy) ** 2))
