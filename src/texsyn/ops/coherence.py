"""Coherent candidates (Ashikhmin 2001): continue the sources of already synthesised neighbours.

A copy-based synthesis records, for every output position, the exemplar position it was
copied from. The *continuation* of a neighbour at offset ``o`` is its source minus ``o``:
the exemplar position that would make the two a copied pair. Preferring continuations keeps
neighbouring pieces together (Ashikhmin, "Synthesizing natural textures", I3D 2001,
section 3), where Efros and Leung's rule draws each position independently among all
windows within a tolerance of the best.

- :class:`CoherentSampler` adds that preference to Efros and Leung's candidate rule for
  :func:`texsyn.drivers.raster.grow_pixels` (the coarsest level of ``cwt``);
- :func:`refine_group` re-chooses positions of a finished source map among their
  neighbours' continuations with full windows of a complex coefficient field (``cwt``'s
  ``refine``), one group of :func:`independent_groups` at a time.

See ``docs/methods/cwt.md``.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .jit import jit
from .nonparametric import NonParametricSampler, candidate_threshold

__all__ = [
    "CoherentSampler",
    "candidate_table",
    "coherent_candidates",
    "independent_groups",
    "pick_within",
    "prefer",
    "refine_group",
    "window_offsets",
]


def window_offsets(window: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets ``(-r .. r)`` of a ``window x window`` neighbourhood, ``(w, w)`` each."""
    half = window // 2
    rows, cols = np.mgrid[-half : half + 1, -half : half + 1]
    return rows, cols


def pick_within(d: np.ndarray, tolerance: float, uniforms: np.ndarray) -> np.ndarray:
    """Efros and Leung's candidate rule on every row of ``d``: a uniformly drawn index among
    ``d <= (1 + tolerance) min d`` (the ``u``-th of them in index order, ``u = floor(uniform
    * count)``), as :meth:`texsyn.ops.nonparametric.NonParametricSampler.match` picks.

    Examples
    --------
    >>> pick_within(np.array([[3.0, 1.0, 1.05, 9.0]]), 0.1, np.array([0.9])).tolist()
    [2]
    """
    best = d.min(axis=1)
    inside = d <= candidate_threshold(best, tolerance)[:, None]
    count = inside.sum(axis=1)
    target = np.minimum((uniforms * count).astype(np.int64), count - 1)
    return np.argmax(np.cumsum(inside, axis=1) > target[:, None], axis=1)


def coherent_candidates(sources: np.ndarray, known: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Ashikhmin's coherent candidates of windows whose known positions carry their sources.

    The known position at offset ``o`` from a window's centre was copied from exemplar
    position ``s``; continuing it puts ``s - o`` at the centre. ``table`` maps an exemplar
    position to its candidate index (``-1`` where it is none).

    Parameters
    ----------
    sources : ndarray of int, shape (k, w, w, 2)
        Exemplar position of every window position (anything where unknown).
    known : ndarray of bool, shape (k, w, w)
    table : ndarray of int, shape (H, W)

    Returns
    -------
    ndarray of int64, shape (k, w * w)
        Candidate indices, ``-1`` for unknown positions and continuations that leave the
        exemplar's candidates; in the window's raster order.
    """
    oy, ox = window_offsets(sources.shape[1])
    rows = sources[..., 0] - oy
    cols = sources[..., 1] - ox
    h, w = table.shape
    ok = known & (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    index = table[np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)]
    return np.where(ok, index, -1).reshape(sources.shape[0], -1)


def prefer(d: np.ndarray, preferred: np.ndarray, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Among ``preferred`` indices of every row of ``d`` (``-1`` = none), the first one of
    smallest distance, and whether it is within ``factor`` times the row's best distance.

    Returns
    -------
    index : ndarray of int64, shape (k,)
        The preferred candidate (meaningless where ``ok`` is False).
    ok : ndarray of bool, shape (k,)
    """
    k = d.shape[0]
    dist = np.where(preferred >= 0, np.take_along_axis(d, np.maximum(preferred, 0), axis=1), np.inf)
    j = np.argmin(dist, axis=1)
    best = dist[np.arange(k), j]
    ok = best <= d.min(axis=1) * factor + 1e-10
    return preferred[np.arange(k), j], ok


class CoherentSampler(NonParametricSampler):
    """Efros-Leung candidates plus Ashikhmin's coherent ones, for :func:`~texsyn.drivers.raster.grow_pixels`.

    The values the growth copies into the output carry, after the feature channels, the
    exemplar row and column they came from, so every window handed to :meth:`match` tells
    where each of its known positions was copied from. A position then compares the best
    of its coherent candidates (each known neighbour's source shifted by the offset between
    them: the continuation of that neighbour) with the best candidate overall, and takes the
    coherent one when its distance is within ``(1 + coherence)`` of the best; otherwise
    Efros and Leung's rule draws among the candidates within ``(1 + tolerance)``.

    It shares the windows of ``base`` (built once, in ``fit``); building one costs a copy of
    the exemplar's channels.

    Parameters
    ----------
    base : NonParametricSampler
        The windows of the exemplar (for ``cwt``: the coarsest DT-CWT level, zero-padded).
    coherence : float
        ``0`` keeps the coherent candidate only when it is as good as the best.

    References
    ----------
    M. Ashikhmin, "Synthesizing natural textures", I3D 2001, section 3 (coherent candidates);
    cited by Gallagher and Kokaram, section 1 (``docs/methods/cwt.md``).
    """

    def __init__(self, base: NonParametricSampler, coherence: float):
        self.window = base.window
        self.bank = base.bank
        self.centres = base.centres
        self.gauss = base.gauss
        self.coherence = float(coherence)
        features = base.exemplar
        self.n_features = features.shape[2]
        rows, cols = np.mgrid[: features.shape[0], : features.shape[1]].astype(np.float64)
        self.exemplar = np.concatenate([features, rows[..., None], cols[..., None]], axis=2)
        self.table = candidate_table(base)

    def distances(self, windows: np.ndarray, known: np.ndarray) -> np.ndarray:
        """Gaussian-weighted SSD per unit weight of ``k`` partly known windows to every candidate, ``(k, n)``."""
        k, c = windows.shape[0], self.n_features
        weights = known * self.gauss
        full = np.broadcast_to(weights[..., None], weights.shape + (c,))
        queries = np.ascontiguousarray(windows[..., :c]).reshape(k, -1)
        d = self.bank.distances(queries, full.reshape(k, -1))
        return d / weights.sum(axis=(1, 2))[:, None]

    def match(
        self, windows: np.ndarray, known: np.ndarray, tolerance: float, uniforms: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Choose an exemplar position for each of ``k`` partly known windows (see the class)."""
        d = self.distances(windows, known)
        choice = pick_within(d, tolerance, uniforms)
        sources = np.rint(windows[..., self.n_features :]).astype(np.int64)
        coherent, ok = prefer(d, coherent_candidates(sources, known, self.table), 1.0 + self.coherence)
        choice = np.where(ok, coherent, choice)
        return self.centres[choice], d[np.arange(d.shape[0]), choice]


def independent_groups(shape: tuple[int, int], step: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Positions of a ``shape`` grid in ``step x step`` groups, each a lattice of spacing
    ``step`` (rows, columns), in a fixed order: positions of a group are further than
    ``step - 1`` apart, so none lies in another's window of radius ``step - 1``, and updating
    a group at once gives the result of updating its positions one by one."""
    for r0 in range(step):
        for c0 in range(step):
            rows, cols = np.meshgrid(
                np.arange(r0, shape[0], step), np.arange(c0, shape[1], step), indexing="ij"
            )
            if rows.size:
                yield rows.ravel(), cols.ravel()


@jit()
def refine_group(rows, cols, choice, padded, gauss, offsets, half):  # pragma: no cover - compiled
    """Re-choose the sources of one group of positions among their neighbours' continuations.

    In place on ``choice``; returns the number of positions changed. For each position ``(rows[i], cols[i])`` (no two within each other's window): the
    candidates are its source, its source plus each of ``offsets``, and the continuation of
    each of its eight neighbours (``choice[neighbour] - (neighbour - position)``); each is
    scored by the ``gauss``-weighted squared modulus, summed over the subbands, between the
    exemplar's zero-padded window ``padded`` around it and the coefficients ``choice``
    assembles around the position (positions outside the grid left out). The first
    candidate of smallest score is kept.
    """
    oh, ow = choice.shape[0], choice.shape[1]
    eh, ew = padded.shape[0] - 2 * half, padded.shape[1] - 2 * half
    bands, width = padded.shape[2], 2 * half + 1
    n_cand = 1 + offsets.shape[0] + 8
    cand = np.empty((n_cand, 2), np.int64)
    changed = 0
    for i in range(rows.size):
        r, c = rows[i], cols[i]
        own_r, own_c = choice[r, c, 0], choice[r, c, 1]
        cand[0, 0], cand[0, 1] = own_r, own_c
        n = 1
        for k in range(offsets.shape[0]):
            cand[n, 0], cand[n, 1] = own_r + offsets[k, 0], own_c + offsets[k, 1]
            n += 1
        for a in range(-1, 2):
            for b in range(-1, 2):
                if a == 0 and b == 0:
                    continue
                nr, nc = r + a, c + b
                if 0 <= nr < oh and 0 <= nc < ow:
                    cand[n, 0], cand[n, 1] = choice[nr, nc, 0] - a, choice[nr, nc, 1] - b
                else:
                    cand[n, 0], cand[n, 1] = own_r, own_c
                n += 1
        best = np.inf
        pick = 0
        for k in range(n_cand):
            y, x = cand[k, 0], cand[k, 1]
            if y < 0 or y >= eh or x < 0 or x >= ew:
                continue
            dist = 0.0
            for u in range(width):
                rr = r + u - half
                if rr < 0 or rr >= oh:
                    continue
                for v in range(width):
                    cc = c + v - half
                    g = gauss[u, v]
                    if cc < 0 or cc >= ow or g == 0.0:
                        continue
                    sy, sx = choice[rr, cc, 0] + half, choice[rr, cc, 1] + half
                    part = 0.0
                    for m in range(bands):
                        dd = padded[y + u, x + v, m] - padded[sy, sx, m]
                        part += dd.real * dd.real + dd.imag * dd.imag
                    dist += g * part
            if dist < best:
                best = dist
                pick = k
        if pick != 0:
            choice[r, c, 0], choice[r, c, 1] = cand[pick, 0], cand[pick, 1]
            if cand[pick, 0] != own_r or cand[pick, 1] != own_c:
                changed += 1
    return changed


def candidate_table(sampler: NonParametricSampler) -> np.ndarray:
    """Index of the candidate window centred on every exemplar position, ``-1`` where none is."""
    table = np.full(sampler.exemplar.shape[:2], -1, dtype=np.int64)
    table[sampler.centres[:, 0], sampler.centres[:, 1]] = np.arange(sampler.centres.shape[0])
    return table
