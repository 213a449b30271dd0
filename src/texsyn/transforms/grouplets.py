"""Wavelet-grouplet transforms along association fields (Peyré 2008, sections 2.2-2.3).

:class:`WaveletGroupletTransform` applies the grouplet tight frame of section 2.2
(:class:`texsyn.transforms.grouplet_frame.GroupletTightFrame`) to every band of a Laplacian
tight frame (section 2.3).

:class:`GroupletTransform`, round 1's construction of ours, is deprecated: at level ``l``
every pixel ``m`` is paired with ``p = A_l(m)``,

    d_l[m] = (a[m] - a[A_l m]) / sqrt(2),      a'[m] = (a[m] + a[A_l m]) / sqrt(2),

and the inverse divides by ``1 + c[p]``, ``c[p]`` the number of pixels associated to ``p``
(``G^T G + H^T H = I + diag(c)`` is diagonal for *any* association map). It is exactly
invertible but not the paper's frame, and the tight frame matches it in quality and beats it
in speed (``docs/methods/grouplets.md``).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from .grouplet_frame import GroupletTightFrame, checked_associations
from .pyramids import LaplacianTightFrame

__all__ = ["GroupletTransform", "WaveletGroupletTransform", "checked_associations"]

_SQRT2 = np.sqrt(2.0)


class GroupletTransform:
    """Deprecated: round 1's redundant Haar transform along association fields (``L + 1`` layers).

    Use :class:`texsyn.transforms.grouplet_frame.GroupletTightFrame`, the tight frame of
    Peyré 2008, section 2.2. Constructing this class warns.

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
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", DeprecationWarning)
    ...     transform = GroupletTransform(shifted[None], (3, 4))
    >>> image = np.random.default_rng(0).random((3, 4))
    >>> coefficients = transform.forward(image)
    >>> coefficients.shape
    (2, 3, 4)
    >>> bool(np.allclose(transform.inverse(coefficients), image))
    True
    """

    def __init__(self, associations: np.ndarray, shape: tuple[int, int]):
        warnings.warn(
            "GroupletTransform (round 1's Haar construction) is deprecated; use "
            "texsyn.transforms.grouplet_frame.GroupletTightFrame",
            DeprecationWarning,
            stacklevel=2,
        )
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
    normalized : bool
        Divide every coefficient by its merge factor relative to an
        unbranched flow line (:attr:`GroupletTightFrame.scales`; 1 along a translation), so
        that coefficients compare across flows whose lines converge differently; the
        inverse multiplies them back. What the grouplet model learns its marginals on.

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

    def __init__(
        self,
        associations: np.ndarray,
        shape: tuple[int, int],
        levels: int = 3,
        *,
        normalized: bool = False,
    ):
        self.pyramid = LaplacianTightFrame(shape, levels)
        self.grouplets = GroupletTightFrame(associations, shape)
        self.shape = self.pyramid.shape
        self.normalized = bool(normalized)
        self._scales = self.grouplets.scales.reshape((-1,) + self.shape)

    def analyse(
        self, image: np.ndarray, *, out: np.ndarray | None = None, work: np.ndarray | None = None
    ) -> np.ndarray:
        """Contiguous coefficients ``(L+1, J+1, C, H, W)`` of an image ``(H, W, C)`` (or ``(H, W)``, ``C = 1``).

        The layout the grouplet frame computes in (grouplet scale first), with no copy; rows
        of ``reshape(-1, H*W)`` are the bands ``(l, j, c)``. :meth:`forward` is the same
        numbers in the order ``(J+1, L+1[, C], H, W)``. ``out`` (the result's size) and
        ``work`` (:meth:`work_buffer`): buffers reused from one call to the next
        (:meth:`GroupletTightFrame.forward`); the same bytes.
        """
        x = np.asarray(image, dtype=np.float64)
        planes = x[None] if x.ndim == 2 else np.moveaxis(x, -1, 0)  # (C, H, W)
        shape = (self.pyramid.levels + 1, planes.shape[0]) + self.shape
        bands = self.pyramid.forward_planes(
            planes, out=None if work is None else work[0, : math.prod(shape)].reshape(shape)
        )  # (J+1, C, H, W)
        flat = bands.reshape((bands.shape[0] * bands.shape[1],) + self.shape)
        coefficients = self.grouplets.forward(
            flat,
            scales=self._scales if self.normalized else None,
            out=out,
            work=None if work is None else work[1:],
        )
        return coefficients.reshape((-1,) + bands.shape)

    def synthesise(self, coefficients: np.ndarray, *, work: np.ndarray | None = None) -> np.ndarray:
        """Image ``(H, W, C)`` from coefficients in :meth:`analyse`'s layout (the pseudo-inverse).

        ``work`` (:meth:`work_buffer`): a buffer reused from one call to the next.
        """
        c = np.asarray(coefficients, dtype=np.float64)
        levels, bands, channels = c.shape[:3]
        images = bands * channels
        planes = self.grouplets.inverse(
            c.reshape((levels, images) + self.shape),
            scales=self._scales if self.normalized else None,
            out=None if work is None else work[0, : images * self.size],
            work=None if work is None else work[1:],
        )
        image = self.pyramid.inverse_planes(planes.reshape((bands, channels) + self.shape))
        return np.moveaxis(image, 0, -1)

    @property
    def size(self) -> int:
        """Pixels ``H * W``."""
        return self.shape[0] * self.shape[1]

    def work_buffer(self, channels: int) -> np.ndarray:
        """Scratch space of :meth:`analyse` and :meth:`synthesise` for ``channels`` channels:
        ``(3, (J+1) C H W)``: the pyramid's bands (analysis) or the grouplet frame's
        synthesis, and the grouplet scan's two residuals."""
        return np.empty((3, (self.pyramid.levels + 1) * int(channels) * self.size))

    def forward(self, image: np.ndarray) -> np.ndarray:
        """``(J+1, L+1, H, W)`` coefficients of a grey image, ``(J+1, L+1, C, H, W)`` of a colour one."""
        grey = np.ndim(image) == 2
        coefficients = np.moveaxis(self.analyse(image), 0, 1)
        return coefficients[:, :, 0] if grey else coefficients

    def inverse(self, coefficients: np.ndarray) -> np.ndarray:
        """Image from coefficients (the pseudo-inverse; exact on the range of :meth:`forward`)."""
        c = np.asarray(coefficients, dtype=np.float64)
        grey = c.ndim == 4
        layout = np.moveaxis(c[:, :, None] if grey else c, 1, 0)
        image = self.synthesise(layout)
        return image[..., 0] if grey else image
