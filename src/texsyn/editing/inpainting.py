"""Inpainting: fill the holes of an image with texture (``docs/editing.md``).

Efros and Leung (1999, section 2) grow the hole inwards from its border pixel by pixel
("constrained synthesis", their hole filling); image quilting (Efros and Freeman 2001,
section 2.1) covers it with blocks whose overlap error is measured on the known pixels. Both
copy from the known part of the image itself, or from a given exemplar, and keep the known
pixels exactly. The methods do the work (``fill`` of :class:`~texsyn.methods.EfrosLeung` and
:class:`~texsyn.methods.Quilting`); this module turns a mask into known pixels, checks the
inputs and chooses where the candidates come from.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._validation import as_exemplar, normalize_rng
from ..errors import InputError
from ..methods import SynthesisResult, get_method, make_method
from ..ops.progress import Progress

__all__ = ["FILL_METHODS", "fill", "hole_mask"]

#: the methods that fill holes, and why the others do not (``docs/editing.md``)
FILL_METHODS = ("efros_leung", "quilting")

#: largest share of a mask's pixels that may be grey (neither black nor white)
GREY_SHARE = 0.02


def hole_mask(mask: np.ndarray, shape: tuple[int, int], *, name: str = "mask") -> np.ndarray:
    """The pixels to fill (True) from a mask image: white (> 0.5) is the hole.

    Parameters
    ----------
    mask : ndarray, shape (H, W) or (H, W, C)
        Boolean, or numbers in [0, 1] (uint8 and uint16 scaled); colour channels are
        averaged. At most 2 % of the pixels may lie strictly between 0.1 and 0.9 (the
        anti-aliased edge of a painted mask); the rest must be black or white.
    shape : (int, int)
        The image's ``(height, width)``.

    Raises
    ------
    InputError
        A mask of another size, or not black and white.
    """
    arr = np.asarray(mask)
    if arr.dtype == bool:
        values = arr.astype(np.float64)
    else:
        if arr.dtype == np.uint8:
            values = arr / 255.0
        elif arr.dtype == np.uint16:
            values = arr / 65535.0
        else:
            values = np.asarray(arr, dtype=np.float64)
    if values.ndim == 3:
        values = values.mean(axis=2)
    if values.shape != tuple(shape):
        raise InputError(
            f"{name} is {values.shape[1] if values.ndim > 1 else '?'}x{values.shape[0]} pixels and the image "
            f"{shape[1]}x{shape[0]}; they must have the same size"
        )
    if not np.all(np.isfinite(values)) or values.min() < 0.0 or values.max() > 1.0:
        raise InputError(f"{name} values must lie in [0, 1] (black: keep, white: fill)")
    grey = np.count_nonzero((values > 0.1) & (values < 0.9))
    if grey > GREY_SHARE * values.size:
        raise InputError(
            f"{name} is not black and white: {100.0 * grey / values.size:.1f} % of its pixels are grey "
            f"(at most {100 * GREY_SHARE:g} % allowed); white marks the pixels to fill"
        )
    return values > 0.5


def fill(
    image: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    method: str = "efros_leung",
    exemplar: np.ndarray | None = None,
    context: int | None = None,
    rng: None | int | np.random.Generator = None,
    callback: Callable[[Progress], None] | None = None,
    **params,
) -> SynthesisResult:
    """Fill the hole of ``image`` with texture; the other pixels are kept exactly.

    Parameters
    ----------
    image : ndarray, shape (H, W), (H, W, 3), or with an alpha channel (H, W, 2|4)
        Values in [0, 1] (uint8 and uint16 scaled). Without ``mask``, the transparent
        pixels (alpha < 0.5) are the hole.
    mask : ndarray, shape (H, W) or (H, W, C), optional
        White (True) where to fill (:func:`hole_mask`).
    method : {'efros_leung', 'quilting'}
        ``'efros_leung'``: pixel by pixel, inwards from the hole's border, the pixels with
        the most known neighbours first (the paper's onion peel, section 2).
        ``'quilting'``: blocks in raster order over the hole, their error on the known
        pixels, joined by the minimum-error cut (section 2.1).
    exemplar : ndarray, optional
        Texture to copy from; by default the known part of ``image`` (only the windows or
        blocks lying wholly in it are candidates). Needed when the whole image is a hole.
    context : int, optional
        Without an exemplar: copy only from the image within ``context`` pixels of the
        hole's bounding box (less memory and time on a large photo); the whole image by
        default.
    rng, callback
        As in :meth:`texsyn.TextureSynthesizer.sample`.
    **params
        Parameters of the method (``window_size``, ``patch_size``, ...).

    Returns
    -------
    SynthesisResult
        ``image`` (float32, the channels of the input without alpha) and ``source_map``:
        where each pixel was copied from, in ``exemplar`` (or the image itself; there a
        known pixel names its own position; with an exemplar, ``-1``).

    Raises
    ------
    InputError
        An unsupported method, a mask of another size or not black and white, an image
        without a mask nor alpha, a whole-image hole without an exemplar, or a hole too
        large for any window of the known part.

    Examples
    --------
    >>> import numpy as np, texsyn.editing
    >>> stripes = np.tile((np.arange(24) % 6 < 3).astype(float), (24, 1))
    >>> hole = np.zeros((24, 24), bool)
    >>> hole[8:14, 9:15] = True
    >>> result = texsyn.editing.fill(stripes, hole, method="quilting", patch_size=6, rng=0)
    >>> bool(np.array_equal(result.image, stripes.astype(np.float32)))
    True
    """
    if method not in FILL_METHODS:
        get_method(method)  # an unknown name gets the registry's message
        raise InputError(
            f"method {method!r} cannot fill holes; methods that can: {', '.join(FILL_METHODS)} (docs/editing.md)"
        )
    pixels = np.asarray(image)
    if mask is None:
        if pixels.ndim != 3 or pixels.shape[2] not in (2, 4):
            raise InputError("give a mask (white: the pixels to fill) or an image with an alpha channel")
        alpha = as_exemplar(pixels[..., -1], name="alpha channel")
        hole = alpha < 0.5
        pixels = pixels[..., :-1]
        img = as_exemplar(pixels, name="image")
    else:
        img = as_exemplar(pixels, name="image")
        hole = hole_mask(mask, img.shape[:2])
    known = ~hole
    if context is not None and (int(context) != context or context < 1):
        raise InputError(f"context must be a positive number of pixels, got {context!r}")
    generator = normalize_rng(rng)
    synthesizer: Any = make_method(method, **params)  # a method with ``fill`` (FILL_METHODS)
    if exemplar is not None:
        texture = as_exemplar(exemplar, name="exemplar")
        if texture.ndim != img.ndim:
            kinds = ("grey", "colour")
            raise InputError(
                f"the image is {kinds[img.ndim - 2]} and the exemplar {kinds[texture.ndim - 2]}; give both grey or both colour"
            )
        synthesizer.fit(texture)
        if not known.any():  # nothing to continue: a plain synthesis of the image's size
            return synthesizer.sample_with_map(img.shape[:2], rng=generator, callback=callback)
    elif not known.any():
        raise InputError("the mask covers the whole image: there is nothing to copy from; give an exemplar")
    if known.all():
        source = (
            _own_positions(img.shape[:2]) if exemplar is None else np.full(img.shape[:2] + (2,), -1, np.int32)
        )
        return SynthesisResult(img.astype(np.float32), source)
    if exemplar is None:
        return _fill_from_image(synthesizer, img, known, context, generator, callback)
    return synthesizer.fill(img, known, rng=generator, callback=callback)


def _fill_from_image(synthesizer, img, known, context, rng, callback) -> SynthesisResult:
    """Fill from the known pixels of the image within ``context`` pixels of the hole's box."""
    height, width = known.shape
    rows, cols = np.nonzero(~known)
    if context is None:
        top, bottom, left, right = 0, height, 0, width
    else:
        top, bottom = max(0, int(rows.min()) - context), min(height, int(rows.max()) + 1 + context)
        left, right = max(0, int(cols.min()) - context), min(width, int(cols.max()) + 1 + context)
    part, part_known = img[top:bottom, left:right], known[top:bottom, left:right]
    kept = part_known[..., None] if part.ndim == 3 else part_known
    synthesizer.fit(np.where(kept, part, part[part_known].mean()))
    result = synthesizer.fill(part, part_known, exemplar_mask=part_known, rng=rng, callback=callback)
    image = img.astype(np.float32)
    image[top:bottom, left:right] = result.image
    source = _own_positions(known.shape)
    moved = result.source_map + np.array([top, left], dtype=np.int32)
    source[top:bottom, left:right] = np.where(part_known[..., None], source[top:bottom, left:right], moved)
    return SynthesisResult(image, source, result.diagnostics)


def _own_positions(shape: tuple[int, int]) -> np.ndarray:
    """Every pixel's own ``(row, col)``: the source map of pixels kept where they are."""
    return np.stack(np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij"), axis=-1).astype(
        np.int32
    )
