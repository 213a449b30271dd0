"""Exemplars: the built-in textures (scikit-image, CC0, no download needed) and the one rule
by which a command, a batch item and the web page read an exemplar argument (``builtin:NAME``,
a file, or by default the built-in brick): :func:`load_exemplar`, :func:`read_exemplar`."""

from __future__ import annotations

import numpy as np

from .errors import InputError

__all__ = ["BUILTIN", "BUILTIN_PREFIX", "exemplar", "load_exemplar", "read_exemplar"]

#: how the command line and batch inputs name a built-in exemplar: ``builtin:brick``
BUILTIN_PREFIX = "builtin:"

#: name -> (scikit-image loader, description)
BUILTIN = {
    "brick": ("brick", "grey brick wall, 512x512 (scikit-image, CC0)"),
    "grass": ("grass", "grey grass, 512x512 (scikit-image, CC0)"),
    "gravel": ("gravel", "grey gravel, 512x512 (scikit-image, CC0)"),
}


def exemplar(name: str = "brick", *, size: int | None = 128) -> np.ndarray:
    """A built-in texture exemplar as float32 in [0, 1].

    Parameters
    ----------
    name : {'brick', 'grass', 'gravel'}
    size : int or None
        Side of the top-left square crop to return (the full 512x512 image when None).
        The default 128 keeps every method fast.
    """
    if name not in BUILTIN:
        raise InputError(f"unknown built-in exemplar {name!r}; choose one of: {', '.join(BUILTIN)}")
    from skimage import data as skdata

    image = getattr(skdata, BUILTIN[name][0])()
    if size is not None:
        if not 2 <= size <= min(image.shape[:2]):
            raise InputError(f"size must be in [2, {min(image.shape[:2])}], got {size}")
        image = image[:size, :size]
    return image.astype(np.float32) / 255.0


def _builtin_name(argument: str | None) -> str | None:
    """The built-in texture an exemplar argument names (``None``: a file)."""
    if argument is None:
        return "brick"
    return argument[len(BUILTIN_PREFIX) :] if argument.startswith(BUILTIN_PREFIX) else None


def load_exemplar(argument: str | None) -> tuple[np.ndarray, str]:
    """The exemplar an argument names as float32 in [0, 1] (a file's alpha dropped, as
    :func:`texsyn.io.read_image` reads it), and how messages name it.

    ``argument`` is ``builtin:NAME``, an image file, or ``None`` for the built-in brick.
    """
    name = _builtin_name(argument)
    if name is not None:
        return exemplar(name), f"built-in {name}"
    from .io import read_image  # the readers load on first use (docs/performance.md)

    assert argument is not None
    return read_image(argument), argument


def read_exemplar(argument: str | None):
    """The exemplar an argument names with its samples as stored (alpha kept, floats in their
    range, the bit depth and ICC profile: :class:`texsyn.io.reading.ImageFile`,
    ``docs/materials.md``), and how messages name it."""
    from .io.reading import ImageFile, read_image_file

    name = _builtin_name(argument)
    if name is not None:
        return ImageFile(exemplar(name), 8, "builtin"), f"built-in {name}"
    assert argument is not None
    return read_image_file(argument), argument
