"""Output shape and canvas policy: written once for every method (``docs/architecture.md``).

- the default output size is twice the exemplar in each direction (:func:`default_output_shape`);
- a method that needs a larger or better-aligned working canvas computes it with
  :func:`padded_canvas` (at least a size, a multiple of a step) or :func:`power_of_two_canvas`
  (for transforms that halve it down to a fixed coarse grid) and returns
  :func:`crop_to_output` of it (the top-left corner);
- an input image analysed on such a canvas is extended to it at the bottom and right
  (:func:`extend_to_canvas`), and the result cropped back;
- a large exemplar is cropped or shrunk before fitting only when asked
  (:func:`prepare_exemplar`).
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
    "prepare_exemplar",
    "prepared_exemplar_shape",
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


def prepared_exemplar_shape(
    shape: tuple[int, ...], *, crop: tuple[int, int] | None = None, max_side: int | None = None
) -> tuple[int, ...]:
    """The shape :func:`prepare_exemplar` gives an exemplar of ``shape`` (from a file's header).

    Examples
    --------
    >>> prepared_exemplar_shape((3000, 4000, 3), max_side=1024)
    (768, 1024, 3)
    >>> prepared_exemplar_shape((3000, 4000, 3), crop=(512, 512), max_side=256)
    (256, 256, 3)
    """
    h, w = int(shape[0]), int(shape[1])
    if crop is not None:
        h, w = min(h, int(crop[0])), min(w, int(crop[1]))
    if max_side is not None and max(h, w) > max_side:
        factor = max_side / max(h, w)
        h, w = max(1, round(h * factor)), max(1, round(w * factor))
    return (h, w) + tuple(shape[2:])


def prepare_exemplar(
    image: np.ndarray, *, crop: tuple[int, int] | None = None, max_side: int | None = None
) -> np.ndarray:
    """A large exemplar (a phone photo) made workable: its centre cropped, then shrunk.

    The cost of fitting grows with the exemplar (every exemplar patch is a candidate), and a
    photo's texture is usually many times larger than its patches. ``crop=(height, width)``
    keeps the central region of that size; ``max_side`` then shrinks the image (area
    averaging, ``skimage.transform.resize`` with anti-aliasing) so that its longer side is at
    most that many pixels (``docs/performance.md``, "Large exemplars").

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    crop : (int, int), optional
        Height and width of the central region kept (clipped to the image).
    max_side : int, optional
        Longest side after shrinking; images already within it are not resized.

    Returns
    -------
    ndarray
        The same image when neither applies; otherwise float values in the input's range.

    Examples
    --------
    >>> prepare_exemplar(np.ones((300, 400)), crop=(100, 200), max_side=50).shape
    (25, 50)
    """
    out = np.asarray(image)
    shape = prepared_exemplar_shape(out.shape, crop=crop, max_side=max_side)
    if crop is not None:
        h, w = min(out.shape[0], int(crop[0])), min(out.shape[1], int(crop[1]))
        top, left = (out.shape[0] - h) // 2, (out.shape[1] - w) // 2
        out = out[top : top + h, left : left + w]
    if out.shape[:2] != shape[:2]:
        from skimage.transform import resize  # loaded only to shrink

        out = resize(out, shape, order=1, anti_aliasing=True, preserve_range=True).astype(np.float32)
    return out
