"""Algorithm 2 of Raad, Desolneux & Morel (2016): single-scale locally Gaussian synthesis.

The loop that LG, CLG and RCLG run (:mod:`texsyn.methods.gaussian`) and that MSLG runs at
its coarsest scale (:mod:`texsyn.methods.multiscale_gaussian`, Algorithm 3 line 3), with
the steps that differ between them. The paper's box, line by line:

- line 1, a seed patch in the top-left corner: :func:`first_patch` (an exemplar patch,
  copied or resampled);
- lines 2-3, raster order in steps of ``n - o``: :func:`single_scale`, through
  :func:`texsyn.drivers.raster.fill_blocks` (or :func:`single_scale_rows`, one row of
  blocks at a time, through :func:`texsyn.drivers.raster.fill_block_rows`);
- lines 5-6, the ``m`` nearest exemplar patches and their Gaussian ``(mu, Sigma)``:
  :meth:`texsyn.models.gaussian.PatchSource.neighbour_gaussian` (section 2.1, eq. 1);
- line 7, the new patch: :func:`lg_patch` (LG, section 2.2) or :func:`conditional_patch`
  (CLG, section 3.1, eqs. 4-6; RCLG, section 3.2, eqs. 7-8);
- line 8, quilt it in: :data:`PASTE` (boundary cut, average of eq. 15, or overwrite).

The overlap ``o`` is in pixels (:func:`overlap_pixels`). Every ``sample`` call makes its own
cache of the search's energy terms (``energies``), so the fitted
:class:`~texsyn.models.gaussian.PatchSource` is never changed (``docs/architecture.md``,
"Fitted state"). See ``docs/methods/local_gaussian.md``.

Why this module is long: the paper's box is here line by line, next to its loop, which runs
two ways (on the whole canvas for ``sample`` and MSLG, one row of blocks at a time for
``sample_rows``); splitting them would separate the algorithm from its steps.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from scipy.ndimage import distance_transform_edt

from ..drivers.raster import (
    Block,
    block_canvas,
    block_positions,
    fill_block_rows,
    fill_blocks,
    torus_positions,
)
from ..errors import InputError
from ..models.gaussian import LocalGaussian, PatchSource
from ..ops.canvas import crop_to_output
from ..ops.histogram import match_histogram
from ..ops.patches import as_channels
from ..ops.progress import Reporter
from ..ops.seams import paste_average, paste_cut
from ._deprecation import warn_deprecated
from ._params import ParamSpec

__all__ = [
    "PASTE",
    "OverlapSpec",
    "clamp_neighbours",
    "conditional_patch",
    "draw",
    "first_patch",
    "lg_patch",
    "local_gaussian_bytes",
    "overlap_fraction_warning",
    "overlap_pixels",
    "single_scale",
    "single_scale_rows",
    "torus_free",
]


# ---------------------------------------------------------------------------- the inputs
def overlap_pixels(overlap: int | float | None, patch_size: int, where: str, *, warn: bool = True) -> int:
    """The overlap ``o`` in pixels: ``None`` is half the patch; a float in (0, 1) is a fraction.

    A fraction is the meaning of round 1, kept with a :class:`DeprecationWarning` (when
    ``warn``; the methods warn once, at construction, :func:`overlap_fraction_warning`); it
    becomes ``round(overlap * patch_size)`` pixels clipped to ``[1, patch_size - 1]``, as
    before, and so does the default (``docs/architecture.md``, "Vocabulary": overlaps are in
    pixels).

    Raises
    ------
    InputError
        A float that is not a fraction in (0, 1), or pixels outside ``[1, patch_size - 1]``.

    Examples
    --------
    >>> overlap_pixels(None, 10, "overlap"), overlap_pixels(3, 10, "overlap")
    (5, 3)
    >>> overlap_pixels(0.25, 10, "overlap", warn=False)
    2
    """
    n = int(patch_size)
    if overlap is None:
        return int(np.clip(round(0.5 * n), 1, n - 1))
    if isinstance(overlap, (float, np.floating)):
        if not 0 < overlap < 1:
            raise InputError(
                f"{where} is a number of pixels (an integer), or a deprecated fraction in (0, 1); "
                f"got {overlap!r}"
            )
        if warn:
            warn_deprecated(overlap_fraction_warning(where, float(overlap), n))
        return int(np.clip(round(overlap * n), 1, n - 1))
    if not 1 <= int(overlap) < n:
        raise InputError(f"{where} must be between 1 and patch_size - 1 = {n - 1} pixels, got {overlap!r}")
    return int(overlap)


def overlap_fraction_warning(where: str, overlap: float, patch_size: object) -> str:
    """The deprecation message of an overlap given as a fraction; pixels when the size is known.

    Examples
    --------
    >>> overlap_fraction_warning("overlap", 0.5, 40)
    'overlap as a fraction of the patch is deprecated; give pixels (overlap=20 for 0.5 of 40)'
    """
    text = f"{where} as a fraction of the patch is deprecated; give pixels"
    if isinstance(patch_size, (int, np.integer)) and not isinstance(patch_size, bool) and patch_size >= 2:
        n = int(patch_size)
        text += f" (overlap={int(np.clip(round(overlap * n), 1, n - 1))} for {overlap!r} of {n})"
    return text


class OverlapSpec(ParamSpec):
    """``overlap``: pixels, or a deprecated fraction such as ``0.5`` (kept as given).

    A fraction warns once, at construction (:meth:`texsyn.methods.gaussian.LG.deprecated_values`);
    ``fit`` checks the pixels it stands for and never changes the parameter.
    """

    def parse(self, text: str, method: str) -> Any:
        try:
            value = float(text)
        except ValueError:
            value = None
        if value is not None and 0 < value < 1:
            return value
        return super().parse(text, method)

    def check(self, value: Any, method: str) -> Any:
        if isinstance(value, (float, np.floating)) and not 0 < value < 1:  # pixels are integers
            raise InputError(
                f"parameter {self.name!r} of method {method!r} is a number of pixels (an integer), "
                f"or a deprecated fraction in (0, 1); got {value!r}"
            )
        return value if isinstance(value, (float, np.floating)) else super().check(value, method)


def clamp_neighbours(m: int, source: PatchSource, name: str) -> int:
    """``m``, or the number of exemplar patches when there are fewer (with a warning)."""
    if m > source.n_anchors:
        warnings.warn(
            f"n_neighbors={m} is more than the {source.n_anchors} exemplar patches of method "
            f"{name!r}; using {source.n_anchors}",
            UserWarning,
            stacklevel=4,
        )
        return source.n_anchors
    return m


def local_gaussian_bytes(m: int, dim: int) -> float:
    """Gathered neighbour patches, the centred factor and a conditional draw of ``dim`` entries."""
    return 16.0 * m * dim + 8.0 * m * m + 32.0 * dim


# ---------------------------------------------------------------------------- the steps
def draw(gauss: LocalGaussian, mode: str, rng: np.random.Generator) -> np.ndarray:
    """A draw of ``gauss`` (line 7), or its mean (the most probable patch) when ``mode='mean'``."""
    return gauss.mean if mode == "mean" else gauss.sample(rng)


def first_patch(
    source: PatchSource, exemplar: np.ndarray, m: int, how: str, mode: str, rng, energies: dict | None = None
) -> np.ndarray:
    """Line 1: the exemplar patch at ``t0``, the first draw of ``rng``, copied or resampled.

    ``how='copy'`` copies it (the paper's Fig. 4); ``'gaussian'`` draws from (or, with
    ``mode='mean'``, takes the mean of) the local Gaussian of its neighbours.
    """
    n = source.size
    t0 = int(rng.integers(source.n_anchors))
    i, j = np.unravel_index(t0, source.anchor_shape)
    patch = exemplar[i : i + n, j : j + n]
    if how == "copy":
        return patch.copy()
    gauss = source.neighbour_gaussian(patch, None, m, energies=energies)
    return draw(gauss, mode, rng).reshape(patch.shape)


def lg_patch(
    block: Block, source: PatchSource, m: int, mode: str, rng, energies: dict | None = None
) -> np.ndarray:
    """Lines 5-7 for LG: a draw of the local Gaussian of the block's neighbours (section 2.2)."""
    gauss = source.neighbour_gaussian(block.values, block.known.astype(np.float64), m, energies=energies)
    return draw(gauss, mode, rng).reshape(block.values.shape)


def conditional_patch(
    block: Block,
    source: PatchSource,
    m: int,
    mode: str,
    sigma: float,
    theta: float | None,
    rng,
    energies: dict | None = None,
    looseness: float = 0.0,
) -> np.ndarray:
    """Lines 5-7 for CLG (``theta=None``) and RCLG: the Gaussian conditioned on the overlap.

    RCLG first moves the overlap values by noise of std ``theta`` (ancestral sampling of
    eqs. 7-8; drawn in ``'sample'`` mode even when ``theta`` is 0), then conditions on them
    (eqs. 4-6, :meth:`~texsyn.models.gaussian.LocalGaussian.conditional`).
    """
    old, mask = block.values, block.known
    gauss = source.neighbour_gaussian(old, mask.astype(np.float64), m, energies=energies)
    entries = np.broadcast_to(mask[..., None], old.shape).ravel()
    given = old.ravel()[entries]
    if theta is not None and mode == "sample":
        given = given + theta * rng.standard_normal(given.size)
    draw_all = gauss.posterior(entries, given, sigma, None if mode == "mean" else rng, looseness=looseness)
    flat = np.empty(old.size)
    flat[entries] = given
    flat[~entries] = draw_all[~entries]
    patch = flat.reshape(old.shape)
    if looseness > 0 and mask.any() and not mask.all():
        # loose conditioning: the draw explains the overlap only up to its noise, so the
        # overlap's residual is carried into the free pixels, fading with the distance
        residual = np.zeros(old.size)
        residual[entries] = given - draw_all[entries]
        patch = patch + continue_residual(residual.reshape(old.shape), mask, FADE * old.shape[0])
    return patch


#: how far the overlap's residual reaches into the free pixels, as a share of the patch side
FADE = 0.1


def continue_residual(residual: np.ndarray, known: np.ndarray, length: float) -> np.ndarray:
    """Extend ``residual`` ``(n, n, C)`` from the ``known`` pixels into the others.

    Each free pixel takes the residual of its nearest known pixel times ``exp(-d / length)``,
    ``d`` the distance in pixels between them; known pixels get 0 (their values are kept).
    ``docs/methods/local_gaussian.md``, "Conditioning".
    """
    distance, (rows, cols) = distance_transform_edt(~known, return_indices=True)
    fade = np.where(known, 0.0, np.exp(-distance / max(length, 1e-9)))
    return residual[rows, cols] * fade[..., None]


def match_exemplar_marginals(image: np.ndarray, exemplar: np.ndarray, *, patch_size: int = 1) -> np.ndarray:
    """Give every channel of ``image`` ``(H, W, C)`` the histogram of the exemplar's channel.

    The LG family's optional last step (``histogram='match'``; not in Raad et al. 2016,
    ``docs/methods/local_gaussian.md``, "Marginals"): Gaussian draws have unbounded tails
    (LG's bright specks) and blends of ``m`` neighbours lose part of the contrast; exact
    matching (:func:`texsyn.ops.histogram.match_histogram`, ties by position) keeps every
    value inside the exemplar's range and restores its marginals.

    An output with fewer pixels than one ``patch_size x patch_size`` patch is not a sample of
    the exemplar's histogram (a 13x9 crop of a texture spans a fraction of its range):
    matching would stretch it to the whole range, so it is only clipped to the exemplar's
    per-channel range.
    """
    x = np.asarray(image, dtype=np.float64)
    ex = as_channels(np.asarray(exemplar, dtype=np.float64))
    if x.shape[0] * x.shape[1] < patch_size * patch_size:
        lo, hi = ex.min(axis=(0, 1)), ex.max(axis=(0, 1))
        return np.clip(x, lo, hi)
    return np.stack([match_histogram(x[..., c], ex[..., c]) for c in range(x.shape[2])], axis=-1)


#: line 8, how a new patch joins the block: boundary cut, average (eq. 15) or overwrite
PASTE: dict[str, Callable[[Block, np.ndarray], np.ndarray]] = {
    "quilt": lambda block, new: paste_cut(block.values, new, block.known),
    "average": lambda block, new: paste_average(block.values, new, block.known),
    "none": lambda block, new: new,
}

#: :data:`PASTE` on a torus: the boundary cut also runs through the known strips on the
#: right and at the bottom (the last column and row, ``docs/tiling.md``); averaging and
#: overwriting treat every known pixel alike already
PASTE_TORUS: dict[str, Callable[[Block, np.ndarray], np.ndarray]] = {
    **PASTE,
    "quilt": lambda block, new: paste_cut(block.values, new, block.known, every_side=True),
}


def torus_free(patch_size: int) -> int:
    """Pixels the last block of a row (column) keeps free between its two overlaps on a torus
    (:func:`~texsyn.drivers.raster.torus_positions`): a quarter of the patch. With one free
    pixel the draw is squeezed between two given sides that the model fits only in part: on
    a 256x256 brick output CLG's and RCLG's line at the wrap measured 3-4 times its
    neighbours, and LG's wrap 1.7 times the interior's strong lines; with a quarter, at most
    1.25 and 0.94 (``docs/tiling.md``, "On a torus")."""
    return max(1, patch_size // 4)


# ---------------------------------------------------------------------------- the loop
def _first_and_choose(
    exemplar: np.ndarray,
    source: PatchSource,
    m: int,
    model: str,
    mode: str,
    sigma: float,
    theta: float,
    seed_patch: str,
    rng: np.random.Generator,
    looseness: float,
) -> tuple[np.ndarray, Callable[[Block], np.ndarray]]:
    """Line 1's seed patch (drawn first) and lines 5-7 as the loop's ``choose`` step.

    Both share one cache of the search's energy terms, made here for one sampling call.
    """
    energies: dict = {}  # this call's cache of the search's energy terms
    first = first_patch(source, exemplar, m, seed_patch, mode, rng, energies)
    if model == "lg":

        def choose(block: Block) -> np.ndarray:
            return lg_patch(block, source, m, mode, rng, energies)

    else:
        moved = theta if model == "rclg" else None

        def choose(block: Block) -> np.ndarray:
            return conditional_patch(block, source, m, mode, sigma, moved, rng, energies, looseness)

    return first, choose


def single_scale(
    exemplar: np.ndarray,
    source: PatchSource,
    shape: tuple[int, int],
    *,
    overlap: int,
    m: int,
    model: str,
    seam: str,
    mode: str,
    sigma: float,
    theta: float,
    seed_patch: str,
    rng: np.random.Generator,
    reporter: Reporter | None,
    looseness: float = 0.0,
    torus: bool = False,
) -> np.ndarray:
    """Algorithm 2 (LG, CLG or RCLG) on an enlarged canvas, cropped to ``shape``.

    1. a seed patch in the top-left corner (:func:`first_patch`);
    2. in raster order, blocks of side ``n`` every ``n - overlap`` pixels: each block's patch
       from the local Gaussian of its ``m`` neighbours (``model='lg'``: :func:`lg_patch`;
       ``'clg'``, ``'rclg'``: conditioned on the overlap, :func:`conditional_patch`), joined
       by ``seam`` (:data:`PASTE`).

    :func:`single_scale_rows` runs the same loop holding one row of blocks.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W, C)
        The scale synthesised (where the seed patch is read).
    source : PatchSource
        Its patches and their search (built by ``fit``; not changed here).
    shape : (int, int)
        Output size.
    overlap, m : int
        Overlap ``o`` in pixels and neighbours ``m``.
    model : {'lg', 'clg', 'rclg'}
    seam : {'quilt', 'average', 'none'}
    mode : {'sample', 'mean'}
    sigma, theta : float
        Regularisation (CLG, RCLG) and overlap noise (RCLG).
    looseness : float
        How loosely a conditioned patch follows its overlap (CLG, RCLG;
        :meth:`~texsyn.models.gaussian.LocalGaussian.conditional`).
    seed_patch : {'gaussian', 'copy'}
    rng : numpy.random.Generator
    reporter : Reporter or None
        Receives ``(done, total)`` after every patch but the seed.
    torus : bool
        Synthesise on the output's torus (tileable outputs, ``docs/tiling.md``, "On a
        torus"): the blocks (:func:`~texsyn.drivers.raster.torus_positions`) wrap across the
        edges, each patch's Gaussian is estimated from and conditioned on every known pixel
        of its block, the wrapped ones included, and the cut runs through every known strip
        (:data:`PASTE_TORUS`); the canvas is the output.
    """
    n = source.size
    step = n - overlap
    first, choose = _first_and_choose(
        exemplar, source, m, model, mode, sigma, theta, seed_patch, rng, looseness
    )
    if torus:
        canvas = np.zeros(tuple(shape) + (exemplar.shape[2],))
        free = torus_free(n)
        rows, cols = (torus_positions(side, n, step, free=free) for side in shape)
        fill_blocks(
            canvas, rows, cols, n, choose, PASTE_TORUS[seam], seed=first, reporter=reporter, torus=True
        )
        return canvas
    canvas = np.zeros(block_canvas(shape, n, step) + (exemplar.shape[2],))
    rows, cols = block_positions(shape[0], n, step), block_positions(shape[1], n, step)
    fill_blocks(canvas, rows, cols, n, choose, PASTE[seam], seed=first, reporter=reporter)
    return crop_to_output(canvas, shape)


def single_scale_rows(
    exemplar: np.ndarray,
    source: PatchSource,
    shape: tuple[int, int],
    *,
    overlap: int,
    m: int,
    model: str,
    seam: str,
    mode: str,
    sigma: float,
    theta: float,
    seed_patch: str,
    rng: np.random.Generator,
    reporter: Reporter | None,
    looseness: float = 0.0,
) -> Iterator[np.ndarray]:
    """:func:`single_scale` holding one row of blocks: its output rows, top to bottom.

    The same draws in the same order (the seed patch, then the blocks in raster order), the
    same blocks and the same pastes, through :func:`texsyn.drivers.raster.fill_block_rows`:
    the rows put together are :func:`single_scale`'s output, byte for byte, and the memory
    is ``n`` rows of the canvas whatever the output's height (``docs/performance.md``,
    "Any size in bounded memory"). Parameters as in :func:`single_scale`.

    Yields
    ------
    ndarray, shape (k, W, C)
        The next ``k`` finished rows (float64, not clipped).
    """
    n = source.size
    step = n - overlap
    first, choose = _first_and_choose(
        exemplar, source, m, model, mode, sigma, theta, seed_patch, rng, looseness
    )
    rows, cols = block_positions(shape[0], n, step), block_positions(shape[1], n, step)
    yield from fill_block_rows(
        shape, exemplar.shape[2], rows, cols, n, choose, PASTE[seam], seed=first, reporter=reporter
    )
