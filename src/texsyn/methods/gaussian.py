"""Locally Gaussian patch models: LG, CLG, RCLG and multiscale MSLG (Raad et al. 2016).

Patches are synthesised in raster order; each new patch is drawn from a Gaussian whose mean
and covariance come from the ``m`` exemplar patches nearest to what is already synthesised
in its overlap (exact FFT search over every exemplar position, one per patch).

* ``lg``: unconditional local Gaussian, pasted along the Efros-Freeman boundary cut.
* ``clg``: the Gaussian conditioned on the overlap values (regularised by ``sigma^2 I``).
* ``rclg``: the overlap itself may move by Gaussian noise of std ``theta`` first.
* ``mslg``: coarse-to-fine; LG with overlap averaging at the coarsest scale, then at each
  finer scale the zoomed-in coarse result keeps the low frequencies and only the high
  frequencies are sampled, from neighbours chosen by the joint distance of eq. (14).

References
----------
L. Raad, A. Desolneux, J.-M. Morel, "A conditional multiscale locally Gaussian texture
synthesis algorithm", J. Math. Imaging Vis. 56 (2016). Implementation notes and the
resolutions of the paper's ambiguities: spec 05 (R1-R19).
"""

from __future__ import annotations

import warnings
from typing import Annotated, Callable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .._validation import OneOf, Range, as_exemplar, normalize_rng
from ..ops import (
    FFTPatchSearch,
    as_channels,
    boundary_cut_mask,
    crop_to_multiple,
    gaussian_blur,
    knn_select,
    overlap_error,
    zoom_in,
    zoom_out,
)
from ..ops.gaussian import local_gaussian
from ..ops.portilla import max_scales
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, fft_search_bytes, output_bytes
from ..errors import InputError
from ..ops.linalg import fixed_order

__all__ = ["LG", "CLG", "RCLG", "MSLG", "gaussian_resample", "raster_positions"]

#: Gaussian blur of the zoom-out and of the low/high split (paper, eq. 9 and Table 1)
ZOOM_SIGMA = 1.4


def raster_positions(size: int, n: int, step: int) -> np.ndarray:
    """Anchors ``0, step, 2 step, ...`` up to ``size - n``, plus ``size - n`` (spec 05, R4)."""
    pos = list(range(0, size - n + 1, step))
    if pos[-1] != size - n:
        pos.append(size - n)
    return np.asarray(pos)


class _PatchSource:
    """One exemplar scale: its windows (views, no copy) and an exact FFT search.

    ``search_image`` is what the search compares (the scale itself, or it stacked with its
    low-pass for eq. 14); ``values`` is where the neighbour patches are read from.
    """

    def __init__(self, search_image: np.ndarray, values: np.ndarray, n: int):
        self.n = n
        self.search = FFTPatchSearch(search_image, (n, n))
        self.windows = sliding_window_view(values, (n, n), axis=(0, 1))
        self.anchor_shape = self.search.anchor_shape
        self.n_anchors = self.anchor_shape[0] * self.anchor_shape[1]

    def gather(self, flat_anchors: np.ndarray) -> np.ndarray:
        """Patches at flat anchor indices as rows ``(m, n*n*C)`` (C-order of ``(n, n, C)``)."""
        rows, cols = np.unravel_index(flat_anchors, self.anchor_shape)
        patches = self.windows[rows, cols]  # (m, C, n, n)
        return np.ascontiguousarray(patches.transpose(0, 2, 3, 1)).reshape(len(rows), -1)

    def nearest(self, query: np.ndarray, weights: np.ndarray | None, m: int) -> np.ndarray:
        """Flat anchors of the ``m`` exemplar windows nearest to ``query`` (tie-safe)."""
        return knn_select(self.search.distances(query, weights), m)


def _local_gaussian_bytes(m: int, dim: int) -> float:
    """Gathered neighbour patches, the centred factor and a conditional draw of ``dim`` entries."""
    return 24.0 * m * dim + 8.0 * m * m + 32.0 * dim


def _clamp_neighbours(m: int, source: _PatchSource, name: str) -> int:
    if m > source.n_anchors:
        warnings.warn(
            f"n_neighbors={m} is more than the {source.n_anchors} exemplar patches of method "
            f"{name!r}; using {source.n_anchors}",
            UserWarning,
            stacklevel=4,
        )
        return source.n_anchors
    return m


def _seed_patch(source: _PatchSource, exemplar: np.ndarray, m: int, how: str, mode: str, rng) -> np.ndarray:
    """First patch (spec 05, 4.8): ``t0`` is the first draw of ``rng``."""
    n = source.n
    t0 = int(rng.integers(source.n_anchors))
    i, j = np.unravel_index(t0, source.anchor_shape)
    patch = exemplar[i : i + n, j : j + n]
    if how == "copy":
        return patch.copy()
    nearest = source.nearest(patch, None, m)
    gauss = local_gaussian(source.gather(nearest))
    vec = gauss.mean if mode == "mean" else gauss.sample(rng)
    return vec.reshape(patch.shape)


def _leading_known(known: np.ndarray) -> tuple[int, int]:
    """Widths of the fully known leading columns and rows of a window's known mask."""
    cols = known.all(axis=0)
    rows = known.all(axis=1)
    left = int(np.argmin(cols)) if not cols.all() else known.shape[1]
    top = int(np.argmin(rows)) if not rows.all() else known.shape[0]
    return left, top


def _single_scale(
    exemplar: np.ndarray,
    source: _PatchSource,
    shape: tuple[int, int],
    *,
    n: int,
    overlap_px: int,
    m: int,
    model: str,
    seam: str,
    mode: str,
    sigma: float,
    theta: float,
    seed_patch: str,
    rng: np.random.Generator,
    report: Callable[[int, int], None] | None,
) -> np.ndarray:
    """Algorithm 2 of Raad et al. (LG, CLG or RCLG) on an enlarged canvas, cropped to ``shape``."""
    h, w = shape
    channels = exemplar.shape[2]
    step = n - overlap_px
    canvas_h = n + step * max(0, -(-(h - n) // step))
    canvas_w = n + step * max(0, -(-(w - n) // step))
    out = np.zeros((canvas_h, canvas_w, channels))
    known = np.zeros((canvas_h, canvas_w), dtype=bool)
    out[:n, :n] = _seed_patch(source, exemplar, m, seed_patch, mode, rng)
    known[:n, :n] = True
    rows = np.arange(0, canvas_h - n + 1, step)
    cols = np.arange(0, canvas_w - n + 1, step)
    total, done = rows.size * cols.size, 1
    for x in rows:
        for y in cols:
            if x == 0 and y == 0:
                continue
            old = out[x : x + n, y : y + n]
            mask = known[x : x + n, y : y + n]
            nearest = source.nearest(old, mask.astype(np.float64), m)
            gauss = local_gaussian(source.gather(nearest))
            if model == "lg":
                vec = gauss.mean if mode == "mean" else gauss.sample(rng)
                new = vec.reshape(old.shape)
            else:
                entries = np.broadcast_to(mask[..., None], old.shape).ravel()
                given = old.ravel()[entries]
                if model == "rclg" and mode == "sample":
                    given = given + theta * rng.standard_normal(given.size)
                flat = np.empty(old.size)
                flat[entries] = given
                flat[~entries] = gauss.conditional(entries, given, sigma, None if mode == "mean" else rng)
                new = flat.reshape(old.shape)
            if seam == "quilt":
                left, top = _leading_known(mask)
                take = boundary_cut_mask(overlap_error(old, new), left, top) | ~mask
                out[x : x + n, y : y + n] = np.where(take[..., None], new, old)
            elif seam == "average":
                out[x : x + n, y : y + n] = np.where(mask[..., None], 0.5 * (old + new), new)
            else:
                out[x : x + n, y : y + n] = new
            known[x : x + n, y : y + n] = True
            done += 1
            if report is not None:
                report(done, total)
    return out[:h, :w]


class _LocalGaussianBase(TextureSynthesizer):
    """Shared fit/sample of the single-scale models (LG, CLG, RCLG)."""

    has_source_map = False
    _model = "lg"

    def _overlap_px(self) -> int:
        return int(np.clip(round(self.overlap * self.patch_size), 1, self.patch_size - 1))

    def min_exemplar_size(self):
        side = self.patch_size + 1
        return side, f"patch_size={self.patch_size} needs at least {side}x{side} pixels (two patches or more)"

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        self.source_ = _PatchSource(ex, ex, self.patch_size)

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Exemplar spectra; the canvas, one FFT search and one local Gaussian (``docs/memory.md``)."""
        h, w, c = shape_dims(exemplar_shape)
        kept, build, query = fft_search_bytes(h, w, c, masks=9)
        terms = {"exemplar and its spectra": 8.0 * h * w * c + kept}
        if output_shape is None:
            terms["spectra construction"] = build
            return terms
        n = self.patch_size
        step = n - self._overlap_px()
        canvas = [n + step * max(0, -(-(side - n) // step)) for side in output_shape[:2]]
        m = min(self.n_neighbors, max(1, (h - n + 1) * (w - n + 1)))
        # the search's transients are freed before the neighbours are gathered
        terms["one search or one local Gaussian"] = max(query, _local_gaussian_bytes(m, n * n * c))
        terms["canvas"] = float(canvas[0]) * canvas[1] * (8.0 * c + 1.0)
        terms["output image"] = output_bytes(c, output_shape)
        return terms

    def _sample(self, shape, rng, callback):
        ex = as_channels(self.exemplar_)
        m = _clamp_neighbours(self.n_neighbors, self.source_, self.name)
        report = None
        if callback is not None:

            def report(done, total):
                callback(Progress("patches", done, total))

        out = _single_scale(
            ex,
            self.source_,
            shape,
            n=self.patch_size,
            overlap_px=self._overlap_px(),
            m=m,
            model=self._model,
            seam=self.seam,
            mode=self.mode,
            sigma=getattr(self, "sigma", 0.0),
            theta=getattr(self, "theta", 0.0),
            seed_patch=self.seed_patch,
            rng=rng,
            report=report,
        )
        return out, None


class LG(_LocalGaussianBase):
    """Locally Gaussian (LG) synthesis: patches sampled from local Gaussian models.

    Raster order; each patch is drawn from ``N(mu, Sigma)`` estimated on the ``m`` exemplar
    patches nearest to the current overlap, then pasted along the Efros-Freeman
    minimum-error boundary cut (Raad et al. 2016, section 2, Algorithm 2).

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : float
        Overlap as a fraction of the patch side (``o``; ``round(o n)`` pixels, at least 1).
    mode : str
        ``'sample'`` draws each patch; ``'mean'`` takes the most probable patch (the mean).
    seed_patch : str
        First patch: ``'gaussian'`` (a local-Gaussian sample around a random exemplar
        patch) or ``'copy'`` (the exemplar patch itself, as in the paper's Fig. 4).
    seam : str
        ``'quilt'`` (boundary cut), ``'none'`` (overwrite) or ``'average'`` (eq. 15).

    References
    ----------
    Raad, Desolneux, Morel, JMIV 2016, sections 2.1-2.2.

    Notes
    -----
    Limitations (paper): slightly blurrier than quilting; structures larger than the patch
    are lost (use ``mslg``).
    """

    name = "lg"
    summary = "Locally Gaussian patch sampling with boundary-cut quilting"
    reference = "Raad, Desolneux, Morel, JMIV 2016 (LG)"
    _model = "lg"

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 256)] = 40,
        n_neighbors: Annotated[int, Range(2, 10000)] = 30,
        overlap: Annotated[float, Range(0.0, 1.0, low_open=True, high_open=True)] = 0.5,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("quilt", "none", "average"))] = "quilt",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam


class CLG(_LocalGaussianBase):
    """Conditional locally Gaussian (CLG) synthesis: each patch conditioned on its overlap.

    The local Gaussian, regularised as ``Sigma + sigma^2 I``, is conditioned on the values
    already synthesised in the overlap, so the overlap is kept exactly and no seam is needed
    (eqs. 4-6). Computed in the ``m x m`` Woodbury form (spec 05, 4.4).

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : float
        Overlap as a fraction of the patch side.
    sigma : float
        Regularisation ``sigma`` of the covariance (pixel values in [0, 1]).
    mode : str
        ``'sample'`` draws each patch; ``'mean'`` takes the conditional mean (eq. 5).
    seed_patch : str
        First patch: ``'gaussian'`` or ``'copy'``.
    seam : str
        ``'none'`` (overwrite, the paper's choice), ``'quilt'`` or ``'average'``.

    References
    ----------
    Raad, Desolneux, Morel, JMIV 2016, section 3.1.

    Notes
    -----
    Limitations (paper, Fig. 6): blur grows along the raster order as constraints
    accumulate.
    """

    name = "clg"
    summary = "Conditional locally Gaussian patch sampling (overlap kept exactly)"
    reference = "Raad, Desolneux, Morel, JMIV 2016 (CLG)"
    _model = "clg"

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 256)] = 40,
        n_neighbors: Annotated[int, Range(2, 10000)] = 30,
        overlap: Annotated[float, Range(0.0, 1.0, low_open=True, high_open=True)] = 0.5,
        sigma: Annotated[float, Range(0.0, 1.0, low_open=True)] = 1 / 255,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("none", "quilt", "average"))] = "none",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.sigma = sigma
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam


class RCLG(_LocalGaussianBase):
    """Regularised conditional locally Gaussian (RCLG) synthesis.

    Like CLG, but the overlap may move: its values are first drawn around the synthesised
    ones with std ``theta``, then the rest of the patch is conditioned on them (eqs. 7-8,
    ancestral sampling, spec 05 R7); the patch overwrites the overlap.

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : float
        Overlap as a fraction of the patch side.
    sigma : float
        Regularisation ``sigma`` of the covariance.
    theta : float
        Standard deviation allowed to the overlap values.
    mode : str
        ``'sample'`` or ``'mean'`` (the mean is CLG's, eq. 5).
    seed_patch : str
        First patch: ``'gaussian'`` or ``'copy'``.
    seam : str
        ``'none'`` (overwrite, the paper's choice), ``'quilt'`` or ``'average'``.

    References
    ----------
    Raad, Desolneux, Morel, JMIV 2016, section 3.2.
    """

    name = "rclg"
    summary = "Regularised conditional locally Gaussian patch sampling"
    reference = "Raad, Desolneux, Morel, JMIV 2016 (RCLG)"
    _model = "rclg"

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 256)] = 40,
        n_neighbors: Annotated[int, Range(2, 10000)] = 30,
        overlap: Annotated[float, Range(0.0, 1.0, low_open=True, high_open=True)] = 0.5,
        sigma: Annotated[float, Range(0.0, 1.0, low_open=True)] = 1 / 255,
        theta: Annotated[float, Range(0.0, 1.0)] = 5 / 255,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("none", "quilt", "average"))] = "none",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.sigma = sigma
        self.theta = theta
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam


class MSLG(TextureSynthesizer):
    """Multiscale locally Gaussian (MSLG) synthesis (Raad et al. 2016, Algorithm 3).

    The exemplar is zoomed out ``n_scales - 1`` times (Gaussian blur 1.4, sub-sampling by
    2). The coarsest scale is synthesised by LG with half-patch overlaps averaged (eq. 15);
    each finer scale zooms the previous result in (Fourier zero-padding, eq. 12) and keeps
    it as the low frequencies of every patch, sampling only the high frequencies from the
    local Gaussian of the ``m`` exemplar patches nearest for the joint distance of eq. (14)
    (overlap term plus low-resolution term). Small patches then reproduce the global
    arrangement of macro-textures.

    Parameters
    ----------
    patch_size : int
        Even patch side ``n`` (the step is ``n / 2``).
    n_neighbors : int
        Number ``m`` of nearest exemplar patches per Gaussian.
    n_scales : int
        Number of scales ``K`` (1 is LG with overlap averaging).
    mode : str
        ``'sample'`` or ``'mean'``.
    seed_patch : str
        First patch at the coarsest scale: ``'gaussian'`` or ``'copy'``.
    zoom_boundary : str
        Boundary handling of the Fourier zoom-in: ``'symmetric'`` (mirror extension, no
        border ringing) or ``'periodic'`` (the paper's literal formula).
    post : str
        ``'portilla_simoncelli'`` uses the MSLG result as the initial image of a short
        Portilla-Simoncelli synthesis (Raad et al. 2016, section 5, Fig. 8); ``'none'`` skips it.
    post_iterations : int
        Portilla-Simoncelli iterations of the post-processing.

    References
    ----------
    Raad, Desolneux, Morel, JMIV 2016, section 4, Algorithm 3, eqs. (9)-(15).
    """

    name = "mslg"
    summary = "Multiscale locally Gaussian patch sampling"
    reference = "Raad, Desolneux, Morel, JMIV 2016 (MSLG)"
    has_source_map = False

    def __init__(
        self,
        *,
        patch_size: Annotated[int, Range(2, 256)] = 20,
        n_neighbors: Annotated[int, Range(2, 10000)] = 20,
        n_scales: Annotated[int, Range(1, 6)] = 2,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        zoom_boundary: Annotated[str, OneOf(("symmetric", "periodic"))] = "symmetric",
        post: Annotated[str, OneOf(("none", "portilla_simoncelli"))] = "none",
        post_iterations: Annotated[int, Range(1, 500)] = 10,
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.n_scales = n_scales
        self.mode = mode
        self.seed_patch = seed_patch
        self.zoom_boundary = zoom_boundary
        self.post = post
        self.post_iterations = post_iterations

    def _check_params(self) -> None:
        super()._check_params()
        if self.patch_size % 2:
            raise InputError(
                f"parameter 'patch_size' of method 'mslg' must be even (the step is n/2), got {self.patch_size}"
            )

    def min_exemplar_size(self):
        side = 2 ** (self.n_scales - 1) * (self.patch_size + 1)
        return side, (
            f"with n_scales={self.n_scales} the coarsest scale is 1/{2 ** (self.n_scales - 1)} of the "
            f"exemplar and patch_size={self.patch_size} needs at least {self.patch_size + 1} pixels there"
        )

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """FFT searches of every scale; the Fourier zoom-in of the finest scale (``docs/memory.md``).

        The zoom-in transforms the mirror extension of each scale, a complex image four times
        the size of the next one, so it dominates the sampling of large outputs.
        """
        h, w, c = shape_dims(exemplar_shape)
        big = 2 ** (self.n_scales - 1)
        hc, wc = (h // big) * big, (w // big) * big
        kept_total, build_max = 8.0 * h * w * c, 0.0
        for k in range(self.n_scales):
            sh, sw = hc >> k, wc >> k
            coarse = k == self.n_scales - 1
            kept, build, _ = fft_search_bytes(sh, sw, c if coarse else 2 * c)
            kept_total += kept + 8.0 * sh * sw * c * (1 if coarse else 2)
            build_max = max(build_max, build + 24.0 * sh * sw * c)
        terms = {"exemplar scales and their spectra": kept_total}
        post = None
        if self.post == "portilla_simoncelli":
            from .portilla_simoncelli import PortillaSimoncelli

            post = PortillaSimoncelli(n_scales=max_scales((h, w)), n_iterations=self.post_iterations)
            terms["Portilla-Simoncelli statistics"] = sum(post.memory_terms(exemplar_shape).values())
        if output_shape is None:
            terms["spectra construction"] = build_max
            return terms
        n = self.patch_size
        canvas = float(big * max(-(-output_shape[0] // big), n)) * float(big * max(-(-output_shape[1] // big), n))
        m = min(self.n_neighbors, max(1, ((hc >> (self.n_scales - 1)) - n + 1) * ((wc >> (self.n_scales - 1)) - n + 1)))
        _, _, query = fft_search_bytes(hc, wc, 2 * c if self.n_scales > 1 else c, masks=9)
        search = max(query, _local_gaussian_bytes(m, n * n * c))
        zoom = (280.0 if self.zoom_boundary == "symmetric" else 48.0) * c * canvas
        if self.n_scales > 1:
            terms["Fourier zoom-in of the finest scale"] = zoom + 8.0 * c * canvas / 4
        terms["one search or one local Gaussian"] = search
        terms["canvas, low-pass and mask"] = canvas * (16.0 * c + 1.0)
        terms["output image"] = output_bytes(c, output_shape)
        if post is not None:
            terms["Portilla-Simoncelli refinement"] = sum(post.memory_terms(exemplar_shape, output_shape).values())
        return terms

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = crop_to_multiple(as_channels(exemplar), 2 ** (self.n_scales - 1))
        scales = [ex]
        for _ in range(self.n_scales - 1):
            scales.append(zoom_out(scales[-1], ZOOM_SIGMA))
        self.scales_ = scales
        n = self.patch_size
        self.coarse_source_ = _PatchSource(scales[-1], scales[-1], n)
        self.fine_sources_ = []
        for k in range(self.n_scales - 1):
            low = gaussian_blur(scales[k], ZOOM_SIGMA)
            high = scales[k] - low
            stacked = np.concatenate([scales[k], low], axis=2)
            self.fine_sources_.append(_PatchSource(stacked, high, n))
        self.post_ = None
        if self.post == "portilla_simoncelli":
            from .portilla_simoncelli import PortillaSimoncelli

            scales = max_scales(exemplar.shape[:2])
            self.post_ = PortillaSimoncelli(n_scales=scales, n_iterations=self.post_iterations).fit(exemplar)

    def _sample(self, shape, rng, callback):
        n, big = self.patch_size, 2 ** (self.n_scales - 1)
        canvas_h = big * max(-(-shape[0] // big), n)
        canvas_w = big * max(-(-shape[1] // big), n)
        sources = [self.coarse_source_] + self.fine_sources_
        m = min(_clamp_neighbours(self.n_neighbors, s, self.name) for s in sources)
        n_steps = self.n_scales

        def reporter(scale_index):
            if callback is None:
                return None

            def report(done, total):
                callback(Progress(f"scale {scale_index + 1}/{n_steps}", done, total))

            return report

        out = _single_scale(
            self.scales_[-1],
            self.coarse_source_,
            (canvas_h // big, canvas_w // big),
            n=n,
            overlap_px=n // 2,
            m=m,
            model="lg",
            seam="average",
            mode=self.mode,
            sigma=0.0,
            theta=0.0,
            seed_patch=self.seed_patch,
            rng=rng,
            report=reporter(0),
        )
        for k in range(self.n_scales - 2, -1, -1):
            low = zoom_in(out, boundary=self.zoom_boundary)
            out = self._fine_scale(low, self.fine_sources_[k], m, rng, reporter(self.n_scales - 1 - k))
        out = out[: shape[0], : shape[1]]
        if self.post_ is not None:
            report = None
            if callback is not None:
                def report(p):
                    callback(Progress("portilla_simoncelli", p.done, p.total, image=p.image))
            out = self.post_.refine(np.clip(out, 0.0, 1.0), callback=report)
        return out, None

    def _fine_scale(self, low, source: _PatchSource, m, rng, report) -> np.ndarray:
        """Alg. 3 lines 5-17: high frequencies sampled on top of the zoomed-in result."""
        n = self.patch_size
        channels = low.shape[2]
        out = np.zeros_like(low)
        known = np.zeros(low.shape[:2], dtype=bool)
        rows = raster_positions(low.shape[0], n, n // 2)
        cols = raster_positions(low.shape[1], n, n // 2)
        low_weight = np.full((n, n, channels), 1.0 / (channels * n * n))
        total, done = rows.size * cols.size, 0
        for x in rows:
            for y in cols:
                mask = known[x : x + n, y : y + n]
                k = int(mask.sum()) * channels
                over = np.broadcast_to(mask[..., None] / max(k, 1), (n, n, channels))
                weights = np.concatenate([over, low_weight], axis=2)
                query = np.concatenate([out[x : x + n, y : y + n], low[x : x + n, y : y + n]], axis=2)
                nearest = source.nearest(query, weights, m)
                gauss = local_gaussian(source.gather(nearest))
                vec = gauss.mean if self.mode == "mean" else gauss.sample(rng)
                out[x : x + n, y : y + n] = low[x : x + n, y : y + n] + vec.reshape(n, n, channels)
                known[x : x + n, y : y + n] = True
                done += 1
                if report is not None:
                    report(done, total)
        return out


@fixed_order
def gaussian_resample(
    image: np.ndarray,
    patch_size: int = 20,
    n_neighbors: int = 20,
    overlap: float = 0.5,
    rng: None | int | np.random.Generator = None,
) -> np.ndarray:
    """Replace every patch of an image by a sample of its local Gaussian (Algorithm 1).

    The model-validation experiment of Raad et al. (2016, section 2.1, Fig. 1): in raster
    order (step ``n - round(o n)``, last row and column included), the patch at each anchor
    is overwritten by a draw from the Gaussian of its ``m`` nearest patches of the image
    (itself included). A plausible variant of the image in which every pixel changed
    supports the locally Gaussian patch model.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
    patch_size, n_neighbors : int
    overlap : float in (0, 1)
    rng : None, int or numpy.random.Generator

    Returns
    -------
    ndarray of float32 clipped to [0, 1], shape of ``image``.
    """
    img = as_exemplar(image, name="image")
    if not 2 <= patch_size <= min(img.shape[:2]):
        raise InputError(f"patch_size must be in [2, {min(img.shape[:2])}], got {patch_size}")
    if not 0 < overlap < 1:
        raise InputError(f"overlap must be in (0, 1), got {overlap}")
    if n_neighbors < 2:
        raise InputError(f"n_neighbors must be at least 2, got {n_neighbors}")
    gen = normalize_rng(rng)
    u = as_channels(img)
    source = _PatchSource(u, u, patch_size)
    m = min(n_neighbors, source.n_anchors)
    step = patch_size - int(np.clip(round(overlap * patch_size), 1, patch_size - 1))
    out = u.copy()
    for x in raster_positions(u.shape[0], patch_size, step):
        for y in raster_positions(u.shape[1], patch_size, step):
            own = u[x : x + patch_size, y : y + patch_size]
            gauss = local_gaussian(source.gather(source.nearest(own, None, m)))
            out[x : x + patch_size, y : y + patch_size] = gauss.sample(gen).reshape(own.shape)
    result = np.clip(out, 0, 1).astype(np.float32)
    return result[..., 0] if img.ndim == 2 else result
