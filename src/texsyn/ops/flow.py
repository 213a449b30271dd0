"""Orientation and flow fields: structure tensor, sign optimisation, association fields.

The geometric layer of Peyré's grouplet model (Peyré 2008, section 2.1;
``docs/methods/grouplets.md``, "Geometric layer").
Vector fields are arrays ``(H, W, 2)`` with ``(row, col)`` components; every operation is
periodic.

Why this module is long: the geometric layer is one chain (orientation, signs, tilings of a
learned field, association fields and their tilings) whose steps share the conventions above
and the integration's rules (rounding, stagnation points, wrapping); split apart, each part
would have to restate them.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from ..errors import InputError
from .fourier import gaussian_wrap
from .jit import jit, prange
from .linalg import worker_count

#: pixels x levels from which the association fields are integrated on numba's threads
PARALLEL_PIXELS = 1 << 14

__all__ = [
    "association_fields",
    "builtin_flow",
    "orient_field",
    "periodic_tiling",
    "structure_tensor_orientation",
    "tiled_associations",
]


def structure_tensor_orientation(
    image: np.ndarray, *, sigma: float = 5.0, presmooth: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Dominant orientation of a grey image from its smoothed structure tensor (Peyré 2008, section 2.1).

    The vector ``v = (-g_c, g_r)`` orthogonal to the gradient of the pre-smoothed image is
    averaged as the tensor ``G_sigma * (v v^T)``; its dominant eigenvector gives the direction
    along the level lines (Peyré 2008, eq. 1).

    Returns
    -------
    orientation : ndarray, shape (H, W, 2)
        Unit vectors ``(row, col)``, defined up to sign.
    coherence : ndarray, shape (H, W)
        ``(lambda+ - lambda-) / (lambda+ + lambda-)`` in [0, 1] (0: isotropic).
    """
    g = (
        gaussian_wrap(np.asarray(image, dtype=np.float64), presmooth)
        if presmooth > 0
        else np.asarray(image, dtype=np.float64)
    )
    gr = 0.5 * (np.roll(g, -1, axis=0) - np.roll(g, 1, axis=0))
    gc = 0.5 * (np.roll(g, -1, axis=1) - np.roll(g, 1, axis=1))
    vr, vc = -gc, gr
    a = gaussian_wrap(vr * vr, sigma)
    b = gaussian_wrap(vr * vc, sigma)
    c = gaussian_wrap(vc * vc, sigma)
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    spread = np.sqrt(((a - c) / 2.0) ** 2 + b * b)
    coherence = 2.0 * spread / (a + c + 1e-12)
    return np.stack([np.cos(theta), np.sin(theta)], axis=-1), np.clip(coherence, 0.0, 1.0)


@jit()
def _propagate_signs(vr, vc, start_r, start_c):
    n0, n1 = vr.shape
    out_r = vr.copy()
    out_c = vc.copy()
    visited = np.zeros((n0, n1), dtype=np.bool_)
    prio = np.full((n0, n1), np.inf)
    prio[start_r, start_c] = 0.0
    heap = [(0.0, start_r * n1 + start_c)]
    steps_r = (1, -1, 0, 0)
    steps_c = (0, 0, 1, -1)
    while len(heap) > 0:
        p, flat = heapq.heappop(heap)
        r = flat // n1
        c = flat % n1
        if visited[r, c] or p > prio[r, c]:
            continue
        acc_r = 0.0
        acc_c = 0.0
        for k in range(4):
            yr = (r + steps_r[k]) % n0
            yc = (c + steps_c[k]) % n1
            if visited[yr, yc]:
                acc_r += out_r[yr, yc]
                acc_c += out_c[yr, yc]
        if acc_r * out_r[r, c] + acc_c * out_c[r, c] < 0.0:
            out_r[r, c] = -out_r[r, c]
            out_c[r, c] = -out_c[r, c]
        visited[r, c] = True
        for k in range(4):
            yr = (r + steps_r[k]) % n0
            yc = (c + steps_c[k]) % n1
            if visited[yr, yc]:
                continue
            q = p + 1.0 - abs(out_r[r, c] * steps_r[k] + out_c[r, c] * steps_c[k])
            if q < prio[yr, yc]:
                prio[yr, yc] = q
                heapq.heappush(heap, (q, yr * n1 + yc))
    return out_r, out_c


def orient_field(orientation: np.ndarray, start: tuple[int, int] | None = None) -> np.ndarray:
    """Turn an orientation field (defined up to sign) into a direction field (Peyré 2008, section 2.1).

    Front propagation from ``start`` (the centre by default) with a priority that grows with
    ``1 - |<v, step>|``: the front runs along the flow lines, each newly reached vector is
    flipped to agree with its already-visited neighbours, and the remaining sign changes end up
    along integral lines (Peyré 2008, section 2.1, "optimised to align the singularities"; the
    paper defers the rule to another preprint, this one is ours: ``docs/methods/grouplets.md``).
    """
    o = np.asarray(orientation, dtype=np.float64)
    h, w = o.shape[:2]
    r0, c0 = (h // 2, w // 2) if start is None else start
    out_r, out_c = _propagate_signs(
        np.ascontiguousarray(o[..., 0]), np.ascontiguousarray(o[..., 1]), int(r0), int(c0)
    )
    return np.stack([out_r, out_c], axis=-1)


def periodic_tiling(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A periodic direction field's pattern repeated over a periodic canvas of another size.

    When ``shape`` is a multiple of the field's size, the field is tiled exactly. Otherwise
    it is tiled the nearest whole number of times (at least once) and the tiling is
    stretched to ``shape``: a scale factor ``s`` per axis, between 3/4 and 3/2 when
    ``shape`` is at least the field's size, and smaller when the canvas is smaller than one
    tile (its pattern is shrunk to fit). The doubled-angle tensor ``(cos 2t, sin 2t)`` is
    interpolated (periodic bilinear, no sign ambiguity), each direction is mapped by the
    stretch (``(s_r d_r, s_c d_c)``, renormalised) so the field stays tangent to the
    stretched pattern, and the signs are chosen again by :func:`orient_field`. The result
    is periodic at ``shape``, so a periodic synthesis has no seam at its border or inside.

    Parameters
    ----------
    flow : ndarray, shape (h, w, 2)
        Unit ``(row, col)`` directions, periodic.
    shape : (int, int)
    """
    f = np.asarray(flow, dtype=np.float64)
    h, w = f.shape[:2]
    out_h, out_w = int(shape[0]), int(shape[1])
    if out_h % h == 0 and out_w % w == 0:
        return np.tile(f, (out_h // h, out_w // w, 1))
    tiled = np.tile(f, (max(1, round(out_h / h)), max(1, round(out_w / w)), 1))
    from scipy.ndimage import zoom  # 0.19 s of start-up that whole tilings do not need

    angle = np.arctan2(tiled[..., 1], tiled[..., 0])
    factors = (out_h / tiled.shape[0], out_w / tiled.shape[1])
    doubled = [
        zoom(np.cos(2.0 * angle), factors, order=1, mode="grid-wrap", grid_mode=True),
        zoom(np.sin(2.0 * angle), factors, order=1, mode="grid-wrap", grid_mode=True),
    ]
    theta = 0.5 * np.arctan2(doubled[1], doubled[0])
    stretched = np.stack([factors[0] * np.cos(theta), factors[1] * np.sin(theta)], axis=-1)
    return orient_field(stretched / np.linalg.norm(stretched, axis=-1, keepdims=True))


@jit()
def _wrap(i, n):
    """``i mod n`` for an index a few periods at most from ``[0, n)``, without a division."""
    while i < 0:
        i += n
    while i >= n:
        i -= n
    return i


@jit()
def _field_at(pr, pc, hr, hc, ur, uc, mask):
    """Sign-aligned bilinear interpolation of a unit field; ``(0, 0)`` when no corner counts."""
    n0, n1 = ur.shape
    fr = math.floor(pr)
    fc = math.floor(pc)
    ar = pr - fr
    ac = pc - fc
    r0 = _wrap(int(fr), n0)
    c0 = _wrap(int(fc), n1)
    vr = 0.0
    vc = 0.0
    total = 0.0
    for dr in range(2):
        wr = ar if dr == 1 else 1.0 - ar
        r = r0 + dr if r0 + dr < n0 else 0
        for dc in range(2):
            wc = ac if dc == 1 else 1.0 - ac
            weight = wr * wc
            if weight <= 0.0:
                continue
            c = c0 + dc if c0 + dc < n1 else 0
            if mask[r, c]:
                continue
            xr = ur[r, c]
            xc = uc[r, c]
            if xr * hr + xc * hc < 0.0:
                xr = -xr
                xc = -xc
            vr += weight * xr
            vc += weight * xc
            total += weight
    if total <= 0.0:
        return 0.0, 0.0
    vr /= total
    vc /= total
    norm = math.sqrt(vr * vr + vc * vc)
    if norm < 1e-9:
        return hr, hc
    return vr / norm, vc / norm


#: flow lines integrated side by side: their RK4 steps are independent chains of dependent
#: operations, so interleaving them lets the processor overlap them
_LINES = 8


@jit()
def _integrate_lines(ur, uc, mask, levels, step, first, last, out):
    """:func:`_integrate` of the pixels ``first .. last - 1``, :data:`_LINES` flow lines at a time.

    Each line gets exactly the arithmetic of one line alone (the same expressions in the
    same order); interleaving only changes which line the processor works on.
    """
    n0, n1 = ur.shape
    n_steps = int(round(2.0 ** (levels - 1) / step))
    idx = np.empty(_LINES, dtype=np.int64)
    pr = np.empty(_LINES)
    pc = np.empty(_LINES)
    hr = np.empty(_LINES)
    hc = np.empty(_LINES)
    k1r = np.empty(_LINES)
    k1c = np.empty(_LINES)
    k2r = np.empty(_LINES)
    k2c = np.empty(_LINES)
    k3r = np.empty(_LINES)
    k3c = np.empty(_LINES)
    pixel = first
    while pixel < last:
        count = 0  # gather up to _LINES unmasked pixels; a stagnation point keeps A_l(x) = x
        while pixel < last and count < _LINES:
            r0 = pixel // n1
            c0 = pixel % n1
            if mask[r0, c0]:
                for lv in range(levels):
                    out[lv, pixel] = pixel
            else:
                idx[count] = pixel
                pr[count] = float(r0)
                pc[count] = float(c0)
                hr[count] = ur[r0, c0]
                hc[count] = uc[r0, c0]
                count += 1
            pixel += 1
        level = 0
        for s in range(n_steps):
            for b in range(count):
                k1r[b], k1c[b] = _field_at(pr[b], pc[b], hr[b], hc[b], ur, uc, mask)
            for b in range(count):
                k2r[b], k2c[b] = _field_at(
                    pr[b] + 0.5 * step * k1r[b], pc[b] + 0.5 * step * k1c[b], hr[b], hc[b], ur, uc, mask
                )
            for b in range(count):
                k3r[b], k3c[b] = _field_at(
                    pr[b] + 0.5 * step * k2r[b], pc[b] + 0.5 * step * k2c[b], hr[b], hc[b], ur, uc, mask
                )
            for b in range(count):
                k4r, k4c = _field_at(pr[b] + step * k3r[b], pc[b] + step * k3c[b], hr[b], hc[b], ur, uc, mask)
                pr[b] += step * (k1r[b] + 2.0 * k2r[b] + 2.0 * k3r[b] + k4r) / 6.0
                pc[b] += step * (k1c[b] + 2.0 * k2c[b] + 2.0 * k3c[b] + k4c) / 6.0
                if k4r != 0.0 or k4c != 0.0:
                    hr[b] = k4r
                    hc[b] = k4c
            t = (s + 1) * step
            while level < levels and t >= 2.0**level:
                for b in range(count):
                    rr = _wrap(int(math.floor(pr[b] + 0.5)), n0)
                    cc = _wrap(int(math.floor(pc[b] + 0.5)), n1)
                    out[level, idx[b]] = rr * n1 + cc
                level += 1


@jit(parallel=True)
def _integrate(ur, uc, mask, levels, step, n_blocks):
    """Association fields of every pixel (:func:`association_fields`), ``n_blocks`` blocks of
    pixels on numba's threads (:func:`_integrate_lines`)."""
    total = ur.shape[0] * ur.shape[1]
    out = np.empty((levels, total), dtype=np.int64)
    size = (total + n_blocks - 1) // n_blocks
    for c in prange(n_blocks):
        _integrate_lines(ur, uc, mask, levels, step, min(total, c * size), min(total, (c + 1) * size), out)
    return out


def association_fields(flow: np.ndarray, levels: int, *, step: float = 0.25) -> np.ndarray:
    """Discrete association fields ``A_l(x) = [phi_x(2^l)]`` of a flow (Peyré 2008, section 2.1).

    The flow lines of the normalised field are integrated with RK4 (``step`` px) through a
    bilinear interpolation that flips each corner vector to agree with the current heading
    (so sign discontinuities are crossed at full speed) and ignores stagnation points
    (``|flow| <= 1e-6 max |flow|``, which keep ``A_l(x) = x``); positions at arc length
    ``2^l`` are rounded half up to the periodic grid.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
        Raw (not necessarily unit) ``(row, col)`` vectors.
    levels : int
        Number ``L`` of association fields (lengths 1, 2, ..., 2^(L-1)).

    Returns
    -------
    ndarray of int64, shape (L, H*W)
        Flat target index ``r * W + c`` of every pixel, per level.
    """
    v = np.asarray(flow, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] != 2:
        raise ValueError(f"flow must have shape (H, W, 2), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("flow contains NaN or infinite values")
    norm = np.hypot(v[..., 0], v[..., 1])
    mask = norm <= 1e-6 * norm.max()
    unit = v / np.maximum(norm, 1e-12)[..., None]
    unit[mask] = 0.0
    ur, uc = np.ascontiguousarray(unit[..., 0]), np.ascontiguousarray(unit[..., 1])
    if v.shape[0] * v.shape[1] * levels < PARALLEL_PIXELS:  # threads would cost more than they save
        out = np.empty((int(levels), v.shape[0] * v.shape[1]), dtype=np.int64)
        _integrate_lines(ur, uc, mask, int(levels), float(step), 0, out.shape[1], out)
        return out
    return _integrate(ur, uc, mask, int(levels), float(step), 4 * worker_count())


def tiled_associations(
    associations: np.ndarray, shape: tuple[int, int], out_shape: tuple[int, int]
) -> np.ndarray | None:
    """Association fields of a field tiled exactly (:func:`periodic_tiling` of a multiple of
    its size), translated from the tile's own; ``None`` where they cannot be.

    A flow line of the tiling is the tile's, moved by whole tiles: each pixel keeps the
    displacement ``A_l(x) - x`` of its copy in the tile. The displacement is read modulo the
    tile, so the lines must be shorter than half of it: ``2^(L-1) + 1 < min(h, w) / 2``
    (otherwise, or when ``out_shape`` is not a multiple of ``shape``, ``None``: integrate the
    tiling with :func:`association_fields`). Integrating the tiling again gives the same
    fields but where a position lands within rounding of a pixel boundary, which depends on
    the absolute coordinates (``docs/methods/grouplets.md``, "Performance").

    Parameters
    ----------
    associations : ndarray of int, shape (L, h*w)
        :func:`association_fields` of the tile.
    shape : (int, int)
        The tile's size ``(h, w)``.
    out_shape : (int, int)
        The tiling's size.

    Returns
    -------
    ndarray of int64, shape (L, H*W), or None

    Examples
    --------
    >>> flow = builtin_flow("constant:30", (16, 16))
    >>> tiled = tiled_associations(association_fields(flow, 3), (16, 16), (32, 48))
    >>> bool(np.array_equal(tiled, association_fields(np.tile(flow, (2, 3, 1)), 3)))
    True
    """
    a = np.asarray(associations, dtype=np.int64)
    h, w = int(shape[0]), int(shape[1])
    out_h, out_w = int(out_shape[0]), int(out_shape[1])
    levels = a.shape[0]
    if out_h % h or out_w % w or (levels and 2 ** (levels - 1) + 1 >= min(h, w) / 2):
        return None
    rows = np.arange(out_h)[:, None]
    cols = np.arange(out_w)[None, :]
    source = a.reshape(levels, h, w)[:, rows % h, cols % w]  # the tile's targets, (L, H, W)
    # displacements within the tile, in [-h/2, h/2) and [-w/2, w/2)
    down = (source // w - rows % h + h // 2) % h - h // 2
    across = (source % w - cols % w + w // 2) % w - w // 2
    return (((rows + down) % out_h) * out_w + (cols + across) % out_w).reshape(levels, -1)


def builtin_flow(name: str, shape: tuple[int, int]) -> np.ndarray:
    """A named flow field for painting a texture along a chosen geometry (Peyré 2008, Fig. 2).

    Parameters
    ----------
    name : str
        ``'vortex'`` (rotation about the centre), ``'constant:ANGLE'`` (one direction,
        ``ANGLE`` in degrees counter-clockwise from the +column axis), ``'sources'`` (two
        sources and two vortices), ``'waves'`` (a sinuous horizontal flow).
    shape : (int, int)

    Returns
    -------
    ndarray, shape (H, W, 2), raw ``(row, col)`` vectors.
    """
    h, w = shape
    r, c = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    key = name.strip().lower()
    if key == "vortex":
        return np.stack([-(c - w // 2), r - h // 2], axis=-1)
    if key.startswith("constant"):
        _, _, text = key.partition(":")
        try:
            # 'constant:' with nothing after the colon names no angle
            degrees = float(text) if text else (0.0 if key == "constant" else math.nan)
        except ValueError:
            degrees = math.nan
        if key[len("constant") :][:1] not in ("", ":") or not math.isfinite(degrees):
            raise InputError(
                f"flow 'constant:ANGLE' needs ANGLE as a finite number of degrees (e.g. constant:30), got {name!r}"
            )
        angle = math.radians(degrees)
        return np.stack([np.full((h, w), -math.sin(angle)), np.full((h, w), math.cos(angle))], axis=-1)
    if key == "sources":
        # two sources and two vortices with Gaussian envelopes, on wrapped displacements
        field = np.zeros((h, w, 2))
        spread = 0.12 * min(h, w)
        for cr, cc, kind in (
            (0.25, 0.25, "source"),
            (0.75, 0.75, "source"),
            (0.25, 0.75, "vortex"),
            (0.75, 0.25, "vortex"),
        ):
            dr = np.mod(r - cr * h + h / 2, h) - h / 2
            dc = np.mod(c - cc * w + w / 2, w) - w / 2
            dist = np.sqrt(dr**2 + dc**2) + 1e-9
            weight = np.exp(-(dist**2) / (2 * spread**2))
            vec = np.stack([dr, dc], axis=-1) if kind == "source" else np.stack([-dc, dr], axis=-1)
            field += (weight / dist)[..., None] * vec
        return field
    if key == "waves":
        return np.stack([0.6 * np.cos(2 * np.pi * 2 * c / w), np.ones((h, w))], axis=-1)
    raise InputError(
        f"unknown flow {name!r}; choose 'learned', 'vortex', 'constant:ANGLE', 'sources' or 'waves'"
    )
