"""Output shape and canvas policy: written once for every method (``docs/architecture.md``).

- the default output size is twice the exemplar in each direction (:func:`default_output_shape`);
- a method that needs a larger or better-aligned working canvas computes it with
  :func:`padded_canvas` (at least a size, a multiple of a step) or :func:`power_of_two_canvas`
  (for transforms that halve it down to a fixed coarse grid) and returns
  :func:`crop_to_output` of it (the top-left corner);
- an input image analysed on such a canvas is extended to it at the bottom and right
  (:func:`extend_to_canvas`), and the result cropped back.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = [
    "crop_to_output",
    "default_output_shape",
    "extend_to_canvas",
    "padded_canvas",
    "power_of_two_canvas",
]


def default_output_shape(exemplar_shape: tuple[int, ...]) -> tuple[int, int]:
    """Twice the exemplar's height and width: the size ``sample(None)`` gives.

    Examples
    --------
    >>> default_output_shape((64, 48, 3))
    (128, 96)
    """
    return (2 * int(exemplar_shape[0]), 2 * int(exemplar_shape[1]))


def padded_canvas(
    shape: tuple[int, int], *, minimum: int | tuple[int, int] = 1, multiple: int = 1, extra: int = 0
) -> tuple[int, int]:
    """The working canvas for an output of ``shape``.

    Each side is ``shape + extra``, at least ``minimum``, rounded up to a multiple of
    ``multiple``.

    Examples
    --------
    >>> padded_canvas((30, 50), minimum=32)
    (32, 50)
    >>> padded_canvas((30, 50), multiple=8)
    (32, 56)
    """
    low: tuple[int, int] = (minimum, minimum) if isinstance(minimum, (int, np.integer)) else tuple(minimum)  # type: ignore[assignment]
    out = []
    for side, least in zip(shape[:2], low):
        n = max(int(side) + int(extra), int(least))
        out.append(-(-n // multiple) * multiple)
    return (out[0], out[1])


def power_of_two_canvas(shape: tuple[int, int], *, minimum: int = 1, square: bool = False) -> tuple[int, int]:
    """The working canvas whose sides are powers of two, for an output of ``shape``.

    Each side, at least ``minimum``, is rounded up to the next power of two; with ``square``
    both sides are that of the longer one.

    Examples
    --------
    >>> power_of_two_canvas((30, 70))
    (32, 128)
    >>> power_of_two_canvas((3, 5), minimum=4, square=True)
    (8, 8)
    """
    sides = [max(int(side), int(minimum), 1) for side in shape[:2]]
    if square:
        sides = [max(sides)] * 2
    out = [1 << (n - 1).bit_length() for n in sides]
    return (out[0], out[1])


def extend_to_canvas(
    image: np.ndarray,
    canvas: tuple[int, int],
    *,
    mode: Literal["symmetric", "reflect", "edge", "wrap"] = "symmetric",
) -> np.ndarray:
    """An image extended at the bottom and right to the ``canvas`` size (channels kept).

    The counterpart of :func:`crop_to_output` for inputs (``numpy.pad`` with ``mode``).

    Examples
    --------
    >>> extend_to_canvas(np.arange(3.0)[None, :], (2, 4)).tolist()
    [[0.0, 1.0, 2.0, 2.0], [0.0, 1.0, 2.0, 2.0]]
    """
    h, w = image.shape[:2]
    rest = ((0, 0),) * (image.ndim - 2)
    return np.pad(image, ((0, int(canvas[0]) - h), (0, int(canvas[1]) - w)) + rest, mode=mode)


def crop_to_output(canvas: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The top-left ``shape`` of a working canvas (rows, columns; channels kept).

    Examples
    --------
    >>> crop_to_output(np.zeros((8, 9, 3)), (4, 5)).shape
    (4, 5, 3)
    """
    return canvas[: int(shape[0]), : int(shape[1])]
