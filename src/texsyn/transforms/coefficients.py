"""The one coefficients container of the transforms (``docs/architecture.md``, "Transforms").

Every transform's ``forward`` returns a :class:`Coefficients`: a read-only mapping from band
addresses to arrays, with the same addresses everywhere:

- ``(level, band)``: level 0-based, the finest first; ``band`` an orientation (steerable),
  one of the six DT-CWT subbands, or a lifting direction (patch-valued wavelets);
- ``'highpass'``: the high-pass residual, where the transform has one (steerable);
- ``'lowpass'``: the coarsest approximation (low-pass image, or the coarse coordinate map).

Code that walks all bands (histogram matching, thresholding, statistics) uses ``keys()`` and
``items()`` and works with any transform.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Hashable, Iterator
from typing import Any

__all__ = ["Coefficients"]


class Coefficients(ABC):
    """Band addresses to coefficient arrays, in a fixed order (finest first, then ``'lowpass'``).

    Subclasses (:class:`~texsyn.transforms.steerable.Pyramid`,
    :class:`~texsyn.transforms.dtcwt.DTCWTPyramid`,
    :class:`~texsyn.transforms.patch_wavelet.PatchWaveletCoefficients`) keep their own
    attributes for the transform's own layout and define :meth:`keys`, :meth:`__getitem__`
    and :attr:`levels`.

    Examples
    --------
    >>> import numpy as np
    >>> from texsyn.transforms.steerable import SteerablePyramid
    >>> pyr = SteerablePyramid((16, 16), 2, 4).forward(np.zeros((16, 16)))
    >>> isinstance(pyr, Coefficients), pyr.levels, len(pyr), list(pyr)[:2]
    (True, 2, 10, ['highpass', (0, 0)])
    """

    @property
    @abstractmethod
    def levels(self) -> int:
        """Number of levels (the coarsest has index ``levels - 1``)."""

    @abstractmethod
    def keys(self) -> list[Hashable]:
        """Every band address, the finest level first."""

    @abstractmethod
    def __getitem__(self, key: Any) -> Any:
        """The coefficients of one band address."""

    def items(self) -> list[tuple[Hashable, Any]]:
        """``(address, coefficients)`` pairs in the order of :meth:`keys`."""
        return [(k, self[k]) for k in self.keys()]

    def __iter__(self) -> Iterator[Hashable]:
        return iter(self.keys())

    def __len__(self) -> int:
        return len(self.keys())

    def __contains__(self, key: object) -> bool:
        return key in self.keys()
