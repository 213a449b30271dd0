"""An approximate Efros–Leung search: k-coherent candidates with exact distances.

:class:`CoherentWindows` stands for :class:`~texsyn.ops.nonparametric.NonParametricSampler`
in :func:`texsyn.drivers.raster.grow_pixels` when a method asks for ``search='approximate'``
(``docs/methods/efros_leung.md``, "Approximate search"): each pixel compares a few dozen
exemplar windows instead of all of them.
"""

from __future__ import annotations

import numpy as np

from .jit import jit
from .linalg import matmul
from .patches import as_channels
from .window_screen import window_ssd, wrap_pixel

__all__ = ["CoherentWindows"]

#: windows on either side in the order of the first principal axis among which the approximate
#: search's table looks for each window's most similar ones (:class:`CoherentWindows`)
REACH = 32


@jit()
def _similar_windows(projected, order, k, reach, out):  # pragma: no cover - compiled
    """For every row of ``projected``, the ``k`` other rows nearest to it (squared distance,
    ties: the lower row) among the ``reach`` before and after it in ``order`` (the rows
    sorted by their first coordinate)."""
    n, dims = projected.shape
    values = np.empty(k)
    for q in range(n):
        i = order[q]
        values[:] = np.inf
        out[i, :] = i
        for p in range(max(0, q - reach), min(n, q + reach + 1)):
            j = order[p]
            if j == i:
                continue
            v = 0.0
            for d in range(dims):
                diff = projected[i, d] - projected[j, d]
                v += diff * diff
            if v < values[k - 1] or (v == values[k - 1] and j < out[i, k - 1]):
                t = k - 1
                while t > 0 and (values[t - 1] > v or (values[t - 1] == v and out[i, t - 1] > j)):
                    values[t] = values[t - 1]
                    out[i, t] = out[i, t - 1]
                    t -= 1
                values[t] = v
                out[i, t] = j


@jit()
def _coherent_pass(
    rows,
    cols,
    uniforms,
    values,
    filled,
    source,
    planes,
    gauss,
    similar,
    tolerance,
    accept,
    stamp,
    first_stamp,
    wrap,
):  # pragma: no cover - compiled
    """One pass of the approximate growth, pixel by pixel in list order (see :class:`CoherentWindows`).

    Pixel ``(rows[i], cols[i])`` of the output (top-left of its window in the padded
    ``values``/``filled`` canvas) gets the Efros-Leung rule among its candidates: the
    continuations of its filled 8-neighbours' sources, moved inside the exemplar, and the
    ``similar`` windows of each; distances are exact (Gaussian-weighted SSD over the known
    pixels, per unit weight). ``stamp`` (one int per window) marks the candidates already
    listed for a pixel. With ``wrap`` the output is a torus: the neighbours and the padding
    wrap around its edges, and every pixel written is copied across the wraps
    (:func:`~texsyn.ops.window_screen.wrap_pixel`). Returns, per pixel, the chosen window
    (``-1`` when refused).
    """
    w = gauss.shape[0]
    r = w // 2
    channels = planes.shape[0]
    grid_rows = planes.shape[1] - w + 1
    grid_cols = planes.shape[2] - w + 1
    n_similar = similar.shape[1]
    size = w * w
    oy = np.empty(size, np.int64)
    ox = np.empty(size, np.int64)
    weights = np.empty(size)
    known = np.empty((size, channels))
    cand = np.empty(9 * (1 + n_similar), np.int64)
    dist = np.empty(9 * (1 + n_similar))
    chosen = np.full(rows.size, -1, np.int64)
    height, width = source.shape[0], source.shape[1]
    for i in range(rows.size):
        top, left = rows[i], cols[i]
        count = 0
        norm = 0.0
        for y in range(w):
            for x in range(w):
                if filled[top + y, left + x]:
                    oy[count] = y
                    ox[count] = x
                    weights[count] = gauss[y, x]
                    norm += gauss[y, x]
                    for c in range(channels):
                        known[count, c] = values[top + y, left + x, c]
                    count += 1
        n_cand = 0
        mark = first_stamp + i
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                if not filled[top + r + dy, left + r + dx] or (dy == 0 and dx == 0):
                    continue
                # the window whose centre continues this neighbour's source
                ny, nx = top + dy, left + dx
                if wrap:  # the neighbour across an edge of the torus
                    ny, nx = ny % height, nx % width
                a = min(max(source[ny, nx, 0] - dy - r, 0), grid_rows - 1)
                b = min(max(source[ny, nx, 1] - dx - r, 0), grid_cols - 1)
                j = a * grid_cols + b
                for t in range(n_similar + 1):
                    if t > 0:
                        j = similar[a * grid_cols + b, t - 1]
                    if stamp[j] != mark:
                        stamp[j] = mark
                        cand[n_cand] = j
                        n_cand += 1
        if n_cand == 0:
            continue
        cand[:n_cand].sort()
        best = np.inf
        for k in range(n_cand):
            a = cand[k] // grid_cols
            b = cand[k] - a * grid_cols
            dist[k] = window_ssd(planes, a, b, oy, ox, weights, known, count) / norm
            best = min(best, dist[k])
        threshold = best * (1.0 + tolerance) + 1e-10
        inside = 0
        for k in range(n_cand):
            if dist[k] <= threshold:
                inside += 1
        target = min(int(uniforms[i] * inside), inside - 1)
        seen = 0
        pick = 0
        for k in range(n_cand):
            if dist[k] <= threshold:
                if seen == target:
                    pick = k
                    break
                seen += 1
        if dist[pick] > accept:
            continue
        a = cand[pick] // grid_cols + r
        b = cand[pick] - (cand[pick] // grid_cols) * grid_cols + r
        chosen[i] = cand[pick]
        for c in range(channels):
            values[top + r, left + r, c] = planes[c, a, b]
        filled[top + r, left + r] = True
        if wrap:
            wrap_pixel(values, filled, top + r, left + r, r)
        source[top, left, 0] = a
        source[top, left, 1] = b
    return chosen


class CoherentWindows:
    """An approximate Efros-Leung search: few candidates per pixel, exact distances.

    The candidates of a pixel are the windows that continue the sources of its filled
    8-neighbours (Ashikhmin 2001, section 3; moved inside the exemplar where they leave it),
    and for each of them its ``k`` most similar exemplar windows, from a table built once
    here (k-coherence: Tong, Zhang, Liu, Guo, Shum, *Synthesis of bidirectional texture
    functions on arbitrary surfaces*, SIGGRAPH 2002, section 3). Their distances are the
    exact Gaussian-weighted SSD over the known pixels, and Efros and Leung's tolerance rule
    picks among them; the exhaustive search is :class:`NonParametricSampler`
    (``docs/methods/efros_leung.md``, "Approximate search").

    The table ranks windows by their Gaussian-weighted SSD, approximated by its projection
    on the ``dims`` principal axes of the weighted windows (the exemplar's PCA, as the IPOL
    code of Aguerrebere, Gousseau and Tartavel uses for its accelerated search).

    Parameters
    ----------
    exemplar : ndarray, shape (H0, W0) or (H0, W0, C)
    window : int
        Odd side of the window.
    k : int
        Similar windows per continuation (0: the continuations only).
    dims : int
        Principal axes used to rank similar windows.
    """

    def __init__(self, exemplar: np.ndarray, window: int = 11, *, k: int = 4, dims: int = 8):
        self.exemplar = as_channels(np.asarray(exemplar, dtype=np.float64))
        self.window = int(window)
        radius = self.window // 2
        grid = np.arange(self.window) - radius
        sigma = self.window / 6.4
        self.gauss = np.exp(-(grid[:, None] ** 2 + grid[None, :] ** 2) / (2.0 * sigma**2))
        self.planes = np.ascontiguousarray(np.moveaxis(self.exemplar, 2, 0))
        height, width, channels = self.exemplar.shape
        grid_rows, grid_cols = height - self.window + 1, width - self.window + 1
        if grid_rows < 1 or grid_cols < 1:
            raise ValueError(f"window {self.window} is larger than the exemplar ({width}x{height})")
        rows, cols = np.meshgrid(np.arange(grid_rows), np.arange(grid_cols), indexing="ij")
        self.centres = np.stack([rows.ravel(), cols.ravel()], axis=1) + radius  # extract_patches' order
        n = grid_rows * grid_cols
        k = int(min(max(k, 0), n - 1))
        self.similar = np.zeros((n, k), dtype=np.int64)
        if k > 0:
            view = np.lib.stride_tricks.sliding_window_view(
                self.exemplar.astype(np.float32), (self.window, self.window), axis=(0, 1)
            )
            patches = np.ascontiguousarray(view.transpose(0, 1, 3, 4, 2)).reshape(n, -1)
            scale = np.repeat(np.sqrt(self.gauss).ravel(), channels)  # the SSD's weights, square-rooted
            sample = patches[:: max(1, n // 4096)].astype(np.float64) * scale
            sample -= sample.mean(axis=0)
            _, vectors = np.linalg.eigh(matmul(sample.T, sample))
            axes = vectors[:, ::-1][:, : min(dims, vectors.shape[1])] * scale[:, None]
            projected = matmul(patches, axes.astype(np.float32))
            order = np.argsort(projected[:, 0], kind="stable")
            _similar_windows(projected, order, k, REACH, self.similar)

    @property
    def n_windows(self) -> int:
        """Number of exemplar windows."""
        return self.centres.shape[0]

    def grow_pass(
        self,
        rows: np.ndarray,
        cols: np.ndarray,
        uniforms: np.ndarray,
        values: np.ndarray,
        filled: np.ndarray,
        source: np.ndarray,
        tolerance: float,
        accept: float,
        stamp: np.ndarray,
        first_stamp: int,
        wrap: bool = False,
    ) -> np.ndarray:
        """Fill the pixels of one pass of :func:`~texsyn.drivers.raster.grow_pixels`, in order.

        Parameters
        ----------
        rows, cols : ndarray of int64
            The pixels (output coordinates), in the order they are filled.
        uniforms : ndarray, shape (n,)
            One uniform draw per pixel: which candidate is taken.
        values, filled : ndarray
            The padded canvas (``window // 2`` on each side) and its mask, updated in place.
        source : ndarray of int64, shape (H, W, 2)
            The source map, updated in place.
        tolerance, accept : float
            Efros and Leung's tolerance and the largest accepted distance.
        stamp : ndarray of int64, shape (N,)
            Marks of candidates already listed; values below ``first_stamp`` mean none.
        first_stamp : int
            Mark of the first pixel (the next pass starts at ``first_stamp + n``).
        wrap : bool
            The output is a torus (``docs/tiling.md``): a pixel's 8-neighbours wrap around
            its edges, and every pixel written is copied across the wraps into the padding.

        Returns
        -------
        ndarray of int64, shape (n,)
            The window chosen for every pixel, ``-1`` where it was refused (the distance of
            the best candidate above ``accept``) or had no candidate.
        """
        chosen = _coherent_pass(
            rows,
            cols,
            uniforms,
            values,
            filled,
            source,
            self.planes,
            self.gauss,
            self.similar,
            float(tolerance),
            float(accept),
            stamp,
            first_stamp,
            bool(wrap),
        )
        return chosen
