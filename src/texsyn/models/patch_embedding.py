"""The parameterisation ``gamma_W`` of a patch manifold (Peyré 2007, section 4).

The patch-valued wavelet transform measures its details as differences of ``p``-dimensional
coordinates of exemplar patches; the coordinates come from a locally linear embedding (Roweis
and Saul) of the patches of one window width, and ``gamma_W^-1`` is a nearest-neighbour search
among them (``docs/methods/patch_wavelet.md``). :class:`PatchEmbedding` is what
:class:`texsyn.models.patch_wavelet.PatchWaveletTransform` keeps per width.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import numpy as np

__all__ = ["PatchEmbedding", "lle_embedding"]


def lle_embedding(
    descriptors: np.ndarray,
    grid_shape: tuple[int, int],
    *,
    n_components: int = 5,
    n_neighbors: int = 12,
    max_points: int = 2048,
    rng: int = 0,
    random_state: int | None = None,
) -> np.ndarray:
    """Locally linear embedding of a patch set, normalised to unit variance per coordinate.

    Roweis and Saul's LLE (scikit-learn's :class:`~sklearn.manifold.LocallyLinearEmbedding`,
    every local Gram matrix regularised by ``1e-3 trace``), the parameterisation ``gamma_W``
    of Peyré 2007, section 4. When there are more than ``max_points`` patches, LLE runs on
    landmarks (the positions of a regular sub-grid with step ``ceil(sqrt(Q / max_points))``)
    and every other patch is placed by the barycentric weights of its nearest landmarks
    (scikit-learn's ``transform``). When the k-NN graph of the landmarks is disconnected,
    ``n_neighbors`` grows by 4 until it is connected (``docs/methods/patch_wavelet.md``).

    Parameters
    ----------
    descriptors : ndarray, shape (Q, D)
        One row per exemplar position, in C order of ``grid_shape``.
    grid_shape : (int, int)
        The exemplar grid ``(H, W)``, ``H * W == Q``.
    rng : int
        Seed of the eigen-solver's start vector.
    random_state : int, optional
        Deprecated name of ``rng``.

    Returns
    -------
    ndarray, shape (Q, n_components)
        Columns with zero mean and unit variance.
    """
    from scipy.sparse.csgraph import connected_components
    from sklearn.manifold import LocallyLinearEmbedding
    from sklearn.neighbors import NearestNeighbors

    if random_state is not None:
        warnings.warn(
            "lle_embedding(random_state=...) is deprecated; use rng", DeprecationWarning, stacklevel=2
        )
        rng = random_state
    X = np.asarray(descriptors, dtype=np.float64)
    q = X.shape[0]
    h, w = grid_shape
    if h * w != q:
        raise ValueError(f"grid {grid_shape} does not match {q} descriptors")
    step = max(1, math.ceil(math.sqrt(q / max_points)))
    grid = np.arange(q).reshape(h, w)
    landmarks = grid[::step, ::step].ravel()
    n = landmarks.size
    if n <= n_components + 1:
        raise ValueError(f"{n} patches are too few for a {n_components}-dimensional embedding")
    X_l = X[landmarks]
    k = min(n_neighbors, n - 1)
    limit = min(n - 1, n_neighbors + 40)
    while True:
        graph = (
            NearestNeighbors(n_neighbors=k, algorithm="brute").fit(X_l).kneighbors_graph(mode="connectivity")
        )
        n_parts, _ = connected_components(graph, directed=False)
        if n_parts == 1 or k >= limit:
            break
        k = min(k + 4, limit)
    if k != n_neighbors:
        warnings.warn(
            f"LLE neighbourhood graph needed {k} neighbours (not {n_neighbors})"
            + (" to be connected" if n_parts == 1 else f" and still has {n_parts} parts"),
            stacklevel=2,
        )
    k = max(k, n_components + 1)
    solver = "dense" if n <= 512 else "arpack"
    lle = LocallyLinearEmbedding(
        n_neighbors=k,
        n_components=n_components,
        reg=1e-3,
        eigen_solver=solver,
        max_iter=1000,
        random_state=rng,
        neighbors_algorithm="brute",
    )
    try:
        Y_l = lle.fit_transform(X_l)
    except (ValueError, RuntimeError):  # singular shift-invert factorisation: dense fallback
        lle.set_params(eigen_solver="dense")
        Y_l = lle.fit_transform(X_l)
    Y = np.empty((q, n_components))
    Y[landmarks] = Y_l
    if n < q:
        others = np.setdiff1d(np.arange(q), landmarks, assume_unique=True)
        Y[others] = lle.transform(X[others])
    Y -= Y.mean(axis=0)
    std = Y.std(axis=0)
    return Y / np.where(std > 0, std, 1.0)


class PatchEmbedding(NamedTuple):
    """``gamma_W`` of one window width: coordinates of every exemplar position and their tree."""

    coordinates: np.ndarray
    """``(H W, p)``, read-only: the embedding of the window centred on each position."""
    tree: object
    """:class:`scipy.spatial.cKDTree` on the coordinates (``gamma_W^-1`` by nearest neighbour)."""
