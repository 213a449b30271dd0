"""The exact Efros–Leung search by float32 lower bounds and exact re-ranking.

:class:`ScreenBank` is what :class:`~texsyn.ops.nonparametric.NonParametricSampler` keeps for
it (built once, in a method's ``fit``): a float32 bank of the exemplar windows' central
discs. :meth:`ScreenBank.screen` bounds from below, in one matrix product, the distances of
many windows to every exemplar window; :meth:`ScreenBank.choose` finds the windows that
could be candidates of Efros and Leung's rule, computes their exact distances and applies the
rule, and says where the result could differ from the float64 matrix product of
:meth:`~texsyn.ops.nonparametric.NonParametricSampler.match` (the sampler then uses that).
``docs/methods/efros_leung.md``, "Performance", gives the bounds and why the bytes are
those of the matrix product.

Why this module is long: the lower bound, the two rounding allowances (float32 products
below, float64 sums against the matrix product above) and the rule they protect are written
once here, side by side, so that the argument that the choice is the matrix product's reads
in one place.
"""

from __future__ import annotations

import numpy as np

from .jit import jit
from .linalg import BLOCK_COLUMNS, fixed_order, parallel_map

__all__ = ["ScreenBank", "WindowScreen", "gather_windows", "window_ssd", "wrap_pixel"]

#: float32 and float64 unit roundoff (half an ulp of 1)
_U32 = 2.0**-24
_U64 = 2.0**-53
#: radius (in pixels, Euclidean) of the central disc of the window whose known pixels give
#: the float32 lower bound of the exact search (``docs/methods/efros_leung.md``, "Performance")
SCREEN_RADIUS = 4.0
#: principal colour axes of the exemplar on which the float32 lower bound is computed
SCREEN_CHANNELS = 2
#: smallest Gaussian weight of a pixel that enters the lower bound when it becomes known
#: after the float32 bound was computed (each adds a term to the bound of every window that
#: passed the first screen)
NEW_MIN_WEIGHT = 0.1
#: factor on the worst-case rounding difference between the exact search's direct sums and
#: the matrix product of ``NonParametricSampler.match`` (at least 2: both errors)
SPREAD_SAFETY = 4.0
#: windows of smallest lower bound whose exact distance bounds the best one from above
_FIRST = 4
#: exemplar windows per block of a row's bounds whose minimum is kept (:func:`_block_minima`)
_BLOCK = 64


@jit()
def window_ssd(planes, top, left, oy, ox, weights, values, count):  # pragma: no cover - compiled
    """``sum_t weights[t] ||values[t] - E[top + oy[t], left + ox[t]]||^2`` over ``t < count``:
    the weighted SSD between known pixels and the exemplar window at ``(top, left)``;
    ``planes[c]`` is channel ``c`` of the exemplar ``E``."""
    total = 0.0
    for t in range(count):
        y = top + oy[t]
        x = left + ox[t]
        part = 0.0
        for c in range(planes.shape[0]):
            diff = values[t, c] - planes[c, y, x]
            part += diff * diff
        total += weights[t] * part
    return total


@jit(nogil=True)
def _block_minima(lower, start, minima):  # pragma: no cover - compiled
    """The minima of the :data:`BLOCK_COLUMNS` columns of ``lower`` from ``start``, by blocks.

    Block ``b`` of the tile is its columns ``b, b + L, b + 2 L...`` (``L`` =
    :data:`_LANES`, :data:`_BLOCK` of them); ``minima[i, start // _BLOCK + b]`` gets its
    minimum. Strided blocks make this a lane-wise minimum of contiguous runs of ``L``.
    """
    lanes = BLOCK_COLUMNS // _BLOCK
    first = start // _BLOCK
    for i in range(lower.shape[0]):
        row = lower[i]
        acc = minima[i, first : first + lanes]
        acc[:] = row[start : start + lanes]
        for k in range(1, _BLOCK):
            base = start + k * lanes
            np.minimum(acc, row[base : base + lanes], acc)


@jit()
def _keep_smallest(values, index, v, i):  # pragma: no cover - compiled
    """Insert ``v`` (of index ``i``) into ``values``, the ascending smallest values seen so far
    with their ``index``, when it is smaller than the last; an equal value stays behind the
    ones already there (the earlier index first)."""
    last = values.size - 1
    if v < values[last]:
        p = last
        while p > 0 and values[p - 1] > v:
            values[p] = values[p - 1]
            index[p] = index[p - 1]
            p -= 1
        values[p] = v
        index[p] = i


@jit()
def _row_scratch(w, channels, n):  # pragma: no cover - compiled
    """The scratch arrays of :func:`_choose_row` for windows of side ``w`` and a bank of
    ``n`` windows: ``(oy, ox, weights, values, passed, bound, dist, index)``, allocated once
    per call of its callers and reused for every row."""
    return (
        np.empty(w * w, np.int64),
        np.empty(w * w, np.int64),
        np.empty(w * w),
        np.empty((w * w, channels)),
        np.empty(n, np.int64),
        np.empty(n),
        np.empty(n),
        np.empty(n, np.int64),
    )


@jit()
def _choose_row(
    win,
    kn,
    before,
    lower,
    minima,
    offset,
    gauss,
    value_max,
    planes,
    grid_cols,
    tolerance,
    uniform,
    accept,
    safety,
    min_weight,
    n_first,
    oy,
    ox,
    weights,
    values,
    passed,
    bound,
    dist,
    index,
):  # pragma: no cover - compiled
    """Efros and Leung's candidate rule for one window from its lower bounds, exactly.

    ``win`` and ``kn`` are the window's values and what of it is known now; ``before`` what
    was known when its bounds ``lower`` (one row of :attr:`WindowScreen.grouped`, with its
    block ``minima``; ``offset`` turns a distance into a bound) were computed. Window ``j``
    of the exemplar has its top-left corner at ``divmod(j, grid_cols)``; ``planes[c]`` is
    channel ``c`` of the exemplar. ``oy`` ... ``index`` are work arrays (``w * w`` and
    ``N`` long). Distances are in raw units (not per unit weight) until the rule.

    1. The known pixels as lists, those known since ``before`` of Gaussian weight at least
       ``min_weight`` first (``n_new`` of them); ``spread`` bounds ``|direct sum - matrix
       product|`` for any exemplar window: ``safety (2 D + 8) u sum_p w_p sum_c (Y^2 + 3 |x|
       Y + 2 x^2)`` with ``Y`` the largest ``|value|`` of the exemplar windows at that place
       and ``D`` the window's length (Higham, *Accuracy and Stability of Numerical
       Algorithms*, section 3.1: ``gamma_D`` bounds a sum of ``D`` products in any order,
       here the product's and this sum's errors together; ``safety`` leaves room).
    2. The first screen: the exact distance of the window of smallest bound (``upper``, at
       least the best distance) allows the windows whose bound is at most ``cut``; the
       blocks whose minimum is above it are skipped whole.
    3. Their bound gets the exact SSD over the new pixels; the ``n_first`` of smallest
       bound get their exact distance (a smaller ``upper``); the windows whose bound leaves
       them a chance to be a candidate (the survivors) get their exact distance; the rule
       ``d <= (1 + tolerance) min d + 1e-10`` (per unit weight) picks among them, in window
       order, the candidate ``int(uniform * count)``.

    Returns
    -------
    choice : int
    error : float
        Its distance per unit weight.
    unsure : bool
        A survivor or the chosen distance lies within ``spread`` (the largest difference
        between this direct sum and the matrix product of
        :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`) of the threshold or
        of ``accept``: the product could choose otherwise.
    """
    w = kn.shape[0]
    channels = planes.shape[0]
    lanes = BLOCK_COLUMNS // _BLOCK
    scale = safety * (2 * w * w * channels + 8) * _U64
    norm = 0.0
    for y in range(w):
        for x in range(w):
            if kn[y, x]:
                norm += gauss[y, x]
    known = 0
    n_new = 0
    spread = 0.0
    for stage in range(2):
        for y in range(w):
            for x in range(w):
                if not kn[y, x]:
                    continue
                g = gauss[y, x]
                fresh = (not before[y, x]) and g >= min_weight
                if fresh != (stage == 0):
                    continue
                oy[known] = y
                ox[known] = x
                weights[known] = g
                terms = 0.0
                for c in range(channels):
                    v = win[y, x, c]
                    values[known, c] = v
                    big = value_max[y, x, c]
                    terms += big * big + 3.0 * abs(v) * big + 2.0 * v * v
                spread += g * terms
                known += 1
        if stage == 0:
            n_new = known
    s = spread * scale
    # the windows of smallest bound in the ``n_first`` blocks of smallest minimum: the
    # least of their exact distances (``upper``) is at least the best distance
    block_val = np.full(n_first, np.inf)
    block_idx = np.zeros(n_first, np.int64)
    for b in range(minima.size):
        _keep_smallest(block_val, block_idx, minima[b], b)
    upper = np.inf
    first = 0
    for t in range(n_first):
        if not block_val[t] < np.inf:
            break
        base = (block_idx[t] // lanes) * BLOCK_COLUMNS + block_idx[t] % lanes
        j = base
        for k in range(_BLOCK):
            if lower[base + k * lanes] == block_val[t]:
                j = base + k * lanes
                break
        top = j // grid_cols
        exact = window_ssd(planes, top, j - top * grid_cols, oy, ox, weights, values, known)
        if exact < upper:
            upper = exact
            first = j
    # a candidate of the product's rule has a true distance below ``reach`` (raw units)
    reach = ((1.0 + tolerance) * (upper + s) + 1e-10 * norm) * (1.0 + 1e-9) + s
    cut = reach + offset
    count = 0
    for b in range(minima.size):
        if np.float64(minima[b]) <= cut:
            base = (b // lanes) * BLOCK_COLUMNS + b % lanes
            for k in range(_BLOCK):
                j = base + k * lanes
                if np.float64(lower[j]) <= cut:  # the padding (infinite) never passes
                    passed[count] = j
                    count += 1
    for k in range(count):  # the bound, with the pixels known since ``lower`` was computed
        j = passed[k]
        top = j // grid_cols
        left = j - top * grid_cols
        value = np.float64(lower[j])
        for t in range(n_new):
            part = 0.0
            for c in range(channels):
                diff = values[t, c] - planes[c, top + oy[t], left + ox[t]]
                part += diff * diff
            value += weights[t] * part
        bound[k] = value
    first_val = np.full(n_first, np.inf)
    first_idx = np.zeros(n_first, np.int64)
    for k in range(count):
        _keep_smallest(first_val, first_idx, bound[k], passed[k])
    best_raw = upper
    n_exact = min(n_first, count)
    for t in range(n_exact):  # their exact distances (kept: they are survivors too, mostly)
        if first_idx[t] == first:
            first_val[t] = upper
        else:
            top = first_idx[t] // grid_cols
            left = first_idx[t] - top * grid_cols
            first_val[t] = window_ssd(planes, top, left, oy, ox, weights, values, known)
        best_raw = min(best_raw, first_val[t])
    reach = ((1.0 + tolerance) * (best_raw + s) + 1e-10 * norm) * (1.0 + 1e-9) + s
    limit = reach + offset
    limit += 1e-11 * (abs(limit) + abs(offset))  # the float64 rounding of ``bound``
    n_in = 0
    best = np.inf
    for k in range(count):
        if bound[k] <= limit:
            j = passed[k]
            raw = -1.0
            for t in range(n_exact):
                if first_idx[t] == j:
                    raw = first_val[t]
            if raw < 0.0:
                top = j // grid_cols
                raw = window_ssd(planes, top, j - top * grid_cols, oy, ox, weights, values, known)
            index[n_in] = j
            dist[n_in] = raw / norm
            best = min(best, dist[n_in])
            n_in += 1
    threshold = best * (1.0 + tolerance) + 1e-10
    margin = 1.01 * (2.0 + tolerance) * s / norm
    unsure = False
    inside = 0
    for k in range(n_in):
        if dist[k] <= threshold:
            index[inside] = index[k]  # the candidates, kept in front
            dist[inside] = dist[k]
            inside += 1
        if abs(dist[k] - threshold) <= margin:
            unsure = True
    # the product's rule takes the candidates in window order
    if inside == 0:  # not a valid bound (NaN values): leave it to the matrix product
        return 0, np.inf, True
    order = np.argsort(index[:inside])
    target = order[min(int(uniform * inside), inside - 1)]
    choice = index[target]
    error = dist[target]
    if abs(error - accept) <= 1.01 * s / norm:
        unsure = True
    return choice, error, unsure


@jit(nogil=True)
def _choose_rows(
    windows,
    known,
    before,
    lower,
    position,
    minima,
    offset,
    gauss,
    value_max,
    planes,
    grid_cols,
    tolerance,
    uniforms,
    accept,
    safety,
    min_weight,
    n_first,
):  # pragma: no cover - compiled
    """:func:`_choose_row` for every row: ``choice, error, unsure``, arrays of ``m``."""
    m, w = known.shape[0], known.shape[1]
    n = lower.shape[1]
    channels = planes.shape[0]
    choice = np.zeros(m, np.int64)
    error = np.zeros(m)
    unsure = np.zeros(m, np.bool_)
    oy, ox, weights, values, passed, bound, dist, index = _row_scratch(w, channels, n)
    for i in range(m):
        row = position[i]
        choice[i], error[i], unsure[i] = _choose_row(
            windows[i], known[i], before[i], lower[row], minima[row], offset[i], gauss, value_max,
            planes, grid_cols, tolerance, uniforms[i], accept, safety, min_weight, n_first,
            oy, ox, weights, values, passed, bound, dist, index,
        )  # fmt: skip
    return choice, error, unsure


@jit(nogil=True)
def _fill_batches(
    canvas,
    filled,
    source,
    rows,
    cols,
    uniforms,
    bounds,
    batch,
    stop,
    chunk_start,
    lower,
    position,
    minima,
    offset,
    before,
    centres,
    gauss,
    value_max,
    planes,
    grid_cols,
    tolerance,
    accept,
    safety,
    min_weight,
    n_first,
    wrap,
):  # pragma: no cover - compiled
    """Batches ``batch`` to ``stop - 1`` of a pass, in order, by :func:`_choose_row`.

    Pixel ``p`` is at ``(rows[p], cols[p])`` of the output (its window is ``canvas[rows[p]
    : rows[p] + w, cols[p] : cols[p] + w]`` and ``filled`` the same of the mask), batch
    ``b`` is pixels ``bounds[b]`` to ``bounds[b + 1] - 1``, and pixel ``p``'s bounds are row
    ``p - chunk_start`` of the screen. A batch's accepted pixels (``error <= accept``) get
    the centre of their window: its values in ``canvas``, True in ``filled``, its exemplar
    ``(row, col)`` (``centres``) in ``source``; they are written when the whole batch is
    chosen (its pixels do not see each other). Stops before writing a batch with an unsure
    row. With ``wrap`` (the output is a torus) every pixel written is copied across the
    wraps into the padding too (:func:`wrap_pixel`).

    Returns
    -------
    next : int
        ``stop``, or the first batch with an unsure row (nothing of it written).
    written : int
        Pixels filled.
    """
    w = gauss.shape[0]
    r = w // 2
    n = lower.shape[1]
    channels = planes.shape[0]
    most = 0
    for b in range(batch, stop):
        most = max(most, bounds[b + 1] - bounds[b])
    choice = np.zeros(most, np.int64)
    error = np.zeros(most)
    win = np.empty((w, w, channels))
    kn = np.empty((w, w), np.bool_)
    oy, ox, weights, values, passed, bound, dist, index = _row_scratch(w, channels, n)
    written = 0
    for b in range(batch, stop):
        start, end = bounds[b], bounds[b + 1]
        for p in range(start, end):
            pr, pc = rows[p], cols[p]
            for y in range(w):
                for x in range(w):
                    kn[y, x] = filled[pr + y, pc + x]
                    for c in range(channels):
                        win[y, x, c] = canvas[pr + y, pc + x, c]
            q = p - chunk_start
            row = position[q]
            choice[p - start], error[p - start], unsure = _choose_row(
                win, kn, before[q], lower[row], minima[row], offset[q], gauss, value_max, planes,
                grid_cols, tolerance, uniforms[p], accept, safety, min_weight, n_first,
                oy, ox, weights, values, passed, bound, dist, index,
            )  # fmt: skip
            if unsure:
                return b, written
        for p in range(start, end):
            if error[p - start] <= accept:
                pr, pc = rows[p], cols[p]
                cy, cx = centres[choice[p - start], 0], centres[choice[p - start], 1]
                for c in range(channels):
                    canvas[pr + r, pc + r, c] = planes[c, cy, cx]
                filled[pr + r, pc + r] = True
                if wrap:
                    wrap_pixel(canvas, filled, pr + r, pc + r, r)
                source[pr, pc, 0] = cy
                source[pr, pc, 1] = cx
                written += 1
    return stop, written


@jit(nogil=True)
def wrap_pixel(canvas, filled, row, col, radius):  # pragma: no cover - compiled
    """Copy pixel ``(row, col)`` of a padded canvas (``radius`` on each side) and its mask to
    the pixels that stand for it across the output's edges, where the output is a torus
    (``docs/tiling.md``, "On a torus"): the padding then holds the other side of every wrap,
    and a window reaching over an edge reads the pixels it wraps to. ``(row, col)`` is in
    the output (``radius <= row < H + radius``); the output must be at least ``radius`` a side."""
    height = canvas.shape[0] - 2 * radius
    width = canvas.shape[1] - 2 * radius
    for i in range(-1, 2):
        a = row + i * height
        if a < 0 or a >= canvas.shape[0]:
            continue
        for j in range(-1, 2):
            b = col + j * width
            if b < 0 or b >= canvas.shape[1] or (i == 0 and j == 0):
                continue
            filled[a, b] = filled[row, col]
            for c in range(canvas.shape[2]):
                canvas[a, b, c] = canvas[row, col, c]


@jit(nogil=True)
def gather_windows(canvas, filled, rows, cols, window):  # pragma: no cover - compiled
    """The windows of side ``window`` with top-left corners ``(rows[i], cols[i])`` of a
    padded canvas ``(H, W, C)`` and of its mask: ``(m, w, w, C)`` values and ``(m, w, w)``
    known (a copy, as ``sliding_window_view(...)[rows, cols]`` gives)."""
    m, channels = rows.size, canvas.shape[2]
    windows = np.empty((m, window, window, channels))
    known = np.empty((m, window, window), np.bool_)
    for i in range(m):
        for y in range(window):
            for x in range(window):
                known[i, y, x] = filled[rows[i] + y, cols[i] + x]
                for c in range(channels):
                    windows[i, y, x, c] = canvas[rows[i] + y, cols[i] + x, c]
    return windows, known


@jit(nogil=True)
def _disc_terms(windows, known, gauss, ring, mean, axes, column_max, ring_dy, ring_dx):  # pragma: no cover
    """The left operand of :meth:`ScreenBank.screen` and what its bound needs, row by row.

    For the disc pixels ``ring`` (flat indices in the window, in angle order) of every
    window: ``a`` the Gaussian weight where known (else 0), ``x`` the values centred on
    ``mean`` and projected on ``axes`` (0 where unknown). Returns ``left[i, p] = [a, -2 a
    x_0, -2 a x_1...]``, ``constant[i] = sum_p a ||x||^2``, ``size[i] = sum |left| *
    column_max`` (bounds ``sum |A| |B|`` of the product), ``present[i, p] = a > 0`` and the
    group ``0..3`` of the direction of the centroid of the known disc pixels.
    """
    m, w = known.shape[0], known.shape[1]
    channels = windows.shape[3]
    pixels, n_axes = ring.size, axes.shape[1]
    left = np.zeros((m, pixels, n_axes + 1))
    constant = np.zeros(m)
    size = np.zeros(m)
    present = np.zeros((m, pixels), np.bool_)
    group = np.zeros(m, np.int64)
    for i in range(m):
        cy = 0.0
        cx = 0.0
        for p in range(pixels):
            y = ring[p] // w
            x = ring[p] - y * w
            if not known[i, y, x]:
                continue
            a = gauss[y, x]
            if not a > 0:
                continue
            present[i, p] = True
            cy += ring_dy[p]
            cx += ring_dx[p]
            left[i, p, 0] = a
            size[i] += a * column_max[p * (n_axes + 1)]
            squares = 0.0
            for k in range(n_axes):
                v = 0.0
                for c in range(channels):
                    v += (windows[i, y, x, c] - mean[c]) * axes[c, k]
                squares += v * v
                left[i, p, k + 1] = -2.0 * a * v
                size[i] += abs(left[i, p, k + 1]) * column_max[p * (n_axes + 1) + k + 1]
            constant[i] += a * squares
        angle = np.arctan2(cy, cx)
        group[i] = int(np.floor((angle + 1.25 * np.pi) / (0.5 * np.pi))) % 4
    return left, constant, size, present, group


def _tile_products(task: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, range]) -> None:
    """``out[:, c:c + BLOCK_COLUMNS] = lhs @ rhs[:, c:c + BLOCK_COLUMNS]`` and its block
    minima for every ``c`` of the task: each tile is one single-thread BLAS call, whose
    bytes do not depend on the thread that runs it."""
    lhs, rhs, out, minima, starts = task
    for c in starts:
        cols = slice(c, min(c + BLOCK_COLUMNS, rhs.shape[1]))
        np.matmul(lhs, rhs[:, cols], out=out[:, cols])
        _block_minima(out, c, minima)


class WindowScreen:
    """Float32 lower bounds of the distances of some windows to every exemplar window.

    Built by :meth:`ScreenBank.screen` from what is known of the windows at that
    moment; valid for as long as that stays known (a pixel's window only gains pixels while
    the texture grows). Row ``i`` bounds from below, with a margin for float32 rounding,
    the Gaussian-weighted SSD over the known pixels of the central disc of radius
    :data:`SCREEN_RADIUS`, which is a part of the sum the exact distance takes.

    Attributes
    ----------
    grouped : ndarray of float32, shape (m, N')
        ``sum a ||y||^2 - 2 sum a x . y`` over the disc (centred values), without the
        window's constant term; row ``position[i]`` belongs to window ``i`` (the rows are
        grouped by the side of the disc that is known, :meth:`ScreenBank.screen`); the
        columns past the ``N`` exemplar windows (up to a multiple of ``BLOCK_COLUMNS``)
        are infinite.
    position : ndarray of int64, shape (m,)
        The row of ``grouped`` of every window.
    minima : ndarray of float32, shape (m, N' / 64)
        The minima of the rows of ``grouped`` by blocks of 64 columns (:func:`_block_minima`).
    offset : ndarray, shape (m,)
        What turns a bound on the exact distance into a bound on ``lower``: the float32
        error bound less the constant ``sum a ||x||^2``.
    known : ndarray of bool, shape (m, w, w)
        What was known of the windows.
    n_windows : int
        ``N``.
    """

    def __init__(
        self,
        grouped: np.ndarray,
        position: np.ndarray,
        minima: np.ndarray,
        offset: np.ndarray,
        known: np.ndarray,
        n_windows: int,
    ):
        self.n_windows = n_windows
        self.grouped = grouped
        self.position = position
        self.minima = minima
        self.offset = offset
        self.known = known

    @property
    def lower(self) -> np.ndarray:
        """The bounds in the windows' order, ``(m, N)`` (a copy of ``grouped``'s rows)."""
        return self.grouped[self.position, : self.n_windows]


def _covering_arc(present: np.ndarray) -> tuple[int, int]:
    """``(start, length)`` of the shortest cyclic run of ``present`` that holds every True."""
    size = present.size
    where = np.flatnonzero(present)
    if where.size == 0:
        return 0, 1
    gaps = np.diff(np.append(where, where[0] + size))
    widest = int(np.argmax(gaps))
    return int(where[(widest + 1) % where.size]), size - int(gaps[widest]) + 1


class ScreenBank:
    """The float32 side of the exact search, built once from the exemplar's windows.

    Over the disc pixels ``p`` (radius :data:`SCREEN_RADIUS`, without the centre, which is
    the pixel being synthesised) of every window, ``[||y(p)||^2, y(p)]`` with ``y`` the
    window's values centred on the exemplar's mean (SSDs do not change, float32 products
    get more accurate) and projected on the exemplar's :data:`SCREEN_CHANNELS` principal
    colour axes (a projection on orthonormal axes never lengthens a difference); the column
    maxima bound the rounding errors. The disc pixels are ordered by angle around the
    centre and the bank is stored twice over, so that the pixels of any arc of the disc are
    one contiguous band of its rows (:meth:`screen`).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W, C)
    patches : ndarray, shape (N, w * w * C)
        Every window, in the order of :func:`~texsyn.ops.patches.extract_patches`.
    gauss : ndarray, shape (w, w)
        The distance's Gaussian weights.
    """

    def __init__(self, exemplar: np.ndarray, patches: np.ndarray, gauss: np.ndarray):
        n, channels = patches.shape[0], exemplar.shape[2]
        window = gauss.shape[0]
        grid = np.arange(window) - window // 2
        self.gauss = gauss
        dy, dx = (v.ravel() for v in np.meshgrid(grid, grid, indexing="ij"))
        radius2 = dy * dy + dx * dx
        ring = np.flatnonzero((radius2 <= SCREEN_RADIUS**2) & (radius2 > 0))
        self.ring = ring[np.lexsort((radius2[ring], np.arctan2(dy[ring], dx[ring])))]
        self.ring_dy, self.ring_dx = dy[self.ring].astype(np.float64), dx[self.ring].astype(np.float64)
        pixels = exemplar.reshape(-1, channels)
        self.mean = pixels.mean(axis=0)
        if channels > SCREEN_CHANNELS:
            centred_pixels = pixels - self.mean
            _, vectors = np.linalg.eigh(centred_pixels.T @ centred_pixels)
            self.axes = np.ascontiguousarray(vectors[:, ::-1][:, :SCREEN_CHANNELS])
        else:
            self.axes = np.eye(channels)
        centred = (patches.reshape(n, -1, channels)[:, self.ring, :] - self.mean) @ self.axes
        # features per disc pixel: [||y||^2, y_0, y_1...], pixel after pixel in angle order
        stacked = np.concatenate([np.sum(centred * centred, axis=2)[..., None], centred], axis=2)
        self.features = stacked.shape[2]
        stacked = stacked.reshape(n, -1)
        # largest magnitudes without an absolute-value copy of the arrays
        self.column_max = np.maximum(stacked.max(axis=0), -stacked.min(axis=0))
        self.bank = np.empty((2 * stacked.shape[1], n), np.float32)
        self.bank[: stacked.shape[1]] = stacked.T
        self.bank[stacked.shape[1] :] = self.bank[: stacked.shape[1]]
        value_max = np.maximum(patches.max(axis=0), -patches.min(axis=0))
        self.value_max = value_max.reshape(window, window, channels)
        self.grid_cols = exemplar.shape[1] - window + 1
        self.planes = np.ascontiguousarray(np.moveaxis(exemplar, 2, 0))

    def buffers(self, rows: int) -> tuple[np.ndarray, np.ndarray]:
        """Room for the bounds of up to ``rows`` windows, for :meth:`screen`'s ``out``."""
        n_windows = self.bank.shape[1]
        padded = -(-n_windows // BLOCK_COLUMNS) * BLOCK_COLUMNS
        grouped = np.empty((rows, padded), np.float32)
        grouped[:, n_windows:] = np.inf
        return grouped, np.empty((rows, padded // _BLOCK), np.float32)

    def screen(
        self, windows: np.ndarray, known: np.ndarray, out: tuple[np.ndarray, np.ndarray] | None = None
    ) -> WindowScreen:
        """Float32 lower bounds of the distances of ``k`` windows to every exemplar window.

        The windows are put in four groups by the side of the disc that is known (the
        direction of the centroid of their known disc pixels); a group only needs the
        shortest arc of the disc (in angle order) that holds all its known pixels, about
        half of the disc at the front of the growing texture. Each group is one matrix
        product ``(k_g x n_g) @ (n_g x N)`` over the ``n_g`` columns of its arc, a
        contiguous band of the bank's rows. The margin is the worst-case float32 error of
        that product, ``(n_g + 3) u sum |A| |B|`` (Higham, *Accuracy and Stability of
        Numerical Algorithms*, section 3.1), with ``sum |A| |B|`` bounded by the bank's
        column maxima. Which columns a product takes changes the bound's rounding only:
        the unknown pixels' columns add zeros.

        Parameters
        ----------
        windows : ndarray, shape (k, w, w, C)
        known : ndarray of bool, shape (k, w, w)
            What is known of them now; it must stay known until they are matched.
        out : (ndarray, ndarray), optional
            :meth:`buffers` of at least ``k`` rows, which the result then uses (a caller
            that screens many times reuses them, rather than new pages each time).
        """
        k = windows.shape[0]
        left, constant, size, present, group = _disc_terms(
            windows,
            known,
            self.gauss,
            self.ring,
            self.mean,
            self.axes,
            self.column_max,
            self.ring_dy,
            self.ring_dx,
        )
        order = np.argsort(group, kind="stable")
        position = np.empty(k, np.int64)
        position[order] = np.arange(k)
        starts = np.searchsorted(group[order], np.arange(5))
        pixels = self.ring.size
        n_windows = self.bank.shape[1]
        if out is None or out[0].shape[0] < k:
            out = self.buffers(k)
        grouped, minima = out[0][:k], out[1][:k]
        padded = grouped.shape[1]
        columns = np.zeros(k)
        tasks = []
        for g in range(4):
            rows = order[starts[g] : starts[g + 1]]
            if rows.size == 0:
                continue
            start, length = _covering_arc(present[rows].any(axis=0))
            arc = np.arange(start, start + length) % pixels
            lhs = np.ascontiguousarray(left[rows][:, arc].reshape(rows.size, -1), dtype=np.float32)
            rhs = self.bank[start * self.features : (start + length) * self.features]
            band = slice(starts[g], starts[g + 1])
            columns[rows] = lhs.shape[1]
            # two tasks a group: few hand-overs to the pool, both cores busy
            half = -(-padded // (2 * BLOCK_COLUMNS)) * BLOCK_COLUMNS
            tasks += [
                (lhs, rhs, grouped[band], minima[band], range(c, min(c + half, padded), BLOCK_COLUMNS))
                for c in (0, half)
            ]
        with fixed_order():
            parallel_map(_tile_products, tasks)
        n = columns + 3.0
        margin = 1.01 * n * _U32 / (1.0 - n * _U32) * size + 1e-9 * (size + constant)
        return WindowScreen(grouped, position, minima, margin - constant, known.copy(), n_windows)

    def choose(
        self,
        windows: np.ndarray,
        known: np.ndarray,
        tolerance: float,
        uniforms: np.ndarray,
        screen: WindowScreen,
        rows: slice,
        accept: float,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Efros and Leung's rule for ``k`` windows from the lower bounds of ``screen``.

        Parameters
        ----------
        windows, known, tolerance, uniforms
            As for :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`; ``known``
            must contain what ``screen`` was built with.
        screen : WindowScreen
        rows : slice
            The rows of ``screen`` that belong to these windows.
        accept : float
            Largest accepted error.

        Returns
        -------
        choice : ndarray of int64, shape (k,)
            The chosen exemplar window of every row.
        error : ndarray, shape (k,)
            Its distance per unit weight.
        sure : bool
            False where the float64 matrix product could choose otherwise (a survivor or
            the error within its rounding of the threshold or of ``accept``).
        """
        choice, error, unsure = _choose_rows(
            windows,
            known,
            screen.known[rows],
            screen.grouped,
            screen.position[rows],
            screen.minima,
            screen.offset[rows],
            self.gauss,
            self.value_max,
            self.planes,
            self.grid_cols,
            float(tolerance),
            uniforms,
            float(accept),
            SPREAD_SAFETY,
            NEW_MIN_WEIGHT,
            _FIRST,
        )
        return choice, error, not np.any(unsure)

    def fill(
        self,
        canvas: np.ndarray,
        filled: np.ndarray,
        source: np.ndarray,
        pixels: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        batches: tuple[int, int],
        screen: WindowScreen,
        chunk_start: int,
        centres: np.ndarray,
        tolerance: float,
        accept: float,
        wrap: bool = False,
    ) -> tuple[int, int]:
        """Choose and write the pixels of consecutive batches of a pass, in order (:func:`_fill_batches`).

        Parameters
        ----------
        canvas, filled : ndarray, shapes (H + 2r, W + 2r, C) and (H + 2r, W + 2r)
            The padded output and its mask (``r = w // 2``), written in place.
        source : ndarray of int64, shape (H, W, 2)
            Written in place: the exemplar pixel of every filled output pixel.
        pixels : (rows, cols, uniforms, bounds)
            The pass's pixels in batch order, their draws, and where each batch starts.
        batches : (int, int)
            The batches to fill, ``start`` to ``stop - 1``.
        screen : WindowScreen
            Their bounds; pixel ``p`` is row ``p - chunk_start``.
        centres : ndarray of int64, shape (N, 2)
            The centre of every exemplar window.
        tolerance, accept : float
        wrap : bool
            The output is a torus: every pixel written is copied across the wraps into the
            padding (:func:`wrap_pixel`).

        Returns
        -------
        next : int
            ``stop``, or the first batch the rounding of the matrix product could decide
            otherwise (not written: :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`'s).
        written : int
        """
        rows, cols, uniforms, bounds = pixels
        return _fill_batches(
            canvas,
            filled,
            source,
            rows,
            cols,
            uniforms,
            bounds,
            batches[0],
            batches[1],
            chunk_start,
            screen.grouped,
            screen.position,
            screen.minima,
            screen.offset,
            screen.known,
            centres,
            self.gauss,
            self.value_max,
            self.planes,
            self.grid_cols,
            float(tolerance),
            float(accept),
            SPREAD_SAFETY,
            NEW_MIN_WEIGHT,
            _FIRST,
            bool(wrap),
        )
