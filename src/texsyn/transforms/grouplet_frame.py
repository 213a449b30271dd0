"""The grouplet tight frame of Peyré 2008, section 2.2, computed by a sequential in-place scan.

Section 2.2 describes the fast grouplet transform in words: at scale ``l`` the pixels ``m``
are processed one after the other in an ordering computed from the association field
``A_l``; a residual ``f~`` (initialised to ``f``) is updated in place; each pixel ``m`` is
linked to ``m~ = A_l(m)``, its detail ``d_l(m)`` is proportional to ``f~(m) - f~(m~)`` and
``f~(m~)`` becomes proportional to their average; after the last scale ``d_L`` is
proportional to ``f~``; the proportionality factors conserve energy even where several
pixels are associated to the same one; the cost is ``O((L+1) N)``; and an image is
recovered from any coefficients by the pseudo-inverse

    f = sum_{l=0..L} tau_l sum_m d_l(m) b_{l,m},   tau_l = 2^-l (l < L),  tau_L = 2^(-L+1).

The paper leaves the factors themselves to a preprint we do not have. The ones used here are
those of a weighted (unbalanced) Haar merge, with a mass ``s`` per pixel (the size of the
support its residual averages; 1 at the start):

    merge of a source m (value a(m), mass s_m) into its target p = A_l(m)
    (current residual r(p), accumulated mass S):
        d_l(m) = sqrt(s_m S / (s_m + S)) (a(m) - r(p)) / sqrt(2)
        r(p)  <- (S r(p) + s_m a(m)) / (S + s_m),        S <- S + s_m
    end of the level: the residual of the next level is r, its masses the final S;
    low-pass: d_L(m) = sqrt(s_L(m) / 2) r_L(m).

Each merge is a rotation of ``(sqrt(s_m) a(m), sqrt(S) r(p))``, so however many sources
converge on ``p`` the energy ``sum s a^2`` is kept. Every pixel enters a level twice (as the
source of its own target, and as the starting residual of its own group), so level ``l``
carries twice the energy of its input; with the ``1/sqrt(2)`` above this gives exactly the
paper's weights: ``sum_l tau_l ||d_l||^2 = ||f||^2`` for every image and every association
field (a tight frame), constants have zero details, and along a one-to-one flow (a
translation) the masses are ``2^l`` everywhere and the transform is the undecimated Haar
transform along the flow lines. The inverse undoes the merges in reverse order, which gives
two estimates of every pixel (as a source and as a group start); their mean is the adjoint,
i.e. the ``tau_l`` reconstruction above.

Why this module is long: the schedule of the merges (scan order, masses, factors) and the
forward and inverse scans that replay it share the conventions above, and each scan comes
as a block of interleaved images plus its threaded driver (issue 20); split apart, every
part would have to restate them.
"""

from __future__ import annotations

import math

import numpy as np

from ..ops.jit import jit, prange
from ..ops.linalg import worker_count

__all__ = ["GroupletTightFrame", "checked_associations", "grouplet_weights"]

_SQRT2 = math.sqrt(2.0)

#: updates (images x (L+1) x pixels) from which a transform runs its images on numba's
#: threads, in one block of interleaved images per worker
PARALLEL_UPDATES = 1 << 18


def checked_associations(associations: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Association fields ``(L, H*W)`` as contiguous int64 flat indexes, checked against ``shape``.

    Raises
    ------
    ValueError
        A wrong shape, or an index outside the image.
    """
    a = np.ascontiguousarray(associations, dtype=np.int64)
    n = int(shape[0]) * int(shape[1])
    if a.ndim != 2 or a.shape[1] != n:
        raise ValueError(f"associations must have shape (L, {n}), got {a.shape}")
    if a.size and (a.min() < 0 or a.max() >= n):
        raise ValueError("associations point outside the image")
    return a


def grouplet_weights(levels: int) -> np.ndarray:
    """Reconstruction weights ``tau_l`` of Peyré 2008, section 2.2, for ``l = 0..L``.

    ``tau_l = 2^-l`` for ``l < L`` and ``tau_L = 2^(-L+1)``.

    Examples
    --------
    >>> grouplet_weights(3).tolist()
    [1.0, 0.5, 0.25, 0.25]
    """
    tau = 2.0 ** -np.arange(levels + 1, dtype=np.float64)
    tau[levels] = 2.0 ** (-levels + 1)
    return tau


@jit()
def _scan_order(target):
    """Ordering of the pixels at one scale computed from ``A_l``: a stable counting sort by target.

    The sources of each target are contiguous; a pixel associated to itself comes first
    in its group (its detail is then zero).
    """
    n = target.size
    start = np.zeros(n + 1, dtype=np.int64)
    for m in range(n):
        start[target[m] + 1] += 1
    for p in range(n):
        start[p + 1] += start[p]
    order = np.empty(n, dtype=np.int64)
    fill = start[:n].copy()
    for m in range(n):
        p = target[m]
        if p == m:
            order[fill[p]] = m
            fill[p] += 1
    for m in range(n):
        p = target[m]
        if p != m:
            order[fill[p]] = m
            fill[p] += 1
    return order


@jit()
def _masses(targets, orders):
    """Masses ``s_l`` (``L+1`` rows) of every pixel: ``s_0 = 1``, ``s_(l+1)(p) = s_l(p) + sum_(A_l m = p) s_l(m)``."""
    levels, n = targets.shape
    masses = np.ones((levels + 1, n))
    for lv in range(levels):
        acc = masses[lv].copy()
        for k in range(n):
            m = orders[lv, k]
            acc[targets[lv, m]] += masses[lv, m]
        masses[lv + 1] = acc
    return masses


@jit()
def _schedule(targets, orders, masses):
    """The merges of every level in processing order, with their image-independent factors.

    For the ``k``-th merge of level ``l`` (source ``m = orders[l, k]``, target ``p``, mass
    ``s_m``, and ``S``, the mass the group of ``p`` has gathered so far): ``dst = p``, the
    detail factor ``sqrt(s_m S / (s_m + S)) / sqrt(2)`` and the share ``s_m / (s_m + S)`` by
    which the residual of ``p`` moves towards ``a(m)``. ``low`` is the low-pass factor
    ``sqrt(s_L / 2)`` of each pixel.
    """
    levels, n = targets.shape
    dst = np.empty((levels, n), dtype=np.int64)
    detail = np.empty((levels, n))
    share = np.empty((levels, n))
    for lv in range(levels):
        acc = masses[lv].copy()
        for k in range(n):
            m = orders[lv, k]
            p = targets[lv, m]
            sm = masses[lv, m]
            big_s = acc[p]
            dst[lv, k] = p
            detail[lv, k] = math.sqrt(sm * big_s / (sm + big_s)) / _SQRT2
            share[lv, k] = sm / (sm + big_s)
            acc[p] = big_s + sm
    low = np.sqrt(masses[levels] / 2.0)
    return dst, detail, share, low


@jit()
def _plan(targets):
    """The whole schedule of association fields ``(L, N)`` in one kernel (one cached function to
    load instead of three): each level's :func:`_scan_order`, the :func:`_masses` and the
    merges of :func:`_schedule`, computed by those functions."""
    levels, n = targets.shape
    orders = np.empty((levels, n), dtype=np.int64)
    for lv in range(levels):
        orders[lv] = _scan_order(targets[lv])
    masses = _masses(targets, orders)
    dst, detail, share, low = _schedule(targets, orders, masses)
    return orders, masses, dst, detail, share, low


@jit()
def _forward_block(images, src, dst, detail, share, low, scales, normalized, out, work, b0, b1):
    """The sequential in-place scan of images ``b0 .. b1 - 1`` of ``(B, N)`` together, into ``out`` ``(L+1, B, N)``.

    Merge ``k`` of level ``l``: ``d_l(m) = detail (a(m) - r(p))``, ``r(p) += share (a(m) - r(p))``
    (the mass-weighted average of the group and ``m``). The images are interleaved (one row of
    ``b1 - b0`` values per pixel), so each merge loads its pixels, target and factors once for
    all of them; every value gets the arithmetic of the one-image scan in the same order, so
    the same bytes (``tests/test_grouplet_frame.py``). With ``normalized`` each coefficient is
    then divided by ``scales[l, m]``. ``work`` ``(2, B * N)`` holds the two interleaved
    residuals (columns ``b0 N .. b1 N``). Returns the updates per image.

    The residual of a level starts as its input, ``r = a``: the targets ``dst`` of a level
    ascend (:func:`_scan_order` groups the merges by target), so the pixels up to each
    group's target are copied when the scan reaches it, while their rows are in the cache,
    instead of in a pass of their own.
    """
    levels, n = src.shape
    nb = b1 - b0
    a = work[0, n * b0 : n * b1].reshape(n, nb)
    for m in range(n):
        for b in range(nb):
            a[m, b] = images[b0 + b, m]
    r = work[1, n * b0 : n * b1].reshape(n, nb)
    count = 0
    for lv in range(levels):
        unset = 0  # the residuals of the pixels below it hold their start, a
        for k in range(n):
            m = src[lv, k]
            p = dst[lv, k]
            if p >= unset:  # the group of p starts: r = a up to p
                for q in range(unset, p + 1):
                    for b in range(nb):
                        r[q, b] = a[q, b]
                unset = p + 1
            f = detail[lv, k]
            g = share[lv, k]
            for b in range(nb):
                diff = a[m, b] - r[p, b]
                d = f * diff
                out[lv, b0 + b, m] = d / scales[lv, m] if normalized else d
                r[p, b] += g * diff
            count += 1
        for q in range(unset, n):
            for b in range(nb):
                r[q, b] = a[q, b]
        a, r = r, a
    for m in range(n):
        for b in range(nb):
            d = low[m] * a[m, b]
            out[levels, b0 + b, m] = d / scales[levels, m] if normalized else d
        count += 1
    return count


@jit(parallel=True)
def _forward_rows(images, src, dst, detail, share, low, scales, normalized, out, work, n_blocks):
    """The scan of every row of ``images`` ``(B, N)`` into ``out`` ``(L+1, B, N)``, in
    ``n_blocks`` blocks of interleaved images on numba's threads (:func:`_forward_block`)."""
    rows = images.shape[0]
    counts = np.zeros(n_blocks, dtype=np.int64)
    size = (rows + n_blocks - 1) // n_blocks
    for c in prange(n_blocks):
        b0 = min(rows, c * size)
        b1 = min(rows, b0 + size)
        if b1 > b0:
            counts[c] = _forward_block(
                images, src, dst, detail, share, low, scales, normalized, out, work, b0, b1
            )
    return counts


@jit()
def _inverse_block(coefficients, src, dst, detail, share, low, scales, normalized, out, work, b0, b1):
    """Undo the merges of images ``b0 .. b1 - 1`` of ``(L+1, B, N)`` coefficients in reverse
    order, interleaved as in :func:`_forward_block`, into ``out`` ``(B, N)``; the mean of each
    pixel's two estimates is the adjoint. With ``normalized`` each coefficient is first
    multiplied by ``scales[l, m]``. ``work`` as in :func:`_forward_block`. Returns the
    updates per image."""
    levels, n = src.shape
    nb = b1 - b0
    r = work[0, n * b0 : n * b1].reshape(n, nb)
    count = 0
    for m in range(n):
        for b in range(nb):
            c = coefficients[levels, b0 + b, m]
            if normalized:
                c = c * scales[levels, m]
            r[m, b] = c / low[m]
        count += 1
    source = work[1, n * b0 : n * b1].reshape(n, nb)
    for lv in range(levels - 1, -1, -1):
        for k in range(n - 1, -1, -1):
            m = src[lv, k]
            p = dst[lv, k]
            f = detail[lv, k]
            g = share[lv, k]
            s = scales[lv, m]
            for b in range(nb):
                c = coefficients[lv, b0 + b, m]
                if normalized:
                    c = c * s
                delta = c / f  # a(m) - r(p) before the merge
                old = r[p, b] - g * delta
                source[m, b] = old + delta
                r[p, b] = old
            count += 1
        for m in range(n):
            for b in range(nb):
                r[m, b] = 0.5 * (r[m, b] + source[m, b])
    for m in range(n):
        for b in range(nb):
            out[b0 + b, m] = r[m, b]
    return count


@jit(parallel=True)
def _inverse_rows(coefficients, src, dst, detail, share, low, scales, normalized, out, work, n_blocks):
    """The inverse of every image of ``(L+1, B, N)`` coefficients into ``out`` ``(B, N)``,
    in blocks of interleaved images on numba's threads (:func:`_inverse_block`)."""
    rows = coefficients.shape[1]
    counts = np.zeros(n_blocks, dtype=np.int64)
    size = (rows + n_blocks - 1) // n_blocks
    for c in prange(n_blocks):
        b0 = min(rows, c * size)
        b1 = min(rows, b0 + size)
        if b1 > b0:
            counts[c] = _inverse_block(
                coefficients, src, dst, detail, share, low, scales, normalized, out, work, b0, b1
            )
    return counts


def _buffer(given: np.ndarray | None, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``given`` checked as a C-contiguous float64 array of ``shape`` (reshaped), or a new one."""
    if given is None:
        return np.empty(shape)
    if given.dtype != np.float64 or not given.flags.c_contiguous or given.size != math.prod(shape):
        raise ValueError(f"{name} must be a C-contiguous float64 array of {math.prod(shape)} values")
    return given.reshape(shape)


class GroupletTightFrame:
    """Grouplet tight frame ``B(Gamma)`` of Peyré 2008, section 2.2 (eq. 2 and the ``tau_l`` formula).

    ``forward`` computes ``d_l(m) = <f, b_{l,m}>`` for ``l = 0..L`` by the sequential
    in-place scan described in the module docstring; ``inverse`` computes
    ``sum_l tau_l sum_m d_l(m) b_{l,m}`` (the pseudo-inverse), which is exact on the range of
    ``forward``. Energy: ``sum_l tau_l ||d_l||^2 = ||f||^2`` for any association field.

    Parameters
    ----------
    associations : ndarray of int, shape (L, N)
        ``associations[l, m]``: flat index of ``A_l(m)``
        (:func:`texsyn.ops.flow.association_fields`).
    shape : (int, int)
        Image size, ``H * W == N``.

    Attributes
    ----------
    tau : ndarray, shape (L+1,)
        The reconstruction weights ``tau_l`` (:func:`grouplet_weights`).
    masses : ndarray, shape (L+1, N)
        Support size ``s_l(m)`` behind each pixel's residual at the start of level ``l``.
    scales : ndarray, shape (L+1, N)
        Each coefficient's merge factor over the one it has on an unbranched flow line
        (masses ``2^l``): 1 along a translation, other values where flow lines converge.
        ``d_l(m) / scales[l, m]`` compares a difference (or an average) of residuals
        wherever the flow converges; the grouplet model learns its marginals on them
        (``docs/methods/grouplets.md``).
    orders : ndarray of int, shape (L, N)
        The processing order of each level, computed from ``A_l``.
    last_count : int
        Elementary updates made by the last ``forward`` or ``inverse`` call on one image:
        ``(L+1) N`` (section 2.2: complexity ``O(N (L+1))``).

    Examples
    --------
    >>> import numpy as np
    >>> from texsyn.ops.flow import association_fields, builtin_flow
    >>> frame = GroupletTightFrame(association_fields(builtin_flow("vortex", (16, 16)), 3), (16, 16))
    >>> image = np.random.default_rng(0).random((16, 16))
    >>> d = frame.forward(image)
    >>> d.shape
    (4, 16, 16)
    >>> bool(np.isclose(frame.energy(d), np.sum(image**2)))
    True
    >>> bool(np.allclose(frame.inverse(d), image))
    True
    """

    def __init__(self, associations: np.ndarray, shape: tuple[int, int]):
        a = checked_associations(associations, shape)
        self.associations = a
        self.shape = (int(shape[0]), int(shape[1]))
        self.levels = a.shape[0]
        self.tau = grouplet_weights(self.levels)
        self.orders, self.masses, *merges = _plan(a)
        self._merges = tuple(merges)
        dst, detail, share, low = self._merges
        factors = np.empty((self.levels + 1, a.shape[1]))
        for level in range(self.levels):
            factors[level, self.orders[level]] = detail[level]
        factors[self.levels] = low
        line = 2.0 ** (np.arange(self.levels + 1) / 2.0 - 1.0)  # 2^(l/2 - 1): masses 2^l on a line
        line[self.levels] = 2.0 ** ((self.levels - 1) / 2.0)
        self.scales = factors / line[:, None]
        self.last_count = 0

    def forward(
        self,
        image: np.ndarray,
        *,
        scales: np.ndarray | None = None,
        out: np.ndarray | None = None,
        work: np.ndarray | None = None,
    ) -> np.ndarray:
        """Coefficients ``d_l(m)``, shape ``(L+1, *batch, H, W)``, of images ``(*batch, H, W)``; layer ``L`` is ``d_L``.

        ``scales`` ``(L+1, H, W)``: return ``d_l(m) / scales[l, m]`` instead (the same bytes
        as dividing afterwards, without another pass over the coefficients). ``out``, a
        C-contiguous float64 array of the result's shape, receives the coefficients, and
        ``work`` (:meth:`work_buffer`) holds the scan's residuals: an iterative method passes
        the same ones at every step instead of faulting in fresh pages (the same bytes).
        """
        x = np.asarray(image, dtype=np.float64)
        if x.shape[-2:] != self.shape:
            raise ValueError(f"image shape {x.shape[-2:]} does not match {self.shape}")
        batch = x.shape[:-2]
        flat = np.ascontiguousarray(x.reshape((-1, self.shape[0] * self.shape[1])))
        factors, normalized = self._scales_of(scales)
        shape = (self.levels + 1,) + flat.shape
        result = _buffer(out, shape, "out")
        scratch = self.work_buffer(flat.shape[0]) if work is None else _buffer(work, (2, flat.size), "work")
        blocks = self._blocks(flat.shape[0])
        if blocks > 1:
            counts = _forward_rows(
                flat, self.orders, *self._merges, factors, normalized, result, scratch, blocks
            )
            self.last_count = int(counts[0])
        else:
            count = _forward_block(
                flat, self.orders, *self._merges, factors, normalized, result, scratch, 0, flat.shape[0]
            )
            self.last_count = int(count) if flat.shape[0] else 0
        return result.reshape((self.levels + 1,) + batch + self.shape)

    def inverse(
        self,
        coefficients: np.ndarray,
        *,
        scales: np.ndarray | None = None,
        out: np.ndarray | None = None,
        work: np.ndarray | None = None,
    ) -> np.ndarray:
        """Images ``(*batch, H, W)`` from ``(L+1, *batch, H, W)``: ``f = sum_l tau_l sum_m d_l(m) b_{l,m}``.

        ``scales`` ``(L+1, H, W)``: the coefficients are ``d_l(m) / scales[l, m]`` (the
        inverse of :meth:`forward` with the same ``scales``); each is multiplied back first.
        ``out`` and ``work``: reused buffers, as in :meth:`forward`.
        """
        c = np.asarray(coefficients, dtype=np.float64)
        if c.shape[0] != self.levels + 1 or c.shape[-2:] != self.shape:
            raise ValueError(
                f"coefficients must have shape ({self.levels + 1}, ..., {self.shape}), got {c.shape}"
            )
        batch = c.shape[1:-2]
        flat = np.ascontiguousarray(c.reshape((self.levels + 1, -1, self.shape[0] * self.shape[1])))
        factors, normalized = self._scales_of(scales)
        result = _buffer(out, flat.shape[1:], "out")
        images = flat.shape[1]
        scratch = self.work_buffer(images) if work is None else _buffer(work, (2, result.size), "work")
        blocks = self._blocks(images)
        if blocks > 1:
            counts = _inverse_rows(
                flat, self.orders, *self._merges, factors, normalized, result, scratch, blocks
            )
            self.last_count = int(counts[0])
        else:
            count = _inverse_block(
                flat, self.orders, *self._merges, factors, normalized, result, scratch, 0, images
            )
            self.last_count = int(count) if images else 0
        return result.reshape(batch + self.shape)

    def work_buffer(self, images: int) -> np.ndarray:
        """Scratch space of :meth:`forward` and :meth:`inverse` for ``images`` images: ``(2, images * N)``."""
        return np.empty((2, int(images) * self.shape[0] * self.shape[1]))

    def _scales_of(self, scales: np.ndarray | None) -> tuple[np.ndarray, bool]:
        """``scales`` as contiguous ``(L+1, N)`` factors, and whether there are any."""
        if scales is None:
            return np.ones((1, 1)), False
        factors = np.ascontiguousarray(scales, dtype=np.float64).reshape(self.levels + 1, -1)
        if factors.shape[1] != self.shape[0] * self.shape[1]:
            raise ValueError(f"scales must have shape ({self.levels + 1}, {self.shape[0]}, {self.shape[1]})")
        return factors, True

    def _blocks(self, images: int) -> int:
        """Blocks of interleaved images run on numba's threads: one per worker for large
        stacks; one block (the calling thread) when starting threads costs more than it saves."""
        work = images * (self.levels + 1) * self.shape[0] * self.shape[1]
        return min(worker_count(), images) if work >= PARALLEL_UPDATES else 1

    def energy(self, coefficients: np.ndarray) -> float:
        """Weighted energy ``sum_l tau_l sum_m d_l(m)^2`` (equals ``||f||^2`` for ``d = forward(f)``)."""
        c = np.asarray(coefficients, dtype=np.float64)
        per_level = np.sum(c.reshape(c.shape[0], -1) ** 2, axis=1)
        return float(np.dot(self.tau, per_level))
