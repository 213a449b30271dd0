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
from .linalg import matmul

__all__ = ["ScreenBank", "WindowScreen", "window_ssd"]

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


@jit()
def _known_lists(
    windows, known, before, gauss, min_weight, value_max, planes, grid_cols, first, safety
):  # pragma: no cover
    """Every row's known pixels as lists for :func:`_screened_pick`, the exact distance to
    window ``first[i]``, and the bound on the rounding difference with the matrix product.

    Row ``i`` lists first its pixels known now but not in ``before`` of Gaussian weight at
    least ``min_weight`` (``n_new[i]`` of them), then its other known pixels (``n_known[i]``
    in all): offsets ``oy, ox`` in the window, weights and values. ``spread[i]`` bounds
    ``|direct sum - expanded product|`` for any exemplar window: ``safety (2 D + 8) u sum_p
    w_p sum_c (Y^2 + 3 |x| Y + 2 x^2)`` with ``Y`` the largest ``|value|`` of the exemplar
    windows at that place and ``D`` the window's length (Higham, *Accuracy and Stability
    of Numerical Algorithms*, section 3.1: ``gamma_D`` bounds a sum of ``D`` products in
    any order, here the product's and this sum's errors together; ``safety`` leaves room).
    """
    m, w, _, channels = windows.shape
    size = w * w
    oy = np.zeros((m, size), np.int64)
    ox = np.zeros((m, size), np.int64)
    weights = np.zeros((m, size))
    values = np.zeros((m, size, channels))
    n_new = np.zeros(m, np.int64)
    n_known = np.zeros(m, np.int64)
    spread = np.zeros(m)
    upper = np.zeros(m)
    scale = safety * (2 * size * channels + 8) * _U64
    for i in range(m):
        for stage in range(2):
            for y in range(w):
                for x in range(w):
                    if not known[i, y, x]:
                        continue
                    g = gauss[y, x]
                    fresh = (not before[i, y, x]) and g >= min_weight
                    if fresh != (stage == 0):
                        continue
                    t = n_known[i]
                    oy[i, t] = y
                    ox[i, t] = x
                    weights[i, t] = g
                    terms = 0.0
                    for c in range(channels):
                        v = windows[i, y, x, c]
                        values[i, t, c] = v
                        big = value_max[y, x, c]
                        terms += big * big + 3.0 * abs(v) * big + 2.0 * v * v
                    spread[i] += g * terms
                    n_known[i] += 1
            if stage == 0:
                n_new[i] = n_known[i]
        spread[i] *= scale
        top = first[i] // grid_cols
        left = first[i] - top * grid_cols
        upper[i] = window_ssd(planes, top, left, oy[i], ox[i], weights[i], values[i], n_known[i])
    return oy, ox, weights, values, n_new, n_known, spread, upper


@jit()
def _screened_pick(
    lower,
    first_limit,
    offset,
    planes,
    grid_cols,
    oy,
    ox,
    weights,
    values,
    n_new,
    n_known,
    upper,
    spread,
    norm,
    tolerance,
    uniforms,
    accept,
    n_first,
):  # pragma: no cover - compiled
    """Efros and Leung's candidate rule from lower bounds and exact re-ranking, row by row.

    Row ``i`` (a pixel) lists its known pixels (offsets ``oy, ox`` in the window, Gaussian
    ``weights``, ``values``): the first ``n_new[i]`` were not known when ``lower`` was
    computed, the others up to ``n_known[i]`` are the rest. Window ``j`` has its top-left
    corner at ``divmod(j, grid_cols)`` in the exemplar, whose channel ``c`` is
    ``planes[c]``. Distances are in raw units (not per unit weight) until the rule.

    The first screen keeps the windows whose float32 bound ``lower[i, j]`` is at most
    ``first_limit[i]``, what an exact distance ``upper[i]``, known to be at least the best
    one, allows. Their bound gets the exact SSD over the new pixels;
    the ``n_first`` of smallest bound get their exact distance (a smaller ``upper``); the
    windows whose bound leaves them a chance to be a candidate (the survivors) get their
    exact distance; and the rule ``d <= (1 + tolerance) min d + 1e-10`` (per unit weight)
    picks among them. ``unsure[i]`` marks rows where a survivor or the chosen distance lies
    within ``spread`` (the largest difference between this direct sum and the matrix
    product of :meth:`~texsyn.ops.nonparametric.NonParametricSampler.match`) of the threshold or of ``accept``.

    Returns
    -------
    choice : ndarray of int64, shape (m,)
    error : ndarray, shape (m,)
    unsure : ndarray of bool, shape (m,)
    survivors : ndarray of int64, shape (m,)
        Windows whose exact distance was computed (statistics).
    """
    m, n = lower.shape
    channels = planes.shape[0]
    choice = np.zeros(m, np.int64)
    error = np.zeros(m)
    unsure = np.zeros(m, np.bool_)
    survivors = np.zeros(m, np.int64)
    passed = np.empty(n, np.int64)
    bound = np.empty(n)
    dist = np.empty(n)
    index = np.empty(n, np.int64)
    for i in range(m):
        count = 0
        cut = first_limit[i]
        for j in range(n):  # the first screen: one pass over the row, rarely taken
            if lower[i, j] <= cut:
                passed[count] = j
                count += 1
        for k in range(count):  # the bound, with the pixels known since ``lower`` was computed
            j = passed[k]
            top = j // grid_cols
            left = j - top * grid_cols
            value = np.float64(lower[i, j])
            for t in range(n_new[i]):
                part = 0.0
                for c in range(channels):
                    diff = values[i, t, c] - planes[c, top + oy[i, t], left + ox[i, t]]
                    part += diff * diff
                value += weights[i, t] * part
            bound[k] = value
        first_val = np.full(n_first, np.inf)
        first_idx = np.zeros(n_first, np.int64)
        for k in range(count):
            v = bound[k]
            if v < first_val[n_first - 1]:
                p = n_first - 1
                while p > 0 and first_val[p - 1] > v:
                    first_val[p] = first_val[p - 1]
                    first_idx[p] = first_idx[p - 1]
                    p -= 1
                first_val[p] = v
                first_idx[p] = passed[k]
        known = n_known[i]
        best_raw = upper[i]
        for t in range(min(n_first, count)):
            top = first_idx[t] // grid_cols
            left = first_idx[t] - top * grid_cols
            best_raw = min(
                best_raw, window_ssd(planes, top, left, oy[i], ox[i], weights[i], values[i], known)
            )
        s = spread[i]
        # a candidate of the product's rule has a true distance below ``reach`` (raw units)
        reach = ((1.0 + tolerance) * (best_raw + s) + 1e-10 * norm[i]) * (1.0 + 1e-9) + s
        limit = reach + offset[i]
        limit += 1e-11 * (abs(limit) + abs(offset[i]))  # the float64 rounding of ``bound``
        n_in = 0
        best = np.inf
        for k in range(count):
            if bound[k] <= limit:
                j = passed[k]
                top = j // grid_cols
                left = j - top * grid_cols
                index[n_in] = j
                dist[n_in] = (
                    window_ssd(planes, top, left, oy[i], ox[i], weights[i], values[i], known) / norm[i]
                )
                best = min(best, dist[n_in])
                n_in += 1
        survivors[i] = n_in
        threshold = best * (1.0 + tolerance) + 1e-10
        margin = 1.01 * (2.0 + tolerance) * s / norm[i]
        inside = 0
        for k in range(n_in):
            if dist[k] <= threshold:
                inside += 1
            if abs(dist[k] - threshold) <= margin:
                unsure[i] = True
        target = min(int(uniforms[i] * inside), inside - 1)
        seen = 0
        for k in range(n_in):
            if dist[k] <= threshold:
                if seen == target:
                    choice[i] = index[k]
                    error[i] = dist[k]
                    break
                seen += 1
        if abs(error[i] - accept) <= 1.01 * s / norm[i]:
            unsure[i] = True
    return choice, error, unsure, survivors


class WindowScreen:
    """Float32 lower bounds of the distances of some windows to every exemplar window.

    Built by :meth:`ScreenBank.screen` from what is known of the windows at that
    moment; valid for as long as that stays known (a pixel's window only gains pixels while
    the texture grows). Row ``i`` bounds from below, with a margin for float32 rounding,
    the Gaussian-weighted SSD over the known pixels of the central disc of radius
    :data:`SCREEN_RADIUS`, which is a part of the sum the exact distance takes.

    Attributes
    ----------
    lower : ndarray of float32, shape (m, N)
        ``sum a ||y||^2 - 2 sum a x . y`` over the disc (centred values), without the
        window's constant term.
    offset : ndarray, shape (m,)
        What turns a bound on the exact distance into a bound on ``lower``: the float32
        error bound less the constant ``sum a ||x||^2``.
    known : ndarray of bool, shape (m, w, w)
        What was known of the windows.
    first : ndarray of int64, shape (m,)
        The window of smallest ``lower`` in every row.
    """

    def __init__(self, lower: np.ndarray, offset: np.ndarray, known: np.ndarray):
        self.lower = lower
        self.offset = offset
        self.known = known
        self.first = lower.argmin(axis=1)


class ScreenBank:
    """The float32 side of the exact search, built once from the exemplar's windows.

    Over the disc pixels ``p`` (radius :data:`SCREEN_RADIUS`) of every window,
    ``[||y(p)||^2, y(p)]`` with ``y`` the window's values centred on the exemplar's mean
    (SSDs do not change, float32 products get more accurate) and projected on the
    exemplar's :data:`SCREEN_CHANNELS` principal colour axes (a projection on orthonormal
    axes never lengthens a difference); the column maxima bound the rounding errors.

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
        self.disc = np.flatnonzero((grid[:, None] ** 2 + grid[None, :] ** 2 <= SCREEN_RADIUS**2).ravel())
        pixels = exemplar.reshape(-1, channels)
        self.mean = pixels.mean(axis=0)
        if channels > SCREEN_CHANNELS:
            centred_pixels = pixels - self.mean
            _, vectors = np.linalg.eigh(centred_pixels.T @ centred_pixels)
            self.axes = np.ascontiguousarray(vectors[:, ::-1][:, :SCREEN_CHANNELS])
        else:
            self.axes = np.eye(channels)
        centred = (patches.reshape(n, -1, channels)[:, self.disc, :] - self.mean) @ self.axes
        stacked = np.concatenate([np.sum(centred * centred, axis=2), centred.reshape(n, -1)], axis=1)
        self.bank = np.ascontiguousarray(stacked.astype(np.float32))
        self.column_max = np.abs(stacked).max(axis=0)
        self.value_max = np.abs(patches).max(axis=0).reshape(window, window, channels)
        self.grid_cols = exemplar.shape[1] - window + 1
        self.planes = np.ascontiguousarray(np.moveaxis(exemplar, 2, 0))

    def screen(self, windows: np.ndarray, known: np.ndarray) -> WindowScreen:
        """Float32 lower bounds of the distances of ``k`` windows to every exemplar window.

        One matrix product ``(k x n) @ (n x N)`` over the ``n = |disc| (1 + C')`` columns of
        the disc. The margin is the worst-case float32 error of that product, ``(n + 3) u
        sum |A| |B|`` (Higham, *Accuracy and Stability of Numerical Algorithms*, section
        3.1), with ``sum |A| |B|`` bounded by the bank's column maxima.

        Parameters
        ----------
        windows : ndarray, shape (k, w, w, C)
        known : ndarray of bool, shape (k, w, w)
            What is known of them now; it must stay known until they are matched.
        """
        k, channels = windows.shape[0], windows.shape[3]
        a = (known * self.gauss).reshape(k, -1)[:, self.disc]
        x = (windows.reshape(k, -1, channels)[:, self.disc, :] - self.mean) @ self.axes
        x = np.where(a[..., None] > 0, x, 0.0)
        left = np.concatenate([a, (-2.0 * a[..., None] * x).reshape(k, -1)], axis=1)
        constant = np.sum(a * np.sum(x * x, axis=2), axis=1)
        lower = matmul(left.astype(np.float32), self.bank.T)
        n = left.shape[1]
        size = np.abs(left) @ self.column_max
        margin = 1.01 * (n + 3) * _U32 / (1.0 - (n + 3) * _U32) * size + 1e-9 * (size + constant)
        return WindowScreen(lower, margin - constant, known.copy())

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
        norm = (known * self.gauss).sum(axis=(1, 2))  # as match computes it
        lower, offset = screen.lower[rows], screen.offset[rows]
        oy, ox, weights, values, n_new, n_known, spread, upper = _known_lists(
            windows,
            known,
            screen.known[rows],
            self.gauss,
            NEW_MIN_WEIGHT,
            self.value_max,
            self.planes,
            self.grid_cols,
            screen.first[rows],
            SPREAD_SAFETY,
        )
        # first screen: every window whose float32 bound is below what the exact distance
        # of the window of smallest bound allows (rounded up to float32)
        reach = ((1.0 + tolerance) * (upper + spread) + 1e-10 * norm) * (1.0 + 1e-9) + spread
        first_limit = np.nextafter((reach + offset).astype(np.float32), np.float32(np.inf))
        choice, error, unsure, _ = _screened_pick(
            lower,
            first_limit,
            offset,
            self.planes,
            self.grid_cols,
            oy,
            ox,
            weights,
            values,
            n_new,
            n_known,
            upper,
            spread,
            norm,
            float(tolerance),
            uniforms,
            float(accept),
            _FIRST,
        )
        return choice, error, not np.any(unsure)
