"""Tileable outputs of the methods that are not periodic by construction: a quilted seam band.

``sample(..., tileable=True)`` (``docs/tiling.md``): the method draws its output as usual;
the output is then rolled by half its size, so that its wrap-around seams become a cross in
the middle, and a band across each seam is filled again by image quilting from the
exemplar (Efros and Freeman 2001, section 2.1; :meth:`texsyn.methods.quilting.Quilting.fill`):
every block is chosen for its error on the known pixels on *both* sides of the band and
joined to the blocks before it along the minimum-error cut, the method's own pixels are
kept exactly, and the image is rolled back. The output then wraps in both directions, with
no cross-fade; the price is a band of copied exemplar blocks one third of a block wide
across each wrap, and a straight join at the band's edges. A copy-based method's source map
takes the blocks' exemplar positions in the band.
"""

from __future__ import annotations

import numpy as np

from .quilting import Quilting

__all__ = ["BAND_PATCH", "BandQuilting", "quilted_seam_band", "seam_band_width"]


class BandQuilting(Quilting):
    """Image quilting of the seam band, on as many channels as the method synthesised jointly
    (a material's images as channels of one image: ``docs/materials.md``); not registered."""

    max_channels = 16


#: side of the quilting blocks that fill the seam band (the quilting default), cut down to
#: the output's and the exemplar's size
BAND_PATCH = 32


def seam_band_width(patch_size: int) -> int:
    """Width of the band re-filled across each wrap: a third of a block, at least 2 pixels,
    so that every block sees known pixels on both sides of the band."""
    return max(2, patch_size // 3)


def quilted_seam_band(
    image: np.ndarray, source: np.ndarray | None, exemplar: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray | None]:
    """An output that wraps: the band across each of its seams quilted again from ``exemplar``.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The method's output, float in [0, 1], the exemplar's rank and channels.
    source : ndarray of int, shape (H, W, 2), or None
        The method's source map; in the band, the exemplar positions of the quilted blocks.
    exemplar : ndarray
        The exemplar the method was fitted on.
    rng : numpy.random.Generator
        Draws the blocks (the method's generator, after its own draws).

    Returns
    -------
    image, source : the output that wraps and its source map (``None`` stays ``None``).
    """
    height, width = image.shape[:2]
    patch = int(min(BAND_PATCH, height, width, *exemplar.shape[:2]))
    band = seam_band_width(patch)
    shift = (height // 2, width // 2)
    rolled = np.roll(image, shift, axis=(0, 1))
    known = np.ones((height, width), dtype=bool)
    known[shift[0] - band // 2 : shift[0] + (band + 1) // 2, :] = False
    known[:, shift[1] - band // 2 : shift[1] + (band + 1) // 2] = False
    filled = BandQuilting(patch_size=patch).fit(exemplar).fill(rolled, known, rng=rng)
    back = (-shift[0], -shift[1])
    out = np.roll(filled.image, back, axis=(0, 1))
    if source is None:
        return out, None
    joined = np.where(known[..., None], np.roll(source, shift, axis=(0, 1)), filled.source_map)
    return out, np.roll(joined, back, axis=(0, 1))
