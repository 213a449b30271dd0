"""Tileable outputs of the methods that are not periodic by construction: a quilted seam band.

``sample(..., tileable=True)`` (``docs/tiling.md``): the method draws its output as usual;
the output is then rolled by half its size, so that its wrap-around seams become a cross in
the middle, and a band across each seam is filled again by image quilting from the
exemplar (Efros and Freeman 2001, section 2.1; :meth:`texsyn.methods.quilting.Quilting.fill`):
every block is chosen for its error on the known pixels on *both* sides of the band and
joined to the blocks before it along the minimum-error cut; then, on each side of the band,
the blocks go on into the method's pixels as far as a minimum-error cut through a zone half
the band wide (the join is a cut where blocks and method agree best, not a straight line),
and the image is rolled back. The output then wraps in both directions, with no cross-fade
or blur: every pixel is the method's or an exemplar pixel. The price is a band of copied
exemplar blocks about two thirds of a block wide across each wrap. A copy-based method's
source map takes the blocks' exemplar positions there.
"""

from __future__ import annotations

import numpy as np

from ..ops.seams import min_path
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
    zone = max(1, band // 2)
    shift = (height // 2, width // 2)
    rolled = np.roll(image, shift, axis=(0, 1))
    known = np.ones((height, width), dtype=bool)
    rows = (shift[0] - band // 2, shift[0] + (band + 1) // 2)
    cols = (shift[1] - band // 2, shift[1] + (band + 1) // 2)
    known[rows[0] : rows[1], :] = False
    known[:, cols[0] : cols[1]] = False
    filled = BandQuilting(patch_size=patch).fit(exemplar).fill(rolled, known, rng=rng)
    out = np.array(filled.image, dtype=np.float32)
    positions = np.array(filled.source_map)  # the blocks' exemplar positions in the band, -1 elsewhere
    method_source = None if source is None else np.roll(source, shift, axis=(0, 1)).astype(np.int32)
    ex = np.asarray(exemplar, dtype=np.float32)
    # the band's edges: the blocks continue into the method's pixels, cut where they agree best;
    # first the vertical band's two edges, then (on the transposed arrays) the horizontal one's
    _cut_into_edges(out, positions, method_source, ex, cols, zone)
    out_t = np.ascontiguousarray(np.swapaxes(out, 0, 1))
    positions_t = _transposed_positions(positions)
    source_t = None if method_source is None else _transposed_positions(method_source)
    _cut_into_edges(out_t, positions_t, source_t, np.ascontiguousarray(np.swapaxes(ex, 0, 1)), rows, zone)
    back = (-shift[0], -shift[1])
    out = np.roll(np.swapaxes(out_t, 0, 1), back, axis=(0, 1))
    if source_t is None:
        return out, None
    joined = np.where(known[..., None], _transposed_positions(source_t), _transposed_positions(positions_t))
    return out, np.roll(joined, back, axis=(0, 1))


def _transposed_positions(positions: np.ndarray) -> np.ndarray:
    """A map of (row, column) positions of the transposed image (and exemplar), as a copy."""
    return np.ascontiguousarray(np.swapaxes(positions, 0, 1)[..., ::-1])


def _cut_into_edges(
    image: np.ndarray,
    positions: np.ndarray,
    method_source: np.ndarray | None,
    exemplar: np.ndarray,
    band: tuple[int, int],
    zone: int,
) -> None:
    """Replace the straight joins at the two edges of the vertical band ``band`` (columns
    ``lo .. hi``) by minimum-error cuts (Efros and Freeman 2001, section 2.1), in place.

    Each band block goes on into the ``zone`` columns beside the band (its exemplar
    continuation, read from the band's edge pixel); the pixels of the zone between the band
    and the cut take the block's, the others keep the method's, and the cut runs where the
    two differ least. ``positions`` (and ``method_source``) get the blocks' positions there.
    """
    lo, hi = band
    h0, w0 = exemplar.shape[:2]
    ex = exemplar if exemplar.ndim == 3 else exemplar[..., None]
    img = image if image.ndim == 3 else image[..., None]
    for side in (-1, 1):  # left of the band, then right of it
        edge = lo if side < 0 else hi - 1
        start = positions[:, edge]  # (H, 2) exemplar position of the band's edge pixel
        steps = np.arange(1, zone + 1)
        columns = edge + side * steps  # the zone, outward from the band
        ex_rows = np.repeat(start[:, :1], zone, axis=1)
        ex_cols = start[:, 1:2] + side * steps[None, :]
        valid = (
            (start[:, :1] >= 0)
            & (ex_cols >= 0)
            & (ex_cols < w0)
            & (columns[None, :] >= 0)
            & (columns[None, :] < img.shape[1])
        )
        safe_rows, safe_cols = np.clip(ex_rows, 0, h0 - 1), np.clip(ex_cols, 0, w0 - 1)
        block = ex[safe_rows, safe_cols]  # (H, zone, C)
        here = img[:, np.clip(columns, 0, img.shape[1] - 1)]
        error = np.where(valid, np.sum((here - block) ** 2, axis=2), 1e9)
        # the cut: per row, how many zone columns (from the band outward) take the block's pixels
        taken = min_path(error[:, ::-1])  # column index counted from the outer edge of the zone
        inner = zone - taken  # 1 .. zone pixels next to the band
        take = (steps[None, :] <= inner[:, None]) & valid
        r_idx, k_idx = np.nonzero(take)
        img[r_idx, columns[k_idx]] = block[r_idx, k_idx]
        positions[r_idx, columns[k_idx], 0] = safe_rows[r_idx, k_idx]
        positions[r_idx, columns[k_idx], 1] = safe_cols[r_idx, k_idx]
        if method_source is not None:
            method_source[r_idx, columns[k_idx]] = positions[r_idx, columns[k_idx]]
