"""Output shape and canvas policy: written once for every method (``docs/architecture.md``).

- the default output size is twice the exemplar in each direction (:func:`default_output_shape`);
- a method that needs a larger or better-aligned working canvas computes it with
  :func:`padded_canvas` and returns :func:`crop_to_output` of it (the top-left corner).
"""

from __future__ import annotations

import numpy as np

__all__ = ["crop_to_output", "default_output_shape", "padded_canvas"]


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


def crop_to_output(canvas: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The top-left ``shape`` of a working canvas (rows, columns; channels kept).

    Examples
    --------
    >>> crop_to_output(np.zeros((8, 9, 3)), (4, 5)).shape
    (4, 5, 3)
    """
    return canvas[: int(shape[0]), : int(shape[1])]
