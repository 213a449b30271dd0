"""Position colour maps for showing where synthesised pixels came from (Raad et al. 2016, Fig. 9)."""

from __future__ import annotations

import numpy as np

__all__ = ["position_colors"]


def position_colors(source_map: np.ndarray, exemplar_shape: tuple[int, int]) -> np.ndarray:
    """Colour every output pixel by the exemplar position it came from.

    ``R = row / (H - 1)``, ``G = col / (W - 1)``, ``B = 0.5`` (Raad et al. 2016, Fig. 9):
    large constant-gradient regions reveal verbatim copies, noisy maps reveal innovation.

    Parameters
    ----------
    source_map : ndarray of int, shape (h, w, 2)
        Exemplar ``(row, col)`` of every output pixel.
    exemplar_shape : (int, int)

    Returns
    -------
    ndarray of float32, shape (h, w, 3), values in [0, 1].
    """
    src = np.asarray(source_map)
    h, w = exemplar_shape[:2]
    out = np.empty(src.shape[:2] + (3,), dtype=np.float32)
    out[..., 0] = src[..., 0] / max(h - 1, 1)
    out[..., 1] = src[..., 1] / max(w - 1, 1)
    out[..., 2] = 0.5
    return out
