"""A proven fast path to the nearest-patch index of a patch-valued wavelet transform.

:class:`texsyn.models.patch_wavelet.PatchWaveletTransform` finds the association-field mean
of two features (Peyré 2007, section 3) as the exemplar window nearest to a glued window,
through a :class:`~texsyn.ops.search.NearestPatchIndex` per window width. For the widths
whose windows are their own descriptors, :class:`FastSearch` returns the index's answers
without screening every window: coherent pairs from isolation proofs, the other pairs through
a :class:`~texsyn.ops.search.BoundedNearestIndex` whose counts prove that the index would
answer the same, and the few it cannot prove through the index itself
(``docs/methods/patch_wavelet.md``, "Performance").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..ops.linalg import BLOCK_COLUMNS, BLOCK_ROWS, matmul
from ..ops.search import BoundedNearestIndex, NearestPatchIndex

if TYPE_CHECKING:
    from .patch_wavelet import ExemplarWindows, PatchWaveletTransform

__all__ = [
    "FAST_SEARCH_DIMENSION",
    "FAST_SEARCH_POSITIONS",
    "PROVEN_CHUNK_VALUES",
    "PROVEN_PAIRS",
    "TWINNED_WINDOWS",
    "FastSearch",
    "index_answers",
    "proven_mean_features",
    "rows_independent",
]

#: widths whose descriptors are the windows themselves (no block means) and have at most this
#: many entries get a proven fast search next to their nearest-patch index (:class:`FastSearch`)
FAST_SEARCH_DIMENSION = 256
#: ... and at least this many exemplar positions (below, the plain search is cheap), unless
#: more than this share of the windows have a near twin
FAST_SEARCH_POSITIONS = 1024
TWINNED_WINDOWS = 0.01
#: descriptor values of the glued windows a fast search makes at once
PROVEN_CHUNK_VALUES = 2**20
#: pairs of features whose coherence a fast search checks at once
PROVEN_PAIRS = 2**16


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


_U64 = 2.0**-53
_U32 = 2.0**-24


def _gamma(n: float, u: float) -> float:
    """Higham's ``gamma_n = n u / (1 - n u)``."""
    return n * u / (1.0 - n * u)


def rows_independent(index: NearestPatchIndex, rows: np.ndarray) -> bool:
    """Whether this BLAS gives every row of the index's products the same bits in any batch.

    The fast search answers most queries itself and hands the few it cannot prove to the
    index in batches other than the ones the plain search would have formed; that changes
    no byte only if a row's float32 products (whole tiles of columns, and the last, shorter
    one) and float64 re-ranking do not depend on the other rows of the batch, as long as the
    batch has two rows or more (a lone row keeps the single-row product of the plain
    search). Checked once per index, on its own rows.
    """
    q = rows[:BLOCK_ROWS]
    q32 = (q - index.mean).astype(np.float32)
    k = index._bank32.shape[0]
    widths = {min(k, BLOCK_COLUMNS), k % BLOCK_COLUMNS} - {0}
    spread = q[:, None, :] - rows[: index.candidates][None]
    ranked = np.einsum("qkd,qkd->qk", spread, spread)
    for width in widths:
        bank32 = index._bank32[k - width :].T
        full = matmul(q32, bank32)
        for m in (2, 3, 5, 8, 17, 31, 64, 85, 129, 200):
            if m < q.shape[0] and not np.array_equal(matmul(q32[:m], bank32), full[:m]):
                return False
    for m in (2, 3, 5, 8, 17, 31, 64, 85, 129, 200):
        part = np.ascontiguousarray(spread[:m])
        if m < q.shape[0] and not np.array_equal(np.einsum("qkd,qkd->qk", part, part), ranked[:m]):
            return False
    return True


class FastSearch:
    """A proven fast path to a width's :class:`~texsyn.ops.search.NearestPatchIndex`.

    ``NearestPatchIndex.query`` ranks every exemplar window by a float32 score, re-ranks its
    ``candidates`` best by their float64 distance and returns the nearest of those (the
    lowest position on a tie). Its float32 score of a window is within
    ``e = gamma32_{D+3} (||q - m|| + max ||b - m||)^2 / 2`` (``m``: the bank mean) of half
    the squared distance between the float32-rounded centred vectors, and these are within
    ``delta = u32 (||q - m|| + max ||b - m||)`` of the exact vectors, so a window can rank
    before the nearest one only if its squared distance is within
    ``band(x) = 2 Delta sqrt(x) + Delta^2``, ``Delta = 2 delta + 2 sqrt(e)``, of the smallest
    ``x``; its float64 distances are within ``gamma_{D+2}`` (relative) of the exact ones.
    When at most ``candidates`` windows lie within ``band`` (the nearest is then among the
    re-ranked ones) and only one within ``3 gamma_{D+2} x`` (no other can win the re-ranking),
    the nearest window is the index's answer: :class:`~texsyn.ops.search.BoundedNearestIndex`
    finds it and proves both counts. ``isolated[k]``, no other window within ``band(0)`` of
    the window of position ``k``, is that proof for a query equal to that window (no search
    needed), which is what the association field's mean of two coherent features is.

    Parameters
    ----------
    index : NearestPatchIndex
        The width's plain index (its mean and candidates).
    bank : ndarray, shape (K, D)
        The descriptors of every exemplar position (the index's rows).
    """

    def __init__(self, index: NearestPatchIndex, bank: np.ndarray):
        self.candidates = index.candidates
        self.mean = index.mean
        self.search = BoundedNearestIndex(bank)
        centred = bank - self.mean
        self.centred_max = float(np.sqrt(np.max(np.einsum("kd,kd->k", centred, centred))))
        del centred
        # no other window within the ranking band of a window itself (x = 0: the band's constant);
        # None (no fast search) when many windows have near twins, whose queries the fast
        # search could not prove (a flat or binary exemplar)
        isolated = self.search.isolated(self.bands(bank)[:, 0, 2], limit=int(TWINNED_WINDOWS * len(bank)))
        self.isolated: np.ndarray | None = None if isolated is None else _read_only(isolated)

    def bands(self, queries: np.ndarray) -> np.ndarray:
        """``(Q, 2, 3)``: the float32 ranking band and the float64 tie band of every query."""
        d = queries.shape[1]
        centred = queries - self.mean
        size = 1.02 * (np.sqrt(np.einsum("kd,kd->k", centred, centred)) + self.centred_max)
        e = 0.5 * _gamma(d + 3, _U32) * size**2
        delta = 2.0 * _U32 * size + 2.0 * np.sqrt(e)
        bands = np.zeros((queries.shape[0], 2, 3))
        bands[:, 0, 1] = 2.0 * delta
        bands[:, 0, 2] = delta**2
        bands[:, 1, 0] = 3.1 * _gamma(d + 2, _U64)
        bands[:, 1, 2] = 1e-300
        return bands

    def proven(self, counts: np.ndarray) -> np.ndarray:
        """Queries whose nearest window is the index's answer, from :meth:`query`'s counts."""
        return (counts[:, 0] <= self.candidates) & (counts[:, 1] == 1)

    def query(self, queries: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest window of every query (positions in C order) and the counts of its bands."""
        best, _, counts = self.search.query(queries, self.bands(queries), seeds)
        return best, counts

    @classmethod
    def for_widths(cls, windows: ExemplarWindows, indexes: dict) -> dict:
        """``{width: FastSearch}`` for the widths of ``indexes`` (``{width: NearestPatchIndex}``) that get one."""
        built = {width: cls.build(windows, index, width) for width, index in indexes.items()}
        return {width: fast for width, fast in built.items() if fast is not None}

    @staticmethod
    def eligible(windows: ExemplarWindows, width: int) -> bool:
        """Whether ``width`` may get a fast search: its windows are their own descriptors, of at
        most :data:`FAST_SEARCH_DIMENSION` values, over at least :data:`FAST_SEARCH_POSITIONS`
        positions (:meth:`build` then still checks the BLAS and the twins)."""
        b, _ = windows.layout(width)
        h, w = windows.shape
        return b == 1 and windows.dimension(width) <= FAST_SEARCH_DIMENSION and h * w >= FAST_SEARCH_POSITIONS

    @classmethod
    def build(
        cls, windows: ExemplarWindows, index: NearestPatchIndex, width: int, bank: np.ndarray | None = None
    ) -> FastSearch | None:
        """The fast search of a width whose windows are their own descriptors, if it pays.

        ``None`` for wide or few windows (:meth:`eligible`), for a BLAS whose products depend
        on the batch (:func:`rows_independent`) and for windows with many near twins
        (:data:`TWINNED_WINDOWS`). ``bank``: the descriptors of every position
        (:meth:`ExemplarWindows.all_descriptors`), when the caller has them already.
        """
        if not cls.eligible(windows, width):
            return None
        if bank is None:
            bank = windows.all_descriptors(width)
        if not rows_independent(index, bank):
            return None
        fast = cls(index, bank)
        return None if fast.isolated is None else fast


def proven_mean_features(
    transform: PatchWaveletTransform,
    fast: FastSearch,
    first: np.ndarray,
    second: np.ndarray,
    axis: int,
    half_distance: int,
    width: int,
) -> np.ndarray:
    """:meth:`PatchWaveletTransform.mean_features` through the width's :class:`FastSearch`: the same positions.

    The glued window of two coherent features (the second one ``2 s`` further along
    ``axis``) is the window of the position between them; when that position lies in
    the exemplar and its window is isolated, it is the answer. The other pairs are
    searched with the two half windows' positions as seeds, and the pairs the search
    cannot prove are answered by the index itself (:func:`index_answers`).
    """
    n = first.shape[0]
    h, w = transform.exemplar_shape
    ph, pw = transform.windows.period_image.shape[:2]
    shift = np.zeros(2, dtype=np.int64)
    shift[axis] = half_distance
    out = np.empty(n, dtype=np.int64)
    isolated = fast.isolated
    assert isolated is not None  # a transform keeps only fast searches with isolation proofs
    # pairs and queries taken a part at a time (a few MiB of positions, 8 MiB of float64
    # descriptors): the answers do not depend on the cut (proven ones are the index's, the
    # others are asked as the plain search would ask them, by their row among the n)
    chunk = max(1, PROVEN_CHUNK_VALUES // max(1, transform.windows.dimension(width)))
    doubtful = []
    for lo in range(0, n, PROVEN_PAIRS):
        hi = min(n, lo + PROVEN_PAIRS)
        a = np.asarray(first[lo:hi], dtype=np.int64) + shift
        bpos = np.asarray(second[lo:hi], dtype=np.int64) - shift
        ar, ac, br, bc = a[:, 0] % ph, a[:, 1] % pw, bpos[:, 0] % ph, bpos[:, 1] % pw
        fa = np.where((ar < h) & (ac < w), ar * w + ac, -1)
        fb = np.where((br < h) & (bc < w), br * w + bc, -1)
        coherent = (ar == br) & (ac == bc) & (fa >= 0)
        direct = coherent & isolated[np.maximum(fa, 0)]
        out[lo:hi][direct] = fa[direct]
        rest = np.flatnonzero(~direct)
        for start in range(0, rest.size, chunk):
            r = rest[start : start + chunk]
            queries = transform.windows.mean_descriptors(
                first[lo + r], second[lo + r], axis, half_distance, width
            )
            best, counts = fast.query(queries, np.stack([fa[r], fb[r]], axis=1))
            proven = fast.proven(counts)
            out[lo + r[proven]] = best[proven]
            doubtful.append(lo + r[~proven])
    rows = np.concatenate(doubtful) if doubtful else np.empty(0, dtype=np.int64)
    if rows.size:
        out[rows] = index_answers(
            transform,
            lambda k: transform.windows.mean_descriptors(first[k], second[k], axis, half_distance, width),
            rows,
            n,
            width,
        )
    return out


def index_answers(
    transform: PatchWaveletTransform, queries_at, rows: np.ndarray, n: int, width: int
) -> np.ndarray:
    """What :meth:`PatchWaveletTransform._nearest` would answer for the queries ``rows`` of ``n``, computed for those only.

    ``_nearest`` cuts its ``n`` queries into chunks, the index cuts chunks into
    blocks and :func:`~texsyn.ops.linalg.matmul` cuts blocks into tiles of
    :data:`~texsyn.ops.linalg.BLOCK_ROWS` rows. A query alone in its tile had a
    single-row product; the others had several rows, and a row's products do not depend
    on the other rows (:func:`_rows_independent`, checked when the fast path was built).
    So the lone ones are asked alone again and the others together, in batches of one
    tile (a batch of one row gets a copy of it, so that no tile has a single row).
    """
    index = transform.index(width)
    chunk = max(1, 2**22 // max(1, transform.windows.dimension(width)))
    offset = rows % chunk
    chunk_size = np.minimum(chunk, n - (rows - offset))
    in_block = offset % index.block
    block_size = np.minimum(index.block, chunk_size - (offset - in_block))
    tile_size = np.minimum(BLOCK_ROWS, block_size - (in_block - in_block % BLOCK_ROWS))
    out = np.empty(rows.size, dtype=np.int64)
    alone = tile_size == 1
    for lone in np.flatnonzero(alone):
        out[lone] = index.query(queries_at(rows[lone : lone + 1]))[0][0]
    together = np.flatnonzero(~alone)
    for start in range(0, together.size, BLOCK_ROWS):
        batch = together[start : start + BLOCK_ROWS]
        queries = queries_at(rows[batch])
        if queries.shape[0] % BLOCK_ROWS == 1:  # no single-row tile: repeat the last query
            queries = np.concatenate([queries, queries[-1:]])
        out[batch] = index.query(queries)[0][: batch.size]
    return out
