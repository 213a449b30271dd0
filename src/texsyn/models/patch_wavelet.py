"""What the patch-valued wavelet transform learns from an exemplar (Peyré 2007, sections 2-4).

- :class:`ExemplarWindows`: the windows of the extended exemplar and their block-averaged
  descriptors (the patch manifold ``M^w`` of section 2) and the glued windows of the
  association-field mean (section 3);
- :func:`lle_embedding` and :class:`PatchEmbedding` (from :mod:`.patch_embedding`): the
  parameterisation ``gamma_W`` of section 4 (locally linear embedding) and its inverse;
- :class:`PatchWaveletTransform`: the transform of one exemplar, the lifting scheme of
  :mod:`texsyn.transforms.patch_wavelet` over these windows, with a nearest-patch index per
  window width and the embeddings it was asked for.

Everything is built in the constructors and never changed afterwards (assigning an attribute
raises): a fitted transform can be shared between threads or pickled for batch workers. What
was not built ahead is built for the call that needs it (``docs/methods/patch_wavelet.md``).

Why this module is long: the exemplar's windows and the transform over them belong together
(the transform's constructor builds, from the windows, every index, proven fast search and
embedding a walk may use); the fast search itself is :mod:`texsyn.models.patch_search`.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Iterable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..ops.linalg import BLOCK_ROWS
from ..ops.patches import as_channels, wrap_seam_ratio
from ..ops.search import NearestPatchIndex
from ..transforms.patch_wavelet import PatchLifting, largest_width
from .patch_embedding import PatchEmbedding, lle_embedding
from .patch_search import FastSearch, proven_mean_features

__all__ = ["QUERY_BLOCK", "ExemplarWindows", "PatchEmbedding", "PatchWaveletTransform", "lle_embedding"]


class _Immutable:
    """Instances refuse attribute assignment once their constructor has sealed them."""

    _sealed = False

    def __setattr__(self, name: str, value: object) -> None:
        if self._sealed:
            raise AttributeError(f"{type(self).__name__} is immutable: {name!r} cannot be set")
        object.__setattr__(self, name, value)

    def _seal(self) -> None:
        object.__setattr__(self, "_sealed", True)


class _FrozenDict(dict):
    """A dict that refuses changes (and still pickles, unlike a mapping proxy)."""

    def _refuse(self, *args: object, **kwargs: object) -> None:
        raise TypeError(f"{type(self).__name__} is immutable")

    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _refuse  # type: ignore[assignment]

    def __reduce__(self):
        return (type(self), (dict(self),))


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


#: queries of one product of a nearest-patch index: one tile of rows of
#: :func:`texsyn.ops.linalg.matmul`, so that the products' bytes are those of any larger
#: multiple of it, and ``QUERY_BLOCK x H W`` float32 products stay small (16 MiB for a
#: 128 x 128 exemplar) and are reused by the allocator from block to block
QUERY_BLOCK = BLOCK_ROWS
#: float64 values of the descriptors made at once while an index is built (2 MiB)
_PART_VALUES = 2**18


def _running_means(image: np.ndarray, b: int, axis: int) -> np.ndarray:
    """Means of ``image`` over ``[i, i + b)`` along ``axis``, periodic, for every ``i``.

    A running sum: the first window summed term by term, then one entry in and one out per
    step (a sequential cumulative sum), each divided by ``b`` at the end; these are the
    very operations of SciPy's ``uniform_filter1d(mode='wrap', origin=-(b // 2))``, so the
    values are the same to the bit (``tests/test_patch_wavelet_speed.py``), without
    importing ``scipy.ndimage`` (about 0.2 s of start-up, ``docs/performance.md``).
    """
    x = np.moveaxis(image, axis, 0)
    n = x.shape[0]
    extended = np.take(x, np.arange(n + b - 1), axis=0, mode="wrap")
    steps = np.empty_like(x)
    first = np.zeros(x.shape[1:])
    for k in range(b):
        first += extended[k]
    steps[0] = first
    np.subtract(extended[b : b + n - 1], extended[: n - 1], out=steps[1:])
    sums = np.cumsum(steps, axis=0, out=steps)
    return np.moveaxis(np.divide(sums, b, out=sums), 0, axis)


def periodic_block_means(image: np.ndarray, b: int) -> np.ndarray:
    """Mean of the ``b x b`` block starting at every position of a periodic ``(H, W, C)`` image.

    Rows first, then columns (the order of ``scipy.ndimage.uniform_filter(image,
    size=(b, b, 1), mode='wrap', origin=(-(b // 2), -(b // 2), 0))``, whose values these are).
    """
    image = np.asarray(image, dtype=np.float64)
    if b == 1:
        return image.copy()
    return np.ascontiguousarray(_running_means(_running_means(image, b, 0), b, 1))


def _window_rows(windows: ExemplarWindows, ecols: int, width: int, flat: np.ndarray) -> np.ndarray:
    """Exact descriptors of the exemplar windows at flat positions (a picklable re-ranking source)."""
    return windows.descriptors(flat // ecols, flat % ecols, width)


class ExemplarWindows(_Immutable):
    """Square windows of an extended image, described by block-averaged pixels (section 2).

    The window of even width ``W`` centred on the integer position ``t`` covers
    ``t + x`` for ``x`` in ``{-W/2, ..., W/2 - 1}^2`` (so the centre pixel is the displayed
    value). Its descriptor is the window itself when ``W <= max_resolution``, otherwise the
    means of its non-overlapping ``b x b`` blocks, ``b = W / max_resolution``, flattened in
    C order of shape ``(m, m, C)`` with ``m = W / b``.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    boundary : {'periodic', 'symmetric'}
        Extension outside the image.
    max_resolution : int
        Largest number of blocks per side of a descriptor (``r_max``), a power of two.
    widths : iterable of int
        Window widths whose block means are computed now and kept; other widths compute
        theirs on each use.
    """

    def __init__(
        self,
        image: np.ndarray,
        boundary: str = "symmetric",
        *,
        max_resolution: int = 16,
        widths: Iterable[int] = (),
    ):
        if boundary not in ("periodic", "symmetric"):
            raise ValueError(f"boundary must be 'periodic' or 'symmetric', got {boundary!r}")
        img = np.array(as_channels(np.asarray(image)), dtype=np.float64)
        self.image = _read_only(img)
        self.shape = img.shape[:2]
        self.boundary = boundary
        self.max_resolution = int(max_resolution)
        if boundary == "periodic":
            period = img
        else:  # one period of the mirrored extension: 2H x 2W
            tall = np.concatenate([img, img[::-1]], axis=0)
            period = _read_only(np.concatenate([tall, tall[:, ::-1]], axis=1))
        self.period_image = period
        sides = sorted({self.layout(int(w))[0] for w in widths})
        self.means = _FrozenDict({b: _read_only(self._compute_means(b)) for b in sides})
        self._seal()

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

    def _compute_means(self, b: int) -> np.ndarray:
        # mean over [y, y+b) x [x, x+b) of the periodic image, for every (y, x)
        return periodic_block_means(self.period_image, b)

    def block_means(self, b: int) -> np.ndarray:
        """Means of the ``b x b`` blocks starting at every position of one period."""
        found = self.means.get(b)
        return self._compute_means(b) if found is None else found

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
        means = self.block_means(b)
        ph, pw = means.shape[:2]
        r = np.mod(np.asarray(rows, dtype=np.int64)[:, None] - width // 2 + b * u[None, :], ph)
        c = np.mod(np.asarray(cols, dtype=np.int64)[:, None] - width // 2 + b * v[None, :], pw)
        return means[r[:, :, None], c[:, None, :]]

    def descriptors(self, rows: np.ndarray, cols: np.ndarray, width: int) -> np.ndarray:
        """Descriptors ``(n, D)`` of the windows of ``width`` centred on ``(rows, cols)``."""
        out = self.blocks(rows, cols, width)
        return out.reshape(out.shape[0], -1)

    def fill_row_descriptors(
        self, width: int, start: int, stop: int, out: np.ndarray, offset: np.ndarray | None = None
    ) -> np.ndarray:
        """Descriptors of the windows centred on every position of the image rows ``[start, stop)``.

        The same values as :meth:`descriptors` of those positions in C order, less ``offset``
        (``(D,)``, none by default), written into ``out`` (float64, ``((stop - start) W, D)``)
        and returned. The windows are strided views of the rows they cover, copied once,
        instead of a gather through index arrays (several times faster, and no index arrays).
        """
        b, m = self.layout(width)
        means = self.block_means(b)
        ph, pw = means.shape[:2]
        w = self.shape[1]
        span = b * (m - 1) + 1  # block starts covered by one window, along each axis
        r = np.arange(start - width // 2, stop - width // 2 + span - 1) % ph
        c = np.arange(-(width // 2), w - width // 2 + span - 1) % pw
        covered = means[r][:, c]
        windows = sliding_window_view(covered, (span, span), axis=(0, 1))[..., ::b, ::b]  # (n, w, C, m, m)
        windows = windows.transpose(0, 1, 3, 4, 2)
        np.copyto(out.reshape(stop - start, w, m, m, -1), windows)
        if offset is not None:
            np.subtract(out, offset, out=out)
        return out

    def all_descriptors(self, width: int) -> np.ndarray:
        """Descriptors ``(H W, D)`` of the windows centred on every position, in C order."""
        h, w = self.shape
        return self.fill_row_descriptors(width, 0, h, np.empty((h * w, self.dimension(width))))

    def mean_descriptors(
        self, first: np.ndarray, second: np.ndarray, axis: int, half_distance: int, width: int
    ) -> np.ndarray:
        """Descriptors of the glued windows ``mu`` of the association-field mean (section 3).

        ``mu(x) = E(ta + s e_a + x)`` where ``x_a < 0`` and ``E(tb - s e_a + x)`` elsewhere:
        the half of the first feature's continuation toward the midpoint, glued to the half of
        the second feature's. With ``width = 2 s`` this is the paper's "right half of g with
        the left half of g'".

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


#: an exemplar tiles when its wrap-around seam is at most this many times its interior's
#: neighbour differences (:func:`~texsyn.ops.wrap_seam_ratio`)
WRAP_SEAM_LIMIT = 1.5


class PatchWaveletTransform(_Immutable, PatchLifting):
    """The patch-valued wavelet transform of one exemplar (Peyré 2007, section 4).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, C)
        The texture whose patches are the features.
    min_width, max_width : int or None
        Patch width of level ``j`` is ``clamp(2^j, min_width, max_width)``;
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
    rng : int
        Seed of the LLE eigen-solver's start vector.
    random_state : int, optional
        Deprecated name of ``rng``.
    widths : iterable of int or None
        Widths whose nearest-patch index is built now (all of :meth:`widths` by default).
    embedding_widths : iterable of int
        Widths whose LLE embedding is built now (none by default; :meth:`prepare` builds all).
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
        rng: int = 0,
        random_state: int | None = None,
        widths: Iterable[int] | None = None,
        embedding_widths: Iterable[int] = (),
    ):
        if random_state is not None:
            warnings.warn(
                "PatchWaveletTransform(random_state=...) is deprecated; use rng",
                DeprecationWarning,
                stacklevel=2,
            )
            rng = random_state
        ex = np.asarray(as_channels(np.asarray(exemplar)), dtype=np.float64)
        h, w = ex.shape[:2]
        if exemplar_boundary == "auto":
            exemplar_boundary = "periodic" if wrap_seam_ratio(ex) <= WRAP_SEAM_LIMIT else "symmetric"
        largest = largest_width(ex.shape)
        self.max_width = largest if max_width is None else int(min(max_width, largest))
        if self.max_width < 2:
            raise ValueError(f"exemplar of {w}x{h} pixels is too small: windows need at least 4x4 pixels")
        self.min_width = int(min(min_width, self.max_width))
        self.feature_width = int(min(feature_width or min_width, self.max_width))
        self.embedding_dim = int(embedding_dim)
        self.lle_neighbors = int(lle_neighbors)
        self.lle_points = int(lle_points)
        self.candidates = int(candidates)
        self.rng = int(rng)
        self.exemplar_boundary = exemplar_boundary
        index_widths = self.widths() if widths is None else sorted({int(v) for v in widths})
        embedded = sorted({int(v) for v in embedding_widths})
        self.windows = ExemplarWindows(
            ex, exemplar_boundary, max_resolution=max_resolution, widths=index_widths + embedded
        )
        # width by width, each fast search next to its index: the float64 descriptors a fast
        # search keeps are built once and shared with its index, and no width's build
        # transients overlap another's (docs/memory.md)
        indexes: dict[int, NearestPatchIndex] = {}
        fast: dict[int, FastSearch] = {}
        for v in index_widths:
            bank = self.windows.all_descriptors(v) if FastSearch.eligible(self.windows, v) else None
            indexes[v] = self._build_index(v, bank=bank)
            if (
                bank is not None
                and (found := FastSearch.build(self.windows, indexes[v], v, bank)) is not None
            ):
                fast[v] = found
            del bank
        self.indexes = _FrozenDict(indexes)
        self.fast = _FrozenDict(fast)
        self.embeddings = _FrozenDict({v: self._build_embedding(v) for v in embedded})
        self._seal()

    # ------------------------------------------------------------------ building blocks
    @property
    def random_state(self) -> int:
        """Deprecated name of :attr:`rng`."""
        warnings.warn(
            "PatchWaveletTransform.random_state is deprecated; use rng", DeprecationWarning, stacklevel=2
        )
        return self.rng

    @property
    def exemplar_shape(self) -> tuple[int, int]:
        return self.windows.shape

    def all_positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of every exemplar position, in C order."""
        h, w = self.exemplar_shape
        rows, cols = np.divmod(np.arange(h * w), w)
        return rows, cols

    def _build_index(self, width: int, bank: np.ndarray | None = None) -> NearestPatchIndex:
        """The nearest-patch index of ``width``, built a few image rows at a time.

        ``bank``: the descriptors of every position, when the caller has them; otherwise they
        are made part by part (:meth:`ExemplarWindows.fill_row_descriptors`), so that the
        float64 descriptors are never held whole (:meth:`NearestPatchIndex.from_parts`: the
        same index as from the whole bank).
        """
        h, w = self.exemplar_shape
        dim = self.windows.dimension(width)
        exact_rows = functools.partial(_window_rows, self.windows, w, width)

        def fill(start: int, stop: int, out: np.ndarray, offset: np.ndarray | None) -> None:
            if bank is None:  # parts are whole image rows
                self.windows.fill_row_descriptors(width, start // w, stop // w, out, offset)
            elif offset is None:
                np.copyto(out, bank[start:stop])
            else:
                np.subtract(bank[start:stop], offset, out=out)

        part_rows = w * max(1, _PART_VALUES // (w * dim))
        return NearestPatchIndex.from_parts(
            fill,
            h * w,
            dim,
            part_rows=part_rows,
            rows=exact_rows,
            candidates=self.candidates,
            block=QUERY_BLOCK,
        )

    def _build_embedding(self, width: int) -> PatchEmbedding:
        from scipy.spatial import cKDTree

        Y = lle_embedding(
            self.windows.all_descriptors(width),
            self.exemplar_shape,
            n_components=self.embedding_dim,
            n_neighbors=self.lle_neighbors,
            max_points=self.lle_points,
            rng=self.rng,
        )
        return PatchEmbedding(_read_only(Y), cKDTree(Y))

    def index(self, width: int) -> NearestPatchIndex:
        """Nearest-patch index over the descriptors of every exemplar position of ``width``."""
        found = self.indexes.get(width)
        return self._build_index(width) if found is None else found

    def embedding(self, width: int) -> PatchEmbedding:
        """``(Y, tree)``: LLE coordinates of every exemplar position and a KD-tree on them."""
        found = self.embeddings.get(width)
        return self._build_embedding(width) if found is None else found

    def prepare(self, widths: Iterable[int] | None = None) -> PatchWaveletTransform:
        """A transform with the indexes and embeddings of ``widths`` (all by default) built.

        ``self`` is unchanged; what it has built already is shared with the new transform.
        """
        wanted = self.widths() if widths is None else sorted({int(v) for v in widths})
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        object.__setattr__(
            new, "indexes", _FrozenDict({**self.indexes, **{v: self.index(v) for v in wanted}})
        )
        object.__setattr__(
            new, "embeddings", _FrozenDict({**self.embeddings, **{v: self.embedding(v) for v in wanted}})
        )
        return new

    def image(self, coords: np.ndarray) -> np.ndarray:
        """The displayed image ``E(T)`` of a coordinate map ``(..., 2)``: ``(..., C)``."""
        return self.windows.image[coords[..., 0], coords[..., 1]]

    def _nearest(self, queries_of, n: int, width: int) -> np.ndarray:
        """Flat position of the nearest window of ``width`` to each query, in chunks.

        The index cuts each chunk of ``2^22 / D`` queries into blocks from the chunk's start
        (the tiles of its products, whose bytes depend on them); the queries are made and
        asked a few whole blocks at a time (``2^20`` values), which cuts them the same way
        with a smaller transient.
        """
        index = self.index(width)
        out = np.empty(n, dtype=np.int64)
        dim = max(1, self.windows.dimension(width))
        chunk = max(1, 2**22 // dim)
        part = index.block * max(1, 2**20 // (index.block * dim))
        for start in range(0, n, chunk):
            stop = min(n, start + chunk)
            for a in range(start, stop, part):
                b = min(stop, a + part)
                out[a:b] = index.query(queries_of(a, b))[0]
        return out

    def mean_features(
        self, first: np.ndarray, second: np.ndarray, axis: int, half_distance: int, width: int
    ) -> np.ndarray:
        """``m^omega(first, second)``: the exemplar window nearest to the glued one (section 3)."""
        if (fast := self.fast.get(width)) is not None:  # the same positions, proven (patch_search)
            return proven_mean_features(self, fast, first, second, axis, half_distance, width)
        return self._nearest(
            lambda a, b: self.windows.mean_descriptors(first[a:b], second[a:b], axis, half_distance, width),
            first.shape[0],
            width,
        )

    def estimate_features(self, image: np.ndarray) -> np.ndarray:
        """Best-fitting exemplar position of every pixel of ``image`` (eq. 4).

        Windows of ``feature_width`` centred on each pixel (the image extended symmetrically)
        are matched to every exemplar window; the image must have the exemplar's channels.
        """
        img = np.asarray(as_channels(np.asarray(image)), dtype=np.float64)
        if img.shape[2] != self.windows.channels:
            raise ValueError(
                f"image has {img.shape[2]} channels but the exemplar has {self.windows.channels}"
            )
        width = self.feature_width
        source = ExemplarWindows(
            img, "symmetric", max_resolution=self.windows.max_resolution, widths=(width,)
        )
        h, w = img.shape[:2]
        rows, cols = np.divmod(np.arange(h * w), w)
        out = self._nearest(lambda a, b: source.descriptors(rows[a:b], cols[a:b], width), h * w, width)
        return self.positions(out).reshape(h, w, 2)
