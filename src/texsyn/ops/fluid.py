"""Stam's stable fluids on a periodic grid: advection, implicit diffusion, projection.

Used by Peyré 2008 (section 4, Table 2) to evolve the flow that drives a dynamic texture
(``docs/methods/grouplets.md``, "Dynamic synthesis"). Vector fields are ``(H, W, 2)`` arrays
of ``(row, col)`` components in pixels per time unit.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

__all__ = ["advect", "diffuse", "divergence", "laplacian_symbol", "project", "rescale_speed"]


def laplacian_symbol(shape: tuple[int, int]) -> np.ndarray:
    """``lambda(k) = 4 sin^2(pi k_r / H) + 4 sin^2(pi k_c / W)``: minus the 5-point Laplacian in Fourier."""
    h, w = shape
    kr = np.arange(h)[:, None]
    kc = np.arange(w)[None, :]
    return 4 * np.sin(np.pi * kr / h) ** 2 + 4 * np.sin(np.pi * kc / w) ** 2


def advect(field: np.ndarray, velocity: np.ndarray, tau: float = 1.0, *, order: int = 1) -> np.ndarray:
    """Semi-Lagrangian warp ``W_{tau U}(g)(x) = g(x - tau U(x))`` (Peyré 2008, eq. 7).

    Back-traces every grid point and interpolates (bilinear by default, periodic wrap); applies
    to every channel of ``field`` (``(H, W)`` or ``(H, W, C)``). Unconditionally stable.
    """
    g = np.asarray(field, dtype=np.float64)
    u = np.asarray(velocity, dtype=np.float64)
    h, w = g.shape[:2]
    r, c = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    coords = np.stack([r - tau * u[..., 0], c - tau * u[..., 1]])
    if g.ndim == 2:
        return map_coordinates(g, coords, order=order, mode="grid-wrap")
    return np.stack(
        [map_coordinates(g[..., k], coords, order=order, mode="grid-wrap") for k in range(g.shape[2])],
        axis=-1,
    )


def diffuse(field: np.ndarray, amount: float) -> np.ndarray:
    """Implicit diffusion ``(I - amount * Laplacian)^-1 g`` by FFT (Stam; ``amount = tau * nu``)."""
    g = np.asarray(field, dtype=np.float64)
    if amount == 0:
        return g.copy()
    symbol = 1.0 + amount * laplacian_symbol(g.shape[:2])
    if g.ndim == 3:
        symbol = symbol[..., None]
    return np.real(np.fft.ifft2(np.fft.fft2(g, axes=(0, 1)) / symbol, axes=(0, 1)))


def divergence(velocity: np.ndarray) -> np.ndarray:
    """Backward-difference divergence ``(V_r - V_r[r-1]) + (V_c - V_c[c-1])`` (periodic)."""
    v = np.asarray(velocity, dtype=np.float64)
    return (v[..., 0] - np.roll(v[..., 0], 1, axis=0)) + (v[..., 1] - np.roll(v[..., 1], 1, axis=1))


def project(velocity: np.ndarray) -> np.ndarray:
    """Projection onto divergence-free fields (Peyré 2008, section 4, eq. 5).

    Solves ``Laplacian p = div V`` by FFT and returns ``V - grad p`` with the forward-difference
    gradient; since ``div(grad)`` is exactly the 5-point Laplacian, the divergence of the
    result vanishes to rounding. The mean flow is kept.
    """
    v = np.asarray(velocity, dtype=np.float64)
    lam = laplacian_symbol(v.shape[:2])
    lam[0, 0] = 1.0
    p_hat = np.fft.fft2(divergence(v)) / (-lam)
    p_hat[0, 0] = 0.0
    p = np.real(np.fft.ifft2(p_hat))
    grad = np.stack([np.roll(p, -1, axis=0) - p, np.roll(p, -1, axis=1) - p], axis=-1)
    return v - grad


def rescale_speed(velocity: np.ndarray, speed: float) -> np.ndarray:
    """Scale a velocity field to a root-mean-square speed (a zero field stays zero)."""
    v = np.asarray(velocity, dtype=np.float64)
    rms = np.sqrt(np.mean(np.sum(v * v, axis=-1)))
    return v * (speed / rms) if rms > 0 else v.copy()
