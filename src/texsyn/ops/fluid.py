"""Stam's stable fluids on a periodic grid, initial flows, and advected coordinate maps.

Used by Peyré 2008 (section 4, Table 2) to evolve the flow that drives a dynamic texture
(``docs/methods/grouplets.md``, "Dynamic synthesis"): advection, implicit diffusion and the
projection onto divergence-free fields; random divergence-free fields with a chosen energy
spectrum or a set of vortices (initial flows and forcing); and coordinate maps carried by
the flow, so that a texture can be advected from a reference frame with one interpolation
instead of one per frame. Vector fields are ``(H, W, 2)`` arrays of ``(row, col)``
components in pixels per time unit; everything is periodic.
"""

from __future__ import annotations

import numpy as np

from .linalg import parallel_map

__all__ = [
    "advect",
    "advect_displacement",
    "curl_of_streamfunction",
    "diffuse",
    "divergence",
    "laplacian_symbol",
    "prefilter",
    "project",
    "rescale_speed",
    "rms_speed",
    "sample_displaced",
    "spectral_velocity",
    "vortex_velocity",
]


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
    from scipy.ndimage import map_coordinates  # animations only: not at import (start-up)

    g = np.asarray(field, dtype=np.float64)
    u = np.asarray(velocity, dtype=np.float64)
    coords = _grid(g.shape[:2]) - tau * np.moveaxis(u, -1, 0)
    return _per_channel(lambda x: map_coordinates(x, coords, order=order, mode="grid-wrap"), g)


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


def rms_speed(velocity: np.ndarray) -> float:
    """Root-mean-square length of the vectors of a ``(H, W, 2)`` field."""
    v = np.asarray(velocity, dtype=np.float64)
    return float(np.sqrt(np.mean(np.sum(v * v, axis=-1))))


def rescale_speed(velocity: np.ndarray, speed: float) -> np.ndarray:
    """Scale a velocity field to a root-mean-square speed (a zero field stays zero)."""
    v = np.asarray(velocity, dtype=np.float64)
    rms = rms_speed(v)
    return v * (speed / rms) if rms > 0 else v.copy()


def curl_of_streamfunction(psi: np.ndarray) -> np.ndarray:
    """``V = (d psi / dc, -d psi / dr)`` by forward differences, made exactly divergence-free.

    The discrete curl is divergence-free up to the discretisation; :func:`project` removes
    the rest, so the result satisfies this module's divergence to rounding.
    """
    p = np.asarray(psi, dtype=np.float64)
    v = np.stack([np.roll(p, -1, axis=1) - p, -(np.roll(p, -1, axis=0) - p)], axis=-1)
    return project(v)


def spectral_velocity(
    shape: tuple[int, int], rng: np.random.Generator, *, scale: float, slope: float = 3.0
) -> np.ndarray:
    """A random divergence-free field with energy spectrum ``E(k)`` peaked at wavelength ``scale``.

    ``E(k)`` grows as ``k^4`` below the peak wavenumber ``k0 = 1 / scale`` (cycles per pixel)
    and falls as ``k^-slope`` above it (``slope = 3``: the enstrophy cascade of 2-D
    turbulence; ``5/3``: Kolmogorov's energy cascade, with more small eddies). Built as the
    curl of a random stream function with ``|psi^(k)|^2 = E(k) / k^3``; unit RMS speed.
    """
    h, w = (int(shape[0]), int(shape[1]))
    kr = np.fft.fftfreq(h)[:, None]
    kc = np.fft.rfftfreq(w)[None, :]
    k = np.hypot(kr, kc)
    k0 = 1.0 / float(scale)
    ratio = np.where(k > 0, k / k0, 1.0)
    energy = np.where(ratio < 1.0, ratio**4, ratio ** (-float(slope)))
    amplitude = np.where(k > 0, np.sqrt(energy / np.maximum(k, 1e-12) ** 3), 0.0)
    psi = np.fft.irfft2(np.fft.rfft2(rng.standard_normal((h, w))) * amplitude, s=(h, w))
    return rescale_speed(curl_of_streamfunction(psi), 1.0)


def vortex_velocity(
    shape: tuple[int, int], rng: np.random.Generator, *, scale: float, count: int | None = None
) -> np.ndarray:
    """Gaussian vortices of radius ``scale`` at random places with random signs; unit RMS speed.

    The stream function is a sum of ``+-exp(-d^2 / (2 scale^2))`` over periodic distances
    ``d``; ``count`` defaults to one vortex per ``(3 scale)^2`` pixels (at least 2).
    """
    h, w = (int(shape[0]), int(shape[1]))
    n = max(2, round(h * w / (3.0 * scale) ** 2)) if count is None else int(count)
    centres = rng.random((n, 2)) * (h, w)
    signs = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    rows = np.arange(h, dtype=np.float64)[:, None]
    cols = np.arange(w, dtype=np.float64)[None, :]
    psi = np.zeros((h, w))
    for (cr, cc), sign in zip(centres, signs):
        dr = np.mod(rows - cr + h / 2, h) - h / 2
        dc = np.mod(cols - cc + w / 2, w) - w / 2
        psi += sign * np.exp(-(dr**2 + dc**2) / (2.0 * scale**2))
    return rescale_speed(curl_of_streamfunction(psi), 1.0)


def _grid(shape: tuple[int, int]) -> np.ndarray:
    h, w = shape
    return np.stack(
        np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    )


def _per_channel(function, image: np.ndarray) -> np.ndarray:
    """``function`` of every channel of ``(H, W[, C])``, the channels on texsyn's worker threads
    (SciPy's interpolation releases the GIL; each channel is computed alike on any thread)."""
    if image.ndim == 2:
        return function(image)
    return np.stack(parallel_map(function, [image[..., k] for k in range(image.shape[2])]), axis=-1)


def advect_displacement(displacement: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Carry a coordinate map one step along the flow: ``D'(x) = D(x - U(x)) - U(x)``.

    A map ``x -> x + D(x)`` says where each pixel of the current frame was in a reference
    frame; after the flow moves every point by ``U = tau V`` (semi-Lagrangian, as
    :func:`advect`), the pixel at ``x`` comes from ``x - U(x)`` and so from
    ``x - U(x) + D(x - U(x))`` in the reference. ``D`` is periodic and smooth, so its bilinear
    interpolation adds no blur to the texture, which is sampled once from the reference
    (:func:`sample_displaced`).

    Parameters
    ----------
    displacement, step : ndarray, shape (H, W, 2)
        ``D`` and ``U`` in pixels, ``(row, col)`` components.
    """
    from scipy.ndimage import map_coordinates

    d = np.asarray(displacement, dtype=np.float64)
    u = np.asarray(step, dtype=np.float64)
    back = _grid(d.shape[:2]) - np.moveaxis(u, -1, 0)
    return _per_channel(lambda x: map_coordinates(x, back, order=1, mode="grid-wrap"), d) - u


def prefilter(image: np.ndarray) -> np.ndarray:
    """Periodic cubic B-spline coefficients of every channel of ``(H, W[, C])`` (for :func:`sample_displaced`)."""
    from scipy.ndimage import spline_filter

    return _per_channel(
        lambda x: spline_filter(x, order=3, mode="grid-wrap"), np.asarray(image, dtype=np.float64)
    )


def sample_displaced(coefficients: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """Sample a periodic image at ``x + D(x)`` by cubic B-spline interpolation.

    ``coefficients`` come from :func:`prefilter` (computed once per reference image); the
    cubic spline keeps the fine scales that bilinear interpolation would blur.
    """
    from scipy.ndimage import map_coordinates

    c = np.asarray(coefficients, dtype=np.float64)
    d = np.asarray(displacement, dtype=np.float64)
    points = _grid(d.shape[:2]) + np.moveaxis(d, -1, 0)

    return _per_channel(lambda x: map_coordinates(x, points, order=3, mode="grid-wrap", prefilter=False), c)
