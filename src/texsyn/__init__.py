"""texsyn: exemplar-based texture synthesis behind one API.

The package front (``docs/architecture.md``, layer 12): :func:`synthesize`, :func:`modify`,
:func:`animate`, the method registry (:data:`METHODS`, :func:`make_method`) and the saved
models (:func:`save`, :func:`load`; ``docs/persistence.md``).

>>> import texsyn
>>> exemplar = texsyn.data.exemplar("brick")
>>> texture = texsyn.synthesize(exemplar, method="quilting", shape=(256, 256), rng=0)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import data
from ._lazy import lazy_exports
from .methods import (
    METHODS,
    Progress,
    SynthesisResult,
    TextureSynthesizer,
    get_method,
    make_method,
)

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from ._version import __version__
    from .materials import StackResult, synthesize_stack
    from .methods import Frame, Modification
    from .persistence import load, save

# the method modules and the model files load on first use (``docs/performance.md``)
__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "Frame": "methods",
        "Modification": "methods",
        "__version__": "_version",
        "load": "persistence",
        "save": "persistence",
        "StackResult": "materials",
        "synthesize_stack": "materials",
    },
)

__all__ = [
    "animate",
    "Frame",
    "METHODS",
    "Modification",
    "Progress",
    "SynthesisResult",
    "TextureSynthesizer",
    "__version__",
    "data",
    "get_method",
    "load",
    "make_method",
    "modify",
    "save",
    "StackResult",
    "synthesize",
    "synthesize_stack",
]


def synthesize(
    exemplar: np.ndarray,
    method: str = "quilting",
    shape: tuple[int, int] | None = None,
    rng: None | int | np.random.Generator = None,
    *,
    tileable: bool = False,
    **params,
) -> np.ndarray:
    """Synthesise a texture from an exemplar in one call (construct, fit, sample).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W), (H, W, 3), or with alpha (H, W, 2) or (H, W, 4)
        Float values in [0, 1] (uint8/uint16 are scaled). An alpha channel is kept and
        carried like the colour (:func:`synthesize_stack`, ``docs/materials.md``): along the
        source map of copy-based methods, as a joint channel of the methods that synthesise
        channels jointly; the other methods drop it with a warning.
    method : str
        A name of :data:`METHODS` (``texsyn methods`` lists them).
    shape : (int, int), optional
        Output ``(height, width)``; twice the exemplar by default.
    rng : None, int or numpy.random.Generator
        The same value gives the same texture.
    tileable : bool
        Make the output wrap seamlessly in both directions (``docs/tiling.md``).
    **params
        Hyperparameters of the method.

    Returns
    -------
    ndarray of float32 in [0, 1], same rank and channels as the exemplar (alpha included
    unless the method drops it).

    Examples
    --------
    >>> exemplar = data.exemplar("gravel", size=32)
    >>> texture = synthesize(exemplar, "random_phase", shape=(48, 64), rng=0)
    >>> texture.shape, texture.dtype
    ((48, 64), dtype('float32'))
    >>> bool((texture == synthesize(exemplar, "random_phase", shape=(48, 64), rng=0)).all())
    True
    """
    arr = np.asarray(exemplar) if not isinstance(exemplar, str) else exemplar
    if isinstance(arr, np.ndarray) and arr.ndim == 3 and arr.shape[2] in (2, 4):
        from .materials import synthesize_stack

        image = synthesize_stack(arr, (), method, shape, rng=rng, tileable=tileable, **params).images[0]
        return np.clip(image, 0.0, 1.0).astype(np.float32)
    return make_method(method, **params).fit(exemplar).sample(shape, rng=rng, tileable=tileable)


def modify(
    texture: np.ndarray,
    exemplar: np.ndarray,
    ratio: float = 0.5,
    *,
    equalize: bool = True,
    grid_boundary: str = "symmetric",
    per_level: bool = False,
    thresholding: str = "local",
    callback=None,
    **params,
) -> np.ndarray:
    """Modify a texture toward an exemplar with the patch-valued wavelet transform (Peyré 2007, 5.2).

    ``texture`` is analysed with the exemplar's patches, its wavelet details are removed on
    the share ``ratio`` of the grid where they carry the least energy and the transform is
    inverted: ``ratio = 0`` rebuilds the texture from exemplar pixels, ``ratio = 1`` is a pure
    synthesis of the exemplar, values in between move steadily from one to the other
    (``docs/methods/patch_wavelet.md``).

    Parameters
    ----------
    texture, exemplar : ndarray, shape (H, W) or (H, W, 3)
        Float values in [0, 1] (uint8/uint16 are scaled); any sizes.
    ratio : float
        In [0, 1]: the share of the grid synthesised (``thresholding='local'``), or the
        threshold as a fraction of the largest detail magnitude (``'coefficient'``, the
        paper's literal rule).
    equalize : bool
        Match the exemplar's colour histograms to the texture's first.
    grid_boundary : {'symmetric', 'periodic'}
        Border rule of the transform ('periodic' for a texture that tiles).
    per_level : bool
        Threshold every level against its own largest detail.
    thresholding : {'local', 'coefficient'}
        How details are removed (:meth:`texsyn.methods.PatchWavelet.modify`).
    callback : callable, optional
        Receives :class:`Progress` records.
    **params
        Hyperparameters of the ``patch_wavelet`` method.

    Returns
    -------
    ndarray of float32 in [0, 1], the texture's size with the exemplar's channels.

    See Also
    --------
    texsyn.methods.PatchWavelet.modify : the same, returning the source map and magnitudes.

    Examples
    --------
    >>> exemplar = data.exemplar("gravel", size=32)
    >>> texture = synthesize(data.exemplar("grass", size=32), "random_phase", rng=0)
    >>> halfway = modify(texture, exemplar, ratio=0.5, min_width=4)
    >>> halfway.shape == texture.shape
    True
    """
    method = make_method("patch_wavelet", **params).fit(exemplar)
    result = method.modify(
        texture,
        ratio,
        equalize=equalize,
        grid_boundary=grid_boundary,
        per_level=per_level,
        thresholding=thresholding,
        callback=callback,
    )
    return result.image


def animate(
    exemplar: np.ndarray,
    n_frames: int = 60,
    shape: tuple[int, int] | None = None,
    rng: None | int | np.random.Generator = None,
    *,
    callback=None,
    loop: int = 0,
    **params,
):
    """Frames of a fluid-driven dynamic texture (Peyré 2008, grouplets), as a generator.

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3)
        An oriented texture (wood grain, fibres, waves, turbulence...).
    n_frames : int
        Number of frames.
    shape : (int, int), optional
        Frame size; the exemplar's by default.
    rng : None, int or numpy.random.Generator
    loop : int
        When positive, the sequence loops seamlessly: the simulation steers the flow back to
        its start over the last ``loop`` frames (``Grouplets.animate``).
    **params
        Hyperparameters of the ``grouplets`` method (``speed`` in pixels per frame,
        ``turbulence``, ``viscosity``, ``initial_flow``...; ``docs/methods/grouplets.md``).

    Yields
    ------
    Frame
        ``frame.image`` (float32 in [0, 1]) and ``frame.flow`` (the velocity field).

    Examples
    --------
    >>> frames = list(animate(data.exemplar("grass", size=32), n_frames=2, rng=0, n_iterations=1))
    >>> len(frames), frames[0].image.shape, frames[0].flow.shape
    (2, (32, 32), (32, 32, 2))
    """
    method = make_method("grouplets", **params).fit(exemplar)
    yield from method.animate(n_frames, shape, rng=rng, callback=callback, loop=loop)
