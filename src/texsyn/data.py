"""Built-in exemplars: real textures shipped with scikit-image (CC0), no download needed."""

from __future__ import annotations

import numpy as np

from .errors import InputError

__all__ = ["BUILTIN", "BUILTIN_PREFIX", "exemplar"]

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
