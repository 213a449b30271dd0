"""texsyn: exemplar-based texture synthesis behind one API.

>>> import texsyn
>>> exemplar = texsyn.data.exemplar("brick")
>>> texture = texsyn.synthesize(exemplar, method="quilting", shape=(256, 256), rng=0)
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import numpy as np

from . import data
from .methods import (
    METHODS,
    Progress,
    SynthesisResult,
    TextureSynthesizer,
    get_method,
    make_method,
)

try:
    __version__ = version("texsyn")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "METHODS",
    "Progress",
    "SynthesisResult",
    "TextureSynthesizer",
    "__version__",
    "data",
    "get_method",
    "make_method",
    "synthesize",
]


def synthesize(
    exemplar: np.ndarray,
    method: str = "quilting",
    shape: tuple[int, int] | None = None,
    rng: None | int | np.random.Generator = None,
    **params,
) -> np.ndarray:
    """Synthesise a texture from an exemplar in one call (construct, fit, sample).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3)
        Float values in [0, 1] (uint8/uint16 are scaled).
    method : str
        A name of :data:`METHODS` (``texsyn methods`` lists them).
    shape : (int, int), optional
        Output ``(height, width)``; twice the exemplar by default.
    rng : None, int or numpy.random.Generator
        The same value gives the same texture.
    **params
        Hyperparameters of the method.

    Returns
    -------
    ndarray of float32 in [0, 1], same rank and channels as the exemplar.
    """
    return make_method(method, **params).fit(exemplar).sample(shape, rng=rng)
