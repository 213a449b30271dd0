"""Texture synthesis and modification with a patch-valued wavelet transform (Peyré 2007).

A texture is a coordinate map into the exemplar, decomposed by a lifting-style multiscale
transform whose prediction is the association-field mean of two neighbouring features
(:mod:`texsyn.transforms.patch_wavelet`, :mod:`texsyn.models.patch_wavelet`). Synthesis
(section 5.1) is the inverse transform of 2x2 random coarse features with zero details (or
Gaussian details with a per-level ``sigma``, Fig. 6), walked from coarse to fine by
:func:`texsyn.drivers.coarse_to_fine.coarse_to_fine`; it tiles the plane. Modification
(section 5.2) analyses an input texture with the exemplar's features, removes the details
below ``ratio`` times the largest, and rebuilds.

Why this module is long: besides the paper's two procedures (synthesis, section 5.1, and
modification, section 5.2), it holds the memory model that fit, sample and modify are checked
against before any work (``docs/memory.md``), about a third of the module. The estimates are
computed from the same window widths, descriptor lengths and query chunks the transform uses,
and stay next to the code whose allocations they mirror so that a change to one is seen with
the other.

References
----------
G. Peyré, "Texture synthesis and modification with a patch-valued wavelet transform",
SSVM 2007, sections 2-5; ``docs/methods/patch_wavelet.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np

from .._validation import OneOf, Range, as_exemplar
from ..drivers.coarse_to_fine import coarse_to_fine
from ..errors import InputError
from ..models.patch_search import FAST_SEARCH_DIMENSION, FAST_SEARCH_POSITIONS
from ..models.patch_wavelet import WRAP_SEAM_LIMIT, PatchWaveletTransform
from ..ops import as_channels, match_histogram
from ..ops.canvas import crop_to_output, extend_to_canvas, power_of_two_canvas
from ..ops.color import colour_space
from ..ops.fourier import periodic_smooth_decomposition
from ..ops.linalg import fixed_order
from ..ops.patches import wrap_seam_ratio
from ..ops.progress import Reporter
from ..ops.search import bounded_index_bytes, bounded_query_bytes
from ..transforms.patch_wavelet import (
    PatchWaveletCoefficients,
    descriptor_dimension,
    largest_width,
    level_width,
    planned_widths,
)
from ._base import Progress, TextureSynthesizer
from ._memory import output_bytes, shape_dims

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
    magnitudes : ndarray of float64, shape (n_h, n_w)
        Magnitudes of the kept details, packed like a wavelet transform (Fig. 7 b, d, f, h);
        ``n_h`` and ``n_w`` are the input's height and width, each rounded up to a power of
        two (``n x n`` for a square input).
    ratio : float
        The ratio asked for: the share of the grid whose details are removed (local
        thresholding), or the threshold as a fraction of the largest detail magnitude
        (``thresholding='coefficient'``).
    kept : ndarray of bool, shape (H, W), or None
        Pixels whose analysed features were kept (local thresholding: these are the input's
        own features, the others are synthesised); ``None`` with coefficient thresholding.
    """

    image: np.ndarray
    source_map: np.ndarray
    feature_map: np.ndarray
    magnitudes: np.ndarray
    ratio: float
    kept: np.ndarray | None = None


class PatchWavelet(TextureSynthesizer):
    """Peyré's patch-valued wavelet transform: synthesis by inverse transform, and modification.

    Output pixels are exemplar pixels (the coordinate map is the source map); a synthesis of
    side ``2^J`` tiles the plane, other sizes are the top-left crop of the next power of two.

    Parameters
    ----------
    min_width : int
        Smallest patch width ``W_min``; level ``j`` uses ``clamp(2^j, min_width, W_max)`` with
        ``W_max`` the largest power of two up to half the exemplar (2 is the paper's
        literal choice).
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
        weights.
    exemplar_boundary : str
        Extension of the exemplar past its border: 'auto', 'periodic' or 'symmetric'.
        'auto' is periodic for a synthesis (a deviation: section 4 mirrors a non-periodic
        exemplar): a synthesis continues exemplar features across its border instead of
        breaking them there, which keeps it as sharp as the exemplar at any output size, at
        the price of straight cuts where runs cross the wrap of an exemplar that does not
        tile (``docs/methods/patch_wavelet.md``, "Deviations"); :meth:`modify` keeps the
        periodic extension for an exemplar that tiles and the symmetric one otherwise.
    candidates : int
        Candidates of the float32 patch search re-ranked exactly.
    fit_rng : int
        Seed of the LLE eigen-solver (fitting only; ``sample`` takes its own ``rng``).
        ``random_state`` is its deprecated name.
    """

    name = "patch_wavelet"
    summary = "Patch-valued wavelet transform: inverse transform of random coarse features (periodic)"
    reference = (
        "G. Peyré, Texture Synthesis and Modification with a Patch-Valued Wavelet Transform, SSVM 2007"
    )
    deprecated_params = {"random_state": "fit_rng"}
    has_source_map = True
    #: the terms follow the build order and the allocator's resident temporaries (:meth:`_fit_terms`);
    #: 10 % covers the resident set's excess over the traced peaks (up to 5 %, ``docs/memory.md``,
    #: "Every method at its defaults")
    memory_margin = 1.1

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
        fit_rng: Annotated[int, Range(0, None)] = 0,
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
        self.fit_rng = fit_rng

    # ------------------------------------------------------------------ fitting
    def min_exemplar_size(self) -> tuple[int, str]:
        side = max(4, 2 * self.min_width, self.feature_width)
        return side, f"patches of min_width={self.min_width} need at least {side}x{side} pixels"

    def _make_transform(
        self, exemplar: np.ndarray, *, exemplar_boundary: str | None = None, **built
    ) -> PatchWaveletTransform:
        return PatchWaveletTransform(
            exemplar,
            min_width=self.min_width,
            max_resolution=self.max_resolution,
            feature_width=self.feature_width,
            embedding_dim=self.embedding_dim,
            lle_neighbors=self.lle_neighbors,
            lle_points=self.lle_points,
            exemplar_boundary=exemplar_boundary or self.exemplar_boundary,
            candidates=self.candidates,
            rng=self.fit_rng,
            **built,
        )

    def _fit(self, exemplar: np.ndarray) -> None:
        # the nearest-patch indexes of every width, and the LLE embeddings of the levels that
        # draw random details (none for a pure synthesis): everything sample uses, whatever the
        # output size (memory was checked by fit, from memory_terms, before this point)
        # 'auto' synthesises on a periodic exemplar (a deviation from section 4's mirror for
        # non-periodic textures): a mirror ends every run of coherent exemplar features at the
        # exemplar's border and makes the synthesis a finer mosaic of smoother joints; an
        # exemplar that does not tile is replaced by its periodic component (Moisan's
        # periodic-plus-smooth decomposition), so that runs crossing its wrap copy no straight
        # cut either (docs/methods/patch_wavelet.md, "Deviations")
        boundary = self.exemplar_boundary
        source = exemplar
        if boundary == "auto":
            boundary = "periodic"
            if wrap_seam_ratio(as_channels(exemplar)) > WRAP_SEAM_LIMIT:
                source = np.clip(periodic_smooth_decomposition(exemplar)[0], 0.0, 1.0)
        self.transform_ = self._make_transform(
            source, exemplar_boundary=boundary, embedding_widths=self._noisy_widths(exemplar.shape)
        )

    @property
    def source_image(self) -> np.ndarray:
        """The image the synthesis copies from: the exemplar, or with ``exemplar_boundary='auto'``
        its periodic component when it does not tile (``_fit``), in the exemplar's rank."""
        image = self.transform_.windows.image
        return image[..., 0] if self._require_fitted().ndim == 2 else image

    def _level_width(self, exemplar_shape, level: int) -> int:
        """Window width of transform level ``level`` (1 the finest) for an exemplar of that shape."""
        top = largest_width(exemplar_shape)
        return level_width(level, min(self.min_width, top), top)

    def _level_widths(self, exemplar_shape, levels: int) -> set[int]:
        return {self._level_width(exemplar_shape, j) for j in range(1, levels + 1)}

    def _noisy_widths(self, exemplar_shape) -> list[int]:
        """Widths of the levels with ``sigma_j > 0``, for any output size (finitely many)."""
        sig = np.asarray(self.sigma, dtype=np.float64).ravel()
        if sig.size == 1:  # every level; level log2(W_max) already reaches the widest window
            levels = list(range(1, int(math.log2(largest_width(exemplar_shape))) + 1)) if sig[0] > 0 else []
        else:
            levels = [j for j, s in enumerate(sig, start=1) if s > 0]
        return sorted({self._level_width(exemplar_shape, j) for j in levels})

    def sigma_profile(self, levels: int) -> np.ndarray:
        """``sigma_j`` for ``j = 1 ... levels`` (finest first)."""
        sig = np.asarray(self.sigma, dtype=np.float64).ravel()
        if sig.size == 1:
            return np.full(levels, sig[0])
        out = np.zeros(levels)
        out[: min(levels, sig.size)] = sig[:levels]
        return out

    # ------------------------------------------------------------------ synthesis
    def _random_coefficients(
        self, exemplar_shape, top: int, rng: np.random.Generator
    ) -> PatchWaveletCoefficients:
        """2x2 random coarse features and ``N(0, sigma_j^2)`` details (section 5.1, Fig. 6)."""
        eh, ew = exemplar_shape[:2]
        coarse = np.stack([rng.integers(0, eh, (2, 2)), rng.integers(0, ew, (2, 2))], axis=-1)
        sigmas = self.sigma_profile(top)
        coefficients = PatchWaveletCoefficients(coarse, top, {}, "periodic")
        for level in range(top, 0, -1):
            for axis in (1, 0):
                if sigmas[level - 1] > 0:
                    size = coefficients.detail_shape(level, axis) + (int(self.embedding_dim),)
                    coefficients.details[(level, axis)] = sigmas[level - 1] * rng.standard_normal(size)
        return coefficients

    def periodic_for(self, shape):
        """The inverse transform is periodic on its N x N map: the output, when it is one."""
        return power_of_two_canvas(shape, minimum=4, square=True) == tuple(shape)

    def _sample(self, shape, rng, callback):
        transform: PatchWaveletTransform = self.transform_
        side = power_of_two_canvas(shape, minimum=4, square=True)[0]  # an N x N map, N >= 4
        top = int(math.log2(side)) - 1  # N = 2^(top + 1)
        coefficients = self._random_coefficients(transform.exemplar_shape, top, rng)
        report = Reporter(callback, "levels", top)
        if report.active:
            report(0, image=transform.image(coefficients.coarse) if report.wants_images else None)
        maps = coarse_to_fine(
            transform.inverse_step(coefficients),
            top,
            start=coefficients.coarse,
            reporter=report,
            preview=transform.image,
        )
        coords = crop_to_output(maps[0], shape)
        # the displayed exemplar pixels, gathered in float32: what _as_output makes of the
        # float64 ones (rounding is monotone and 0, 1 are float32 numbers, so clipping to
        # [0, 1] commutes with it), without a float64 image of the output's size
        pixels = transform.windows.image.astype(np.float32)
        return pixels[coords[..., 0], coords[..., 1]], coords

    # ------------------------------------------------------------------ modification
    @staticmethod
    def modify_grid(shape: tuple[int, int]) -> tuple[int, int]:
        """Sample grid ``(n_h, n_w)`` that :meth:`modify` analyses for an input of ``shape``.

        Each side is rounded up to a power of two (at least 2) on its own, so the grid has
        fewer than four times the input's pixels whatever its aspect ratio.
        """
        return power_of_two_canvas(shape, minimum=2)

    @fixed_order
    def modify(
        self,
        texture: np.ndarray,
        ratio: float | Sequence[float] = 0.5,
        *,
        equalize: bool = True,
        grid_boundary: str = "symmetric",
        per_level: bool = False,
        thresholding: str = "local",
        callback: Callable[[Progress], None] | None = None,
    ) -> Modification | list[Modification]:
        """Modify ``texture`` toward the fitted exemplar (paper section 5.2).

        The texture is expressed with the exemplar's features (eq. 4, after equalising the
        exemplar's colours to the texture's, channel by channel), decomposed by the forward
        transform, its small details are removed and the inverse transform rebuilds it.
        ``ratio = 0`` rebuilds the texture from exemplar pixels, ``ratio = 1`` is a pure
        synthesis from one coarse feature; values in between interpolate (Figs. 7-8).

        By default (``thresholding='local'``) the details are removed by regions: the share
        ``ratio`` of the grid where the local energy of the details is lowest (the input is
        best predicted by the exemplar's association field there) is synthesised, the rest
        keeps the input's own features, and the synthesis continues them across the border.
        The statistics then move steadily with ``ratio`` and the structures of both textures
        stay whole. ``thresholding='coefficient'`` is the paper's literal rule: every detail
        of magnitude at most ``ratio`` times the largest is set to zero and the kept ones are
        applied to the new predictions as ``gamma^-1(gamma(mu) - d)``; since the magnitudes
        are heavy-tailed nearly every detail is gone by ``ratio = 0.1``, and kept details
        applied to changed predictions give unrelated patches that break structures
        (``docs/methods/patch_wavelet.md``, "Deviations"). Each side that is not a power of two is extended
        symmetrically to the next one, on its own, and cropped back: an ``H x W`` input is
        analysed on a ``2^a x 2^b`` grid (``2^a >= H``, ``2^b >= W``), so a long thin input
        costs what its number of pixels says, not what a square of its longer side would
        (the transform of a rectangular grid stops at ``min(a, b)`` levels and keeps a few
        coarse features, :meth:`PatchLifting.forward
        <texsyn.transforms.patch_wavelet.PatchLifting.forward>`). Memory is checked before
        the work (``docs/memory.md``). The fitted model is not changed: the embeddings the
        analysis needs are built for this call.

        Parameters
        ----------
        texture : ndarray, shape (H, W) or (H, W, C)
            Converted to the exemplar's channels (grey is replicated, colour becomes luma).
        ratio : float or sequence of float
            In [0, 1]: the share of the grid whose details are removed (local thresholding),
            or the threshold as a fraction of the largest detail magnitude (coefficient
            thresholding); a sequence shares one analysis and returns one result per value.
        equalize : bool
            Match the exemplar's colour histograms to the texture's first (Fig. 2).
        grid_boundary : {'symmetric', 'periodic'}
            Neighbour rule at the border of the sample grid ('periodic' for textures that tile).
        per_level : bool
            Measure each level against its own largest detail instead of the global one
            (local thresholding: each level's magnitudes are divided by their largest before
            they add up to the local energy).
        thresholding : {'local', 'coefficient'}
            Remove details by regions of low local detail energy (the default), or one by one
            against ``ratio`` times the largest (the paper's literal rule).
        callback : callable, optional
            Receives :class:`Progress` records (stages 'features', 'analysis', 'synthesis').

        Returns
        -------
        Modification, or a list of them when ``ratio`` is a sequence.

        References
        ----------
        G. Peyré, SSVM 2007, section 5.2 (thresholding, Figs. 7-8), section 4 (Tables 1-2).
        """
        exemplar = self._require_fitted()
        ratios: list[Any] = [ratio] if np.ndim(ratio) == 0 else list(ratio)  # type: ignore[arg-type]
        for r in ratios:
            if (
                isinstance(r, (bool, np.bool_))
                or not isinstance(r, (int, float, np.integer, np.floating))
                or not 0.0 <= float(r) <= 1.0
            ):
                raise InputError(f"ratio must be a number in [0, 1], got {r!r}")
        if grid_boundary not in ("symmetric", "periodic"):
            raise InputError(f"grid_boundary must be 'symmetric' or 'periodic', got {grid_boundary!r}")
        if thresholding not in ("local", "coefficient"):
            raise InputError(f"thresholding must be 'local' or 'coefficient', got {thresholding!r}")
        # the fitted transform wraps the exemplar (synthesis); a modification mirrors one that
        # does not tile, with transforms of its own (the equalised exemplar's, or this one)
        mirrored = self.exemplar_boundary == "auto" and wrap_seam_ratio(exemplar) > WRAP_SEAM_LIMIT
        size = np.shape(texture) if not isinstance(texture, (str, bytes)) else ()
        if len(size) in (2, 3) and min(size[:2]) >= 1:  # before the texture is even converted
            (h, w), (n_h, n_w) = size[:2], self.modify_grid(size[:2])
            self._check_memory(
                exemplar.shape,
                task=f"modifying a {w}x{h} texture ({n_w}x{n_h} grid) with a {exemplar.shape[1]}x{exemplar.shape[0]} exemplar",
                advice="use a smaller texture or exemplar",
                terms=self._modify_terms(exemplar.shape, size, bool(equalize) or mirrored, len(ratios)),
            )
        tex = as_channels(np.asarray(as_exemplar(texture, name="texture"), dtype=np.float64))
        ex = as_channels(exemplar)
        tex = colour_space("rgb", ex).forward(tex)  # the exemplar's channels: grey repeated, or luma
        h, w = tex.shape[:2]
        n_h, n_w = self.modify_grid((h, w))
        padded = extend_to_canvas(tex, (n_h, n_w), mode="symmetric")
        used = sorted(self._level_widths(ex.shape, int(math.log2(min(n_h, n_w)))))
        if equalize or mirrored:
            if equalize:
                ex = np.stack([match_histogram(ex[..., c], tex[..., c]) for c in range(ex.shape[2])], axis=-1)
            feature = min(self.feature_width, largest_width(ex.shape))
            transform = self._make_transform(ex, widths=used + [feature], embedding_widths=used)
        else:  # the fitted transform, with this call's embeddings (self.transform_ is unchanged)
            transform = self.transform_.prepare(used)

        report = Reporter(callback, "features", 1)
        report(0)
        features = transform.estimate_features(padded)
        report(1)
        coefficients = transform.forward(
            features, grid_boundary=grid_boundary, report=report.stage_of("analysis")
        )
        results = []
        local = thresholding == "local"
        for r in ratios:
            region = None
            if local:  # regions of low detail energy, smoothed over half the feature window
                region = coefficients.kept_region(
                    float(r), per_level=per_level, smoothing=transform.feature_width / 2, valid=(h, w)
                )
                kept = coefficients.restricted(region)
            else:
                kept = coefficients.thresholded(float(r), per_level=per_level)
            walk = report.stage_of("synthesis", kept.top_level)
            coords = coarse_to_fine(
                transform.inverse_step(kept, restore=local), kept.top_level, start=kept.coarse, reporter=walk
            )[0]
            coords = crop_to_output(coords, (h, w))
            results.append(
                Modification(
                    image=self._as_output(transform.image(coords)),
                    source_map=coords.astype(np.int32),
                    feature_map=crop_to_output(features, (h, w)).astype(np.int32),
                    magnitudes=kept.magnitudes(),
                    ratio=float(r),
                    kept=None if region is None else crop_to_output(region, (h, w)),
                )
            )
        return results[0] if np.ndim(ratio) == 0 else results

    # ------------------------------------------------------------------ memory (docs/memory.md)
    def _width_dims(self, exemplar_shape) -> dict[int, int]:
        """Descriptor length of every width the transform indexes."""
        _, _, c = shape_dims(exemplar_shape)
        widths = planned_widths(exemplar_shape, min_width=self.min_width, feature_width=self.feature_width)
        return {width: descriptor_dimension(width, self.max_resolution, c) for width in widths}

    def _embedding_bytes(self, k: float, dim: int) -> tuple[float, float]:
        """``(kept, transient)`` bytes of the LLE embedding of one width (coordinates and tree)."""
        n = min(k, self.lle_points * 1.0)
        neighbours = self.lle_neighbors + 40
        transient = 16.0 * k * dim + 8.0 * n * dim + (24.0 * n * n if n <= 512 else 64.0 * n * neighbours)
        return k * (16.0 * self.embedding_dim + 32.0), transient + 8.0 * k * (neighbours + dim)

    def _fast_widths(self, exemplar_shape) -> dict[int, int]:
        """Widths (and descriptor lengths) that get a proven fast search next to their index."""
        h, w, _ = shape_dims(exemplar_shape)
        if h * w < FAST_SEARCH_POSITIONS:
            return {}
        dims = self._width_dims(exemplar_shape)
        return {v: d for v, d in dims.items() if v <= self.max_resolution and d <= FAST_SEARCH_DIMENSION}

    def _model_terms(self, exemplar_shape) -> dict[str, float]:
        """What a fitted transform holds: float32 indexes, extended exemplar, block means, embeddings."""
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        dims = self._width_dims(exemplar_shape)
        sides = {max(1, width // self.max_resolution) for width in dims}  # block means kept per side
        terms = {
            "patch indexes": sum(4.0 * k * d + 4.0 * k for d in dims.values()),
            "extended exemplar and block means": 8.0 * k * c + 32.0 * k * c * (1 + len(sides)),
        }
        fast = self._fast_widths(exemplar_shape)
        if fast:  # float64 descriptors, their bounded index and isolation flags
            terms["fast searches"] = sum(
                8.0 * k * d + bounded_index_bytes(k, d)[0] + k for d in fast.values()
            )
        noisy = self._noisy_widths(exemplar_shape)
        if noisy:
            terms["embeddings"] = sum(self._embedding_bytes(k, dims[width])[0] for width in noisy)
        return terms

    def _fit_terms(self, exemplar_shape) -> dict[str, float]:
        """The fit's peak, width after width as :class:`PatchWaveletTransform` builds them.

        Each width's index (and, for a fast width, its float64 descriptors and the build of
        its bounded index) is made while only the widths before it exist, so a build's
        transients meet those widths, not the ones after it. After a fast search's build the
        allocator keeps its float64 temporaries resident where each is under glibc's 32 MiB
        mmap threshold: the coordinates and their squares (``16 K t``) and the centred copy of
        the bank (``8 K D``, when under 32 MiB); the resident peak can come at the end, with
        every width kept. The LLE embeddings are built last (``docs/memory.md``, "Every
        method at its defaults").
        """
        h, w, _ = shape_dims(exemplar_shape)
        k = float(h * w)
        model = self._model_terms(exemplar_shape)
        dims = self._width_dims(exemplar_shape)
        fast = self._fast_widths(exemplar_shape)
        built = model["extended exemplar and block means"]
        during: dict[str, float] = {}
        resident = 0.0
        for width in sorted(dims):
            d = dims[width]
            index = 4.0 * k * d + 4.0 * k
            part = 8.0 * max(2.0**18, w * d) + 24.0 * k  # one part of the index's descriptors
            bank = 8.0 * k * d if width in fast else 0.0
            build = max(part, bounded_index_bytes(k, d)[1]) if width in fast else part
            if built + bank + index + build > sum(during.values()):
                during = {
                    "patch indexes built before the largest build": built,
                    "patch indexes: the largest build's index and float64 descriptors": bank + index,
                    "patch indexes: the largest build's temporaries": build,
                }
            if width in fast:
                built += bank + bounded_index_bytes(k, d)[0] + k
                t = min(64, d)  # BoundedNearestIndex's coordinates: dims + extra
                resident = max(resident, 16.0 * k * t + (bank if bank < 2.0**25 else 0.0))
            built += index
        noisy = self._noisy_widths(exemplar_shape)
        last = max([resident] + [self._embedding_bytes(k, dims[width])[1] for width in noisy])
        if sum(model.values()) + last > sum(during.values()):
            return {**model, "build temporaries kept resident, or an embedding's build": last}
        return during

    def _build_bytes(self, exemplar_shape) -> float:
        """Largest transient of the fit: one part of an index's descriptors, a fast search's
        bounded index, or an LLE embedding (the indexes are built a few rows at a time,
        :meth:`NearestPatchIndex.from_parts <texsyn.ops.search.NearestPatchIndex.from_parts>`)."""
        h, w, _ = shape_dims(exemplar_shape)
        k = float(h * w)
        dims = self._width_dims(exemplar_shape)
        out = max(8.0 * max(2.0**18, w * d) + 24.0 * k for d in dims.values())
        fast = self._fast_widths(exemplar_shape).values()
        out = max([out] + [bounded_index_bytes(k, d)[1] for d in fast])
        return max(
            [out] + [self._embedding_bytes(k, dims[width])[1] for width in self._noisy_widths(exemplar_shape)]
        )

    def _query_bytes(
        self,
        n_queries: float,
        dim: int,
        k: float,
        *,
        glued: bool,
        fast: bool = False,
        incoherent: bool = False,
    ) -> float:
        """Transient of one width's nearest-patch queries (descriptors, products, re-ranking).

        The plain search makes its queries a few blocks of 256 at a time (``2^20`` values)
        and holds one block's float32 products and candidate rows; a fast search checks
        ``2^16`` pairs at a time, makes ``2^20`` descriptor values of queries at a time and
        holds a tile of float32 products per worker, and the index answers the queries it
        cannot prove one block at a time (``models/patch_search.py``). ``incoherent``: the
        coordinate maps have random details (``sigma > 0``), so few glued windows are found
        directly and whole chunks of queries are searched, each holding its candidates
        (:func:`~texsyn.ops.search.bounded_query_bytes`; measured: 16 MiB of the 46 MiB
        transient of a 64x64 grey exemplar to 256x256 with ``sigma=0.5``).
        """
        block = min(n_queries, 256.0)
        part = min(n_queries, block * max(1, 2**20 // int(block * dim)))
        make = (16.0 if glued else 8.0) * part * dim
        products = 4.0 * block * k + 8.0 * block * self.candidates * dim + 12.0 * block * dim
        search = max(make, 8.0 * part * dim + products)
        if fast:
            chunk = min(n_queries, max(1, 2**20 // dim))
            pairs = 112.0 * min(n_queries, 2.0**16)
            bounded = 8.0 * chunk * dim + 120.0 * chunk + 8.0 * 256 * 2048 + 64.0 * 256 * dim
            if incoherent:
                bounded += bounded_query_bytes(chunk, k)
            search = max(search, pairs + max(16.0 * chunk * dim, bounded))
        return search + 8.0 * n_queries

    def _transform_query_bytes(
        self, grid: float, levels: int, exemplar_shape, *, incoherent: bool = False
    ) -> float:
        """Largest query transient of a transform of ``grid`` samples: level ``j`` predicts at
        most ``grid / 2^(2j - 1)`` samples with windows of ``clamp(2^j, min_width, W_max)``."""
        h, w, _ = shape_dims(exemplar_shape)
        dims = self._width_dims(exemplar_shape)
        fast = self._fast_widths(exemplar_shape)
        return max(
            self._query_bytes(
                max(1.0, grid / 2 ** (2 * j - 1)),
                dims[self._level_width(exemplar_shape, j)],
                float(h * w),
                glued=True,
                fast=self._level_width(exemplar_shape, j) in fast,
                incoherent=incoherent,
            )
            for j in range(1, levels + 1)
        )

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Patch indexes of every width, embeddings, their construction, searches and maps.

        The fit holds one float32 index of ``H W`` descriptors per window width (the
        descriptor has ``min(width, max_resolution)^2 C`` entries), built from float64
        descriptors, and the embeddings of the levels with random details; a synthesis of
        ``h x w`` works on the ``N x N`` coordinate map of the next power of two
        ``N >= max(h, w)`` and searches in chunks (``docs/memory.md``).
        """
        _, _, c = shape_dims(exemplar_shape)
        if output_shape is None:
            return self._fit_terms(exemplar_shape)
        terms = self._model_terms(exemplar_shape)
        oh, ow = output_shape[:2]
        n = float(power_of_two_canvas((oh, ow), minimum=4, square=True)[0])
        grid = n * n
        pixels = float(oh) * float(ow)
        levels = int(math.log2(n)) - 1
        noisy = bool(np.any(self.sigma_profile(levels) > 0))
        if noisy:
            terms["random details"] = grid * self.embedding_dim * 8.0 * 2
        # every level's map is kept (16 bytes a sample, 16/3 for the coarser ones together);
        # the finest step holds the half-resolution map and its neighbours (16 bytes a
        # sample) while it searches, then their positions (20 more), and the result the
        # float32 pixels, their clipped copy and the int32 source map (docs/memory.md)
        terms["coordinate maps"] = 22.0 * grid
        terms["searches, or the output image (larger)"] = max(
            self._transform_query_bytes(grid, levels, exemplar_shape, incoherent=noisy),
            20.0 * grid,
            output_bytes(c, output_shape) + 8.0 * pixels,
        )
        return terms

    def estimate_modify_memory(
        self,
        exemplar_shape: tuple[int, ...],
        texture_shape: tuple[int, ...],
        *,
        equalize: bool = True,
        n_ratios: int = 1,
    ) -> int:
        """Estimated peak bytes of :meth:`modify` of a texture of ``texture_shape`` (``docs/memory.md``).

        Parameters
        ----------
        exemplar_shape, texture_shape : tuple
            ``(H, W)`` or ``(H, W, C)``.
        equalize : bool
            Whether the exemplar is equalised first (a second set of indexes is built; also
            true of an exemplar that does not tile with ``exemplar_boundary='auto'``, which a
            modification mirrors while the fitted transform wraps it).
        n_ratios : int
            Number of thresholds (results kept at once).

        Returns
        -------
        int
        """
        self._check_params()
        terms = self._modify_terms(exemplar_shape, texture_shape, equalize, n_ratios)
        return int(math.ceil(self._memory_total(terms)))

    def _modify_terms(self, exemplar_shape, texture_shape, equalize: bool, n_ratios: int) -> dict[str, float]:
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        n_h, n_w = self.modify_grid(texture_shape[:2])
        grid = float(n_h * n_w)
        th, tw = texture_shape[:2]
        model = self._model_terms(exemplar_shape)
        terms = {"fitted patch indexes": sum(model.values())}
        transients = []
        if equalize:
            terms["patch indexes of the equalised exemplar"] = sum(model.values())
            transients.append(self._build_bytes(exemplar_shape))
        dims = self._width_dims(exemplar_shape)
        feature = min(self.feature_width, max(dims))
        transients.append(self._query_bytes(grid, dims[feature], k, glued=False))
        levels = int(math.log2(min(n_h, n_w)))
        used = self._level_widths(exemplar_shape, levels)
        transients.append(self._transform_query_bytes(grid, levels, exemplar_shape))
        kept = [self._embedding_bytes(k, dims[width]) for width in used]
        terms["embeddings"] = sum(e[0] for e in kept)
        transients.append(max(e[1] for e in kept))
        terms["searches and embeddings (largest)"] = max(transients)
        terms["texture, its extension and feature map"] = grid * (40.0 * c + 40.0)
        # details, their norms and the analysed features (two int64 per sample), once for the
        # analysis and once per ratio; the local energy map, its smoothing and its ranking
        terms["wavelet details"] = grid * (self.embedding_dim * 8.0 + 8.0 + 16.0) * (1 + n_ratios)
        terms["local detail energy"] = grid * 25.0
        per_result = grid * 8.0 + float(th) * float(tw) * (8.0 * c + 24.0) + output_bytes(c, texture_shape)
        terms["coordinate maps and results"] = 64.0 * grid + n_ratios * per_result
        return terms
