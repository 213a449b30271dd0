"""Fourier-domain helpers: periodic-plus-smooth decomposition."""

from __future__ import annotations

import numpy as np

__all__ = ["periodic_smooth_decomposition"]


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
