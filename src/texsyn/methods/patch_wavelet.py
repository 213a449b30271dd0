"""Texture synthesis and modification with a patch-valued wavelet transform (Peyré 2007).

A texture is a coordinate map into the exemplar, decomposed by a lifting-style multiscale
transform whose prediction is the association-field mean of two neighbouring features
(:mod:`texsyn.ops.patch_wavelet`). Synthesis (section 5.1) is the inverse transform of 2x2
random coarse features with zero details (or Gaussian details with a per-level ``sigma``,
Fig. 6); it tiles the plane. Modification (section 5.2) analyses an input texture with the
exemplar's features, removes the details below ``ratio`` times the largest, and rebuilds.

References
----------
G. Peyré, "Texture synthesis and modification with a patch-valued wavelet transform",
SSVM 2007, sections 2-5. Implementation notes: spec 01 (resolutions A1-A16).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Callable, Sequence

import numpy as np

from .._validation import OneOf, Range, as_exemplar, memory_limit_bytes
from ..ops import as_channels, luma, match_histogram
from ..ops.patch_wavelet import PatchWaveletCoefficients, PatchWaveletTransform
from ._base import Progress, TextureSynthesizer
from ..errors import InputError, MemoryLimitError
from ..ops.linalg import fixed_order

__all__ = ["Modification", "PatchWavelet"]

_POWERS = (2, 4, 8, 16, 32, 64)


@dataclass(frozen=True)
class Modification:
    """One texture modification (paper section 5.2, Figs. 7-8).

    Attributes
    ----------
    image : ndarray of float32, shape (H, W) or (H, W, C)
        The modified texture, made of (colour-equalised) exemplar pixels.
    source_map : ndarray of int32, shape (H, W, 2)
        Exemplar position of every output pixel.
    feature_map : ndarray of int32, shape (H, W, 2)
        The input expressed with the exemplar's features (eq. 4), before the transform.
    magnitudes : ndarray of float64, shape (n, n)
        Magnitudes of the kept details, packed like a wavelet transform (Fig. 7 b, d, f, h);
        ``n`` is the input side rounded up to a power of two.
    ratio : float
        The threshold as a fraction of the largest detail magnitude.
    """

    image: np.ndarray
    source_map: np.ndarray
    feature_map: np.ndarray
    magnitudes: np.ndarray
    ratio: float


class PatchWavelet(TextureSynthesizer):
    """Peyré's patch-valued wavelet transform: synthesis by inverse transform, and modification.

    Output pixels are exemplar pixels (the coordinate map is the source map); a synthesis of
    side ``2^J`` tiles the plane, other sizes are the top-left crop of the next power of two.

    Parameters
    ----------
    min_width : int
        Smallest patch width ``W_min``; level ``j`` uses ``clamp(2^j, min_width, W_max)`` with
        ``W_max`` the largest power of two up to half the exemplar (spec 01, A7; 2 is the
        literal paper).
    max_resolution : int
        Wider patches are compared through ``max_resolution x max_resolution`` block means.
    sigma : tuple of float
        Standard deviation of the random details per level (Fig. 6), finest level first; one
        value applies to every level, levels beyond a longer list get 0. 0 is the pure
        synthesis of Fig. 5; useful values lie in [0, 0.5] (the embedding has unit variance).
    feature_width : int
        Window ``m0`` of the feature estimation of an input texture (eq. 4, modification).
    embedding_dim : int
        Dimension ``p`` of the LLE parameterisation of the patch manifold (the paper uses 5).
    lle_neighbors : int
        Neighbours of the locally linear embedding.
    lle_points : int
        LLE runs on at most this many landmark patches; the others are placed by barycentric
        weights (spec 01, A11).
    exemplar_boundary : str
        Extension of the exemplar past its border: 'auto' (periodic if it tiles, else
        symmetric), 'periodic' or 'symmetric'.
    candidates : int
        Candidates of the float32 patch search re-ranked exactly.
    random_state : int
        Seed of the LLE eigen-solver (fitting only).
    """

    name = "patch_wavelet"
    summary = "Patch-valued wavelet transform: inverse transform of random coarse features (periodic)"
    reference = (
        "G. Peyré, Texture Synthesis and Modification with a Patch-Valued Wavelet Transform, "
        "SSVM 2007"
    )
    has_source_map = True
    source_map_exact = True
    bytes_per_pixel = 96.0

    def __init__(
        self,
        *,
        min_width: Annotated[int, OneOf(_POWERS)] = 8,
        max_resolution: Annotated[int, OneOf(_POWERS)] = 16,
        sigma: Annotated[tuple[float, ...], Range(0.0, 4.0)] = (0.0,),
        feature_width: Annotated[int, OneOf(_POWERS)] = 8,
        embedding_dim: Annotated[int, Range(1, 32)] = 5,
        lle_neighbors: Annotated[int, Range(2, 200)] = 12,
        lle_points: Annotated[int, Range(64, 1 << 20)] = 2048,
        exemplar_boundary: Annotated[str, OneOf(("auto", "periodic", "symmetric"))] = "auto",
        candidates: Annotated[int, Range(1, 64)] = 4,
        random_state: Annotated[int, Range(0, None)] = 0,
    ):
        self.min_width = min_width
        self.max_resolution = max_resolution
        self.sigma = sigma
        self.feature_width = feature_width
        self.embedding_dim = embedding_dim
        self.lle_neighbors = lle_neighbors
        self.lle_points = lle_points
        self.exemplar_boundary = exemplar_boundary
        self.candidates = candidates
        self.random_state = random_state

    # ------------------------------------------------------------------ fitting
    def min_exemplar_size(self) -> tuple[int, str]:
        side = max(4, 2 * self.min_width, self.feature_width)
        return side, f"patches of min_width={self.min_width} need at least {side}x{side} pixels"

    def _make_transform(self, exemplar: np.ndarray) -> PatchWaveletTransform:
        return PatchWaveletTransform(
            exemplar,
            min_width=self.min_width,
            max_resolution=self.max_resolution,
            feature_width=self.feature_width,
            embedding_dim=self.embedding_dim,
            lle_neighbors=self.lle_neighbors,
            lle_points=self.lle_points,
            exemplar_boundary=self.exemplar_boundary,
            candidates=self.candidates,
            random_state=self.random_state,
        )

    def _fit(self, exemplar: np.ndarray) -> None:
        # descriptors and search indexes of every width; the LLE embeddings are computed on
        # first use (only random details and modification need them) and kept.
        transform = self._make_transform(exemplar)
        self._check_index_memory(transform)
        self.transform_ = transform.prepare()

    @staticmethod
    def _check_index_memory(transform: PatchWaveletTransform) -> None:
        """Refuse exemplars whose float32 search indexes would not fit in memory."""
        h, w = transform.exemplar_shape
        need = sum(4.0 * h * w * transform.windows.dimension(width) for width in transform.widths())
        limit = memory_limit_bytes()
        if need > limit:
            raise MemoryLimitError(
                f"exemplar of {w}x{h} pixels needs about {need / 2**30:.1f} GiB of patch indexes for "
                f"method 'patch_wavelet', more than the {limit / 2**30:.1f} GiB allowed; use a smaller "
                "exemplar, a smaller max_resolution, or set TEXSYN_MEMORY_LIMIT"
            )

    def sigma_profile(self, levels: int) -> np.ndarray:
        """``sigma_j`` for ``j = 1 ... levels`` (finest first)."""
        sig = np.asarray(self.sigma, dtype=np.float64).ravel()
        if sig.size == 1:
            return np.full(levels, sig[0])
        out = np.zeros(levels)
        out[: min(levels, sig.size)] = sig[:levels]
        return out

    # ------------------------------------------------------------------ synthesis
    def _sample(self, shape, rng, callback):
        transform: PatchWaveletTransform = self.transform_
        h, w = shape
        levels = max(2, math.ceil(math.log2(max(h, w))))  # output side N = 2^levels >= 4
        top = levels - 1
        eh, ew = transform.exemplar_shape
        coarse = np.stack([rng.integers(0, eh, (2, 2)), rng.integers(0, ew, (2, 2))], axis=-1)
        sigmas = self.sigma_profile(top)
        coefficients = PatchWaveletCoefficients(coarse, top, {}, "periodic")
        for level in range(top, 0, -1):
            for axis in (1, 0):
                if sigmas[level - 1] > 0:
                    size = coefficients.detail_shape(level, axis) + (transform.embedding_dim,)
                    coefficients.details[(level, axis)] = sigmas[level - 1] * rng.standard_normal(size)
        if callback is not None:
            callback(Progress("levels", 0, top, image=transform.image(coarse)))

            def report(done, total, coords):
                callback(Progress("levels", done, total, image=transform.image(coords)))
        else:
            report = None
        coords = transform.inverse(coefficients, callback=report)
        coords = coords[:h, :w]
        return transform.image(coords), coords

    # ------------------------------------------------------------------ modification
    @fixed_order
    def modify(
        self,
        texture: np.ndarray,
        ratio: float | Sequence[float] = 0.5,
        *,
        equalize: bool = True,
        grid_boundary: str = "symmetric",
        per_level: bool = False,
        callback: Callable[[Progress], None] | None = None,
    ) -> Modification | list[Modification]:
        """Modify ``texture`` toward the fitted exemplar (paper section 5.2, spec 01 5.4).

        The texture is expressed with the exemplar's features (eq. 4, after equalising the
        exemplar's colours to the texture's, channel by channel), decomposed by the forward
        transform, the details of magnitude at most ``ratio`` times the largest are set to
        zero, and the inverse transform rebuilds it. ``ratio = 0`` rebuilds the texture from
        exemplar pixels, ``ratio = 1`` is a pure synthesis from one coarse feature; values in
        between interpolate (Figs. 7-8). Sizes other than ``2^J x 2^J`` are extended
        symmetrically to the next power of two and cropped back.

        Parameters
        ----------
        texture : ndarray, shape (H, W) or (H, W, C)
            Converted to the exemplar's channels (grey is replicated, colour becomes luma).
        ratio : float or sequence of float
            Threshold(s) as a fraction of the largest detail magnitude, in [0, 1]; a sequence
            shares one analysis and returns one result per value.
        equalize : bool
            Match the exemplar's colour histograms to the texture's first (Fig. 2).
        grid_boundary : {'symmetric', 'periodic'}
            Neighbour rule at the border of the sample grid ('periodic' for textures that tile).
        per_level : bool
            Threshold each level against its own largest detail instead of the global one.
        callback : callable, optional
            Receives :class:`Progress` records (stages 'features', 'analysis', 'synthesis').

        Returns
        -------
        Modification, or a list of them when ``ratio`` is a sequence.
        """
        exemplar = self._require_fitted()
        ratios = [ratio] if np.ndim(ratio) == 0 else list(ratio)
        for r in ratios:
            if isinstance(r, (bool, np.bool_)) or not isinstance(r, (int, float, np.integer, np.floating)) or not 0.0 <= float(r) <= 1.0:
                raise InputError(f"ratio must be a number in [0, 1], got {r!r}")
        if grid_boundary not in ("symmetric", "periodic"):
            raise InputError(f"grid_boundary must be 'symmetric' or 'periodic', got {grid_boundary!r}")
        tex = as_channels(np.asarray(as_exemplar(texture, name="texture"), dtype=np.float64))
        ex = as_channels(exemplar)
        if tex.shape[2] != ex.shape[2]:
            tex = np.repeat(tex, ex.shape[2], axis=2) if tex.shape[2] == 1 else luma(tex)[..., None]
        h, w = tex.shape[:2]
        n = 2 ** max(1, math.ceil(math.log2(max(h, w))))
        padded = np.pad(tex, ((0, n - h), (0, n - w), (0, 0)), mode="symmetric")
        if equalize:
            equalized = np.stack(
                [match_histogram(ex[..., c], tex[..., c]) for c in range(ex.shape[2])], axis=-1
            )
            transform = self._make_transform(equalized)
        else:
            transform = self.transform_

        def stage(name):
            if callback is None:
                return None
            return lambda done, total, *_: callback(Progress(name, done, total))

        if callback is not None:
            callback(Progress("features", 0, 1))
        features = transform.estimate_features(padded)
        if callback is not None:
            callback(Progress("features", 1, 1))
        coefficients = transform.forward(features, grid_boundary=grid_boundary, callback=stage("analysis"))
        results = []
        for r in ratios:
            kept = coefficients.thresholded(float(r), per_level=per_level)
            coords = transform.inverse(kept, callback=stage("synthesis"))[:h, :w]
            results.append(
                Modification(
                    image=self._as_output(transform.image(coords)),
                    source_map=coords.astype(np.int32),
                    feature_map=features[:h, :w].astype(np.int32),
                    magnitudes=kept.magnitudes(),
                    ratio=float(r),
                )
            )
        return results[0] if np.ndim(ratio) == 0 else results
