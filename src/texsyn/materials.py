"""Material stacks: several images of one surface synthesised once, in register.

A game material is an albedo with its normal, height, roughness, AO and alpha images, all
of one size and aligned pixel for pixel. :func:`synthesize_stack` synthesises them so that
they stay aligned in the output (``docs/materials.md``):

- a copy-based method (``has_source_map``: quilting, efros_leung, wei_levoy, cwt,
  patch_wavelet) synthesises the guide (the albedo, without its alpha) once, and every other
  image, alpha included, is carried along the same source map
  (:func:`texsyn.ops.materials.replay`);
- a method that synthesises channels jointly (``max_channels`` above 3: lg, clg, rclg, mslg,
  random_phase, heeger_bergen) synthesises all the images as the channels of one image, so
  that its statistics (patches, spectra, colour axes) couple them;
- other methods take no extra images (one line lists those that do); an alpha channel is
  dropped with a warning, as their ``fit`` does.

Every image first goes through its :class:`~texsyn.ops.materials.LayerEncoding` (float
images outside [0, 1] are mapped affinely from their own range, never clipped; the guide's
colour may be decoded from sRGB to linear light) and comes back through it. Normal maps
are renormalised to unit length at the end.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .methods import METHODS, make_method
from .ops.materials import LayerEncoding, replay, unit_normals
from .ops.progress import Progress

__all__ = ["StackResult", "joint_methods", "replay_methods", "synthesize_stack"]


def replay_methods() -> list[str]:
    """Methods that carry extra images along their source map."""
    return sorted(n for n, c in METHODS.items() if c.has_source_map)


def joint_methods() -> list[str]:
    """Methods that synthesise extra images as joint channels."""
    return sorted(n for n, c in METHODS.items() if not c.has_source_map and c.max_channels > 3)


@dataclass(frozen=True)
class StackResult:
    """The images of a synthesised material, in the order given.

    Attributes
    ----------
    images : list of ndarray of float64
        The guide (with its alpha, when it had one) then each extra image, each with its
        input's channels and value range (:class:`~texsyn.ops.materials.LayerEncoding`).
    source_map : ndarray of int32, shape (h, w, 2), or None
        The guide's source map (copy-based methods).
    encodings : list of LayerEncoding
        How each image was taken to [0, 1] and back (what a sidecar records).
    how : str
        ``'replay'``, ``'joint'`` or ``'single'`` (no extra image).
    diagnostics : dict or None
        The method's diagnostics of the run.
    """

    images: list[np.ndarray]
    source_map: np.ndarray | None
    encodings: list[LayerEncoding] = field(default_factory=list)
    how: str = "single"
    diagnostics: dict | None = None


def _as_float(image, name: str) -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype == np.uint8:
        return arr.astype(np.float64) / 255.0
    if arr.dtype == np.uint16:
        return arr.astype(np.float64) / 65535.0
    if arr.dtype.kind not in "fb":
        raise InputError(f"{name} must be float, uint8 or uint16, got {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and not 1 <= arr.shape[2] <= 4):
        raise InputError(f"{name} must have shape (H, W) or (H, W, C) with C from 1 to 4, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} holds NaN or infinite values")
    return arr


def _channels(image: np.ndarray) -> np.ndarray:
    return image[..., None] if image.ndim == 2 else image


def synthesize_stack(
    guide: np.ndarray,
    extras: Sequence[np.ndarray] = (),
    method: str = "quilting",
    shape: tuple[int, int] | None = None,
    *,
    rng: None | int | np.random.Generator = None,
    normals: Sequence[int] = (),
    linear: bool = False,
    callback: Callable[[Progress], None] | None = None,
    tileable: bool = False,
    **params,
) -> StackResult:
    """Synthesise a material: a guide image and extra images aligned with it, in register.

    Parameters
    ----------
    guide : ndarray, shape (H, W) or (H, W, C), C from 1 to 4
        The albedo (or any image that leads the synthesis); a second (grey) or fourth (RGB)
        channel is alpha and is carried like an extra image. Float (any finite range), uint8
        or uint16.
    extras : sequence of ndarray
        Images of the guide's height and width (normal, height, roughness...), 1 to 4
        channels each, float (any finite range), uint8 or uint16.
    method : str
        A copy-based method (:func:`replay_methods`) or one that synthesises channels
        jointly (:func:`joint_methods`); any method when ``extras`` is empty.
    shape : (int, int), optional
        Output ``(height, width)``; twice the guide by default.
    rng : None, int or numpy.random.Generator
    normals : sequence of int
        Indices in ``extras`` of normal maps (3 channels): renormalised to unit length at
        the end (encoded ``(n + 1) / 2`` when their values lie in [0, 1], raw otherwise).
    linear : bool
        Synthesise the guide's colour in linear light: sRGB-decoded before, encoded after
        (alpha and extra images are never decoded).
    callback : callable, optional
        Receives :class:`~texsyn.ops.progress.Progress` records.
    tileable : bool
        Every image wraps seamlessly (``docs/tiling.md``): the guide's source map, or the joint
        image, gets the quilted seam band, so the images stay in register.
    **params
        The method's parameters.

    Returns
    -------
    StackResult

    Raises
    ------
    InputError
        Images of different sizes, a method that takes no extra images (the message lists
        those that do), a normal map without three channels.

    Examples
    --------
    >>> from texsyn import data
    >>> from texsyn.ops.color import luma
    >>> grey = data.exemplar("brick", size=48)
    >>> albedo = np.dstack([grey, grey**2, 0.5 * grey + 0.25])
    >>> height = luma(albedo)
    >>> out = synthesize_stack(albedo, [height], "quilting", (64, 64), rng=0, patch_size=12)
    >>> bool(np.allclose(out.images[1], luma(out.images[0]), atol=0.51 / 255))
    True
    """
    base = _as_float(guide, "guide")
    layers = [base] + [_as_float(x, f"extra image {i}") for i, x in enumerate(extras)]
    for i, layer in enumerate(layers[1:]):
        if layer.shape[:2] != base.shape[:2]:
            raise InputError(
                f"extra image {i} is {layer.shape[1]}x{layer.shape[0]}; every image of a material must "
                f"have the guide's size, {base.shape[1]}x{base.shape[0]}"
            )
    for i in normals:
        if not 0 <= i < len(extras) or layers[1 + i].ndim != 3 or layers[1 + i].shape[2] != 3:
            raise InputError(f"extra image {i} is marked as a normal map; a normal map has three channels")
    has_alpha = base.ndim == 3 and base.shape[2] in (2, 4)
    colour = base[..., :-1] if has_alpha else base
    if colour.ndim == 3 and colour.shape[2] == 1:
        colour = colour[..., 0]
    parts = [colour] + ([base[..., -1]] if has_alpha else []) + layers[1:]
    encodings = [LayerEncoding.of(colour, linear=linear)] + [LayerEncoding.of(p) for p in parts[1:]]
    units = [code.to_unit(p) for code, p in zip(encodings, parts)]
    model = make_method(method, **params)
    cls = type(model)
    if len(parts) > 1 and not cls.has_source_map and cls.max_channels <= 3:
        if extras:
            raise InputError(
                f"method {method!r} synthesises one image; the methods that carry a material's "
                f"images in register are {', '.join(replay_methods() + joint_methods())}"
            )
        warnings.warn(
            f"method {method!r} synthesises colour or grey only, so the alpha channel is dropped; "
            f"methods that keep it: {', '.join(replay_methods() + joint_methods())}",
            UserWarning,
            stacklevel=2,
        )
        parts, encodings, units = parts[:1], encodings[:1], units[:1]
        has_alpha = False
    if len(parts) == 1 or cls.has_source_map:
        result = model.fit(units[0]).sample_with_map(shape, rng=rng, callback=callback, tileable=tileable)
        outputs = [np.asarray(result.image, dtype=np.float64)]
        if len(parts) > 1:
            outputs += [replay(result.source_map, u) for u in units[1:]]
        how, source = ("replay" if len(parts) > 1 else "single"), result.source_map
    else:
        widths = [1 if u.ndim == 2 else u.shape[2] for u in units]
        if sum(widths) > cls.max_channels:
            raise InputError(
                f"method {method!r} synthesises at most {cls.max_channels} channels jointly; this "
                f"material has {sum(widths)}"
            )
        result = model.fit(np.concatenate([_channels(u) for u in units], axis=2)).sample_with_map(
            shape, rng=rng, callback=callback, tileable=tileable
        )
        joint, outputs, start = np.asarray(result.image, dtype=np.float64), [], 0
        for u, width in zip(units, widths):
            piece = joint[..., start : start + width]
            outputs.append(piece[..., 0] if u.ndim == 2 else piece)
            start += width
        how, source = "joint", None
    images = [code.from_unit(out) for code, out in zip(encodings, outputs)]
    first_extra = 2 if has_alpha else 1
    for i in normals:
        k = first_extra + i
        images[k] = unit_normals(images[k], encoded=encodings[k].low >= 0.0 and encodings[k].high <= 1.0)
    if has_alpha:
        guide_out = _channels(images[0])
        images = [np.concatenate([guide_out, images[1][..., None]], axis=2)] + images[2:]
        encodings = [encodings[0]] + encodings[2:]
    return StackResult(images, source, encodings, how, result.diagnostics)
