"""Tree-structured vector quantisation: the approximate neighbourhood search of Wei and Levoy.

The exemplar's neighbourhood vectors are split recursively in two by 2-means (a few Lloyd
iterations from two random vectors) until a node holds at most ``leaf_size`` vectors. A query
descends from the root to the child with the nearer centroid and is answered by an exact
search among the vectors of the leaf it reaches (Wei and Levoy 2000, section 3;
``docs/methods/wei_levoy.md``). The exact search over every vector is
:func:`texsyn.ops.search.nearest_rows`.

The tree is built once in the constructor; queries never change it (``docs/architecture.md``,
"Fitted state").

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000, section 3.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TSVQ"]

#: Lloyd iterations of every 2-means split
LLOYD_ITERATIONS = 8


class TSVQ:
    """Tree-structured vector quantiser: recursive 2-means splits of a set of vectors.

    A query descends to the child with the nearer centroid and is answered by an exact
    search among the (few) vectors of the leaf it reaches (Wei and Levoy 2000, section 3).

    Parameters
    ----------
    vectors : ndarray, shape (K, D)
        The vectors to search (Wei–Levoy: one neighbourhood vector per exemplar pixel).
    leaf_size : int
        Largest number of vectors in a leaf; a node of identical vectors stays a leaf
        whatever its size.
    rng : numpy.random.Generator
        Source of the two initial centres of every split.

    Examples
    --------
    >>> vectors = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0]])
    >>> tree = TSVQ(vectors, leaf_size=1, rng=np.random.default_rng(0))
    >>> tree.query(np.array([4.9, 5.2])), tree.nearest(np.array([[0.2, 0.0], [5.2, 5.0]])).tolist()
    (2, [1, 3])
    """

    def __init__(self, vectors: np.ndarray, leaf_size: int, rng: np.random.Generator):
        self.vectors = vectors
        self.centroids: list[np.ndarray] = []
        self.children: list[tuple[int, int]] = []
        self.members: list[np.ndarray | None] = []
        self._build(np.arange(len(vectors)), leaf_size, rng)

    def _build(self, index: np.ndarray, leaf_size: int, rng: np.random.Generator) -> int:
        """Add the node of the vectors ``index`` (and its subtree); return its number."""
        node = len(self.centroids)
        data = self.vectors[index]
        self.centroids.append(data.mean(axis=0))
        self.children.append((-1, -1))
        self.members.append(None)
        if len(index) <= leaf_size:
            self.members[node] = index
            return node
        centres = data[rng.choice(len(index), 2, replace=False)]
        for _ in range(LLOYD_ITERATIONS):
            d = ((data[:, None, :] - centres[None]) ** 2).sum(-1)
            side = np.argmin(d, axis=1)
            if side.min() == side.max():
                break
            centres = np.stack([data[side == s].mean(axis=0) for s in (0, 1)])
        if side.min() == side.max():  # identical vectors: no split possible
            self.members[node] = index
            return node
        left = self._build(index[side == 0], leaf_size, rng)
        right = self._build(index[side == 1], leaf_size, rng)
        self.children[node] = (left, right)
        return node

    def query(self, q: np.ndarray) -> int:
        """Row of :attr:`vectors` that the tree finds for the vector ``q`` (shape ``(D,)``).

        The nearer centroid wins at every node (the left child on a tie); in the leaf, the
        nearest vector (the lowest row on a tie).
        """
        node = 0
        while self.members[node] is None:
            left, right = self.children[node]
            dl = np.sum((self.centroids[left] - q) ** 2)
            dr = np.sum((self.centroids[right] - q) ** 2)
            node = left if dl <= dr else right
        idx = self.members[node]
        assert idx is not None  # a leaf
        d = np.sum((self.vectors[idx] - q) ** 2, axis=1)
        return int(idx[np.argmin(d)])

    def nearest(self, queries: np.ndarray) -> np.ndarray:
        """:meth:`query` of every row of ``queries`` ``(Q, D)``: an integer array ``(Q,)``."""
        return np.array([self.query(v) for v in queries], dtype=np.int64)
