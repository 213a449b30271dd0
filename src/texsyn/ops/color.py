"""Colour spaces: BT.601 YUV and PCA-decorrelated colour axes (spec 00, 5.5 and 6.1)."""

from __future__ import annotations

import numpy as np

__all__ = ["rgb_to_yuv", "yuv_to_rgb", "luma", "ColorPCA"]

RGB_TO_YUV = np.array(
    [
        [0.299, 0.587, 0.114],
        [-0.14713, -0.28886, 0.436],
        [0.615, -0.51499, -0.10001],
    ]
)
YUV_TO_RGB = np.linalg.inv(RGB_TO_YUV)


def rgb_to_yuv(image: np.ndarray) -> np.ndarray:
    """Analogue BT.601 YUV of an ``(H, W, 3)`` RGB image (spec 00, 6.1)."""
    return np.asarray(image, dtype=np.float64) @ RGB_TO_YUV.T


def luma(image: np.ndarray) -> np.ndarray:
    """BT.601 luma ``Y`` of an ``(..., 3)`` RGB image; a grey ``(H, W)`` image is returned as is."""
    img = np.asarray(image, dtype=np.float64)
    return img @ RGB_TO_YUV[0] if img.ndim == 3 and img.shape[-1] == 3 else img


def yuv_to_rgb(image: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rgb_to_yuv` with the exact matrix inverse."""
    return np.asarray(image, dtype=np.float64) @ YUV_TO_RGB.T


class ColorPCA:
    """Principal colour axes of a set of pixels: ``a = (u - mean) V``, ``u = a V^T + mean``.

    Used to match colour histograms along decorrelated axes (Heeger and Bergen colour
    variant; Tartavel et al. 2013, section 3; spec 00, section 5.5).

    Parameters
    ----------
    pixels : ndarray, shape (..., C)
        Reference pixels (typically the exemplar).
    """

    def __init__(self, pixels: np.ndarray):
        flat = np.asarray(pixels, dtype=np.float64).reshape(-1, pixels.shape[-1])
        self.mean = flat.mean(axis=0)
        cov = np.cov(flat, rowvar=False).reshape(flat.shape[1], flat.shape[1])
        eigval, eigvec = np.linalg.eigh(cov)
        order = np.argsort(eigval)[::-1]
        vecs = eigvec[:, order]
        # fix the sign of each axis so that results do not depend on the LAPACK build
        signs = np.sign(vecs[np.argmax(np.abs(vecs), axis=0), np.arange(vecs.shape[1])])
        self.axes = vecs * np.where(signs == 0, 1.0, signs)
        self.variances = eigval[order]

    def forward(self, image: np.ndarray) -> np.ndarray:
        """Coordinates along the principal axes, same shape as ``image``."""
        return (np.asarray(image, dtype=np.float64) - self.mean) @ self.axes

    def inverse(self, coords: np.ndarray) -> np.ndarray:
        """Back to the original colour space."""
        return np.asarray(coords, dtype=np.float64) @ self.axes.T + self.mean
