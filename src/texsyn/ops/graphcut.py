"""Exact graph-cut seams with Kwatra's normalised cost, and graph-cut patch re-assembly.

The non-linear reconstruction of Tartavel, Gousseau and Peyré (2013), section 4.1, eq. (8),
with the cost of Kwatra et al. (2003). The minimum cut between the pixels forced to the old
content ``A`` (left column) and those forced to the new patch ``B`` (right column) of a
planar strip is a shortest top-to-bottom path in the dual grid, found exactly by Dijkstra's
algorithm (compiled with numba); the paper's "linear programming" is replaced by this exact
shortest path (``docs/methods/sparse.md``, "Deviations").
"""

from __future__ import annotations

import heapq

import numpy as np

from .jit import jit, prange
from .linalg import worker_count
from .seam_costs import kwatra_costs_stack

__all__ = ["kwatra_costs", "seam_take_old", "cut_value", "graphcut_reassemble"]


def kwatra_costs(old: np.ndarray, new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised costs of Kwatra et al. (2003), Tartavel et al. eq. (8), for 4-adjacent pairs.

    ``M(x1, x2) = (|A(x1)-B(x1)|^2 + |A(x2)-B(x2)|^2) / (|A(x1)-A(x2)|^2 + |B(x1)-B(x2)|^2 + eps)``
    with ``eps = 1e-3 * mean(denominator) + 1e-12``, which keeps flat regions from dividing by
    zero (``docs/methods/sparse.md``).

    Parameters
    ----------
    old, new : ndarray, shape (h, w) or (h, w, C)

    Returns
    -------
    horizontal : ndarray, shape (h, w - 1)
        Cost of the pair ``(r, c)-(r, c+1)``.
    vertical : ndarray, shape (h - 1, w)
        Cost of the pair ``(r, c)-(r+1, c)``.
    """
    a = np.asarray(old, dtype=np.float64)
    b = np.asarray(new, dtype=np.float64)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    cost_h, cost_v = _kwatra_costs_stack(a[None], b[None])
    return cost_h[0], cost_v[0]


def _kwatra_costs_stack(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`kwatra_costs` of a stack of overlaps ``(S, h, w, C)``: ``(S, h, w-1)``, ``(S, h-1, w)``.

    Every sum runs over the last axis of a fresh contiguous array, with the same NumPy
    reductions for one overlap as for many: the costs of each overlap are the bytes of a
    call on it alone (``tests/test_sparse.py``).
    """
    diff = np.sum((a - b) ** 2, axis=3)
    num_h = diff[:, :, :-1] + diff[:, :, 1:]
    num_v = diff[:, :-1, :] + diff[:, 1:, :]
    den_h = np.sum((a[:, :, :-1] - a[:, :, 1:]) ** 2 + (b[:, :, :-1] - b[:, :, 1:]) ** 2, axis=3)
    den_v = np.sum((a[:, :-1] - a[:, 1:]) ** 2 + (b[:, :-1] - b[:, 1:]) ** 2, axis=3)
    count = a.shape[0]
    if den_h[0].size + den_v[0].size:
        mean_den = np.concatenate([den_h.reshape(count, -1), den_v.reshape(count, -1)], axis=1).mean(axis=1)
    else:
        mean_den = np.zeros(count)
    eps = (1e-3 * mean_den + 1e-12)[:, None, None]
    return num_h / (den_h + eps), num_v / (den_v + eps)


@jit()
def _dual_shortest_cut(cost_h, cost_v):
    """Minimum cut separating column 0 from column w-1, as a dual shortest path.

    Dual node ``(r, c)``, ``r in 0..h``, ``c in 1..w-1``, is the lattice corner left of pixel
    column ``c``. Moving down ``(r, c) -> (r+1, c)`` crosses the pair ``((r, c-1), (r, c))``;
    moving sideways ``(r, c) -> (r, c+1)`` on an interior row boundary crosses
    ``((r-1, c), (r, c))``. Returns boolean masks of the crossed horizontal and vertical pairs.
    """
    h = cost_h.shape[0]
    w = cost_h.shape[1] + 1
    nc = w - 1
    n_nodes = (h + 1) * nc
    dist = np.full(n_nodes, np.inf)
    prev = np.full(n_nodes, -1, np.int64)
    done = np.zeros(n_nodes, np.bool_)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for c in range(nc):
        dist[c] = 0.0
        heapq.heappush(heap, (0.0, np.int64(c)))
    target = -1
    while len(heap) > 0:
        d, node = heapq.heappop(heap)
        if done[node]:
            continue
        done[node] = True
        r = node // nc
        c = node % nc + 1
        if r == h:
            target = node
            break
        # down
        nxt = node + nc
        nd = d + cost_h[r, c - 1]
        if nd < dist[nxt]:
            dist[nxt] = nd
            prev[nxt] = node
            heapq.heappush(heap, (nd, nxt))
        # up
        if r > 0:
            nxt = node - nc
            nd = d + cost_h[r - 1, c - 1]
            if nd < dist[nxt]:
                dist[nxt] = nd
                prev[nxt] = node
                heapq.heappush(heap, (nd, nxt))
        if 1 <= r <= h - 1:
            if c + 1 <= w - 1:  # right
                nxt = node + 1
                nd = d + cost_v[r - 1, c]
                if nd < dist[nxt]:
                    dist[nxt] = nd
                    prev[nxt] = node
                    heapq.heappush(heap, (nd, nxt))
            if c - 1 >= 1:  # left
                nxt = node - 1
                nd = d + cost_v[r - 1, c - 1]
                if nd < dist[nxt]:
                    dist[nxt] = nd
                    prev[nxt] = node
                    heapq.heappush(heap, (nd, nxt))
    cut_h = np.zeros(cost_h.shape, np.bool_)
    cut_v = np.zeros(cost_v.shape, np.bool_)
    node = target
    while node >= 0 and prev[node] >= 0:
        p = prev[node]
        r1, c1 = p // nc, p % nc + 1
        r2, c2 = node // nc, node % nc + 1
        if c1 == c2:  # vertical move crosses a horizontal pair
            cut_h[min(r1, r2), c1 - 1] = True
        else:  # sideways move crosses a vertical pair
            cut_v[r1 - 1, min(c1, c2)] = True
        node = p
    return cut_h, cut_v


@jit()
def _flood_from_left(cut_h, cut_v):
    """Pixels reachable from column 0 without crossing a cut pair (4-connectivity)."""
    h = cut_h.shape[0]
    w = cut_h.shape[1] + 1
    seen = np.zeros((h, w), np.bool_)
    stack = []
    for r in range(h):
        seen[r, 0] = True
        stack.append(r * w)
    while len(stack) > 0:
        p = stack.pop()
        r, c = p // w, p % w
        if c + 1 < w and not seen[r, c + 1] and not cut_h[r, c]:
            seen[r, c + 1] = True
            stack.append(r * w + c + 1)
        if c - 1 >= 0 and not seen[r, c - 1] and not cut_h[r, c - 1]:
            seen[r, c - 1] = True
            stack.append(r * w + c - 1)
        if r + 1 < h and not seen[r + 1, c] and not cut_v[r, c]:
            seen[r + 1, c] = True
            stack.append((r + 1) * w + c)
        if r - 1 >= 0 and not seen[r - 1, c] and not cut_v[r - 1, c]:
            seen[r - 1, c] = True
            stack.append((r - 1) * w + c)
    return seen


@jit()
def _seams_take_old_rows(cost_h, cost_v, keep, start, stop):
    """:func:`seam_take_old`'s cut of the overlaps ``[start, stop)`` of a stack, from its
    costs ``(S, ...)``, into ``keep``."""
    for k in range(start, stop):
        cut_h, cut_v = _dual_shortest_cut(cost_h[k], cost_v[k])
        keep[k] = _flood_from_left(cut_h, cut_v)


@jit(parallel=True)
def _seams_take_old_parallel(cost_h, cost_v, keep, n_chunks):
    """:func:`_seams_take_old_rows` over ``n_chunks`` chunks of the stack on numba's threads."""
    count = cost_h.shape[0]
    size = (count + n_chunks - 1) // n_chunks
    for c in prange(n_chunks):
        _seams_take_old_rows(cost_h, cost_v, keep, c * size, min(count, (c + 1) * size))


#: pairs of pixels from which the seams of a stack are cut on numba's threads (below,
#: starting and stopping them costs more than the cuts)
_PARALLEL_SEAM_PAIRS = 1 << 15


def _seams_take_old(cost_h: np.ndarray, cost_v: np.ndarray) -> np.ndarray:
    """:func:`seam_take_old`'s cut of every overlap of a stack, from its costs ``(S, ...)``.

    Each seam is cut alone (its own shortest path and flood fill), so the result is the same
    however the stack is split among threads (``docs/determinism.md``).
    """
    count, h = cost_h.shape[0], cost_h.shape[1]
    keep = np.empty((count, h, cost_h.shape[2] + 1), dtype=np.bool_)
    workers = worker_count()
    if workers > 1 and count > 1 and cost_h.size + cost_v.size >= _PARALLEL_SEAM_PAIRS:
        _seams_take_old_parallel(cost_h, cost_v, keep, min(workers, count))
    else:
        _seams_take_old_rows(cost_h, cost_v, keep, 0, count)
    return keep


def seam_take_old(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Exact minimum-cost seam between ``old`` (left column forced) and ``new`` (right column).

    Parameters
    ----------
    old, new : ndarray, shape (h, w) or (h, w, C), ``w >= 2``
        The overlap region as seen in the old content and in the new patch.

    Returns
    -------
    ndarray of bool, shape (h, w)
        True where the old content is kept (the side of the cut that holds column 0).
    """
    a = np.asarray(old, dtype=np.float64)
    if a.shape[1] < 2:
        return np.ones(a.shape[:2], dtype=bool)
    cost_h, cost_v = kwatra_costs(old, new)
    cut_h, cut_v = _dual_shortest_cut(np.ascontiguousarray(cost_h), np.ascontiguousarray(cost_v))
    return _flood_from_left(cut_h, cut_v)


def cut_value(take_old: np.ndarray, cost_h: np.ndarray, cost_v: np.ndarray) -> float:
    """Cost of a labelling: the sum of the costs of the pairs whose two pixels differ."""
    lab = np.asarray(take_old, dtype=bool)
    return float(np.sum(cost_h[lab[:, :-1] != lab[:, 1:]]) + np.sum(cost_v[lab[:-1] != lab[1:]]))


def graphcut_reassemble(patches: np.ndarray, step: int, shape: tuple[int, int]) -> np.ndarray:
    """Stitch the patches of a periodic grid with exact graph-cut seams (Tartavel et al. 2013, 4.1).

    Rows of patches are first assembled into strips with vertical cuts (plus the wrap-around
    cut of the last patch onto the first), then the strips are merged with horizontal cuts
    (plus the wrap-around cut of the last strip onto the first). For identical patches in
    every overlap the result is exactly the image they were taken from.

    Parameters
    ----------
    patches : ndarray, shape (Kr, Kc, tau, tau, C)
        Patch ``(i, j)`` has its top-left corner at ``(i step, j step)`` on the torus.
    step : int
        Grid step ``Delta`` with ``tau % step == 0`` and ``2 step >= tau``.
    shape : (int, int)
        Canvas size ``(Kr step, Kc step)``.

    Returns
    -------
    ndarray, shape (H, W, C)

    References
    ----------
    V. Kwatra, A. Schodl, I. Essa, G. Turk, A. Bobick, "Graphcut textures", SIGGRAPH 2003;
    Tartavel, Gousseau, Peyre (2013), section 4.1, eq. (8).
    """
    kr, kc, tau = patches.shape[:3]
    height, width = shape
    o = tau - step
    if 0 < o <= step and kc * step == width and kr * step == height:  # every seam at once
        strips = _assemble_closed_lines(patches, step, o)  # (kr, tau, width, C)
        rows = strips.transpose(0, 2, 1, 3)[None]  # strips as (width, tau) "patches"
        return _assemble_closed_lines(rows, step, o)[0].transpose(1, 0, 2)
    channels = patches.shape[4]
    strips = np.empty((kr, tau, width, channels))
    for i in range(kr):
        strips[i] = _assemble_line(patches[i], step, width, o)
    rows = np.ascontiguousarray(strips.transpose(0, 2, 1, 3))
    canvas_t = _assemble_line(rows, step, height, o)  # (width, height, C)
    return canvas_t.transpose(1, 0, 2)


def _assemble_line(items: np.ndarray, step: int, length: int, o: int) -> np.ndarray:
    """Join ``items`` (each ``(h, tau, C)``) side by side on a periodic line of ``length``.

    With single overlaps (``o <= step``) on a closed line (``count step == length``) every
    seam is between the tail of one item and the head of the next, whatever the other seams
    are, so all of them are cut at once (:func:`_assemble_closed_lines`); otherwise, or with
    ``o = 0``, item by item (:func:`_assemble_line_sequential`, the reference).
    """
    count = items.shape[0]
    if 0 < o <= step and count * step == length:
        return _assemble_closed_lines(items[None], step, o)[0]
    return _assemble_line_sequential(items, step, length, o)


def _assemble_closed_lines(items: np.ndarray, step: int, o: int) -> np.ndarray:
    """:func:`_assemble_line_sequential` of ``B`` closed lines ``(B, count, h, tau, C)`` with
    single overlaps (``0 < o <= step``), all seams cut at once: ``(B, h, count step, C)``.

    Columns ``[c step, c step + o)`` of a line are the seam between the tail
    ``items[c - 1][:, tau - o:]`` (the old content; the last item's for ``c = 0``, the
    wrap-around) and the head ``items[c][:, :o]``; columns ``[c step + o, (c + 1) step)`` are
    ``items[c]``'s own. The same costs and cuts as item by item, so the same bytes.
    """
    lines, count, h, tau, channels = items.shape
    tails = np.roll(items[:, :, :, tau - o :], 1, axis=1).reshape(lines * count, h, o, channels)
    heads = items[:, :, :, :o].reshape(lines * count, h, o, channels)
    if o < 2:
        joined = tails
    else:
        cost_h, cost_v = kwatra_costs_stack(tails, heads)
        keep = _seams_take_old(cost_h, cost_v)
        joined = np.where(keep[..., None], tails, heads)
    out = np.empty((lines, h, count, step, channels))
    out[:, :, :, :o] = joined.reshape(lines, count, h, o, channels).transpose(0, 2, 1, 3, 4)
    out[:, :, :, o:] = items[:, :, :, o:step].transpose(0, 2, 1, 3, 4)
    return out.reshape(lines, h, count * step, channels)


def _assemble_line_sequential(items: np.ndarray, step: int, length: int, o: int) -> np.ndarray:
    """:func:`_assemble_line` item by item: each seam cut against the line built so far."""
    count, h, tau, channels = items.shape
    line = np.zeros((h, length, channels))
    line[:, :tau] = items[0]
    if o == 0:
        for c in range(1, count):
            x0 = c * step
            line[:, x0 : x0 + tau] = items[c][:, : min(tau, length - x0)]
        return line
    for c in range(1, count):
        x0 = c * step
        old = line[:, x0 : x0 + o]
        new = items[c][:, :o]
        keep = seam_take_old(old, new)
        line[:, x0 : x0 + o] = np.where(keep[..., None], old, new)
        end = min(x0 + tau, length)
        line[:, x0 + o : end] = items[c][:, o : end - x0]
    # wrap-around: the last item's columns beyond the end fall on columns [0, o)
    wrapped = items[count - 1][:, tau - o :]
    first = line[:, :o]
    keep = seam_take_old(wrapped, first)
    line[:, :o] = np.where(keep[..., None], wrapped, first)
    return line
