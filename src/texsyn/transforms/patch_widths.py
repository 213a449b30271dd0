"""Window widths of the patch-valued wavelet transform: which patch size each level uses.

G. Peyré, SSVM 2007, section 4.2 (``docs/methods/patch_wavelet.md``): the window of level
``j`` grows with the spacing of its samples, from ``min_width`` up to the largest window the
exemplar holds; descriptors are subsampled to at most ``max_resolution`` pixels a side.
"""

from __future__ import annotations

import math

__all__ = ["descriptor_dimension", "largest_width", "level_width", "planned_widths", "width_chain"]


def largest_width(exemplar_shape: tuple[int, ...]) -> int:
    """Largest window width an exemplar allows: the largest power of two ``<= min(H, W) / 2``."""
    h, w = int(exemplar_shape[0]), int(exemplar_shape[1])
    return 2 ** int(math.floor(math.log2(max(min(h, w) // 2, 1))))


def level_width(level: int, min_width: int, max_width: int) -> int:
    """Window width of ``level`` (1 is the finest): ``clamp(2^level, min_width, max_width)``.

    The paper's ``w_j`` is ``2^j`` pixels, twice the spacing of the samples split at level
    ``j`` (section 4); it is clamped below so that fine levels compare windows that carry
    geometry and above so that coarse levels fit in the exemplar
    (``docs/methods/patch_wavelet.md``, "Deviations").
    """
    return int(min(max(2**level, min_width), max_width))


def width_chain(min_width: int, max_width: int, feature_width: int) -> list[int]:
    """Every width a transform can use: ``min_width, 2 min_width, ... <= max_width`` and ``feature_width``."""
    out, width = [], max(int(min_width), 1)
    while width <= max_width:
        out.append(width)
        width *= 2
    return sorted(set(out) | {int(feature_width)})


def planned_widths(
    exemplar_shape: tuple[int, ...],
    *,
    min_width: int = 8,
    max_width: int | None = None,
    feature_width: int | None = None,
) -> list[int]:
    """The window widths :meth:`PatchLifting.widths` will use, from shapes alone.

    For memory estimates made before any array exists (``docs/memory.md``).

    Examples
    --------
    >>> planned_widths((40, 40))
    [8, 16]
    >>> planned_widths((128, 128), min_width=4)
    [4, 8, 16, 32, 64]
    """
    largest = largest_width(exemplar_shape)
    top = largest if max_width is None else int(min(max_width, largest))
    low = int(min(min_width, top))
    feature = int(min(feature_width or min_width, top))
    return width_chain(low, top, feature)


def descriptor_dimension(width: int, max_resolution: int, channels: int) -> int:
    """Length of the descriptor of a window of ``width``: ``min(width, max_resolution)^2 C``.

    Examples
    --------
    >>> descriptor_dimension(32, 16, 3)
    768
    """
    b = max(1, int(width) // int(max_resolution))
    return (int(width) // b) ** 2 * int(channels)
