"""Texture transfer: render a target image with a texture (Efros and Freeman 2001, section 3).

The output is quilted from the texture's blocks, each chosen for its agreement with the
blocks already placed and for the agreement of its correspondence map with the target's
under it; by default both maps are the blurred luminance. Several iterations refine the
result with blocks a third smaller each time, the weight of the overlap growing from
``alpha`` to 0.9 (``docs/editing.md``). The loop is :meth:`texsyn.methods.Quilting.transfer`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._validation import as_exemplar, normalize_rng
from ..errors import InputError
from ..methods import SynthesisResult, get_method, make_method
from ..ops.color import luma
from ..ops.progress import Progress

__all__ = ["TRANSFER_METHODS", "correspondence_map", "transfer"]


def correspondence_map(image: np.ndarray, blur: float = 1.0) -> np.ndarray:
    """The paper's correspondence map: the luminance (BT.601 luma) blurred by a Gaussian.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Values in [0, 1].
    blur : float
        Standard deviation of the Gaussian in pixels (0: no blur); the borders are mirrored.
    """
    from scipy import ndimage  # only the transfer needs it

    lum = luma(as_exemplar(image, name="image"))
    return ndimage.gaussian_filter(lum, blur, mode="reflect") if blur > 0 else lum


#: the methods that transfer a texture (``docs/editing.md``)
TRANSFER_METHODS = ("quilting", "efros_leung")


def transfer(
    texture: np.ndarray,
    target: np.ndarray,
    *,
    method: str = "quilting",
    alpha: float = 0.1,
    iterations: int | None = None,
    blur: float = 1.0,
    texture_map: np.ndarray | None = None,
    target_map: np.ndarray | None = None,
    rng: None | int | np.random.Generator = None,
    callback: Callable[[Progress], None] | None = None,
    **params,
) -> SynthesisResult:
    """Render ``target`` with blocks of ``texture`` (image quilting's texture transfer).

    Parameters
    ----------
    texture : ndarray, shape (H0, W0) or (H0, W0, 3)
        The texture to copy from (the output has its channels).
    target : ndarray, shape (H, W) or (H, W, 3)
        The image to follow; the output has its size.
    method : {'quilting', 'efros_leung'}
        ``'quilting'``: the paper's blocks and iterations. ``'efros_leung'``: one pass of
        pixel-by-pixel growth whose neighbourhood distance adds ``(1 - alpha) / alpha``
        times the correspondence maps' distance (``iterations`` must be 1; slow: the exact
        matrix-product search over the whole output).
    alpha : float
        Weight of the overlap error in the first iteration, in [0, 1]; the rest is the
        correspondence error. Later iterations raise it linearly to 0.9 (the paper's
        ``alpha_i = 0.8 (i - 1) / (N - 1) + 0.1`` for ``alpha = 0.1``).
    iterations : int, optional
        Passes ``N``, the block shrinking by a third after each; 3 by default (quilting),
        1 for efros_leung (its only choice).
    blur : float
        Gaussian blur (pixels) of the luminance maps.
    texture_map, target_map : ndarray, optional
        Correspondence maps to use instead of the blurred luminance (both or neither;
        ``texture_map`` of the texture's size, ``target_map`` of the target's, with the same
        channels).
    rng, callback
        As in :meth:`texsyn.TextureSynthesizer.sample`.
    **params
        Parameters of the method: for quilting ``patch_size`` (the first iteration's
        block), ``overlap`` (scaled with the block), ``tolerance``, ``boundary_cut``.

    Returns
    -------
    SynthesisResult
        The output and its source map (texture position of every pixel).
    """
    if method not in TRANSFER_METHODS:
        get_method(method)
        raise InputError(
            f"method {method!r} does not transfer textures; methods that do: {', '.join(TRANSFER_METHODS)}"
        )
    if iterations is None:
        iterations = 1 if method == "efros_leung" else 3
    if not 0.0 <= float(alpha) <= 1.0:
        raise InputError(f"alpha must lie in [0, 1], got {alpha!r}")
    if int(iterations) < 1 or int(iterations) != iterations:
        raise InputError(f"iterations must be a positive integer, got {iterations!r}")
    if (texture_map is None) != (target_map is None):
        raise InputError("give both correspondence maps (texture and target) or neither")
    if not np.isfinite(blur) or blur < 0:
        raise InputError(f"blur must be a finite number >= 0, got {blur!r}")
    tex = as_exemplar(texture, name="texture")
    aim = as_exemplar(target, name="target")
    if texture_map is None:
        texture_map, target_map = correspondence_map(tex, blur), correspondence_map(aim, blur)
    if method == "efros_leung":
        if iterations != 1:
            raise InputError("efros_leung transfers in one pass; give iterations=1 (--iterations 1)")
        if alpha == 0.0:
            raise InputError("efros_leung needs alpha > 0 (its guide weight is (1 - alpha) / alpha)")
        grower = make_method("efros_leung", **params).fit(tex)
        return grower.sample_guided(
            texture_map, target_map, weight=(1.0 - alpha) / alpha, rng=normalize_rng(rng), callback=callback
        )
    synthesizer = make_method("quilting", **params).fit(tex)
    return synthesizer.transfer(
        texture_map,
        target_map,
        alpha=float(alpha),
        iterations=int(iterations),
        rng=normalize_rng(rng),
        callback=callback,
    )
