"""Patch-based metrics: coherence, completeness, verbatim copies and synthesis maps.

All of them rest on one exact nearest-patch field between the synthesised image and the
exemplar (every ``n x n`` patch of each against every patch of the other, by matrix
products: :func:`texsyn.ops.nearest_both_ways`, ``docs/determinism.md``), computed once by
:func:`nearest_patch_field` and shared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..ops import extract_patches, nearest_both_ways, position_colors
from .texture import check_pair

__all__ = [
    "NearestPatchField",
    "CopyMap",
    "nearest_patch_field",
    "patch_coherence",
    "completeness",
    "copy_map",
    "innovation",
    "synthesis_map",
    "source_map_regions",
]

#: default patch side of the patch metrics
PATCH_SIZE = 7
#: per-value mean squared error below which a patch counts as a verbatim copy (about 2.5
#: grey levels of an 8-bit image)
COPY_TOLERANCE = 1e-4
#: copied regions count towards the copied share from this many pixels on (a 16x16 square)
MIN_COPY_AREA = 16 * 16


@dataclass(frozen=True)
class NearestPatchField:
    """Exact nearest patches between an image and an exemplar.

    Attributes
    ----------
    patch_size : int
    image_shape, exemplar_shape : (int, int)
    source : ndarray of int, shape (Ha, Wa, 2)
        For every top-left anchor of the image, the anchor of its nearest exemplar patch.
    distance : ndarray, shape (Ha, Wa)
        Its squared distance divided by the patch dimension (mean squared error per value).
    reverse_source : ndarray of int, shape (Ea, Eb, 2)
        For every exemplar anchor, the anchor of its nearest image patch.
    reverse_distance : ndarray, shape (Ea, Eb)
    """

    patch_size: int
    image_shape: tuple[int, int]
    exemplar_shape: tuple[int, int]
    source: np.ndarray
    distance: np.ndarray
    reverse_source: np.ndarray
    reverse_distance: np.ndarray


def nearest_patch_field(image, exemplar, *, patch_size: int = PATCH_SIZE) -> NearestPatchField:
    """Exact nearest-patch field in both directions (one blocked BLAS pass).

    Cost: about ``2 * Q * K * D`` flops for ``Q`` image patches, ``K`` exemplar patches of
    dimension ``D``; a 256x256 colour image against a 128x128 exemplar takes a few seconds.
    """
    img, ex = check_pair(image, exemplar)
    n = int(patch_size)
    if n < 1 or n > min(img.shape[0], img.shape[1], ex.shape[0], ex.shape[1]):
        raise ValueError(f"patch_size must be between 1 and the smallest image side, got {patch_size}")
    q, q_anchor = extract_patches(img, n)
    b, b_anchor = extract_patches(ex, n)
    q_idx, q_dist, b_idx, b_dist = nearest_both_ways(q, b)
    ha, wa = img.shape[0] - n + 1, img.shape[1] - n + 1
    ea, eb = ex.shape[0] - n + 1, ex.shape[1] - n + 1
    dim = q.shape[1]
    return NearestPatchField(
        patch_size=n,
        image_shape=img.shape[:2],
        exemplar_shape=ex.shape[:2],
        source=b_anchor[q_idx].reshape(ha, wa, 2),
        distance=(q_dist / dim).reshape(ha, wa),
        reverse_source=q_anchor[b_idx].reshape(ea, eb, 2),
        reverse_distance=(b_dist / dim).reshape(ea, eb),
    )


def _field(image, exemplar, patch_size, field):
    return field if field is not None else nearest_patch_field(image, exemplar, patch_size=patch_size)


def patch_coherence(image=None, exemplar=None, *, patch_size: int = PATCH_SIZE, field=None) -> float:
    """Mean distance from every image patch to its nearest exemplar patch.

    Per-value mean squared error (0 when every patch of the image occurs in the exemplar).
    Pass a precomputed ``field`` to avoid a second search.
    """
    return float(_field(image, exemplar, patch_size, field).distance.mean())


def completeness(image=None, exemplar=None, *, patch_size: int = PATCH_SIZE, field=None) -> dict:
    """How much of the exemplar the image uses, and how well it represents it.

    Returns
    -------
    dict
        ``used``: share of exemplar pixels covered by the exemplar patches that are nearest
        neighbours of some image patch (1 = the image draws on the whole exemplar);
        ``reverse_distance``: mean distance from every exemplar patch to its nearest image
        patch (per-value MSE; 0 when every exemplar patch occurs in the image).
    """
    f = _field(image, exemplar, patch_size, field)
    n = f.patch_size
    ea, eb = f.reverse_distance.shape
    used_anchor = np.zeros((ea, eb), dtype=bool)
    used_anchor[f.source[..., 0].ravel(), f.source[..., 1].ravel()] = True
    covered = np.zeros(f.exemplar_shape, dtype=bool)
    rows, cols = np.nonzero(used_anchor)
    for di in range(n):
        for dj in range(n):
            covered[rows + di, cols + dj] = True
    return {"used": float(covered.mean()), "reverse_distance": float(f.reverse_distance.mean())}


@dataclass(frozen=True)
class CopyMap:
    """Connected regions of the image copied verbatim from the exemplar.

    Attributes
    ----------
    labels : ndarray of int, shape (Ha, Wa)
        Region of every image anchor (top-left of a patch); -1 where the nearest exemplar
        patch is farther than the copy tolerance. Anchors are in one region when they are
        4-connected and their nearest patches sit at the same offset.
    offsets : ndarray of int, shape (Ha, Wa, 2)
        Exemplar anchor minus image anchor.
    areas : ndarray of int
        Pixel footprint (union of the region's patches) of every region.
    largest : float
        Footprint of the largest region as a share of the image area.
    copied_share : float
        Share of image pixels inside regions whose footprint holds at least ``min_area``
        pixels.
    """

    labels: np.ndarray
    offsets: np.ndarray
    areas: np.ndarray
    largest: float
    copied_share: float


def copy_map(
    image=None,
    exemplar=None,
    *,
    patch_size: int = PATCH_SIZE,
    tolerance: float = COPY_TOLERANCE,
    min_area: int = MIN_COPY_AREA,
    field: NearestPatchField | None = None,
) -> CopyMap:
    """Verbatim copies: connected regions of constant offset in the exact nearest-patch field.

    Parameters
    ----------
    tolerance : float
        A patch counts as copied when its nearest exemplar patch is within this per-value
        mean squared error.
    min_area : int
        Regions whose footprint has at least this many pixels count towards
        ``copied_share`` (a 16x16 square by default).
    """
    f = _field(image, exemplar, patch_size, field)
    n = f.patch_size
    ha, wa = f.distance.shape
    anchors = np.stack(list(np.mgrid[:ha, :wa]), axis=-1)
    offsets = f.source - anchors
    copied = f.distance <= tolerance
    labels = _constant_offset_regions(offsets, copied)
    n_regions = int(labels.max()) + 1
    h, w = f.image_shape
    if n_regions == 0:
        return CopyMap(labels, offsets, np.zeros(0, dtype=np.int64), 0.0, 0.0)
    # footprint: every (region, pixel) pair covered by a patch of the region, counted once
    rows, cols = np.nonzero(labels >= 0)
    region = labels[rows, cols]
    di, dj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    pix = ((rows[:, None] + di.ravel()) * w + (cols[:, None] + dj.ravel())).ravel()
    pairs = np.unique(np.repeat(region, n * n) * (h * w) + pix)
    pair_region = pairs // (h * w)
    areas = np.bincount(pair_region, minlength=n_regions)
    big = areas[pair_region] >= min_area
    copied_pixels = np.unique(pairs[big] % (h * w)).size
    return CopyMap(
        labels=labels,
        offsets=offsets,
        areas=areas,
        largest=float(areas.max() / (h * w)),
        copied_share=float(copied_pixels / (h * w)),
    )


def _constant_offset_regions(offsets: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Label 4-connected regions of equal offset among ``valid`` positions (-1 elsewhere)."""
    ha, wa = valid.shape
    index = np.arange(ha * wa).reshape(ha, wa)
    same_r = valid[:, 1:] & valid[:, :-1] & np.all(offsets[:, 1:] == offsets[:, :-1], axis=2)
    same_d = valid[1:, :] & valid[:-1, :] & np.all(offsets[1:, :] == offsets[:-1, :], axis=2)
    src = np.concatenate([index[:, :-1][same_r], index[:-1, :][same_d]])
    dst = np.concatenate([index[:, 1:][same_r], index[1:, :][same_d]])
    graph = coo_matrix((np.ones(src.size), (src, dst)), shape=(ha * wa, ha * wa))
    _, comp = connected_components(graph, directed=False)
    labels = np.full(ha * wa, -1, dtype=np.int64)
    flat_valid = valid.ravel()
    _, labels[flat_valid] = np.unique(comp[flat_valid], return_inverse=True)
    return labels.reshape(ha, wa)


def source_map_regions(source_map: np.ndarray) -> tuple[np.ndarray, float]:
    """Regions copied in one piece according to a method's own source map.

    Pixels are in one region when they are 4-connected and their sources sit at the same
    offset (source minus position). Returns the labels and the largest region's share of
    the output area.
    """
    src = np.asarray(source_map)
    h, w = src.shape[:2]
    offsets = src - np.stack(list(np.mgrid[:h, :w]), axis=-1)
    labels = _constant_offset_regions(offsets, np.ones((h, w), dtype=bool))
    return labels, float(np.bincount(labels.ravel()).max() / (h * w))


def innovation(image=None, exemplar=None, **kwargs) -> dict:
    """Summary of :func:`copy_map`: ``{"largest_copy": ..., "copied_share": ...}``.

    Both are fractions of the image area: the largest verbatim-copied region, and the share
    of pixels in copied regions of at least a 16x16 square's area. Low values mean
    innovation; a tiled exemplar scores about 1.
    """
    cm = copy_map(image, exemplar, **kwargs)
    return {"largest_copy": cm.largest, "copied_share": cm.copied_share}


def synthesis_map(
    image,
    exemplar,
    *,
    source_map: np.ndarray | None = None,
    patch_size: int = PATCH_SIZE,
    field: NearestPatchField | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pictures of where every pixel came from (Raad, Desolneux, Morel 2016, Fig. 9).

    Parameters
    ----------
    source_map : ndarray of int, shape (H, W, 2), optional
        The method's own source map; without one, every pixel takes the exemplar position
        given by the nearest-patch field (the patch containing it at the same offset).

    Returns
    -------
    exemplar_colours : ndarray, shape (H0, W0, 3)
        The exemplar coloured by position (red = row, green = column).
    image_colours : ndarray, shape (H, W, 3)
        Every image pixel coloured by its source position.
    """
    img, ex = check_pair(image, exemplar)
    h0, w0 = ex.shape[:2]
    grid = np.stack(list(np.mgrid[:h0, :w0]), axis=-1)
    if source_map is None:
        f = _field(img, ex, patch_size, field)
        ha, wa = f.distance.shape
        h, w = img.shape[:2]
        rows = np.arange(h)[:, None]
        cols = np.arange(w)[None, :]
        a_r = np.clip(rows - f.patch_size // 2, 0, ha - 1)
        a_c = np.clip(cols - f.patch_size // 2, 0, wa - 1)
        src = f.source[a_r, a_c] + np.stack(np.broadcast_arrays(rows - a_r, cols - a_c), axis=-1)
        source_map = src
    return position_colors(grid, (h0, w0)), position_colors(source_map, (h0, w0))
