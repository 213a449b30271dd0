"""Joining a new patch to what is already synthesised: minimum-error boundary cut, averaging.

The boundary cut is Efros and Freeman's (2001, section 2.1): the pixels of the overlap are
split along the path of least accumulated squared error, vertical, horizontal or L-shaped
(``docs/methods/quilting.md``). :func:`paste_cut` and :func:`paste_average` are the two
joining rules of the raster patch loop (:mod:`texsyn.drivers.raster`): quilting, LG and (by
default) MSLG's coarsest scale join blocks along the cut; averaging the overlap is Raad et
al. 2016's eq. 15 (LG's ``seam='average'``, MSLG's ``coarse_seam='average'``).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "boundary_cut_mask",
    "cumulative_path_cost",
    "cut_mask",
    "l_shaped_cut",
    "leading_known",
    "min_path",
    "overlap_error",
    "paste_average",
    "paste_cut",
]


def overlap_error(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Per-pixel squared error ``e = sum_c (A - B)^2`` between two equally shaped blocks."""
    diff = np.asarray(old, dtype=np.float64) - np.asarray(new, dtype=np.float64)
    return diff * diff if diff.ndim == 2 else np.sum(diff * diff, axis=2)


def cumulative_path_cost(cost: np.ndarray) -> np.ndarray:
    """Dynamic programme ``E[i, j] = e[i, j] + min(E[i-1, j-1], E[i-1, j], E[i-1, j+1])``.

    ``E[i, j]`` is the least cost of a top-to-bottom path ending at ``(i, j)`` that moves at
    most one column per row (Efros and Freeman 2001, section 2.1).
    """
    e = np.asarray(cost, dtype=np.float64)
    out = np.empty_like(e)
    out[0] = e[0]
    padded = np.full(e.shape[1] + 2, np.inf)
    for i in range(1, e.shape[0]):
        padded[1:-1] = out[i - 1]
        out[i] = e[i] + np.minimum(np.minimum(padded[:-2], padded[1:-1]), padded[2:])
    return out


def _trace(cum: np.ndarray, start_row: int, start_col: int, step: int) -> np.ndarray:
    """Follow the least cumulative cost from ``(start_row, start_col)`` in direction ``step``."""
    n_rows, n_cols = cum.shape
    rows = np.arange(start_row, n_rows if step > 0 else -1, step)
    cols = np.empty(rows.size, dtype=np.intp)
    col = start_col
    cols[0] = col
    for k, r in enumerate(rows[1:], start=1):
        lo, hi = max(col - 1, 0), min(col + 2, n_cols)
        col = lo + int(np.argmin(cum[r, lo:hi]))
        cols[k] = col
    return cols


def min_path(cost: np.ndarray) -> np.ndarray:
    """Column of the minimum-error top-to-bottom path in every row of ``cost``."""
    cum = cumulative_path_cost(cost[::-1])[::-1]  # cost-to-go from each pixel to the bottom
    return _trace(cum, 0, int(np.argmin(cum[0])), 1)


def l_shaped_cut(error: np.ndarray, left: int, top: int) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Minimum-error L-shaped cut: a vertical path in the left strip and a horizontal path
    in the top strip that meet at a corner pixel (Efros and Freeman 2001, section 2.1).

    Both cumulative costs are computed from the far ends (bottom row, rightmost column);
    the corner ``(ci, cj)`` minimises ``E_v + E_h - e``.

    Returns
    -------
    ci, cj : int
        The corner pixel.
    v_cols : ndarray
        Column of the vertical path in rows ``ci .. h-1``.
    h_rows : ndarray
        Row of the horizontal path in columns ``cj .. w-1``.
    """
    e = np.asarray(error, dtype=np.float64)
    cum_v = cumulative_path_cost(e[::-1, :left])[::-1]
    cum_h = cumulative_path_cost(e[:top, ::-1].T)[::-1].T
    corner = cum_v[:top, :left] + cum_h[:top, :left] - e[:top, :left]
    ci, cj = np.unravel_index(int(np.argmin(corner)), corner.shape)
    v_cols = _trace(cum_v, int(ci), int(cj), 1)
    h_rows = _trace(cum_h.T, int(cj), int(ci), 1)
    return int(ci), int(cj), v_cols, h_rows


def boundary_cut_mask(error: np.ndarray, left: int, top: int) -> np.ndarray:
    """Which pixels of a new patch replace the existing content after the boundary cut.

    Parameters
    ----------
    error : ndarray, shape (h, w)
        Squared error between old content and new patch, see :func:`overlap_error`.
    left : int
        Width of the overlap with the content on the left (0 if none).
    top : int
        Height of the overlap with the content above (0 if none).

    Returns
    -------
    ndarray of bool, shape (h, w)
        True where the new patch is taken. Pixels strictly left of (above) the cut keep the
        old content; the cut itself and everything right of (below) it take the new patch.
        For an L-shaped overlap both cuts start from their far ends and meet at the corner
        pixel minimising ``E_v + E_h - e`` (``docs/methods/quilting.md``).

    References
    ----------
    A. Efros, W. Freeman, "Image quilting for texture synthesis and transfer", SIGGRAPH 2001,
    section 2.1.
    """
    e = np.asarray(error, dtype=np.float64)
    h, w = e.shape
    take_new = np.ones((h, w), dtype=bool)
    if left <= 0 and top <= 0:
        return take_new
    if top <= 0:
        path = min_path(e[:, :left])
        take_new[:, :left] = np.arange(left)[None, :] >= path[:, None]
        return take_new
    if left <= 0:
        path = min_path(e[:top, :].T)
        take_new[:top, :] = np.arange(top)[:, None] >= path[None, :]
        return take_new
    ci, cj, v_cols, h_rows = l_shaped_cut(e, left, top)
    side = _inside_l_cut(h, w, ci, cj, v_cols, h_rows)
    if side is None:  # the two paths touch diagonally and may close off a pocket
        side = _inside_l_cut_by_labels(h, w, ci, cj, v_cols, h_rows)
    take_new = side
    # outside the overlap the new patch is always taken
    take_new[top:, left:] = True
    return take_new


def _inside_l_cut(
    h: int, w: int, ci: int, cj: int, v_cols: np.ndarray, h_rows: np.ndarray
) -> np.ndarray | None:
    """The cut and the side of it holding the block's bottom-right pixel, or None.

    The pixels right of the vertical path (rows ``ci ..``), below the horizontal path
    (columns ``cj ..``) and not above-left of the corner are closed under 4-neighbour moves
    that avoid the cut (a step left or up from them lands on the cut or among them, since
    each path moves at most one pixel per step). From any of them, steps down or right reach
    the bottom-right pixel (the paths stay off the last row and column) unless one of them,
    ``(r, c)``, has the vertical path at ``(r + 1, c)`` and the horizontal one at
    ``(r, c + 1)``: the paths touch diagonally and may close off a pocket. Without such a
    pixel the side is exactly the 4-connected component that a labelling finds (the one
    ``scipy.ndimage.label`` would give, 0.15 s of start-up); with one, None, and the caller
    labels the components (``tests/test_seams.py`` compares both on random cuts).
    """
    if v_cols.max(initial=0) >= w - 1 or h_rows.max(initial=0) >= h - 1:
        return None
    r = np.arange(h)[:, None]
    c = np.arange(w)[None, :]
    vertical = np.full(h, -1, dtype=np.intp)
    vertical[ci:] = v_cols
    horizontal = np.full(w, -1, dtype=np.intp)
    horizontal[cj:] = h_rows
    right_of_vertical = (r < ci) | (c > vertical[:, None])
    below_horizontal = (c < cj) | (r > horizontal[None, :])
    marked = (c == vertical[:, None]) | (r == horizontal[None, :])
    side = right_of_vertical & below_horizontal & ~((r < ci) & (c < cj)) & ~marked
    # a pixel of that side at (r, c) with the vertical path at (r + 1, c) and the horizontal
    # one at (r, c + 1) has no step down or right: a pocket may be closed off
    touch_rows = np.arange(ci, h - 1)
    touch_cols = v_cols[1:]
    at = touch_cols + 1 - cj
    on_path = (at >= 0) & (at < h_rows.size)
    touching = h_rows[at[on_path]] == touch_rows[on_path]
    if np.any(side[touch_rows[on_path][touching], touch_cols[on_path][touching]]):
        return None
    return side | marked


def _inside_l_cut_by_labels(
    h: int, w: int, ci: int, cj: int, v_cols: np.ndarray, h_rows: np.ndarray
) -> np.ndarray:
    """:func:`_inside_l_cut` by labelling the 4-connected components around the cut."""
    from scipy import ndimage  # 0.15 s of start-up, for the rare cut that needs it

    marked = np.zeros((h, w), dtype=bool)
    marked[np.arange(ci, h), v_cols] = True
    marked[h_rows, np.arange(cj, w)] = True
    labels, _ = ndimage.label(~marked)
    reached = labels == labels[h - 1, w - 1] if not marked[h - 1, w - 1] else np.zeros_like(marked)
    return reached | marked


def leading_known(known: np.ndarray) -> tuple[int, int]:
    """Widths of the fully known leading columns and rows of a block's known mask.

    In raster order the known part of a block is an L: ``left`` columns on the left and
    ``top`` rows at the top (0 when there are none).

    Examples
    --------
    >>> mask = np.zeros((4, 4), dtype=bool)
    >>> mask[:, :1] = True
    >>> mask[:2, :] = True
    >>> leading_known(mask)
    (1, 2)
    """
    cols = known.all(axis=0)
    rows = known.all(axis=1)
    left = int(np.argmin(cols)) if not cols.all() else known.shape[1]
    top = int(np.argmin(rows)) if not rows.all() else known.shape[0]
    return left, top


def cut_mask(old: np.ndarray, new: np.ndarray, known: np.ndarray, *, every_side: bool = False) -> np.ndarray:
    """Which pixels of ``new`` are taken when it joins ``old`` along the boundary cut.

    The cut runs through the L-shaped known part of the block (:func:`leading_known`);
    every unknown pixel takes the new patch.

    Parameters
    ----------
    old, new : ndarray, shape (h, w) or (h, w, C)
        The block's current content and the new patch.
    known : ndarray of bool, shape (h, w)
        The pixels already synthesised.
    every_side : bool
        Cut through the known strips on the right and at the bottom too (blocks on a
        torus, whose last column, last row and last block overlap blocks placed on those
        sides, ``docs/tiling.md``): a second L-shaped cut through the trailing strips, the
        new patch taken where both cuts take it. Without trailing strips it is the plain cut.

    Returns
    -------
    ndarray of bool, shape (h, w)
    """
    left, top = leading_known(known)
    error = overlap_error(old, new)
    take = boundary_cut_mask(error, left, top)
    if every_side:
        right, bottom = leading_known(known[::-1, ::-1])
        if right or bottom:
            take &= boundary_cut_mask(error[::-1, ::-1], right, bottom)[::-1, ::-1]
    return take | ~known


def paste_cut(old: np.ndarray, new: np.ndarray, known: np.ndarray, *, every_side: bool = False) -> np.ndarray:
    """The block after ``new`` joins ``old`` along the minimum-error boundary cut.

    Efros and Freeman (2001, section 2.1); ``old`` and ``new`` of shape ``(h, w, C)``;
    ``every_side`` as in :func:`cut_mask`.
    """
    return np.where(cut_mask(old, new, known, every_side=every_side)[..., None], new, old)


def paste_average(old: np.ndarray, new: np.ndarray, known: np.ndarray) -> np.ndarray:
    """The block after ``new`` joins ``old`` by averaging the two on the known pixels.

    Raad, Desolneux and Morel (2016, eq. 15); ``old`` and ``new`` of shape ``(h, w, C)``.
    """
    return np.where(known[..., None], 0.5 * (old + new), new)
