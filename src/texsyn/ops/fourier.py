"""Periodic-image helpers: periodic-plus-smooth decomposition, periodic Gaussian filter."""

from __future__ import annotations

import numpy as np

from .jit import jit

__all__ = ["gaussian_wrap", "periodic_smooth_decomposition"]


def periodic_smooth_decomposition(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split an image into a periodic component and a smooth component, ``u = p + s``.

    ``p`` is the unique image whose periodic discrete Laplacian equals the interior
    (free-boundary) Laplacian of ``u`` and whose mean equals ``u``'s; its spectrum has no
    cross-shaped artefact from the image borders, which is what spectral methods need.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    periodic, smooth : ndarray
        Same shape as the input, float64.

    References
    ----------
    L. Moisan, "Periodic plus smooth image decomposition", J. Math. Imaging Vis. 39 (2011),
    Theorem 1: ``s_hat(q, r) = v_hat(q, r) / (2 cos(2 pi q / M) + 2 cos(2 pi r / N) - 4)``.
    """
    u = np.asarray(image, dtype=np.float64)
    m, n = u.shape[:2]
    v = np.zeros_like(u)
    top_bottom = u[-1] - u[0]
    v[0] += top_bottom
    v[-1] -= top_bottom
    left_right = u[:, -1] - u[:, 0]
    v[:, 0] += left_right
    v[:, -1] -= left_right
    q = np.arange(m)[:, None]
    r = np.arange(n // 2 + 1)[None, :]
    denom = 2.0 * np.cos(2 * np.pi * q / m) + 2.0 * np.cos(2 * np.pi * r / n) - 4.0
    denom[0, 0] = 1.0
    if u.ndim == 3:
        denom = denom[..., None]
    s_hat = np.fft.rfft2(v, axes=(0, 1)) / denom
    s_hat[0, 0] = 0.0
    smooth = np.fft.irfft2(s_hat, s=(m, n), axes=(0, 1))
    return u - smooth, smooth


def gaussian_wrap(image: np.ndarray, sigma: float, truncate: float = 4.0) -> np.ndarray:
    """``scipy.ndimage.gaussian_filter(image, sigma, mode="wrap", truncate=truncate)`` of a 2-D image.

    The same weights (SciPy's ``_gaussian_kernel1d``, radius ``int(truncate sigma + 0.5)``)
    and the same arithmetic as SciPy's symmetric 1-D correlation (``x[i] w_0``, then
    ``(x[i - j] + x[i + j]) w_j`` added from the outermost tap in), rows then columns, so the
    same bytes (``tests/test_grouplets.py``) without importing ``scipy.ndimage`` (0.19 s of
    start-up for ``texsyn synth -m grouplets``).
    """
    x = np.asarray(image, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"gaussian_wrap needs a 2-D image, got shape {x.shape}")
    if sigma <= 1e-15:  # SciPy skips the axes of a zero sigma
        return x.copy()
    radius = int(truncate * float(sigma) + 0.5)
    taps = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sigma * sigma) * taps**2)
    weights = np.ascontiguousarray((phi / phi.sum())[::-1])
    along_rows = _correlate_lines_wrap(np.ascontiguousarray(x.T), weights).T
    return _correlate_lines_wrap(np.ascontiguousarray(along_rows), weights)


@jit()
def _correlate_lines_wrap(lines, weights):
    """Periodic correlation of every row of ``lines`` with symmetric ``weights`` (odd length),
    in the order of SciPy's ``NI_Correlate1D`` for a symmetric filter."""
    count, n = lines.shape
    r = weights.size // 2
    out = np.empty_like(lines)
    for i in range(count):
        for k in range(n):
            acc = lines[i, k] * weights[r]
            for j in range(-r, 0):
                acc += (lines[i, (k + j) % n] + lines[i, (k - j) % n]) * weights[r + j]
            out[i, k] = acc
    return out
