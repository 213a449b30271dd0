"""Patch-valued wavelet transform of coordinate maps (Peyré 2007), spec 01.

A feature-valued image is a *coordinate map* ``T`` of shape ``(n_h, n_w, 2)`` (sides powers of
two, not necessarily equal): every sample holds the exemplar position ``(row, col)`` of its
feature, the exemplar window centred there; the
displayed image is ``E(T)``. The transform is a lifting scheme on such maps (paper section 4,
Tables 1-2): at level ``j`` the samples spaced ``s = 2^(j-1)`` apart are split into even and
odd ones along rows, then along columns; each odd sample is predicted by the association-field
mean ``m^omega`` of its two even neighbours (section 3) and the detail is the difference, in a
``p``-dimensional LLE embedding of the exemplar's patches, between prediction and truth.

Building blocks here: :class:`ExemplarWindows` (extended exemplar, block-averaged window
descriptors, mean-operator descriptors), :func:`lle_embedding` (the manifold
parameterisation ``gamma_W``), :class:`PatchWaveletTransform` (forward, inverse, feature
estimation of eq. 4) and :class:`PatchWaveletCoefficients` (details addressed by
``(level, axis)``, thresholding, packed magnitudes).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.ndimage import uniform_filter

from .patches import as_channels, wrap_seam_ratio
from .search import NearestPatchIndex

__all__ = [
    "ExemplarWindows",
    "PatchWaveletCoefficients",
    "PatchWaveletTransform",
    "descriptor_dimension",
    "lle_embedding",
    "planned_widths",
]


class ExemplarWindows:
    """Square windows of an extended image, described by block-averaged pixels (spec 01, 4.1).

    The window of even width ``W`` centred on the integer position ``t`` covers
    ``t + x`` for ``x`` in ``{-W/2, ..., W/2 - 1}^2`` (so the centre pixel is the displayed
    value). Its descriptor is the window itself when ``W <= max_resolution``, otherwise the
    means of its non-overlapping ``b x b`` blocks, ``b = W / max_resolution``, flattened in
    C order of shape ``(m, m, C)`` with ``m = W / b``.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    boundary : {'periodic', 'symmetric'}
        Extension outside the image (spec 00, section 0).
    max_resolution : int
        Largest number of blocks per side of a descriptor (``r_max``), a power of two.
    """

    def __init__(self, image: np.ndarray, boundary: str = "symmetric", *, max_resolution: int = 16):
        if boundary not in ("periodic", "symmetric"):
            raise ValueError(f"boundary must be 'periodic' or 'symmetric', got {boundary!r}")
        img = np.asarray(as_channels(np.asarray(image)), dtype=np.float64)
        self.image = img
        self.shape = img.shape[:2]
        self.boundary = boundary
        self.max_resolution = int(max_resolution)
        if boundary == "periodic":
            self._period_image = img
        else:  # one period of the mirrored extension: 2H x 2W
            tall = np.concatenate([img, img[::-1]], axis=0)
            self._period_image = np.concatenate([tall, tall[:, ::-1]], axis=1)
        self._means: dict[int, np.ndarray] = {}

    @property
    def channels(self) -> int:
        return self.image.shape[2]

    def layout(self, width: int) -> tuple[int, int]:
        """Block side ``b`` and blocks per side ``m`` of the descriptor of ``width``."""
        if width < 2 or width % 2:
            raise ValueError(f"window width must be an even number >= 2, got {width}")
        b = max(1, width // self.max_resolution)
        if width % b:
            raise ValueError(f"window width {width} is not a multiple of its block side {b}")
        return b, width // b

    def dimension(self, width: int) -> int:
        """Length of a descriptor of ``width``."""
        return self.layout(width)[1] ** 2 * self.channels

    def _block_means(self, b: int) -> np.ndarray:
        means = self._means.get(b)
        if means is None:
            # mean over [y, y+b) x [x, x+b) of the periodic image, for every (y, x)
            means = uniform_filter(self._period_image, size=(b, b, 1), mode="wrap", origin=(-(b // 2), -(b // 2), 0))
            self._means[b] = means
        return means

    def blocks(
        self,
        rows: np.ndarray,
        cols: np.ndarray,
        width: int,
        row_blocks: slice = slice(None),
        col_blocks: slice = slice(None),
    ) -> np.ndarray:
        """Block means of the windows centred on ``(rows, cols)``.

        Returns
        -------
        ndarray, shape (n, mu, mv, C)
            The selected block rows and columns of each window's ``m x m`` block grid.
        """
        b, m = self.layout(width)
        u = np.arange(m)[row_blocks]
        v = np.arange(m)[col_blocks]
        means = self._block_means(b)
        ph, pw = means.shape[:2]
        r = np.mod(np.asarray(rows, dtype=np.int64)[:, None] - width // 2 + b * u[None, :], ph)
        c = np.mod(np.asarray(cols, dtype=np.int64)[:, None] - width // 2 + b * v[None, :], pw)
        return means[r[:, :, None], c[:, None, :]]

    def descriptors(self, rows: np.ndarray, cols: np.ndarray, width: int) -> np.ndarray:
        """Descriptors ``(n, D)`` of the windows of ``width`` centred on ``(rows, cols)``."""
        out = self.blocks(rows, cols, width)
        return out.reshape(out.shape[0], -1)

    def mean_descriptors(
        self, first: np.ndarray, second: np.ndarray, axis: int, half_distance: int, width: int
    ) -> np.ndarray:
        """Descriptors of the glued windows ``mu`` of the association-field mean (spec 01, 4.3).

        ``mu(x) = E(ta + s e_a + x)`` where ``x_a < 0`` and ``E(tb - s e_a + x)`` elsewhere:
        the half of the first feature's continuation toward the midpoint, glued to the half of
        the second feature's. With ``width = 2 s`` this is the paper's "right half of g with
        the left half of g'" (section 3).

        Parameters
        ----------
        first, second : ndarray of int, shape (n, 2)
            Exemplar positions of the two even neighbours (``ta`` left or upper).
        axis : {0, 1}
            0: vertical pairs (the paper's omega = (1, 0) on rows), 1: horizontal pairs.
        half_distance : int
            ``s``: the two samples are ``2 s`` output pixels apart.
        """
        _, m = self.layout(width)
        half = m // 2
        shift = np.zeros(2, dtype=np.int64)
        shift[axis] = half_distance
        a = np.asarray(first, dtype=np.int64) + shift
        bpos = np.asarray(second, dtype=np.int64) - shift
        lead, tail = slice(0, half), slice(half, m)
        if axis == 0:
            top = self.blocks(a[:, 0], a[:, 1], width, row_blocks=lead)
            bottom = self.blocks(bpos[:, 0], bpos[:, 1], width, row_blocks=tail)
            glued = np.concatenate([top, bottom], axis=1)
        else:
            left = self.blocks(a[:, 0], a[:, 1], width, col_blocks=lead)
            right = self.blocks(bpos[:, 0], bpos[:, 1], width, col_blocks=tail)
            glued = np.concatenate([left, right], axis=2)
        return glued.reshape(glued.shape[0], -1)


def lle_embedding(
    descriptors: np.ndarray,
    grid_shape: tuple[int, int],
    *,
    n_components: int = 5,
    n_neighbors: int = 12,
    max_points: int = 2048,
    random_state: int = 0,
) -> np.ndarray:
    """Locally linear embedding of a patch set, normalised to unit variance per coordinate.

    Roweis and Saul's LLE (scikit-learn's :class:`~sklearn.manifold.LocallyLinearEmbedding`,
    every local Gram matrix regularised by ``1e-3 trace``), the parameterisation ``gamma_W``
    of Peyré 2007, section 4 (spec 01, 4.2 and A10-A11). When there are more than
    ``max_points`` patches, LLE runs on landmarks (the positions of a regular sub-grid with
    step ``ceil(sqrt(Q / max_points))``) and every other patch is placed by the barycentric
    weights of its nearest landmarks (scikit-learn's ``transform``). When the k-NN graph of
    the landmarks is disconnected, ``n_neighbors`` grows by 4 until it is connected.

    Parameters
    ----------
    descriptors : ndarray, shape (Q, D)
        One row per exemplar position, in C order of ``grid_shape``.
    grid_shape : (int, int)
        The exemplar grid ``(H, W)``, ``H * W == Q``.

    Returns
    -------
    ndarray, shape (Q, n_components)
        Columns with zero mean and unit variance.
    """
    from scipy.sparse.csgraph import connected_components
    from sklearn.manifold import LocallyLinearEmbedding
    from sklearn.neighbors import NearestNeighbors

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
        graph = NearestNeighbors(n_neighbors=k, algorithm="brute").fit(X_l).kneighbors_graph(mode="connectivity")
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
        random_state=random_state,
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


@dataclass
class PatchWaveletCoefficients:
    """Coefficients of the patch-valued wavelet transform (spec 01, 5.1-5.2).

    Attributes
    ----------
    coarse : ndarray of int64, shape (c_h, c_w, 2)
        Coarse coordinate map at level ``top_level``: ``1 x 1`` after a full forward
        transform of a square map, ``2^a x 2^b`` with ``min(a, b) = 0`` after that of a
        rectangular one; ``2 x 2`` for a square synthesis.
    top_level : int
        Coarsest level ``j_top``; the full map has shape ``(c_h 2^j_top, c_w 2^j_top)``.
    details : dict
        ``details[(j, axis)]``, ``j = 1 ... top_level`` (1 is the finest), ``axis`` 0 (vertical
        pairs) or 1 (horizontal pairs): arrays ``(rows, cols, p)`` of detail vectors; a missing
        entry means zero details. Shapes, for a map of shape ``(n_h, n_w)``:
        ``(n_h/2^j, n_w/2^(j-1), p)`` for axis 0 and ``(n_h/2^j, n_w/2^j, p)`` for axis 1.
    grid_boundary : {'periodic', 'symmetric'}
        Boundary rule of the sample grid that produced them (the inverse must use the same).
    """

    coarse: np.ndarray
    top_level: int
    details: dict = field(default_factory=dict)
    grid_boundary: str = "periodic"

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_h, n_w)``: shape of the coordinate map these coefficients describe."""
        scale = 2**self.top_level
        return (self.coarse.shape[0] * scale, self.coarse.shape[1] * scale)

    @property
    def size(self) -> int:
        """Longest side of the coordinate map (its side ``n`` when it is square)."""
        return max(self.shape)

    def detail_shape(self, level: int, axis: int) -> tuple[int, int]:
        """``(rows, cols)`` of the details of ``(level, axis)``."""
        rows = self.shape[0] // 2**level
        cols = self.shape[1] // 2**level
        return (rows, 2 * cols) if axis == 0 else (rows, cols)

    def __getitem__(self, key: tuple[int, int]) -> np.ndarray | None:
        return self.details.get(key)

    def norms(self) -> dict:
        """``||d||_2`` of every detail vector, per ``(level, axis)``."""
        return {key: np.linalg.norm(d, axis=-1) for key, d in self.details.items()}

    def max_norm(self) -> float:
        """Largest detail magnitude over all levels and directions (spec 01, A5)."""
        return max((float(n.max()) for n in self.norms().values() if n.size), default=0.0)

    def thresholded(self, ratio: float, *, per_level: bool = False) -> "PatchWaveletCoefficients":
        """Hard thresholding that removes the small details (paper section 5.2, spec 01 A4).

        A detail is kept iff ``||d|| > ratio * max``; the maximum is global, or per level
        (both directions) with ``per_level=True``. ``ratio = 1`` removes every detail (pure
        synthesis from the coarse features), ``ratio = 0`` removes none.
        """
        if not 0.0 <= ratio <= 1.0:
            raise ValueError(f"ratio must be in [0, 1], got {ratio!r}")
        norms = self.norms()
        global_max = self.max_norm()
        out = {}
        for (level, axis), d in self.details.items():
            if per_level:
                top = max(float(norms[(level, a)].max()) for a in (0, 1) if (level, a) in norms)
            else:
                top = global_max
            keep = norms[(level, axis)] > ratio * top
            out[(level, axis)] = np.where(keep[..., None], d, 0.0)
        return PatchWaveletCoefficients(self.coarse.copy(), self.top_level, out, self.grid_boundary)

    def magnitudes(self) -> np.ndarray:
        """Detail magnitudes packed like an orthogonal wavelet transform (paper Fig. 7).

        Level ``j`` with ``a = n_h / 2^j`` and ``b = n_w / 2^j`` puts the horizontal-pair
        magnitudes (``a x b``) in ``[0:a, b:2b]`` and the vertical-pair magnitudes
        (``a x 2b``) in ``[a:2a, 0:2b]``; the coarse corner stays 0. The result has the shape
        ``(n_h, n_w)`` of the map (``n x n`` for a square one).
        """
        n_h, n_w = self.shape
        out = np.zeros((n_h, n_w))
        norms = self.norms()
        for level in range(1, self.top_level + 1):
            a, b = n_h // 2**level, n_w // 2**level
            if (level, 1) in norms:
                out[0:a, b : 2 * b] = norms[(level, 1)]
            if (level, 0) in norms:
                out[a : 2 * a, 0 : 2 * b] = norms[(level, 0)]
        return out


def planned_widths(
    exemplar_shape: tuple[int, ...],
    *,
    min_width: int = 8,
    max_width: int | None = None,
    feature_width: int | None = None,
) -> list[int]:
    """The window widths :meth:`PatchWaveletTransform.widths` will use, from shapes alone.

    For memory estimates made before any array exists (``docs/memory.md``).
    """
    h, w = int(exemplar_shape[0]), int(exemplar_shape[1])
    largest = 2 ** int(math.floor(math.log2(max(min(h, w) // 2, 1))))
    top = largest if max_width is None else int(min(max_width, largest))
    low = int(min(min_width, top))
    feature = int(min(feature_width or min_width, top))
    out, width = [], max(low, 1)
    while width <= top:
        out.append(width)
        width *= 2
    return sorted(set(out) | {feature})


def descriptor_dimension(width: int, max_resolution: int, channels: int) -> int:
    """Length of the descriptor of a window of ``width`` (:meth:`ExemplarWindows.dimension`)."""
    b = max(1, int(width) // int(max_resolution))
    return (int(width) // b) ** 2 * int(channels)


def _split(samples: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    moved = np.moveaxis(samples, axis, 0)
    return np.moveaxis(moved[0::2], 0, axis), np.moveaxis(moved[1::2], 0, axis)


def _interleave(even: np.ndarray, odd: np.ndarray, axis: int) -> np.ndarray:
    e = np.moveaxis(even, axis, 0)
    out = np.empty((2 * e.shape[0],) + e.shape[1:], dtype=even.dtype)
    out[0::2] = e
    out[1::2] = np.moveaxis(odd, axis, 0)
    return np.moveaxis(out, 0, axis)


def _next_even(even: np.ndarray, axis: int, boundary: str) -> np.ndarray:
    """The even neighbour ``k + 1`` of every even sample (spec 01, A13)."""
    if boundary == "periodic":
        return np.roll(even, -1, axis=axis)
    moved = np.moveaxis(even, axis, 0)
    shifted = np.concatenate([moved[1:], moved[-1:]], axis=0)
    return np.moveaxis(shifted, 0, axis)


class PatchWaveletTransform:
    """Invertible multiscale transform of coordinate maps into an exemplar (Peyré 2007, section 4).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, C)
        The texture whose patches are the features.
    min_width, max_width : int or None
        Patch width of level ``j`` is ``clamp(2^j, min_width, max_width)`` (spec 01, A7);
        ``max_width`` defaults to the largest power of two ``<= min(H, W) / 2``.
    max_resolution : int
        Blocks per side of a descriptor (``r_max``; wider windows are block-averaged).
    feature_width : int or None
        Window ``m0`` of the feature estimation (eq. 4); ``min_width`` by default.
    embedding_dim : int
        Dimension ``p`` of the LLE parameterisation (the paper uses 5).
    lle_neighbors, lle_points : int
        LLE neighbourhood size and the number of landmark patches it runs on.
    exemplar_boundary : {'auto', 'periodic', 'symmetric'}
        Extension of the exemplar beyond its border: 'auto' is periodic when the exemplar
        tiles (:func:`~texsyn.ops.wrap_seam_ratio` at most 1.5), symmetric otherwise.
    candidates : int
        Candidates re-ranked exactly by every nearest-patch query.
    random_state : int
        Seed of the LLE eigen-solver's start vector.
    """

    def __init__(
        self,
        exemplar: np.ndarray,
        *,
        min_width: int = 8,
        max_width: int | None = None,
        max_resolution: int = 16,
        feature_width: int | None = None,
        embedding_dim: int = 5,
        lle_neighbors: int = 12,
        lle_points: int = 2048,
        exemplar_boundary: str = "auto",
        candidates: int = 4,
        random_state: int = 0,
    ):
        ex = np.asarray(as_channels(np.asarray(exemplar)), dtype=np.float64)
        h, w = ex.shape[:2]
        if exemplar_boundary == "auto":
            exemplar_boundary = "periodic" if wrap_seam_ratio(ex) <= 1.5 else "symmetric"
        largest = 2 ** int(math.floor(math.log2(max(min(h, w) // 2, 1))))
        self.max_width = largest if max_width is None else int(min(max_width, largest))
        if self.max_width < 2:
            raise ValueError(f"exemplar of {w}x{h} pixels is too small: windows need at least 4x4 pixels")
        self.min_width = int(min(min_width, self.max_width))
        self.feature_width = int(min(feature_width or min_width, self.max_width))
        self.embedding_dim = int(embedding_dim)
        self.lle_neighbors = int(lle_neighbors)
        self.lle_points = int(lle_points)
        self.candidates = int(candidates)
        self.random_state = int(random_state)
        self.windows = ExemplarWindows(ex, exemplar_boundary, max_resolution=max_resolution)
        self.exemplar_boundary = exemplar_boundary
        self._indexes: dict[int, NearestPatchIndex] = {}
        self._embeddings: dict[int, tuple[np.ndarray, object]] = {}

    # ------------------------------------------------------------------ building blocks
    @property
    def exemplar_shape(self) -> tuple[int, int]:
        return self.windows.shape

    def width(self, level: int) -> int:
        """Patch width of ``level`` (1 is the finest)."""
        return int(min(max(2**level, self.min_width), self.max_width))

    def widths(self) -> list[int]:
        """Every width any level can use."""
        out, w = [], self.min_width
        while w <= self.max_width:
            out.append(w)
            w *= 2
        return sorted(set(out) | {self.feature_width})

    def all_positions(self) -> tuple[np.ndarray, np.ndarray]:
        h, w = self.exemplar_shape
        rows, cols = np.divmod(np.arange(h * w), w)
        return rows, cols

    def index(self, width: int) -> NearestPatchIndex:
        """Nearest-patch index over the descriptors of every exemplar position (cached)."""
        found = self._indexes.get(width)
        if found is None:
            rows, cols = self.all_positions()
            bank = self.windows.descriptors(rows, cols, width)
            ecols = self.exemplar_shape[1]

            def exact_rows(flat: np.ndarray, width=width, ecols=ecols) -> np.ndarray:
                return self.windows.descriptors(flat // ecols, flat % ecols, width)

            found = NearestPatchIndex(bank, candidates=self.candidates, rows=exact_rows)
            self._indexes[width] = found
        return found

    def prepare(self, widths=None) -> "PatchWaveletTransform":
        """Build the nearest-patch indexes of ``widths`` (all by default) ahead of use."""
        for w in self.widths() if widths is None else widths:
            self.index(w)
        return self

    def embedding(self, width: int) -> tuple[np.ndarray, object]:
        """``(Y, tree)``: LLE coordinates of every exemplar position and a KD-tree on them."""
        found = self._embeddings.get(width)
        if found is None:
            from scipy.spatial import cKDTree

            rows, cols = self.all_positions()
            Y = lle_embedding(
                self.windows.descriptors(rows, cols, width),
                self.exemplar_shape,
                n_components=self.embedding_dim,
                n_neighbors=self.lle_neighbors,
                max_points=self.lle_points,
                random_state=self.random_state,
            )
            found = (Y, cKDTree(Y))
            self._embeddings[width] = found
        return found

    def _flat(self, coords: np.ndarray) -> np.ndarray:
        return coords[..., 0] * self.exemplar_shape[1] + coords[..., 1]

    def _coords(self, flat: np.ndarray) -> np.ndarray:
        return np.stack(np.divmod(flat, self.exemplar_shape[1]), axis=-1).astype(np.int64)

    def image(self, coords: np.ndarray) -> np.ndarray:
        """The displayed image ``E(T)`` of a coordinate map ``(..., 2)``: ``(..., C)``."""
        return self.windows.image[coords[..., 0], coords[..., 1]]

    def predict(self, even: np.ndarray, axis: int, level: int, boundary: str) -> np.ndarray:
        """Association-field mean of every even sample and its next even neighbour along ``axis``."""
        nxt = _next_even(even, axis, boundary)
        width = self.width(level)
        s = 2 ** (level - 1)
        first = even.reshape(-1, 2)
        second = nxt.reshape(-1, 2)
        index = self.index(width)
        out = np.empty(first.shape[0], dtype=np.int64)
        chunk = max(1, 2**22 // max(1, self.windows.dimension(width)))
        for start in range(0, first.shape[0], chunk):
            stop = start + chunk
            queries = self.windows.mean_descriptors(first[start:stop], second[start:stop], axis, s, width)
            out[start:stop] = index.query(queries)[0]
        return self._coords(out).reshape(even.shape)

    # ------------------------------------------------------------------ the transform
    def forward(
        self,
        coords: np.ndarray,
        *,
        grid_boundary: str = "periodic",
        callback: Callable[[int, int], None] | None = None,
    ) -> PatchWaveletCoefficients:
        """Forward transform of an ``n x n`` coordinate map, ``n = 2^J`` (paper Table 1, spec 01 5.1).

        A rectangular map of shape ``(2^a, 2^b)`` is transformed over ``min(a, b)`` levels,
        which leaves a coarse map of ``2^(a - min) x 2^(b - min)`` features: the cost is
        proportional to the number of samples, never to the square of the longer side.

        Parameters
        ----------
        coords : ndarray of int, shape (n, n, 2) or (n_h, n_w, 2)
            Sides powers of two, at least 2.
        grid_boundary : {'periodic', 'symmetric'}
            Neighbour rule at the border of the sample grid (spec 01, A13).
        callback : callable, optional
            ``callback(level_done, levels)`` after each level.
        """
        T = self._check_map(coords)
        levels = int(round(math.log2(min(T.shape[:2]))))
        details = {}
        for level in range(1, levels + 1):
            width = self.width(level)
            Y = self.embedding(width)[0]
            for axis in (0, 1):
                even, odd = _split(T, axis)
                predicted = self.predict(even, axis, level, grid_boundary)
                details[(level, axis)] = Y[self._flat(predicted)] - Y[self._flat(odd)]
                T = even
            if callback is not None:
                callback(level, levels)
        return PatchWaveletCoefficients(T.copy(), levels, details, grid_boundary)

    def inverse(
        self,
        coefficients: PatchWaveletCoefficients,
        *,
        callback: Callable[[int, int, np.ndarray], None] | None = None,
    ) -> np.ndarray:
        """Backward transform (paper Table 2): the ``coefficients.shape + (2,)`` coordinate map.

        Odd samples with an exactly zero detail take the prediction itself (A16), so zero
        details need no embedding; others take ``gamma^-1(gamma(prediction) - d)``.

        Parameters
        ----------
        callback : callable, optional
            ``callback(levels_done, levels, T)`` with the coordinate map after each level
            (the paper's Fig. 4 progression; sides double each time).
        """
        T = np.asarray(coefficients.coarse, dtype=np.int64)
        top = coefficients.top_level
        for level in range(top, 0, -1):
            width = self.width(level)
            for axis in (1, 0):
                predicted = self.predict(T, axis, level, coefficients.grid_boundary)
                d = coefficients[(level, axis)]
                odd = predicted
                if d is not None:
                    if d.shape[:2] != T.shape[:2]:
                        raise ValueError(
                            f"details of level {level}, axis {axis} have shape {d.shape[:2]}, expected {T.shape[:2]}"
                        )
                    moved = np.any(d != 0, axis=-1)
                    if moved.any():
                        Y, tree = self.embedding(width)
                        target = Y[self._flat(predicted[moved])] - d[moved]
                        odd = predicted.copy()
                        odd[moved] = self._coords(tree.query(target)[1])
                T = _interleave(T, odd, axis)
            if callback is not None:
                callback(top - level + 1, top, T)
        return T

    def estimate_features(self, image: np.ndarray) -> np.ndarray:
        """Best-fitting exemplar position of every pixel of ``image`` (paper eq. 4, spec 01 4.4).

        Windows of ``feature_width`` centred on each pixel (the image extended symmetrically)
        are matched to every exemplar window; the image must have the exemplar's channels.
        """
        img = np.asarray(as_channels(np.asarray(image)), dtype=np.float64)
        if img.shape[2] != self.windows.channels:
            raise ValueError(
                f"image has {img.shape[2]} channels but the exemplar has {self.windows.channels}"
            )
        source = ExemplarWindows(img, "symmetric", max_resolution=self.windows.max_resolution)
        h, w = img.shape[:2]
        rows, cols = np.divmod(np.arange(h * w), w)
        width = self.feature_width
        index = self.index(width)
        out = np.empty(h * w, dtype=np.int64)
        chunk = max(1, 2**22 // max(1, self.windows.dimension(width)))
        for start in range(0, h * w, chunk):
            queries = source.descriptors(rows[start : start + chunk], cols[start : start + chunk], width)
            out[start : start + chunk] = index.query(queries)[0]
        return self._coords(out).reshape(h, w, 2)

    def _check_map(self, coords: np.ndarray) -> np.ndarray:
        T = np.asarray(coords)
        if T.ndim != 3 or T.shape[2] != 2:
            raise ValueError(f"coordinate map must have shape (n_h, n_w, 2), got {T.shape}")
        for n in T.shape[:2]:
            if n < 2 or n & (n - 1):
                raise ValueError(f"coordinate map sides must be powers of two >= 2, got {T.shape[:2]}")
        h, w = self.exemplar_shape
        if T.min() < 0 or T[..., 0].max() >= h or T[..., 1].max() >= w:
            raise ValueError("coordinate map holds positions outside the exemplar")
        return T.astype(np.int64)
