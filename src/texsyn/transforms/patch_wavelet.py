"""The patch-valued wavelet transform of coordinate maps: lifting scheme and coefficients.

G. Peyré, *Texture synthesis and modification with a patch-valued wavelet transform*, SSVM
2007, section 4 (``docs/methods/patch_wavelet.md``). A feature-valued image is a *coordinate
map* ``T`` of shape ``(n_h, n_w, 2)`` (sides powers of two): every sample holds the exemplar
position ``(row, col)`` of its feature, the exemplar window centred there; the displayed image
is ``E(T)``. At level ``j`` the samples spaced ``s = 2^(j-1)`` apart are split into even and
odd ones along rows, then along columns; each odd sample is predicted by the association-field
mean ``m^omega`` of its two even neighbours (section 3) and the detail is the difference, in a
``p``-dimensional embedding of the exemplar's patches, between prediction and truth.

Here is what does not depend on an exemplar: the lifting steps, the walks of Tables 1-2 over
a patch space (:class:`PatchLifting`) and the window width of each level (the coefficients
and their thresholding: :mod:`texsyn.transforms.patch_wavelet_coefficients`);
the patch space of one exemplar is :class:`texsyn.models.patch_wavelet.PatchWaveletTransform`.
Levels keep the paper's numbering ``j = 1 ... J``, 1 the finest (detail keys ``(j, axis)``);
0-based coarse-to-fine walks call :meth:`PatchLifting.inverse_step` with ``level = j - 1``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ..ops.progress import Reporter
from .patch_wavelet_coefficients import PatchWaveletCoefficients
from .patch_widths import descriptor_dimension, largest_width, level_width, planned_widths, width_chain

__all__ = [
    "PatchLifting", "PatchWaveletCoefficients", "descriptor_dimension", "interleave", "largest_width",
    "level_width", "next_even", "planned_widths", "split", "width_chain",
]  # fmt: skip


# ---------------------------------------------------------------------- lifting steps
def split(samples: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """(Split) Even and odd samples along ``axis`` (Table 1)."""
    moved = np.moveaxis(samples, axis, 0)
    return np.moveaxis(moved[0::2], 0, axis), np.moveaxis(moved[1::2], 0, axis)


def interleave(even: np.ndarray, odd: np.ndarray, axis: int) -> np.ndarray:
    """(Join) Even samples at even indices, odd ones between them along ``axis`` (Table 2)."""
    e = np.moveaxis(even, axis, 0)
    out = np.empty((2 * e.shape[0],) + e.shape[1:], dtype=even.dtype)
    out[0::2] = e
    out[1::2] = np.moveaxis(odd, axis, 0)
    return np.moveaxis(out, 0, axis)


def next_even(even: np.ndarray, axis: int, boundary: str) -> np.ndarray:
    """The even neighbour ``k + 1`` of every even sample along ``axis``: the cyclic one
    (``'periodic'``, section 4) or, at the end, the last sample itself (``'symmetric'``, the
    whole-sample mirror with which the paper analyses non-periodic textures)."""
    if boundary == "periodic":
        return np.roll(even, -1, axis=axis)
    moved = np.moveaxis(even, axis, 0)
    shifted = np.concatenate([moved[1:], moved[-1:]], axis=0)
    return np.moveaxis(shifted, 0, axis)


# ---------------------------------------------------------------------- the lifting scheme
class PatchLifting:
    """Forward and inverse patch-valued wavelet transform over a patch space (Tables 1-2).

    A subclass supplies the patch space of one exemplar: :attr:`exemplar_shape`,
    :meth:`image` (the display ``E(T)``), :meth:`mean_features` (the association-field mean
    ``m^omega`` of section 3, projected on the exemplar's windows) and :meth:`embedding`
    (the parameterisation ``gamma_W`` and a nearest-neighbour tree for its inverse);
    :class:`texsyn.models.patch_wavelet.PatchWaveletTransform` is the one texsyn uses. What
    a walk needs and was not built ahead is built for that call only, never kept.

    Attributes
    ----------
    min_width, max_width : int
        Bounds of the window width of a level (:func:`level_width`).
    feature_width : int
        Window ``m0`` of the feature estimation (eq. 4).
    """

    min_width: int
    max_width: int
    feature_width: int

    @property
    def exemplar_shape(self) -> tuple[int, int]:
        """``(H, W)`` of the exemplar whose positions the coordinate maps hold."""
        raise NotImplementedError

    def image(self, coords: np.ndarray) -> np.ndarray:
        """The displayed image ``E(T)`` of a coordinate map ``(..., 2)``: ``(..., C)``."""
        raise NotImplementedError

    def mean_features(
        self, first: np.ndarray, second: np.ndarray, axis: int, half_distance: int, width: int
    ) -> np.ndarray:
        """Flat exemplar position of ``m^omega(first, second)`` for every pair ``(n, 2)``."""
        raise NotImplementedError

    def embedding(self, width: int) -> tuple[np.ndarray, Any]:
        """``(Y, tree)``: ``gamma_W`` of every exemplar position and a tree for ``gamma_W^-1``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ widths and positions
    def width(self, level: int) -> int:
        """Patch width of ``level`` (1 is the finest)."""
        return level_width(level, self.min_width, self.max_width)

    def widths(self) -> list[int]:
        """Every width any level (or the feature estimation) can use."""
        return width_chain(self.min_width, self.max_width, self.feature_width)

    def flat_positions(self, coords: np.ndarray) -> np.ndarray:
        """Flat (C-order) exemplar indices of the positions ``(..., 2)``."""
        return coords[..., 0] * self.exemplar_shape[1] + coords[..., 1]

    def positions(self, flat: np.ndarray) -> np.ndarray:
        """Exemplar positions ``(..., 2)`` of flat indices (int64)."""
        return np.stack(np.divmod(flat, self.exemplar_shape[1]), axis=-1).astype(np.int64, copy=False)

    def predict(self, even: np.ndarray, axis: int, level: int, boundary: str) -> np.ndarray:
        """Association-field mean of every even sample and its next even neighbour along ``axis``."""
        nxt = next_even(even, axis, boundary)
        flat = self.mean_features(
            even.reshape(-1, 2), nxt.reshape(-1, 2), axis, 2 ** (level - 1), self.width(level)
        )
        return self.positions(flat).reshape(even.shape)

    # ------------------------------------------------------------------ the transform
    def forward(
        self,
        coords: np.ndarray,
        *,
        grid_boundary: str = "periodic",
        report: Reporter | None = None,
        callback: Callable[[int, int], None] | None = None,
    ) -> PatchWaveletCoefficients:
        """Forward transform of an ``n x n`` coordinate map, ``n = 2^J`` (Table 1).

        A rectangular map of shape ``(2^a, 2^b)`` is transformed over ``min(a, b)`` levels,
        which leaves a coarse map of ``2^(a - min) x 2^(b - min)`` features: the cost is
        proportional to the number of samples, never to the square of the longer side.

        Parameters
        ----------
        coords : ndarray of int, shape (n, n, 2) or (n_h, n_w, 2)
            Sides powers of two, at least 2.
        grid_boundary : {'periodic', 'symmetric'}
            Neighbour rule at the border of the sample grid (:func:`next_even`).
        report : Reporter, optional
            Receives ``(level, levels)`` after each level.
        callback : callable, optional
            Deprecated (round 1): ``callback(level, levels)`` after each level; use ``report``.
        """
        if callback is not None:
            _deprecated_callback(type(self).__name__, "forward")
        T = self._check_map(coords)
        levels = int(round(math.log2(min(T.shape[:2]))))
        details, features = {}, {}
        embeddings: dict[int, tuple[np.ndarray, Any]] = {}  # this call's, never kept
        for level in range(1, levels + 1):
            width = self.width(level)
            if width not in embeddings:
                embeddings[width] = self.embedding(width)
            Y = embeddings[width][0]
            for axis in (0, 1):
                even, odd = split(T, axis)
                predicted = self.predict(even, axis, level, grid_boundary)
                details[(level, axis)] = Y[self.flat_positions(predicted)] - Y[self.flat_positions(odd)]
                features[(level, axis)] = odd
                T = even
            if report is not None:
                report(level, levels)
            if callback is not None:
                callback(level, levels)
        return PatchWaveletCoefficients(T.copy(), levels, details, grid_boundary, features)

    def inverse_step(
        self, coefficients: PatchWaveletCoefficients, *, restore: bool = False
    ) -> Callable[[int, np.ndarray | None], np.ndarray]:
        """One level of the backward transform (Table 2), as a coarse-to-fine step.

        Returns ``step(level, T)``: the coordinate map of 0-based ``level`` (transform level
        ``j = level + 1``) from the map ``T`` of the level above it. Odd samples with an
        exactly zero detail take the prediction itself, so zero details need no embedding;
        others take ``gamma^-1(gamma(prediction) - d)``.

        With ``restore=True`` an odd sample whose analysed feature is known
        (``coefficients.features``, not ``-1``) takes that feature instead: the same as
        ``gamma^-1(gamma(prediction) - d)`` where the prediction is the analysis' own (and
        ``gamma`` injective), and what a modification needs where removing coarser details
        has changed the prediction, since moving a detail measured at one point of the
        embedding to another lands on an unrelated patch (``docs/methods/patch_wavelet.md``).
        """
        boundary = coefficients.grid_boundary
        embeddings: dict[int, tuple[np.ndarray, Any]] = {}  # this walk's, never kept

        def step(level: int, coarser: np.ndarray | None) -> np.ndarray:
            j, T = level + 1, np.asarray(coefficients.coarse if coarser is None else coarser, dtype=np.int64)
            width = self.width(j)
            for axis in (1, 0):
                d = coefficients.details.get((j, axis))
                if d is not None and d.shape[:2] != T.shape[:2]:
                    raise ValueError(
                        f"details of level {j}, axis {axis} have shape {d.shape[:2]}, expected {T.shape[:2]}"
                    )
                known = coefficients.features.get((j, axis)) if restore else None
                if known is None:
                    predicted = self.predict(T, axis, j, boundary)
                    odd = predicted
                else:
                    if known.shape[:2] != T.shape[:2]:
                        raise ValueError(
                            f"features of level {j}, axis {axis} have shape {known.shape[:2]}, expected {T.shape[:2]}"
                        )
                    open_ = known[..., 0] < 0  # the samples left to the transform
                    predicted = np.array(known, dtype=np.int64)
                    if open_.any():  # predict only those: a small ratio restores nearly all
                        nxt = next_even(T, axis, boundary)
                        flat = self.mean_features(T[open_], nxt[open_], axis, 2 ** (j - 1), width)
                        predicted[open_] = self.positions(flat)
                    odd = predicted
                    d = None if d is None else np.where(open_[..., None], d, 0.0)
                if d is not None:
                    moved = np.any(d != 0, axis=-1)
                    if moved.any():
                        if width not in embeddings:
                            embeddings[width] = self.embedding(width)
                        Y, tree = embeddings[width]
                        target = Y[self.flat_positions(predicted[moved])] - d[moved]
                        odd = predicted.copy()
                        odd[moved] = self.positions(tree.query(target)[1])
                T = interleave(T, odd, axis)
            return T

        return step

    def inverse(
        self,
        coefficients: PatchWaveletCoefficients,
        *,
        restore: bool = False,
        report: Reporter | None = None,
        callback: Callable[[int, int, np.ndarray], None] | None = None,
    ) -> np.ndarray:
        """Backward transform (Table 2): the ``coefficients.shape + (2,)`` coordinate map.

        ``restore`` is that of :meth:`inverse_step`. ``report`` (optional) receives
        ``(levels_done, levels)`` after each level; the deprecated ``callback`` of round 1
        receives ``(levels_done, levels, T)``, ``T`` the coordinate map reached.
        """
        if callback is not None:
            _deprecated_callback(type(self).__name__, "inverse")
        step = self.inverse_step(coefficients, restore=restore)
        T = np.asarray(coefficients.coarse, dtype=np.int64)
        top = coefficients.top_level
        for done, level in enumerate(range(top - 1, -1, -1), start=1):
            T = step(level, T)
            if report is not None:
                report(done, top)
            if callback is not None:
                callback(done, top, T)
        return T

    def _check_map(self, coords: np.ndarray) -> np.ndarray:
        T = np.asarray(coords)
        if T.ndim != 3 or T.shape[2] != 2:
            raise ValueError(f"coordinate map must have shape (n_h, n_w, 2), got {T.shape}")
        for n in T.shape[:2]:
            if n < 2 or n & (n - 1):
                raise ValueError(f"coordinate map sides must be powers of two >= 2, got {T.shape[:2]}")
        h, w = self.exemplar_shape
        if T.min() < 0 or T[..., 0].max() >= h or T[..., 1].max() >= w:
            raise ValueError("coordinate map holds positions outside the exemplar")
        return T.astype(np.int64)


def _deprecated_callback(owner: str, name: str) -> None:
    """Warn that round 1's ``callback=`` of :meth:`PatchLifting.forward`/``inverse`` was used."""
    warnings.warn(
        f"{owner}.{name}(callback=...) is deprecated; use report=texsyn.ops.progress.Reporter(...)",
        DeprecationWarning,
        stacklevel=3,
    )
