"""Patch extraction and overlap re-assembly: the patch operator and its pseudo-inverse."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .jit import jit

__all__ = [
    "as_channels",
    "average_patches",
    "extend_index",
    "extract_patches",
    "gather_wrapped",
    "gather_wrapped_kernel",
    "overlap_add",
    "wrap_seam_ratio",
]


def as_channels(image: np.ndarray) -> np.ndarray:
    """View a ``(H, W)`` image as ``(H, W, 1)``; leave ``(H, W, C)`` unchanged."""
    return image[..., None] if image.ndim == 2 else image


@jit()
def gather_wrapped_kernel(image, rows, cols, offsets, out, start):
    """:func:`gather_wrapped` as a compiled kernel, for other kernels to call (every argument
    given, ``start`` included)."""
    h, w, channels = image.shape
    for i in range(rows.shape[0]):
        k = start
        for o in range(offsets.shape[0]):
            r = rows[i] + offsets[o, 0]
            c = cols[i] + offsets[o, 1]
            if r < 0 or r >= h:  # a division only across the wrap
                r %= h
            if c < 0 or c >= w:
                c %= w
            for ch in range(channels):
                out[i, k] = image[r, c, ch]
                k += 1


def gather_wrapped(
    image: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    offsets: np.ndarray,
    out: np.ndarray,
    start: int = 0,
) -> None:
    """Toroidal neighbourhood vectors of some pixels, written into columns of ``out``.

    ``out[i, start + o C + c] = image[(rows[i] + dy_o) % H, (cols[i] + dx_o) % W, c]`` for
    the offsets ``(dy_o, dx_o)`` in order: one compiled pass, for loops that gather a few
    pixels' neighbourhoods many times (Wei and Levoy's wavefronts).

    Parameters
    ----------
    image : ndarray, shape (H, W, C)
    rows, cols : ndarray of int, shape (n,)
    offsets : ndarray of int, shape (P, 2)
    out : ndarray, shape (n, >= start + P C)
    start : int
        First column written.
    """
    gather_wrapped_kernel(image, rows, cols, offsets, out, start)


def extend_index(index: np.ndarray, size: int, mode: str = "symmetric") -> np.ndarray:
    """Map integer indices of an infinitely extended signal back into ``[0, size)``.

    Parameters
    ----------
    index : ndarray of int
    size : int
    mode : {'symmetric', 'periodic'}
        ``'symmetric'`` mirrors with the edge sample repeated (``-1 -> 0``, ``size -> size-1``;
        NumPy's ``np.pad(mode='symmetric')``); ``'periodic'`` wraps.
    """
    index = np.asarray(index)
    if mode == "periodic":
        return np.mod(index, size)
    if mode == "symmetric":
        u = np.mod(index, 2 * size)
        return np.where(u < size, u, 2 * size - 1 - u)
    raise ValueError(f"mode must be 'symmetric' or 'periodic', got {mode!r}")


def wrap_seam_ratio(image: np.ndarray) -> float:
    """How visible the seam of a periodic tiling is: 1 for an image that tiles seamlessly.

    The mean absolute difference across the wrap-around (last row to first row, last column
    to first column) divided by the mean absolute difference between adjacent interior rows
    and columns. Natural photographs give values well above 1.5; periodic textures about 1.
    """
    img = as_channels(np.asarray(image, dtype=np.float64))
    across = np.concatenate([np.abs(img[-1] - img[0]).ravel(), np.abs(img[:, -1] - img[:, 0]).ravel()]).mean()
    inside = np.concatenate(
        [np.abs(np.diff(img, axis=0)).ravel(), np.abs(np.diff(img, axis=1)).ravel()]
    ).mean()
    return float(across / inside) if inside > 0 else (1.0 if across == 0 else np.inf)


def _anchors(size: int, n: int, stride: int, mode: str) -> np.ndarray:
    if mode == "valid":
        return np.arange(0, size - n + 1, stride)
    if mode == "periodic":
        return np.arange(0, size, stride)
    raise ValueError(f"mode must be 'valid' or 'periodic', got {mode!r}")


def extract_patches(
    image: np.ndarray, n: int, *, stride: int = 1, mode: str = "valid"
) -> tuple[np.ndarray, np.ndarray]:
    """All ``n x n`` patches of an image as flat vectors, top-left anchored.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    n : int
        Patch side.
    stride : int
        Step between anchors.
    mode : {'valid', 'periodic'}
        ``'valid'`` keeps anchors whose patch lies inside the image (Raad's ``V_u``);
        ``'periodic'`` takes every ``stride``-th anchor with indices wrapped modulo the size.

    Returns
    -------
    patches : ndarray, shape (K, n*n*C)
        Patch vectors flattened in C order of shape ``(n, n, C)``.
    anchors : ndarray, shape (K, 2)
        ``(row, col)`` of each patch's top-left pixel.
    """
    img = as_channels(np.asarray(image))
    h, w, _ = img.shape
    if mode == "periodic":
        img = np.pad(img, ((0, n - 1), (0, n - 1), (0, 0)), mode="wrap")
    elif n > h or n > w:
        raise ValueError(f"patch size {n} is larger than the image ({w}x{h})")
    rows = _anchors(h, n, stride, mode)
    cols = _anchors(w, n, stride, mode)
    windows = sliding_window_view(img, (n, n), axis=(0, 1))  # (h', w', C, n, n)
    windows = windows[np.ix_(rows, cols)]  # one copy of the chosen windows only
    patches = np.ascontiguousarray(windows.transpose(0, 1, 3, 4, 2)).reshape(len(rows) * len(cols), -1)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    return patches, np.stack([rr.ravel(), cc.ravel()], axis=1)


def overlap_add(
    patches: np.ndarray,
    anchors: np.ndarray,
    shape: tuple[int, ...],
    n: int,
    *,
    mode: str = "valid",
) -> tuple[np.ndarray, np.ndarray]:
    """Adjoint of :func:`extract_patches`: add every patch back at its anchor.

    Returns
    -------
    image : ndarray, shape ``shape``
        The sum of the patches covering each pixel.
    coverage : ndarray, shape ``shape[:2]``
        The number of patches covering each pixel (``rho``).
    """
    h, w = shape[:2]
    c = shape[2] if len(shape) == 3 else 1
    blocks = np.asarray(patches, dtype=np.float64).reshape(-1, n, n, c)
    di, dj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    rows = anchors[:, 0, None, None] + di
    cols = anchors[:, 1, None, None] + dj
    if mode == "periodic":
        rows, cols = rows % h, cols % w
    elif mode != "valid":
        raise ValueError(f"mode must be 'valid' or 'periodic', got {mode!r}")
    flat = (rows * w + cols).ravel()
    out = np.zeros((h * w, c))
    for ch in range(c):
        out[:, ch] = np.bincount(flat, weights=blocks[..., ch].ravel(), minlength=h * w)
    coverage = np.bincount(flat, minlength=h * w).reshape(h, w).astype(np.float64)
    image = out.reshape(h, w, c)
    return (image[..., 0] if len(shape) == 2 else image), coverage


def average_patches(
    patches: np.ndarray,
    anchors: np.ndarray,
    shape: tuple[int, ...],
    n: int,
    *,
    mode: str = "valid",
) -> np.ndarray:
    """Least-squares re-assembly ``Pi^+(P) = Pi^*(P) / rho``: the average of the overlapping patches.

    Pixels covered by no patch are set to zero.
    """
    total, coverage = overlap_add(patches, anchors, shape, n, mode=mode)
    cov = np.maximum(coverage, 1.0)
    return total / (cov if total.ndim == 2 else cov[..., None])
