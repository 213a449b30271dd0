"""Locally Gaussian patch synthesis: LG, CLG and RCLG (Raad, Desolneux & Morel 2016).

Around any patch, the ``m`` exemplar patches most like it are draws of one Gaussian
(section 2.1). The paper's algorithm boxes, and where each runs:

- Algorithm 1 (model validation: every patch of an image replaced by a draw of its local
  Gaussian): :func:`gaussian_resample`, below;
- Algorithm 2 (synthesis in raster order, each new patch drawn from the Gaussian of the
  patches nearest to its overlap): :class:`LG` (drawn, then quilted in, section 2.2),
  :class:`CLG` (conditioned on the overlap, section 3.1) and :class:`RCLG` (the overlap may
  move by noise of std ``theta``, section 3.2). Their ``fit`` builds the model
  (:class:`~texsyn.models.gaussian.PatchSource`: the exemplar's patches and an exact FFT
  search over them); their ``sample`` runs the box,
  :func:`texsyn.methods.single_scale_gaussian.single_scale`, whose steps sit next to it;
- Algorithm 3 (multiscale, section 4): :class:`~texsyn.methods.multiscale_gaussian.MSLG`,
  also importable from here.

See ``docs/methods/local_gaussian.md``.

Why this module is long: the three single-scale methods share one base but each class's
``__init__`` signature is its parameter list (``docs/architecture.md``), with its own
docstring, so the three parameter lists and their documentation live here side by side.

References
----------
L. Raad, A. Desolneux, J.-M. Morel, "A conditional multiscale locally Gaussian texture
synthesis algorithm", J. Math. Imaging Vis. 56 (2016).
"""

from __future__ import annotations

from dataclasses import fields
from typing import Annotated, Any

import numpy as np

from .._validation import OneOf, Range, as_exemplar, normalize_rng
from ..drivers.raster import Block, block_canvas, fill_blocks, raster_positions, torus_fits
from ..errors import InputError
from ..models.gaussian import PatchSource
from ..ops.linalg import fixed_order
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ._base import TextureSynthesizer
from ._memory import fft_search_terms, output_bytes, pixel_count, shape_dims
from ._params import ParamSpec
from .multiscale_gaussian import MSLG, ZOOM_SIGMA  # noqa: F401  (round 1 imported ZOOM_SIGMA from here)
from .single_scale_gaussian import (
    PASTE,
    OverlapSpec,
    clamp_neighbours,
    local_gaussian_bytes,
    match_exemplar_marginals,
    overlap_fraction_warning,
    overlap_pixels,
    single_scale,
    single_scale_rows,
    torus_free,
)

__all__ = ["CLG", "LG", "MSLG", "RCLG", "gaussian_resample", "raster_positions"]


#: default ``looseness`` of CLG and RCLG (``docs/methods/local_gaussian.md``, "Conditioning"):
#: with the final marginals, CLG and RCLG keep sharpness and contrast within 0.8-1.2 on 29 of
#: the 32 shared exemplars (seeds 0 and 1), against 21 and 23 with exact conditioning; larger
#: values sample more but their patch boundaries show, and the marginals then sharpen them
LOOSENESS = 0.1


# ---------------------------------------------------------------------------- Algorithm 2: the methods
class _StreamsWithoutMatching:
    """``streams_rows`` of the LG family: true for a model with ``histogram='none'``.

    Algorithm 2 runs in raster order and streams one row of blocks
    (:func:`~texsyn.methods.single_scale_gaussian.single_scale_rows`), but ``'match'`` is
    a global last step: exact histogram matching ranks every output value among all the
    others (ties by position), so no row is final before the whole output is made
    (``docs/methods/local_gaussian.md``, "Streaming"). Read on the class (as the command
    line does, before the parameters are known) it is ``False``, the default's answer.
    """

    def __get__(self, obj: Any, owner: Any = None) -> bool:
        return obj is not None and obj.histogram == "none"


class _LocalGaussianBase(TextureSynthesizer):
    """Shared parameters, fit and sample of the single-scale models (LG, CLG, RCLG)."""

    has_source_map = False
    #: channels are synthesised jointly: a material stack or an RGBA exemplar (docs/materials.md)
    max_channels = 16
    #: only ``histogram='none'`` streams; the class itself says no (its default is ``'match'``)
    streams_rows = _StreamsWithoutMatching()  # type: ignore[assignment]
    #: the terms count the traced peak within 2 %; the resident set of these runs of a few MiB
    #: holds 1 to 1.6 MiB more (the heap the loop's many small FFT temporaries leave behind),
    #: up to 20 % of a 128 -> 256 colour run (``docs/memory.md``, "Every method at its
    #: defaults")
    memory_margin = 1.15
    _model = "lg"
    # set by each subclass's __init__ (its signature is the parameter list)
    patch_size: int
    n_neighbors: int
    overlap: int | float | None
    mode: str
    seed_patch: str
    seam: str
    histogram: str

    @classmethod
    def param_specs(cls) -> dict[str, ParamSpec]:
        """The parameters; ``overlap`` also parses a deprecated fraction on the command line."""
        specs = super().param_specs()
        spec = specs["overlap"]
        specs["overlap"] = OverlapSpec(**{f.name: getattr(spec, f.name) for f in fields(spec)})
        return specs

    @classmethod
    def deprecated_values(cls, params: dict[str, Any]) -> list[str]:
        """An ``overlap`` given as a fraction of the patch (round 1's meaning)."""
        overlap = params.get("overlap")
        if not isinstance(overlap, (float, np.floating)) or not 0 < overlap < 1:
            return []
        size = params.get("patch_size", cls.param_specs()["patch_size"].default)
        return [overlap_fraction_warning(f"parameter 'overlap' of method {cls.name!r}", float(overlap), size)]

    def _check_params(self) -> None:
        super()._check_params()
        if self.overlap is not None:  # the pixels it stands for fit the patch
            overlap_pixels(
                self.overlap, self.patch_size, f"parameter 'overlap' of method {self.name!r}", warn=False
            )

    def _overlap_px(self) -> int:
        """The overlap in pixels (computed each time: ``overlap`` stays as given)."""
        return overlap_pixels(self.overlap, self.patch_size, "overlap", warn=False)

    def min_exemplar_size(self):
        side = self.patch_size + 1
        return side, f"patch_size={self.patch_size} needs at least {side}x{side} pixels (two patches or more)"

    def _fit(self, exemplar: np.ndarray) -> None:
        ex = as_channels(exemplar)
        self.source_ = PatchSource.build(ex, ex, self.patch_size)

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Exemplar spectra; the canvas, one FFT search and one local Gaussian (``docs/memory.md``)."""
        # three overlap masks: the first row's blocks, the first column's and all the others
        terms, query = fft_search_terms(exemplar_shape, masks=3, fitting=output_shape is None)
        if output_shape is None:
            return terms
        h, w, c = shape_dims(exemplar_shape)
        n = self.patch_size
        canvas = block_canvas(output_shape[:2], n, n - self._overlap_px())
        m = min(self.n_neighbors, max(1, (h - n + 1) * (w - n + 1)))
        # the search's transients are freed before the neighbours are gathered
        search = max(query, local_gaussian_bytes(m, n * n * c))
        blocks = float(canvas[0]) * canvas[1] * (8.0 * c + 1.0)
        if self.histogram == "match":
            # after the loop (its canvas and searches freed): the loop's output, the matched
            # channels before the one being matched, that channel's contiguous copy and
            # hist_target's quantiles (41 bytes a pixel: positions, indices and their
            # gathers), 128 -> 512 grey 14.8 MiB traced, 14.6 counted (docs/memory.md, "Every
            # method at its defaults"); the output's copies come later and take less (20 C
            # bytes a pixel)
            terms["canvas and one search, or the matched marginals (larger)"] = max(
                blocks + search, (16.0 * c + 41.0) * pixel_count(output_shape)
            )
        else:
            terms["one search or one local Gaussian"] = search
            terms["canvas"] = blocks
            terms["output image"] = output_bytes(c, output_shape)
        return terms

    def streaming_memory_terms(self, exemplar_shape, output_shape) -> dict[str, float]:
        """:meth:`memory_terms` without the canvas: a band of one row of blocks instead.

        With ``histogram='none'`` :meth:`sample_rows` keeps the exemplar's spectra and makes
        one search or one local Gaussian at a time, as :meth:`sample` does, but holds
        ``patch_size`` rows of the canvas (float64 and its mask) and the ``n - o`` finished
        rows it yields (a float64 copy, then the clipped float32 output): none grows with the
        output's height (``docs/performance.md``, "Any size in bounded memory"). What a
        writer then holds to encode a band is the writer's. With ``'match'`` the whole output
        is made first: :meth:`memory_terms`.
        """
        whole = self.memory_terms(exemplar_shape, output_shape)
        if not self.streams_rows:
            return whole
        terms = {k: v for k, v in whole.items() if k not in ("canvas", "output image")}
        c = shape_dims(exemplar_shape)[2]
        n = self.patch_size
        step = n - self._overlap_px()
        width = float(block_canvas(output_shape[:2], n, step)[1])
        terms["band of one row of blocks"] = n * width * (8.0 * c + 1.0)
        terms["finished rows"] = step * width * (8.0 + 12.0) * c
        return terms

    def _loop_options(self, rng, callback) -> dict[str, Any]:
        """The arguments of Algorithm 2's loop (:func:`single_scale`, :func:`single_scale_rows`)."""
        return {
            "overlap": self._overlap_px(),
            "m": clamp_neighbours(self.n_neighbors, self.source_, self.name),
            "model": self._model,
            "seam": self.seam,
            "mode": self.mode,
            "sigma": getattr(self, "sigma", 0.0),
            "theta": getattr(self, "theta", 0.0),
            "looseness": getattr(self, "looseness", 0.0),
            "seed_patch": self.seed_patch,
            "rng": rng,
            "reporter": Reporter(callback, "patches"),
        }

    def _sample(self, shape, rng, callback):
        options = self._loop_options(rng, callback)
        out = single_scale(as_channels(self.exemplar_), self.source_, shape, **options)
        if self.histogram == "match":
            out = match_exemplar_marginals(out, self.exemplar_, patch_size=self.patch_size)
        return out, None

    def torus_for(self, shape: tuple[int, int]) -> bool:
        """True where the blocks fit on the output's torus
        (:func:`~texsyn.drivers.raster.torus_fits`: steps of more than half a patch)."""
        n, step = self.patch_size, self.patch_size - self._overlap_px()
        return all(torus_fits(length, n, step, free=torus_free(n)) for length in shape)

    def _sample_torus(self, shape, rng, callback):
        """Algorithm 2 on the output's torus (``docs/tiling.md``, "On a torus"): the patches
        wrap across the edges, each conditioned on (CLG, RCLG) or estimated from (LG) every
        known pixel of its block, the wrapped ones included, and cut through every overlap."""
        options = self._loop_options(rng, callback)
        out = single_scale(as_channels(self.exemplar_), self.source_, shape, torus=True, **options)
        if self.histogram == "match":
            out = match_exemplar_marginals(out, self.exemplar_, patch_size=self.patch_size)
        return out, None

    def _sample_rows(self, shape, rng, callback):
        """Algorithm 2 one row of blocks at a time (``histogram='none'`` only, :attr:`streams_rows`)."""
        options = self._loop_options(rng, callback)
        for rows in single_scale_rows(as_channels(self.exemplar_), self.source_, shape, **options):
            yield rows, None


class LG(_LocalGaussianBase):
    """Locally Gaussian (LG) synthesis: patches sampled from local Gaussian models.

    Raster order; each patch is drawn from ``N(mu, Sigma)`` estimated on the ``m`` exemplar
    patches nearest to the current overlap, then pasted along the Efros-Freeman
    minimum-error boundary cut (Raad et al. 2016, section 2, Algorithm 2;
    :func:`~texsyn.methods.single_scale_gaussian.single_scale`,
    :func:`~texsyn.methods.single_scale_gaussian.lg_patch`).

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : int or None
        Overlap between neighbouring patches, in pixels; ``None`` is half the patch
        (``round(n / 2)``). A float in (0, 1) is read as a fraction of the patch, as in
        round 1, with a DeprecationWarning when the method is made; the parameter keeps the
        value given (``fit`` never changes it).
    mode : str
        ``'sample'`` draws each patch; ``'mean'`` takes the most probable patch (the mean).
    seed_patch : str
        First patch: ``'gaussian'`` (a local-Gaussian sample around a random exemplar
        patch) or ``'copy'`` (the exemplar patch itself, as in the paper's Fig. 4).
    seam : str
        ``'quilt'`` (boundary cut), ``'none'`` (overwrite) or ``'average'`` (eq. 15).
    histogram : str
        ``'match'`` gives the output the exemplar's histogram per channel at the end (values
        inside its range, its contrast; not in the paper, ``docs/methods/local_gaussian.md``,
        "Marginals"); ``'none'`` returns the model's draws as they are.

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
        overlap: Annotated[int | None, Range(1, 255)] = None,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("quilt", "none", "average"))] = "quilt",
        histogram: Annotated[str, OneOf(("match", "none"))] = "match",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam
        self.histogram = histogram


class CLG(_LocalGaussianBase):
    """Conditional locally Gaussian (CLG) synthesis: each patch conditioned on its overlap.

    The local Gaussian, regularised as ``Sigma + sigma^2 I``, is conditioned on the values
    already synthesised in the overlap, so the overlap is kept exactly and no seam is needed
    (eqs. 4-6, :func:`~texsyn.methods.single_scale_gaussian.conditional_patch`). Computed in
    the ``m x m`` Woodbury form (:meth:`texsyn.models.gaussian.LocalGaussian.conditional`).

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : int or None
        Overlap in pixels; ``None`` is half the patch (a float in (0, 1) is a deprecated
        fraction).
    sigma : float
        Regularisation ``sigma`` of the covariance (pixel values in [0, 1]).
    looseness : float
        How loosely each patch follows its overlap: the overlap is read as a noisy
        observation with a variance of ``looseness`` times the mean eigenvalue of the
        neighbours' overlap Gram matrix (:meth:`texsyn.models.gaussian.LocalGaussian.conditional`).
        0 is the paper's exact conditioning, under which the ``m`` neighbours are fully
        determined by the overlap and the synthesis blurs out after the seed patch.
    mode : str
        ``'sample'`` draws each patch; ``'mean'`` takes the conditional mean (eq. 5).
    seed_patch : str
        First patch: ``'gaussian'`` or ``'copy'``.
    seam : str
        ``'none'`` (overwrite, the paper's choice), ``'quilt'`` or ``'average'``.
    histogram : str
        ``'match'`` gives the output the exemplar's histogram per channel at the end (values
        inside its range, its contrast; not in the paper, ``docs/methods/local_gaussian.md``,
        "Marginals"); ``'none'`` returns the model's draws as they are.

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
        overlap: Annotated[int | None, Range(1, 255)] = None,
        sigma: Annotated[float, Range(0.0, 1.0, low_open=True)] = 1 / 255,
        looseness: Annotated[float, Range(0.0, 1000.0)] = LOOSENESS,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("none", "quilt", "average"))] = "none",
        histogram: Annotated[str, OneOf(("match", "none"))] = "match",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.sigma = sigma
        self.looseness = looseness
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam
        self.histogram = histogram


class RCLG(_LocalGaussianBase):
    """Regularised conditional locally Gaussian (RCLG) synthesis.

    Like CLG, but the overlap may move: its values are first drawn around the synthesised
    ones with std ``theta``, then the rest of the patch is conditioned on them (eqs. 7-8,
    ancestral sampling, :func:`~texsyn.methods.single_scale_gaussian.conditional_patch`);
    the patch overwrites the overlap.

    Parameters
    ----------
    patch_size : int
        Patch side ``n`` in pixels.
    n_neighbors : int
        Number ``m`` of nearest exemplar patches that estimate each Gaussian.
    overlap : int or None
        Overlap in pixels; ``None`` is half the patch (a float in (0, 1) is a deprecated
        fraction).
    sigma : float
        Regularisation ``sigma`` of the covariance.
    looseness : float
        How loosely each patch follows its (moved) overlap, as in :class:`CLG`.
    theta : float
        Standard deviation allowed to the overlap values.
    mode : str
        ``'sample'`` or ``'mean'`` (the mean is CLG's, eq. 5).
    seed_patch : str
        First patch: ``'gaussian'`` or ``'copy'``.
    seam : str
        ``'none'`` (overwrite, the paper's choice), ``'quilt'`` or ``'average'``.
    histogram : str
        ``'match'`` gives the output the exemplar's histogram per channel at the end (values
        inside its range, its contrast; not in the paper, ``docs/methods/local_gaussian.md``,
        "Marginals"); ``'none'`` returns the model's draws as they are.

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
        overlap: Annotated[int | None, Range(1, 255)] = None,
        sigma: Annotated[float, Range(0.0, 1.0, low_open=True)] = 1 / 255,
        theta: Annotated[float, Range(0.0, 1.0)] = 0.5 / 255,
        looseness: Annotated[float, Range(0.0, 1000.0)] = LOOSENESS,
        mode: Annotated[str, OneOf(("sample", "mean"))] = "sample",
        seed_patch: Annotated[str, OneOf(("gaussian", "copy"))] = "gaussian",
        seam: Annotated[str, OneOf(("none", "quilt", "average"))] = "none",
        histogram: Annotated[str, OneOf(("match", "none"))] = "match",
    ):
        self.patch_size = patch_size
        self.n_neighbors = n_neighbors
        self.overlap = overlap
        self.sigma = sigma
        self.theta = theta
        self.looseness = looseness
        self.mode = mode
        self.seed_patch = seed_patch
        self.seam = seam
        self.histogram = histogram


# ---------------------------------------------------------------------------- Algorithm 1
@fixed_order
def gaussian_resample(
    image: np.ndarray,
    patch_size: int = 20,
    n_neighbors: int = 20,
    overlap: int | float | None = None,
    rng: None | int | np.random.Generator = None,
) -> np.ndarray:
    """Replace every patch of an image by a sample of its local Gaussian (Algorithm 1).

    The model-validation experiment of Raad et al. (2016, section 2.1, Fig. 1): in raster
    order (step ``n - overlap``, last row and column included), the patch at each corner
    is overwritten by a draw from the Gaussian of its ``m`` nearest patches of the image
    (itself included). A plausible variant of the image in which every pixel changed
    supports the locally Gaussian patch model.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
    patch_size, n_neighbors : int
    overlap : int or None
        In pixels; ``None`` is half the patch. A float in (0, 1) is a fraction of the patch
        (round 1's meaning), with a DeprecationWarning.
    rng : None, int or numpy.random.Generator

    Returns
    -------
    ndarray of float32 clipped to [0, 1], shape of ``image``.
    """
    img = as_exemplar(image, name="image")
    if not 2 <= patch_size <= min(img.shape[:2]):
        raise InputError(f"patch_size must be in [2, {min(img.shape[:2])}], got {patch_size}")
    step = patch_size - overlap_pixels(overlap, patch_size, "overlap")
    if n_neighbors < 2:
        raise InputError(f"n_neighbors must be at least 2, got {n_neighbors}")
    gen = normalize_rng(rng)
    u = as_channels(img)
    source = PatchSource.build(u, u, patch_size)
    m = min(n_neighbors, source.n_anchors)
    energies: dict = {}  # this call's cache of the search's energy terms

    def choose(block: Block) -> np.ndarray:  # lines 3-5
        own = u[block.row : block.row + patch_size, block.col : block.col + patch_size]
        return source.neighbour_gaussian(own, None, m, energies=energies).sample(gen).reshape(own.shape)

    out = u.copy()
    rows, cols = (
        raster_positions(u.shape[0], patch_size, step),
        raster_positions(u.shape[1], patch_size, step),
    )
    fill_blocks(out, rows, cols, patch_size, choose, PASTE["none"])
    result = np.clip(out, 0, 1).astype(np.float32)
    return result[..., 0] if img.ndim == 2 else result
