"""Wei-Levoy multiresolution pixel synthesis with causal neighbourhoods (Wei and Levoy 2000).

Both exemplar and output are Gaussian pyramids; the output starts as noise with the
exemplar's histogram and is synthesised coarse to fine, each level in raster order: every
pixel takes the value of the exemplar pixel whose neighbourhood (the causal L-shaped half of
a ``window x window`` square at the same level, plus the full ``parent x parent`` square at
the next coarser level) is nearest. Both images are treated toroidally, as in the paper.
The search is exact, or approximate with the paper's tree-structured vector quantisation
(``search='tsvq'``).

Vectorisation: pixels are visited along wavefronts ``x + (r + 1) y = t`` (``r = window // 2``)
and each wavefront is searched with one matrix product. A pixel's causal neighbourhood only
reaches ``r`` columns to the right in the rows above and ``r`` to the left in its own row, so
every pixel sees exactly what raster order would show it -- except the few pixels of the
first ``r`` columns, whose toroidally wrapped neighbours at the end of the previous row are
not synthesised yet (they hold the initial noise, as the wrapped rows of the first line do in
the paper).

References
----------
L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
SIGGRAPH 2000, sections 2-3.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from .._validation import OneOf, Range
from ..ops import as_channels, gaussian_pyramid
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, output_bytes, pixel_count
from ..errors import InputError
from ..ops.linalg import matmul

__all__ = ["WeiLevoy", "causal_offsets", "TSVQ"]


def causal_offsets(window: int) -> np.ndarray:
    """Offsets ``(dy, dx)`` of the pixels before the centre, in raster order, in a square window."""
    r = window // 2
    return np.array([(dy, dx) for dy in range(-r, 1) for dx in range(-r, r + 1) if dy < 0 or dx < 0])


def square_offsets(window: int) -> np.ndarray:
    r = window // 2
    return np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])


def _gather(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Toroidal neighbourhood vectors ``(n, len(offsets) * C)`` at the given pixels."""
    h, w = image.shape[:2]
    rr = (rows[:, None] + offsets[None, :, 0]) % h
    cc = (cols[:, None] + offsets[None, :, 1]) % w
    return image[rr, cc].reshape(len(rows), -1)


class TSVQ:
    """Tree-structured vector quantiser: recursive 2-means splits of the neighbourhoods.

    A query descends to the child with the nearer centroid and is answered by an exact
    search among the (few) vectors of the leaf it reaches (Wei and Levoy 2000, section 3.2).

    Parameters
    ----------
    vectors : ndarray, shape (K, D)
    leaf_size : int
    rng : numpy.random.Generator
    """

    def __init__(self, vectors: np.ndarray, leaf_size: int, rng: np.random.Generator):
        self.vectors = vectors
        self.centroids: list[np.ndarray] = []
        self.children: list[tuple[int, int]] = []
        self.members: list[np.ndarray | None] = []
        self._build(np.arange(len(vectors)), leaf_size, rng)

    def _build(self, index: np.ndarray, leaf_size: int, rng) -> int:
        node = len(self.centroids)
        data = self.vectors[index]
        self.centroids.append(data.mean(axis=0))
        self.children.append((-1, -1))
        self.members.append(None)
        if len(index) <= leaf_size:
            self.members[node] = index
            return node
        centres = data[rng.choice(len(index), 2, replace=False)]
        for _ in range(8):  # Lloyd iterations
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
        node = 0
        while self.members[node] is None:
            left, right = self.children[node]
            dl = np.sum((self.centroids[left] - q) ** 2)
            dr = np.sum((self.centroids[right] - q) ** 2)
            node = left if dl <= dr else right
        idx = self.members[node]
        d = np.sum((self.vectors[idx] - q) ** 2, axis=1)
        return int(idx[np.argmin(d)])


class WeiLevoy(TextureSynthesizer):
    """Wei-Levoy synthesis: multiresolution raster-order pixel sampling.

    Parameters
    ----------
    levels : int
        Number of Gaussian pyramid levels.
    window : int
        Odd side of the neighbourhood square at the current level (its causal half is used).
    parent_window : int
        Odd side of the full square neighbourhood at the next coarser level.
    search : str
        'exact' nearest neighbourhood, or 'tsvq' (the original tree-structured vector
        quantisation, approximate and faster on large exemplars).
    leaf_size : int
        Vectors per leaf of the TSVQ tree.
    random_state : int
        Seed of the TSVQ construction in fit.

    References
    ----------
    L.-Y. Wei, M. Levoy, "Fast texture synthesis using tree-structured vector quantization",
    SIGGRAPH 2000.
    """

    name = "wei_levoy"
    summary = "Wei-Levoy multiresolution synthesis with causal neighbourhoods"
    reference = "Wei, Levoy, SIGGRAPH 2000"
    has_source_map = True

    def __init__(
        self,
        *,
        levels: Annotated[int, Range(1, 6)] = 4,
        window: Annotated[int, Range(3, 21)] = 9,
        parent_window: Annotated[int, Range(1, 21)] = 5,
        search: Annotated[str, OneOf(("exact", "tsvq"))] = "exact",
        leaf_size: Annotated[int, Range(1, 4096)] = 32,
        random_state: Annotated[int, Range(0, 2**32 - 1)] = 0,
    ):
        self.levels = levels
        self.window = window
        self.parent_window = parent_window
        self.search = search
        self.leaf_size = leaf_size
        self.random_state = random_state

    def _check_params(self) -> None:
        super()._check_params()
        for name in ("window", "parent_window"):
            if getattr(self, name) % 2 == 0:
                raise InputError(f"parameter {name!r} of method 'wei_levoy' must be odd, got {getattr(self, name)}")

    def min_exemplar_size(self):
        side = max(2 ** (self.levels - 1) * 2, self.window // 2 + 1)
        return side, f"levels={self.levels} needs at least {side}x{side} pixels"

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Neighbourhood banks of every exemplar pixel and level; one wavefront of searches.

        An exact search compares a whole wavefront (about ``width / (window // 2 + 1)``
        pixels) with every exemplar pixel at once (``docs/memory.md``).
        """
        h, w, c = shape_dims(exemplar_shape)
        causal = (self.window**2 - 1) // 2
        parent = self.parent_window**2
        sizes = [(h, w)]
        for _ in range(self.levels - 1):
            sizes.append(((sizes[-1][0] + 1) // 2, (sizes[-1][1] + 1) // 2))
        kept, peak, dims = 8.0 * h * w * c * 7 / 3, 0.0, []
        for level, (sh, sw) in enumerate(sizes):  # the finest (largest) level is built first
            k = float(sh * sw)
            dim = (causal + (parent if level + 1 < self.levels else 0)) * c
            dims.append(dim)
            # the gathered parts, the bank and its squares (for the norms) coexist
            widest = max(causal, parent)
            build = max(20.0 * k * dim, 24.0 * k * widest + 8.0 * k * widest * c)
            if self.search == "tsvq":
                build = max(build, 40.0 * k * dim)
            peak = max(peak, kept + 8.0 * k * dim + build)
            kept += 8.0 * k * dim + 8.0 * k
            if self.search == "tsvq":
                kept += 16.0 * k * dim / max(1, self.leaf_size) + 16.0 * k
        terms = {"exemplar pyramid and neighbourhood banks": kept}
        if output_shape is None:
            terms["bank construction"] = max(0.0, peak - kept)
            return terms
        oh, ow = output_shape[:2]
        slope = self.window // 2 + 1
        front = 0.0
        out_sizes = [(oh, ow)]
        for _ in range(self.levels - 1):
            out_sizes.append(((out_sizes[-1][0] + 1) // 2, (out_sizes[-1][1] + 1) // 2))
        for level, (sh, sw) in enumerate(out_sizes):
            n = float(min(sh, -(-sw // slope)))
            k = float(sizes[level][0] * sizes[level][1])
            search = 24.0 * n * k if self.search == "exact" else 0.0
            front = max(front, 24.0 * n * dims[level] + 16.0 * n * max(causal, parent) + search)
        pixels = pixel_count(output_shape)
        terms["one wavefront of searches"] = front
        terms["output pyramid and source maps"] = pixels * (4.0 / 3 * 8.0 * c + 16.0 * c + 56.0)
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        self.pyramid_ = gaussian_pyramid(ex, self.levels, sigma=1.0)
        self.causal_ = causal_offsets(self.window)
        self.parent_ = square_offsets(self.parent_window)
        rng = np.random.default_rng(self.random_state)
        self.banks_, self.norms_, self.trees_ = [], [], []
        for level, image in enumerate(self.pyramid_):
            rows, cols = np.divmod(np.arange(image.shape[0] * image.shape[1]), image.shape[1])
            parts = [_gather(image, rows, cols, self.causal_)]
            if level + 1 < self.levels:
                parts.append(_gather(self.pyramid_[level + 1], rows // 2, cols // 2, self.parent_))
            bank = np.ascontiguousarray(np.concatenate(parts, axis=1))
            self.banks_.append(bank)
            self.norms_.append(np.sum(bank * bank, axis=1))
            self.trees_.append(TSVQ(bank, self.leaf_size, rng) if self.search == "tsvq" else None)

    def _sample(self, shape, rng, callback):
        sizes = [shape]
        for _ in range(self.levels - 1):
            sizes.append(((sizes[-1][0] + 1) // 2, (sizes[-1][1] + 1) // 2))
        outputs: list[np.ndarray | None] = [None] * self.levels
        source = None
        total = sum(h * w for h, w in sizes)
        done = 0
        for level in reversed(range(self.levels)):
            ex = self.pyramid_[level]
            h, w = sizes[level]
            flat_ex = ex.reshape(-1, ex.shape[2])
            out = flat_ex[rng.integers(len(flat_ex), size=h * w)].reshape(h, w, ex.shape[2]).copy()
            src = np.zeros((h, w), dtype=np.int64)
            bank, norms, tree = self.banks_[level], self.norms_[level], self.trees_[level]
            parent = outputs[level + 1] if level + 1 < self.levels else None
            slope = self.window // 2 + 1
            ys_all = np.arange(h)
            for t in range(w + slope * (h - 1)):
                xs = t - slope * ys_all
                ok = (xs >= 0) & (xs < w)
                ys, xs = ys_all[ok], xs[ok]
                if ys.size == 0:
                    continue
                q = _gather(out, ys, xs, self.causal_)
                if parent is not None:
                    q = np.concatenate([q, _gather(parent, ys // 2, xs // 2, self.parent_)], axis=1)
                if tree is not None:
                    best = np.array([tree.query(v) for v in q])
                else:
                    best = np.argmin(norms[None, :] - 2.0 * matmul(q, bank.T), axis=1)
                out[ys, xs] = flat_ex[best]
                src[ys, xs] = best
                done += len(ys)
                if callback is not None and t % 64 == 0:
                    callback(Progress(f"level {self.levels - level}/{self.levels}", done, total))
            outputs[level] = out
            source = src
        ex_w = self.pyramid_[0].shape[1]
        source_map = np.stack(np.divmod(source, ex_w), axis=-1)
        return outputs[0], source_map
