"""Sparse coding and the image step of constrained sparse synthesis (Tartavel et al. 2013).

Batch orthogonal matching pursuit and K-SVD (dictionary learning, eq. 1), the constrained
matching pursuit (section 4.2, Algorithm 2), the gradient steps of the image update and the
energy they decrease (section 4.1, eqs. 6-7), and the bicubic up-sampling between scales
(section 4.3); ``docs/methods/sparse.md``. Matrices follow the paper: patches are columns,
``P`` is ``(L, K)``, the dictionary ``D`` is ``(L, N)`` with unit-norm atoms, the codes
``W`` are ``(N, K)``.

Why this module is long: the learning (batch OMP, K-SVD and its exact rank-one update), the
constrained pursuit and the image step (gradient, energy, spectrum projection of the
low-pass reference) are the paper's two alternating half-steps and share the same matrix
conventions; split apart, each half would need the other's conventions restated.
"""

from __future__ import annotations

import functools
import heapq
from collections.abc import Callable
from typing import Literal, overload

import numpy as np
from scipy import fft as sfft
from scipy import linalg, ndimage

from .jit import jit, prange
from .linalg import BLOCK_COLUMNS, BLOCK_ROWS, fixed_order, matmul, worker_count
from .patches import as_channels, extract_patches

__all__ = [
    "batch_omp",
    "box_power",
    "constrained_matching_pursuit",
    "image_energy",
    "image_update",
    "ksvd",
    "SpectrumProjector",
    "upsample_bicubic",
]


def batch_omp(
    dictionary: np.ndarray,
    signals: np.ndarray,
    n_nonzero: int,
    *,
    gram: np.ndarray | None = None,
) -> np.ndarray:
    """Orthogonal matching pursuit of many signals at once (at most ``n_nonzero`` atoms each).

    Each step picks, for every column, the atom most correlated with its residual, then
    solves the normal equations of the selected atoms for all columns together (a stack of
    ``s x s`` systems). Works in the Gram domain: ``D^T r = D^T x - G[:, support] coef``.

    Parameters
    ----------
    dictionary : ndarray, shape (L, N)
        Unit-norm atoms as columns.
    signals : ndarray, shape (L, K)
    n_nonzero : int
        The exact l0 budget ``S`` of eq. (1).
    gram : ndarray, shape (N, N), optional
        ``D^T D`` if already computed.

    Returns
    -------
    ndarray, shape (N, K)
        Codes with at most ``n_nonzero`` non-zeros per column.

    References
    ----------
    Y. Pati, R. Rezaiifar, P. Krishnaprasad, "Orthogonal matching pursuit", 1993;
    R. Rubinstein, M. Zibulevsky, M. Elad, "Efficient implementation of the K-SVD algorithm
    using batch orthogonal matching pursuit", Technion report CS-2008-08.
    """
    d = np.asarray(dictionary, dtype=np.float64)
    x = np.asarray(signals, dtype=np.float64)
    g = np.ascontiguousarray(d.T @ d if gram is None else gram, dtype=np.float64)
    n_atoms, n_signals = d.shape[1], x.shape[1]
    n_steps = min(n_nonzero, n_atoms)
    xtd = matmul(x.T, d)  # (K, N): rows are contiguous for the per-signal argmax
    corr = np.empty_like(xtd)  # written for every signal still active after a step
    codes = np.zeros((n_atoms, n_signals))
    support = np.zeros((n_signals, n_steps), dtype=np.int64)
    active = np.ones(n_signals, dtype=bool)
    floor = 1e-12 * np.sqrt(np.maximum(np.einsum("ij,ij->j", x, x), 1e-300))
    for step in range(n_steps):
        # the atom of largest |correlation| outside the support; signals already
        # represented exactly stop growing (their residual is zero)
        scores = xtd if step == 0 else corr
        work = n_signals * n_atoms
        _rows_kernel(
            _omp_select_rows, _omp_select_parallel, n_signals, work, scores, support, step, floor, active
        )
        if not active.any():
            break
        idx = np.flatnonzero(active)
        sup = support[idx, : step + 1]
        sub_gram = g[sup[:, :, None], sup[:, None, :]]  # (k, s, s)
        rhs = xtd[idx[:, None], sup]  # (k, s)
        coef = np.linalg.solve(sub_gram, rhs[..., None])[..., 0]
        # D^T r = D^T x - G w with w sparse, and the codes of the new support
        work = idx.size * n_atoms * (step + 2)
        _rows_kernel(
            _omp_update_rows, _omp_update_parallel, idx.size, work, corr, codes, xtd, g, idx, sup, coef
        )
    return codes


#: multiply-adds from which a pursuit step runs its rows on numba's threads: below, starting
#: and stopping them costs more than it saves (and much more on a loaded machine)
_PARALLEL_ROWS_WORK = 1 << 21


def _rows_kernel(serial, parallel, n_rows: int, work: int, *args) -> None:
    """Run ``serial(*args, start, stop)`` over the rows, in parallel chunks for large ``work``.

    Each row is computed alone, so the result is the same however the rows are split.
    """
    if work >= _PARALLEL_ROWS_WORK and worker_count() > 1 and n_rows > 1:
        parallel(*args, n_rows, worker_count())
    else:
        serial(*args, 0, n_rows)


@jit()
def _omp_select_rows(corr, support, step, floor, active, start, stop):
    """One selection of :func:`batch_omp` for the active signals (rows of ``corr``) in
    ``[start, stop)``.

    ``support[i, step]`` becomes the first atom of largest ``|corr[i]|`` among those not in
    ``support[i, :step]`` (``numpy.argmax`` of the scores with the support at -1), and the
    signal stays active while that score exceeds ``floor[i]``.
    """
    n_atoms = corr.shape[1]
    score = np.empty(n_atoms)
    for i in range(start, stop):
        if not active[i]:
            continue
        for n in range(n_atoms):
            score[n] = abs(corr[i, n])
        for t in range(step):
            score[support[i, t]] = -1.0
        best = 0
        for n in range(1, n_atoms):
            if score[n] > score[best]:
                best = n
        support[i, step] = best
        active[i] = score[best] > floor[i]


@jit(parallel=True)
def _omp_select_parallel(corr, support, step, floor, active, n_rows, n_chunks):
    """:func:`_omp_select_rows` over ``n_chunks`` chunks of rows on numba's threads."""
    size = (n_rows + n_chunks - 1) // n_chunks
    for c in prange(n_chunks):
        _omp_select_rows(corr, support, step, floor, active, c * size, min(n_rows, (c + 1) * size))


@jit()
def _omp_update_rows(corr, codes, xtd, gram, idx, sup, coef, start, stop):
    """``corr[i] = xtd[i] - sum_t coef[j, t] gram[sup[j, t]]`` and column ``i`` of the codes
    ``(N, K)``, for the signals ``i = idx[j]``, ``j`` in ``[start, stop)``.

    The sum runs over the support in increasing atom order from zero, as the product of a
    sorted CSR matrix and a dense one (SciPy's ``csr_matvecs``) adds it.
    """
    n_atoms = corr.shape[1]
    size = sup.shape[1]
    total = np.empty(n_atoms)
    order = np.empty(size, dtype=np.int64)
    for j in range(start, stop):
        i = idx[j]
        for t in range(size):  # insertion sort of the support positions by atom
            k = t
            while k > 0 and sup[j, order[k - 1]] > sup[j, t]:
                order[k] = order[k - 1]
                k -= 1
            order[k] = t
        total[:] = 0.0
        for t in order:
            a = sup[j, t]
            c = coef[j, t]
            for n in range(n_atoms):
                total[n] += c * gram[a, n]
        for n in range(n_atoms):
            corr[i, n] = xtd[i, n] - total[n]
        for t in range(size):
            codes[sup[j, t], i] = coef[j, t]


@jit(parallel=True)
def _omp_update_parallel(corr, codes, xtd, gram, idx, sup, coef, n_rows, n_chunks):
    """:func:`_omp_update_rows` over ``n_chunks`` chunks of signals on numba's threads."""
    size = (n_rows + n_chunks - 1) // n_chunks
    for c in prange(n_chunks):
        _omp_update_rows(corr, codes, xtd, gram, idx, sup, coef, c * size, min(n_rows, (c + 1) * size))


@functools.cache
def _syevr(n: int) -> tuple[Callable, int, int]:
    """LAPACK's ``dsyevr`` and the workspace sizes it asks for at order ``n`` (lower triangle)."""
    driver, query = linalg.get_lapack_funcs(("syevr", "syevr_lwork"), (np.zeros((1, 1)),))
    work, iwork, info = query(n=n, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dsyevr workspace query failed ({info})")
    return driver, int(work.real), int(iwork)


def _top_eigenvector(gram: np.ndarray) -> np.ndarray:
    """The eigenvector of the largest eigenvalue of a symmetric matrix.

    The call :func:`scipy.linalg.eigh` makes for ``subset_by_index=[n - 1, n - 1]`` (``dsyevr``
    on the lower triangle, same workspace), without its per-call checks: K-SVD makes one
    per atom and iteration.
    """
    n = gram.shape[0]
    driver, lwork, liwork = _syevr(n)
    _, vec, found, _, info = driver(
        a=gram, compute_v=1, range="I", lower=1, il=n, iu=n, lwork=lwork, liwork=liwork, overwrite_a=0
    )
    if info != 0 or found != 1:
        raise np.linalg.LinAlgError(f"dsyevr failed on a {n}x{n} Gram matrix ({info})")
    return vec[:, 0]


def _small_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`texsyn.ops.linalg.matmul` ``(a, b)`` without its per-call set-up when the product
    is a single tile: then ``matmul`` computes ``a @ b`` itself, so the bytes are the same.

    The caller runs inside :func:`texsyn.ops.linalg.fixed_order` (K-SVD's atom loop, about
    17 000 calls per fit, where entering and leaving the context cost as much as the product).
    """
    if a.shape[0] <= BLOCK_ROWS and b.shape[1] <= BLOCK_COLUMNS:
        return a @ b
    return matmul(a, b)


def _rank_one(err: np.ndarray, previous: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The best rank-one approximation ``atom coeffs^T`` of ``err`` (its leading singular pair).

    Computed from the leading eigenpair of the smaller Gram matrix (``err^T err`` or
    ``err err^T``, :func:`_top_eigenvector`); the sign is
    chosen so that ``atom . previous >= 0``, which keeps the result deterministic.
    """
    rows, cols = err.shape
    if cols <= rows:
        gram = _small_product(err.T, err)
        vec = _top_eigenvector(gram)
        atom = err @ vec
        norm = float(np.linalg.norm(atom))
        if norm < 1e-12:
            return previous, np.zeros(cols)
        atom /= norm
    else:
        gram = matmul(err, err.T)
        atom = _top_eigenvector(gram).copy()
    if atom @ previous < 0:
        atom = -atom
    return atom, atom @ err


#: patches handled together by the K-SVD gather and scatter (a tile of the transposition)
_TILE = 8


@jit()
def _gather_error(residual_rows, users, codes, atom):
    """``E = R[:, users] + atom codes[users]^T`` (K-SVD's error without the atom), ``(L, |users|)``,
    from the residual stored as rows ``R^T`` (one per training patch), by tiles of patches
    (their rows and codes read once per tile)."""
    n_dims = residual_rows.shape[1]
    err = np.empty((n_dims, users.size))
    rows = np.empty(_TILE, dtype=np.int64)
    weights = np.empty(_TILE)
    for j0 in range(0, users.size, _TILE):
        width = min(_TILE, users.size - j0)
        for t in range(width):
            rows[t] = users[j0 + t]
            weights[t] = codes[rows[t]]
        for i in range(n_dims):
            a = atom[i]
            for t in range(width):
                err[i, j0 + t] = residual_rows[rows[t], i] + a * weights[t]
    return err


@jit()
def _scatter_error(residual_rows, users, err, coeffs, atom):
    """``R[:, users] = E - atom coeffs^T`` on the residual stored as rows (in place)."""
    n_dims = residual_rows.shape[1]
    rows = np.empty(_TILE, dtype=np.int64)
    weights = np.empty(_TILE)
    for j0 in range(0, users.size, _TILE):
        width = min(_TILE, users.size - j0)
        for t in range(width):
            rows[t] = users[j0 + t]
            weights[t] = coeffs[j0 + t]
        for i in range(n_dims):
            a = atom[i]
            for t in range(width):
                residual_rows[rows[t], i] = err[i, j0 + t] - a * weights[t]


@overload
def ksvd(
    patches: np.ndarray,
    n_atoms: int,
    n_nonzero: int,
    *,
    n_iterations: int = ...,
    max_training: int = ...,
    rng: np.random.Generator,
    tol: float = ...,
    update: str = ...,
    return_errors: Literal[False] = ...,
) -> np.ndarray: ...


@overload
def ksvd(
    patches: np.ndarray,
    n_atoms: int,
    n_nonzero: int,
    *,
    n_iterations: int = ...,
    max_training: int = ...,
    rng: np.random.Generator,
    tol: float = ...,
    update: str = ...,
    return_errors: Literal[True],
) -> tuple[np.ndarray, np.ndarray]: ...


@fixed_order  # the atom loop's small products call BLAS directly (_small_product)
def ksvd(
    patches: np.ndarray,
    n_atoms: int,
    n_nonzero: int,
    *,
    n_iterations: int = 20,
    max_training: int = 8000,
    rng: np.random.Generator,
    tol: float = 1e-3,
    update: str = "svd",
    return_errors: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Learn a dictionary with unit-norm atoms by K-SVD with exact S-sparse OMP coding.

    Initialisation with ``n_atoms`` distinct random patches (normalised); each iteration
    codes a fresh random subset of at most ``max_training`` patches with
    :func:`batch_omp`, then updates every atom and its coefficients by the best rank-one
    approximation of its residual restricted to the patches that use it (the leading
    singular pair, Aharon et al. 2006, section IV-B), keeping the residual up to date; an
    unused atom is replaced by the worst-approximated patch.

    Parameters
    ----------
    patches : ndarray, shape (L, K0)
    n_atoms : int
    n_nonzero : int
    n_iterations : int
        At most this many iterations.
    max_training : int
    rng : numpy.random.Generator
    tol : float
        Convergence: stop when the relative coding error ``||X - D W||^2 / ||X||^2`` (after
        an iteration's OMP step) has not gone below ``(1 - tol)`` times its best value for 3
        iterations in a row. ``0`` runs every iteration.
    update : {'svd', 'power'}
        'svd': the exact K-SVD atom update; 'power': one power-iteration step (the
        "approximate K-SVD" of texsyn 0.2, kept for comparisons).
    return_errors : bool
        Also return the relative coding error of every iteration run (the energy of eq. 1
        on that iteration's training subset, before its dictionary update).

    Returns
    -------
    ndarray, shape (L, n_atoms), unit-norm columns; with ``return_errors`` also an ndarray
    of the errors per iteration.

    References
    ----------
    M. Aharon, M. Elad, A. Bruckstein, "K-SVD: an algorithm for designing overcomplete
    dictionaries for sparse representation", IEEE TSP 54 (2006). Tartavel et al. (2013), eq. (1).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d, errors = ksvd(rng.standard_normal((8, 60)), 10, 2, n_iterations=3, rng=rng,
    ...                  return_errors=True)
    >>> d.shape, bool(np.allclose(np.linalg.norm(d, axis=0), 1.0)), errors.shape[0] <= 3
    ((8, 10), True, True)
    """
    if update not in ("svd", "power"):
        raise ValueError(f"update must be 'svd' or 'power', got {update!r}")
    p = np.asarray(patches, dtype=np.float64)
    n_dims, n_patches = p.shape
    if n_patches < n_atoms:
        raise ValueError(f"need at least {n_atoms} patches to learn {n_atoms} atoms, got {n_patches}")
    start = rng.choice(n_patches, n_atoms, replace=False)
    d = p[:, start].copy()
    norms = np.linalg.norm(d, axis=0)
    for j in np.flatnonzero(norms < 1e-12):
        vec = rng.standard_normal(n_dims)
        d[:, j] = vec
        norms[j] = np.linalg.norm(vec)
    d /= norms
    errors: list[float] = []
    best, stalled, patience = np.inf, 0, 3
    for _ in range(n_iterations):
        subset = rng.choice(n_patches, min(n_patches, max_training), replace=False)
        x = p[:, subset]
        w = batch_omp(d, x, n_nonzero)
        residual = x - matmul(d, w)
        errors.append(float(np.sum(residual**2) / max(np.sum(x**2), 1e-300)))
        if errors[-1] < best * (1.0 - tol):
            best, stalled = errors[-1], 0
        else:
            stalled += 1
            if tol > 0 and stalled >= patience:
                break  # converged: the last updates no longer lower the coding error
        # the residual with one row per training patch: the patches of an atom are gathered
        # and written back as whole rows (the same values and arithmetic as by columns)
        residual_rows = np.ascontiguousarray(residual.T)
        del residual  # (memory: one residual at a time)
        # the users of every atom at once: row n of the codes changes only at atom n's turn
        atom_of, patch_of = np.nonzero(w)
        bounds = np.concatenate(([0], np.cumsum(np.bincount(atom_of, minlength=n_atoms))))
        for n in range(n_atoms):
            users = patch_of[bounds[n] : bounds[n + 1]]
            if users.size == 0:
                residual = np.ascontiguousarray(residual_rows.T)
                worst = int(np.argmax(np.einsum("ij,ij->j", residual, residual)))
                patch = x[:, worst]
                norm = float(np.linalg.norm(patch))
                d[:, n] = patch / norm if norm > 1e-12 else d[:, n]
                continue
            err = _gather_error(residual_rows, users, w[n], d[:, n])
            if update == "svd":
                atom, coeffs = _rank_one(err, d[:, n])
            else:
                atom = err @ w[n, users]
                norm = float(np.linalg.norm(atom))
                if norm < 1e-12:
                    continue
                atom /= norm
                coeffs = atom @ err
            d[:, n] = atom
            w[n, users] = coeffs
            _scatter_error(residual_rows, users, err, coeffs, atom)
    d /= np.maximum(np.linalg.norm(d, axis=0), 1e-300)
    if return_errors:
        return d, np.asarray(errors)
    return d


def constrained_matching_pursuit(
    patches: np.ndarray,
    dictionary: np.ndarray,
    n_nonzero: int,
    budget: np.ndarray | None = None,
    *,
    gram: np.ndarray | None = None,
) -> np.ndarray:
    """Matching pursuit with a per-patch sparsity ``S`` and a per-atom usage budget ``F``.

    Global greedy pursuit (Tartavel et al. 2013, section 4.2, Algorithm 2, eqs. 10-12): at
    each step the (patch, atom) pair of largest correlation among the available pairs is
    selected, its coefficient increased by the correlation and that patch's correlations
    updated through the Gram matrix. A pair is available when it is already used, or when
    the patch has fewer than ``S`` atoms and the atom fewer than ``F[n]`` patches. One heap
    entry per patch, validated when popped (atoms saturate meanwhile). ``S K`` steps.

    Parameters
    ----------
    patches : ndarray, shape (L, K)
    dictionary : ndarray, shape (L, N)
        Unit-norm atoms.
    n_nonzero : int
        ``S``.
    budget : ndarray of int, shape (N,), optional
        ``F``; ``None`` means no per-atom constraint.

    Returns
    -------
    ndarray, shape (N, K)
    """
    d = np.asarray(dictionary, dtype=np.float64)
    g = d.T @ d if gram is None else gram
    corr = matmul(d.T, np.asarray(patches, dtype=np.float64))  # (N, K): <r_k, d_n>
    n_atoms = corr.shape[0]
    limit = np.full(n_atoms, np.iinfo(np.int64).max) if budget is None else np.asarray(budget, dtype=np.int64)
    # one row per patch and per atom: the kernel reads and updates a patch's correlations
    # (and a Gram column) contiguously; the values are copies, the arithmetic unchanged
    corr_rows = np.ascontiguousarray(corr.T)
    del corr  # (memory)
    w = _pursuit(
        corr_rows,
        np.ascontiguousarray(np.asarray(g, dtype=np.float64).T),
        int(n_nonzero),
        np.ascontiguousarray(limit),
    )
    del corr_rows
    return np.ascontiguousarray(w.T)


@jit()
def _best_atom(corr_k, used_k, room, per_atom, limit):
    """The available atom of largest ``|corr|`` for one patch (the first on ties), or -1.

    An atom is available when the patch already uses it, or when the patch has ``room``
    for one more atom and the atom is below its budget.
    """
    best = -1
    score = -1.0
    for n in range(corr_k.size):
        if used_k[n] or (room and per_atom[n] < limit[n]):
            value = abs(corr_k[n])
            if value > score or best < 0:
                best, score = n, value
    return best


@jit(nogil=True)  # fit runs the exemplar codes on a second thread (models.sparse)
def _pursuit(corr, gram_rows, n_nonzero, limit):
    """Algorithm 2 of Tartavel et al. (2013) on ``corr`` ``(K, N)`` (updated in place).

    ``gram_rows[n]`` is column ``n`` of the Gram matrix. The heap holds one entry
    ``(-|corr|, k)`` per patch, so its pops follow the order of those pairs whatever the
    heap's layout: the same steps as the reference's Python heap. Returns the codes ``(K, N)``.
    """
    n_patches, n_atoms = corr.shape
    w = np.zeros((n_patches, n_atoms))
    used = np.zeros((n_patches, n_atoms), dtype=np.bool_)
    per_patch = np.zeros(n_patches, dtype=np.int64)
    per_atom = np.zeros(n_atoms, dtype=np.int64)
    best = np.full(n_patches, -1, dtype=np.int64)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for k in range(n_patches):
        best[k] = _best_atom(corr[k], used[k], per_patch[k] < n_nonzero, per_atom, limit)
        if best[k] >= 0:
            heap.append((-abs(corr[k, best[k]]), np.int64(k)))
    heapq.heapify(heap)
    steps = 0
    while steps < n_nonzero * n_patches and len(heap) > 0:
        _, k = heapq.heappop(heap)
        n = best[k]
        if not used[k, n] and (per_patch[k] >= n_nonzero or per_atom[n] >= limit[n]):
            best[k] = _best_atom(corr[k], used[k], per_patch[k] < n_nonzero, per_atom, limit)
            if best[k] >= 0:
                heapq.heappush(heap, (-abs(corr[k, best[k]]), k))
            continue
        c = corr[k, n]
        if abs(c) < 1e-12:
            break
        if not used[k, n]:
            used[k, n] = True
            per_patch[k] += 1
            per_atom[n] += 1
        w[k, n] += c
        column = gram_rows[n]
        row = corr[k]
        for i in range(n_atoms):
            row[i] -= c * column[i]
        best[k] = _best_atom(row, used[k], per_patch[k] < n_nonzero, per_atom, limit)
        if best[k] >= 0:
            heapq.heappush(heap, (-abs(row[best[k]]), k))
        steps += 1
    return w


# ---------------------------------------------------------------------------- image step
#: a histogram projection ``T_hist(u, rng)``: :class:`texsyn.ops.HistogramMatcher`
Projector = Callable[[np.ndarray, "np.random.Generator | None"], np.ndarray]


def _rfft2(x: np.ndarray) -> np.ndarray:
    """``numpy.fft.rfft2(x, axes=(0, 1))``, by :mod:`scipy.fft` with its lines on the worker threads.

    Both run the same pocketfft transforms in the same order (``rfft`` of the last axis,
    then ``fft`` of the first), so the bytes are NumPy's, on any number of threads (each
    line is computed alone); SciPy's is faster (``tests/test_sparse.py``).
    """
    return sfft.rfft2(x, axes=(0, 1), workers=worker_count())


def _irfft2(spectrum: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``numpy.fft.irfft2(spectrum, s=shape, axes=(0, 1))`` by :mod:`scipy.fft`, one axis at a
    time as NumPy does (each axis normalised by its own ``1/n``; SciPy's ``irfft2`` applies
    ``1/(H W)`` at once, which rounds differently)."""
    workers = worker_count()
    rows = sfft.ifft(spectrum, n=shape[0], axis=0, workers=workers)
    return sfft.irfft(rows, n=shape[1], axis=1, workers=workers)


def upsample_bicubic(image: np.ndarray) -> np.ndarray:
    """Periodic cubic-spline up-sampling by 2 between two scales (Tartavel et al. 2013, 4.3).

    Fine pixel ``j`` sits at coarse coordinate ``j / 2``, so ``up[::2, ::2] == image``: the
    grid of the coarse scale is the even pixels of the fine one.

    Examples
    --------
    >>> coarse = np.arange(16.0).reshape(4, 4)
    >>> up = upsample_bicubic(coarse)
    >>> up.shape, bool(np.allclose(up[::2, ::2, 0], coarse))
    ((8, 8, 1), True)
    """
    img = as_channels(np.asarray(image, dtype=np.float64))
    h, w, channels = img.shape
    ii, jj = np.meshgrid(np.arange(2 * h) / 2.0, np.arange(2 * w) / 2.0, indexing="ij")
    out = np.empty((2 * h, 2 * w, channels))
    for c in range(channels):
        out[..., c] = ndimage.map_coordinates(img[..., c], [ii, jj], order=3, mode="grid-wrap")
    return out


def box_power(shape: tuple[int, int], tau: int) -> np.ndarray:
    """``|h_hat|^2`` of the normalised ``tau x tau`` box ``h`` on a periodic canvas (eq. 3).

    Examples
    --------
    >>> float(box_power((8, 8), 4)[0, 0])  # the box sums to 1
    1.0
    """
    box = np.zeros(shape)
    box[:tau, :tau] = 1.0 / tau**2
    return np.abs(_rfft2(box)) ** 2


def lowpass_towards(u: np.ndarray, target: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``u`` with its spectrum moved toward ``target``'s by ``weight`` per frequency.

    ``F^{-1}[u^ + weight (target^ - u^)]``: weight 1 takes ``target``'s coefficient, 0 keeps
    ``u``'s. With the box filter's modulus ``|h^|`` as weight and a spectrum projection as
    target, it sets the large-scale energy without touching the fine scales
    (``docs/methods/sparse.md``, "Final rounds").

    Parameters
    ----------
    u, target : ndarray, shape (H, W, C)
    weight : ndarray, shape (H, W // 2 + 1)
        Per-frequency weight in [0, 1] on the real-FFT grid.
    """
    spec = _rfft2(u)
    spec += weight[..., None] * (_rfft2(target) - spec)
    return _irfft2(spec, u.shape[:2])


class SpectrumProjector:
    """Projection on the images whose Fourier transform is the exemplar's up to a phase.

    The translation-invariant reference ``u_ref = P(u)`` of the low-pass term: at every
    frequency ``w`` the exemplar's spectrum ``s(w)`` (a vector over the colour channels) is
    turned by the single phase that best aligns it with ``u``'s, ``P(u)^(w) = s(w)
    exp(i arg <u^(w), s(w)>)``, the nearest point to ``u^(w)`` with that modulus and the
    exemplar's colour correlations (the spectrum constraint of Tartavel, Gousseau, Peyre,
    "Variational texture synthesis with sparsity and spectrum constraints", JMIV 52, 2015). The term
    ``beta ||h * (u - P(u))||^2`` is then a weighted distance to that set: it is unchanged by
    any translation of ``u`` and keeps the exemplar's energy at every low frequency, whereas
    the constant reference 'mean' pulls all of it to zero (``docs/methods/sparse.md``,
    "Low-pass reference").

    ``s`` is the spectrum of the exemplar, its mean removed, centred in a zero canvas of the
    synthesis size (cropped first if larger) and scaled by ``sqrt(H W / (h w))`` so that the
    expected energy per pixel is the exemplar's (the "spot" of random phase noise); the zero
    frequency is the exemplar's mean. The raw exemplar is used rather than its periodic
    component: the zero padding already removes the periodisation's border jumps, and the
    periodic component's local-mean spread differs from the exemplar's by -4 % to +22 % on
    VisTex crops (the raw spot's by less than 3 %).

    Parameters
    ----------
    exemplar : ndarray, shape (h, w) or (h, w, C)
    size : tuple of int
        The synthesis canvas ``(H, W)``.

    Examples
    --------
    >>> ex = np.random.default_rng(0).random((16, 16))
    >>> project = SpectrumProjector(ex, (32, 32))
    >>> u = project(np.random.default_rng(1).random((32, 32, 1)))
    >>> bool(np.allclose(np.abs(np.fft.rfft2(u[..., 0])), np.abs(project.spectrum[..., 0])))
    True
    """

    def __init__(self, exemplar: np.ndarray, size: tuple[int, int]):
        ex = as_channels(np.asarray(exemplar, dtype=np.float64))
        mean = ex.mean(axis=(0, 1))
        spot = ex - mean
        big_h, big_w = int(size[0]), int(size[1])
        h, w = min(spot.shape[0], big_h), min(spot.shape[1], big_w)
        top, left = (spot.shape[0] - h) // 2, (spot.shape[1] - w) // 2
        spot = spot[top : top + h, left : left + w]
        spot = spot - spot.mean(axis=(0, 1))
        canvas = np.zeros((big_h, big_w, ex.shape[2]))
        r0, c0 = (big_h - h) // 2, (big_w - w) // 2
        canvas[r0 : r0 + h, c0 : c0 + w] = spot * np.sqrt(big_h * big_w / (h * w))
        canvas += mean
        self.size = (big_h, big_w)
        self.spectrum = _rfft2(canvas)
        self.spectrum.flags.writeable = False

    def __call__(self, u: np.ndarray) -> np.ndarray:
        spec = _rfft2(u)
        # np.conj inline: NumPy then multiplies into that temporary, and its vectorised
        # complex product rounds differently with the operands swapped
        inner = np.sum(spec * np.conj(self.spectrum), axis=2)
        magnitude = np.abs(inner)
        phase = np.where(magnitude > 1e-300, inner / np.maximum(magnitude, 1e-300), 1.0)
        return _irfft2(self.spectrum * phase[..., None], u.shape[:2])


def _reference_of(u: np.ndarray, reference) -> np.ndarray:
    """``u_ref`` of the low-pass term: a fixed image, or a map ``u -> u_ref`` applied to ``u``."""
    return reference(u) if callable(reference) else reference


def _lowpass_apply(e: np.ndarray, power: np.ndarray) -> np.ndarray:
    """``h_bar * h * e`` per channel (periodic)."""
    spec = _rfft2(e) * power[..., None]
    return _irfft2(spec, e.shape[:2])


def image_update(
    u: np.ndarray,
    recon: np.ndarray,
    projector: Projector,
    *,
    alpha: float,
    beta: float,
    box_power: np.ndarray,
    reference: np.ndarray | Callable[[np.ndarray], np.ndarray],
    n_steps: int,
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Gradient steps on the energy (6) for fixed codes (Tartavel et al. 2013, eq. 7).

    ``g = 2 (u - R) + 2 alpha (u - T_hist(u)) + 2 beta h_bar * h * (u - u_ref)`` with step
    ``eta = 1 / (2 (1 + alpha + beta))``. ``R`` is the reconstruction of the coded patches
    (linear average or graph cuts). ``reference`` is a fixed ``u_ref`` or a projection
    ``u -> u_ref`` (:class:`SpectrumProjector`), re-evaluated at every step like the
    histogram projection ``T_hist``.

    What this guarantees, and what it does not (``docs/methods/sparse.md``, "Step size"):
    ``T_hist`` and the spectrum projection are projections onto non-convex sets (the images
    with the exemplar's histogram, with its Fourier modulus); they jump, so the energy's
    gradient is not Lipschitz and no gradient-descent rate or convergence holds. ``eta`` is
    the inverse of the Lipschitz constant ``2 (1 + alpha + beta)`` of the quadratic obtained
    by freezing both projections at the current ``u`` (the low-pass weights are at most 1).
    As both are exact nearest points, that quadratic lies above the energy and touches it at
    ``u``, so a step does not raise the energy (6) of fixed codes with the linear
    reconstruction (``tests/test_sparse.py``). With graph cuts, ``R`` is not the linear
    data term's target, and across outer iterations the greedy pursuit and the cuts change
    the codes: the caller's energy (3) is only monitored (:func:`image_energy`), and its
    decrease is observed, not guaranteed (it jitters by 0.1-2 %). Alternating these
    projections is a heuristic, as in the paper.
    """
    eta = 1.0 / (2.0 * (1.0 + alpha + beta))
    recon = np.ascontiguousarray(recon, dtype=np.float64)
    for _ in range(n_steps):
        projected = projector(u, rng)
        lowpass = None
        if beta > 0:
            lowpass = _lowpass_apply(u - _reference_of(u, reference), box_power)
        u = _gradient_step(u, recon, projected, lowpass, 2.0 * alpha, 2.0 * beta, eta)
    return u


def _gradient_step(
    u: np.ndarray,
    recon: np.ndarray,
    projected: np.ndarray,
    lowpass: np.ndarray | None,
    alpha2: float,
    beta2: float,
    eta: float,
) -> np.ndarray:
    """``u - eta g``, ``g = 2 (u - recon) + alpha2 (u - projected) [+ beta2 lowpass]`` (eq. 7).

    One compiled pass instead of NumPy's nine array temporaries, with the same operations on
    each pixel in the same order (no fused multiply-add), so the same bytes
    (``tests/test_sparse.py``).
    """
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (u, recon, projected)]
    if lowpass is None:
        extra, beta2 = arrays[0], 0.0  # not read
    else:
        extra = np.ascontiguousarray(lowpass, dtype=np.float64)
    out = np.empty(arrays[0].shape)
    _gradient_step_flat(
        *(a.reshape(-1) for a in arrays), extra.reshape(-1), lowpass is not None, alpha2, beta2, eta,
        out.reshape(-1),
    )  # fmt: skip
    return out


@jit()
def _gradient_step_flat(u, recon, projected, lowpass, with_lowpass, alpha2, beta2, eta, out):
    """:func:`_gradient_step` on flat arrays: NumPy's ``2.0 * (u - recon) + alpha2 * (u -
    projected)``, then ``+= beta2 * lowpass``, then ``u - eta * grad``, value by value."""
    for i in range(u.size):
        grad = 2.0 * (u[i] - recon[i]) + alpha2 * (u[i] - projected[i])
        if with_lowpass:
            grad += beta2 * lowpass[i]
        out[i] = u[i] - eta * grad


def image_energy(
    u: np.ndarray,
    coded: np.ndarray,
    tau: int,
    step: int,
    projector: Projector,
    *,
    alpha: float,
    beta: float,
    box_power: np.ndarray,
    reference: np.ndarray | Callable[[np.ndarray], np.ndarray],
) -> float:
    """``E_W(u) = (1/Z)||Pi(u) - D W||^2 + alpha N W_2^2 + beta ||h * (u - u_ref)||^2`` (eq. 6).

    ``reference`` as in :func:`image_update` (a fixed image or a projection of ``u``).
    """
    patches, _ = extract_patches(u, tau, stride=step, mode="periodic")
    z = (tau / step) ** 2
    data = np.sum((patches - coded) ** 2) / z
    hist = np.sum((u - projector(u, None)) ** 2)
    low = 0.0
    if beta > 0:
        filtered = _irfft2(
            _rfft2(u - _reference_of(u, reference)) * np.sqrt(box_power)[..., None], u.shape[:2]
        )
        low = np.sum(filtered**2)
    return float(data + alpha * hist + beta * low)
