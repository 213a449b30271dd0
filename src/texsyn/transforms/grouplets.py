"""Grouplet and wavelet-grouplet transforms along association fields (Peyré 2008, sections 2.2-2.3).

The paper defers the exact grouplet algorithm to Mallat's and its own preprints; this is our
exactly invertible construction (``docs/methods/grouplets.md``, "The grouplet transform"):
at level ``l`` every pixel ``m`` is paired with ``p = A_l(m)``,

    d_l[m] = (a[m] - a[A_l m]) / sqrt(2),      a'[m] = (a[m] + a[A_l m]) / sqrt(2),

and the inverse divides by ``1 + c[p]``, ``c[p]`` the number of pixels associated to ``p``
(``G^T G + H^T H = I + diag(c)`` is diagonal for *any* association map). The transform is
therefore exact for converging (many-to-one) associations, as section 2.2 asks, and a tight
frame with unit-norm atoms for bijective ones. No pixel ordering is needed.
"""

from __future__ import annotations

import numpy as np

from .pyramids import LaplacianTightFrame

__all__ = ["GroupletTransform", "WaveletGroupletTransform", "checked_associations"]

_SQRT2 = np.sqrt(2.0)


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


class GroupletTransform:
    """Redundant Haar transform along association fields, ``L + 1`` coefficient layers.

    Parameters
    ----------
    associations : ndarray of int, shape (L, N)
        ``associations[l, m]``: flat index of the pixel associated to ``m`` at level ``l``
        (:func:`texsyn.ops.flow.association_fields`).
    shape : (int, int)
        Image size, ``H * W == N``.

    Examples
    --------
    Pair every pixel with its right neighbour (a constant horizontal flow, one level); the
    inverse is exact:

    >>> import numpy as np
    >>> shifted = np.roll(np.arange(12).reshape(3, 4), -1, axis=1).ravel()
    >>> transform = GroupletTransform(shifted[None], (3, 4))
    >>> image = np.random.default_rng(0).random((3, 4))
    >>> coefficients = transform.forward(image)
    >>> coefficients.shape
    (2, 3, 4)
    >>> bool(np.allclose(transform.inverse(coefficients), image))
    True
    """

    def __init__(self, associations: np.ndarray, shape: tuple[int, int]):
        a = checked_associations(associations, shape)
        n = a.shape[1]
        self.associations = a
        self.shape = (int(shape[0]), int(shape[1]))
        self.levels = a.shape[0]
        self.in_degree = (
            np.stack([np.bincount(row, minlength=n) for row in a]) if self.levels else np.zeros((0, n))
        )

    def forward(self, image: np.ndarray) -> np.ndarray:
        """Coefficients ``(L+1, *batch, H, W)`` of images ``(*batch, H, W)``; layer ``L`` is the low-pass."""
        x = np.asarray(image, dtype=np.float64)
        batch = x.shape[:-2]
        a = x.reshape(batch + (-1,))
        out = []
        for level in range(self.levels):
            paired = a[..., self.associations[level]]
            out.append((a - paired) / _SQRT2)
            a = (a + paired) / _SQRT2
        out.append(a)
        return np.stack(out).reshape((self.levels + 1,) + batch + self.shape)

    def inverse(self, coefficients: np.ndarray) -> np.ndarray:
        """Images ``(*batch, H, W)`` from coefficients ``(L+1, *batch, H, W)`` (level-wise least squares)."""
        c = np.asarray(coefficients, dtype=np.float64)
        batch = c.shape[1:-2]
        n = self.shape[0] * self.shape[1]
        flat = c.reshape((c.shape[0], -1, n))
        bands = flat.shape[1]
        offsets = (np.arange(bands) * n)[:, None]
        a = flat[self.levels]
        for level in range(self.levels - 1, -1, -1):
            d = flat[level]
            back = (a - d) / _SQRT2
            scattered = np.bincount(
                (self.associations[level][None, :] + offsets).ravel(),
                weights=back.ravel(),
                minlength=bands * n,
            ).reshape(bands, n)
            a = ((a + d) / _SQRT2 + scattered) / (1.0 + self.in_degree[level])
        return a.reshape(batch + self.shape)


class WaveletGroupletTransform:
    """Grouplet transform of every band of a Laplacian tight frame (Peyré 2008, section 2.3).

    Atoms are strokes of width ``~2^j`` and length ``~2^l`` along the flow; coefficients have
    shape ``(J+1, L+1, H, W)`` per channel (redundancy ``(J+1)(L+1)``).

    Parameters
    ----------
    associations : ndarray of int, shape (L, H*W)
    shape : (int, int)
    levels : int
        Detail bands ``J`` of the pyramid.

    Examples
    --------
    >>> import numpy as np
    >>> from texsyn.ops.flow import association_fields, builtin_flow
    >>> flow = builtin_flow("vortex", (16, 16))
    >>> transform = WaveletGroupletTransform(association_fields(flow, 2), (16, 16), levels=2)
    >>> image = np.random.default_rng(0).random((16, 16))
    >>> coefficients = transform.forward(image)
    >>> coefficients.shape
    (3, 3, 16, 16)
    >>> bool(np.allclose(transform.inverse(coefficients), image))
    True
    """

    def __init__(self, associations: np.ndarray, shape: tuple[int, int], levels: int = 3):
        self.pyramid = LaplacianTightFrame(shape, levels)
        self.grouplets = GroupletTransform(associations, shape)
        self.shape = self.pyramid.shape

    def forward(self, image: np.ndarray) -> np.ndarray:
        """``(J+1, L+1, H, W)`` coefficients of a grey image, ``(J+1, L+1, C, H, W)`` of a colour one."""
        bands = self.pyramid.forward(image)  # (J+1, H, W[, C])
        if bands.ndim == 4:
            bands = np.moveaxis(bands, -1, 1)  # (J+1, C, H, W)
        return np.moveaxis(self.grouplets.forward(bands), 0, 1)

    def inverse(self, coefficients: np.ndarray) -> np.ndarray:
        """Image from coefficients (exact: the pyramid is tight, the grouplets invertible)."""
        bands = self.grouplets.inverse(np.moveaxis(np.asarray(coefficients), 1, 0))
        if bands.ndim == 4:
            bands = np.moveaxis(bands, 1, -1)
        return self.pyramid.inverse(bands)
